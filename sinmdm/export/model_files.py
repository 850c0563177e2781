"""What `sinmdm calibrate` and `sinmdm quantize` share on an exported model's files: the
clip it learned (refused when it is another), one folder for its windows, and rewriting
a graph's metadata together with its sidecar."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Callable

import onnx

from ..runtime.atomic import OutputSet, file_sha256
from ..runtime.bvh import BVH, read_bvh
from ..runtime.errors import SinMDMError
from ..runtime.model import MotionModel
from ..runtime.model_format import METADATA_KEY, decode_metadata, encode_metadata, sidecar_path


def learned_clip(model: MotionModel, clip: str | os.PathLike, why: str, source_fps: float | None = None) -> BVH:
    """The clip `model` learned, read (`source_fps` overrides its frame rate); another clip
    (by the sha256 in the model's provenance) is refused, saying `why` it matters."""
    reference = read_bvh(clip)  # a missing or unreadable clip is refused here, in one line
    provenance = model.metadata["provenance"]
    expected = provenance.get("clip_sha256")
    if expected and file_sha256(clip) != expected:
        raise SinMDMError(f"{clip} is not the clip this model learned ({provenance.get('clip')!r}, sha256 "
                          f"{str(expected)[:12]}): {why}")
    if source_fps:
        reference = BVH(reference.skeleton, 1.0 / source_fps, reference.values, reference.path)
    return reference


def one_folder(files: list[Path], verb: str) -> Path:
    """The folder all of a model's windows lie in."""
    directory = files[0].parent
    if any(path.parent.resolve() != directory.resolve() for path in files):
        raise SinMDMError(f"{verb} the windows of a model in one folder")
    return directory


def write_with_metadata(output: OutputSet, name: str, graph: onnx.ModelProto, source: Path,
                        change: Callable[[dict], None]) -> None:
    """`graph` as `name` in `output`, its sinmdm metadata (read as from `source`) changed by
    `change` and validated before anything is written, the sidecar beside it the same document."""
    entry = next(e for e in graph.metadata_props if e.key == METADATA_KEY)
    document = decode_metadata(entry.value, str(source))
    change(document)
    entry.value = encode_metadata({k: v for k, v in document.items() if k not in ("format", "format_version")})
    decode_metadata(entry.value, str(source))
    output.write_bytes(name, graph.SerializeToString())
    output.write_text(sidecar_path(Path(name)).name, entry.value)
