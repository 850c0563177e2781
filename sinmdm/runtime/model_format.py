"""The metadata stored inside every exported `.onnx` file (one JSON document in
`metadata_props` under METADATA_KEY). Export writes it, the runtime reads it;
this module is the single definition of its shape."""

from __future__ import annotations

import json
from typing import Any

from .errors import ModelError

METADATA_KEY = "sinmdm"
FORMAT_NAME = "sinmdm-denoiser"
FORMAT_VERSION = 1
INPUT_NAMES = ("x_t", "t")
OUTPUT_NAME = "x0"


def encode_metadata(document: dict[str, Any]) -> str:
    return json.dumps({"format": FORMAT_NAME, "format_version": FORMAT_VERSION, **document}, separators=(",", ":"))


def decode_metadata(text: str | None, source: str) -> dict[str, Any]:
    """Parse and validate the document; ModelError names the file and the problem."""
    if text is None:
        raise ModelError(f"{source} is not a sinmdm model: no '{METADATA_KEY}' metadata")
    try:
        document = json.loads(text)
    except json.JSONDecodeError:
        raise ModelError(f"{source}: the sinmdm metadata is damaged (not JSON)") from None
    if not isinstance(document, dict) or document.get("format") != FORMAT_NAME:
        raise ModelError(f"{source} is not a sinmdm model (metadata format {document.get('format')!r})")
    version = document.get("format_version")
    if version != FORMAT_VERSION:
        raise ModelError(
            f"{source} was exported with model format {version}; this sinmdm reads format {FORMAT_VERSION}: "
            "re-export it with this version"
        )
    for key in ("codec", "alphas_cumprod", "window", "receptive_field", "model_id", "provenance"):
        if key not in document:
            raise ModelError(f"{source}: the sinmdm metadata lacks '{key}'")
    return document
