"""The metadata stored inside every exported `.onnx` file (one JSON document in
`metadata_props` under METADATA_KEY). Export writes it, the runtime reads it;
this module is the single definition of its shape, checked (types and ranges)
before anything uses it."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Callable

from .errors import ModelError
from .smoothing import MAX_SMOOTH

METADATA_KEY = "sinmdm"
FORMAT_NAME = "sinmdm-denoiser"
FORMAT_VERSION = 1
INPUT_NAMES = ("x_t", "t")
OUTPUT_NAME = "x0"
MAX_WINDOW = 1 << 16  # frames
MAX_TIMESTEPS = 100_000
MAX_FPS = 10_000.0


def sidecar_path(onnx_path: str | os.PathLike) -> Path:
    """Where the metadata document also lies as plain JSON, beside the graph (`m_w64.onnx` ->
    `m_w64.json`), for runtimes that cannot read ONNX metadata (onnxruntime-node, tract)."""
    return Path(onnx_path).with_suffix(".json")


def encode_metadata(document: dict[str, Any]) -> str:
    return json.dumps({"format": FORMAT_NAME, "format_version": FORMAT_VERSION, **document}, separators=(",", ":"))


def decode_metadata(text: str | None, source: str) -> dict[str, Any]:
    """Parse and validate the document; ModelError names the file and the problem."""
    if text is None:
        raise ModelError(f"{source} is not a sinmdm model: no '{METADATA_KEY}' metadata")
    try:
        document = json.loads(text)
    except (json.JSONDecodeError, RecursionError):  # RecursionError: JSON nested too deep to be ours
        raise ModelError(f"{source}: the sinmdm metadata is damaged (not JSON)") from None
    if not isinstance(document, dict):
        raise ModelError(f"{source} is not a sinmdm model (its metadata is not a JSON object: {_shown(document)})")
    if document.get("format") != FORMAT_NAME:
        raise ModelError(f"{source} is not a sinmdm model (metadata format {document.get('format')!r})")
    version = document.get("format_version")
    if version != FORMAT_VERSION:
        raise ModelError(
            f"{source} was exported with model format {version}; this sinmdm reads format {FORMAT_VERSION}: "
            "re-export it with this version"
        )
    for key in ("codec", "alphas_cumprod", "schedule", "window", "receptive_field", "model_id", "provenance"):
        if key not in document:
            raise ModelError(f"{source}: the sinmdm metadata lacks '{key}'")
    problem = _first_problem(document, _SCHEMA) or _alphas_problem(document)
    if problem:
        raise ModelError(f"{source}: the sinmdm metadata is invalid: {problem}")
    return document


# ------------------------------------------------------------------- the schema
# A check returns None when the value is valid, else what is wrong with it.
Check = Callable[[Any], "str | None"]


def _integer(low: int, high: int) -> Check:
    def check(value: Any) -> str | None:
        ok = isinstance(value, int) and not isinstance(value, bool) and low <= value <= high
        return None if ok else f"must be a whole number from {low} to {high}, got {_shown(value)}"
    return check


def _number(low: float, high: float, low_open: bool = False) -> Check:
    def check(value: Any) -> str | None:
        ok = (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
              and (low < value if low_open else low <= value) and value <= high)
        bound = f"{'above' if low_open else 'from'} {low:g} to {high:g}"
        return None if ok else f"must be a finite number {bound}, got {_shown(value)}"
    return check


def _of_type(kind: type, name: str) -> Check:
    def check(value: Any) -> str | None:
        return None if isinstance(value, kind) else f"must be {name}, got {_shown(value)}"
    return check


def _one_of(*allowed: str) -> Check:
    return lambda value: None if value in allowed else f"must be one of {', '.join(allowed)}, got {_shown(value)}"


def _optional(check: Check) -> Check:
    return lambda value: None if value is None else check(value)


def _list_of(item: Check, length: int | None = None) -> Check:
    def check(value: Any) -> str | None:
        if not isinstance(value, list) or (length is not None and len(value) != length):
            return f"must be a list{'' if length is None else f' of {length}'}, got {_shown(value)}"
        return next((f"item {i} {p}" for i, v in enumerate(value) if (p := item(v))), None)
    return check


def _fields(required: dict[str, Check], optional: dict[str, Check] | None = None) -> Check:
    def check(value: Any) -> str | None:
        if not isinstance(value, dict):
            return f"must be an object, got {_shown(value)}"
        return _first_problem(value, required, True) or _first_problem(value, optional or {})
    return check


def _first_problem(document: dict, schema: dict[str, Check], required: bool = False) -> str | None:
    for key, check in schema.items():
        if key not in document:
            if required:
                return f"'{key}' is missing"
            continue
        if problem := check(document[key]):
            return f"'{key}' {problem}" if not problem.startswith("'") else f"'{key}'.{problem}"
    return None


def _shown(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, float) or math.isfinite(value) else str(value)
    return text if len(text) <= 40 else text[:40] + "..."


_NAME = _of_type(str, "a string")
_SKELETON = _fields({
    "names": _list_of(_NAME),
    "parents": _list_of(_integer(-1, 1 << 20)),
    "offsets": _list_of(_list_of(_number(-3.4e38, 3.4e38), 3)),
    "channels": _list_of(_list_of(_NAME)),
    "end_sites": _list_of(_of_type(list, "a list")),
})
_CODEC = _fields({
    "skeleton": _SKELETON,
    "fps": _number(0.0, MAX_FPS, low_open=True),
    "scale": _number(0.0, 1e6, low_open=True),
    "trajectory_joint": _optional(_NAME),
    "translation_joints": _list_of(_NAME),
    "contact_joints": _list_of(_NAME),
    "contact_speed": _number(0.0, 1e6),
    "rest_translations": _list_of(_list_of(_number(-3.4e38, 3.4e38), 3)),
}, {
    "resample": _one_of("slerp", "drop"),
    "up_axis": _integer(1, 2),
    "height_axis": _integer(0, 2),
    "fixed_joints": _list_of(_NAME),
    "rest_rotations": _optional(_list_of(_list_of(_number(-1.0, 1.0), 4))),  # unit quaternions
    "contact_floors": _optional(_list_of(_number(-1e6, 1e6))),  # metres, one per contact joint
})
_SCHEMA: dict[str, Check] = {
    "codec": _CODEC,
    "alphas_cumprod": _list_of(_number(0.0, 1.0, low_open=True)),
    "schedule": _fields({"name": _NAME, "timesteps": _integer(2, MAX_TIMESTEPS)}),
    "window": _integer(1, MAX_WINDOW),
    "trained_window": _integer(1, MAX_WINDOW),
    "receptive_field": _integer(1, MAX_WINDOW),
    "model_id": _NAME,
    "provenance": _of_type(dict, "an object"),
    "model": _of_type(dict, "an object"),
    "start_position": _optional(_list_of(_number(-1e9, 1e9), 2)),
    "sampling_defaults": _optional(_fields({}, {"steps": _integer(1, MAX_TIMESTEPS), "hop": _integer(1, MAX_WINDOW),
                                                  "smooth": _number(0.0, MAX_SMOOTH)})),
    "velocity_unit": _one_of("frame", "second"),
    # the graph sees the trajectory joint from its own heading (runtime.heading)
    "heading_frame": _optional(_fields({"forward": _list_of(_number(-1.0, 1.0), 3), "start": _number(-1e6, 1e6)})),
    # mixed precision (`sinmdm quantize`): int8 convolutions while t > int8_above_t
    "precision": _optional(_fields({"int8_above_t": _integer(0, MAX_TIMESTEPS)})),
}


def _alphas_problem(document: dict) -> str | None:
    """The cumulative alphas: one per timestep of the schedule, strictly decreasing."""
    alphas, timesteps = document["alphas_cumprod"], document["schedule"]["timesteps"]
    if len(alphas) != timesteps:
        return f"'alphas_cumprod' has {len(alphas)} values for a schedule of {timesteps} timesteps"
    if any(b >= a for a, b in zip(alphas, alphas[1:])):
        return "'alphas_cumprod' must be strictly decreasing"
    return None
