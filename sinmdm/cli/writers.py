"""The GLB and GIF writers the CLI hands to the runtime's outputs (the runtime never imports
sinmdm.preview). Each writes the exact path it is given: the OutputSet's temp file."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from ..runtime.bvh import BVH
from ..runtime.errors import SinMDMError
from ..runtime.outputs import PREVIEW_EXTRA


def _write_glb(clip: BVH, path: Path) -> None:
    from ..preview.gltf import bvh_to_glb

    path.write_bytes(bvh_to_glb(clip))


def _write_gif(clips: list[BVH], path: Path) -> None:
    from ..preview.render import render_file

    render_file(clips, path)


def _check_preview_extra(option: str) -> None:
    from ..preview import import_extra

    try:
        import_extra("PIL.Image")
        import_extra("matplotlib")
    except SinMDMError:
        raise SinMDMError(f"{option} needs the preview extra: {PREVIEW_EXTRA}") from None


def extra_writers(fmt: str, preview: bool) -> dict[str, Callable]:
    """The writers `fmt` and `preview` need, after checking the preview extra is installed."""
    writers: dict[str, Callable] = {}
    if fmt == "glb":
        writers["glb"] = _write_glb  # numpy only, no extra library
    if preview:
        _check_preview_extra("--preview")
        writers["gif"] = _write_gif
    return writers
