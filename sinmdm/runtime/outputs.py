"""Writing a generation's outputs: every file of a command appears together or not at all."""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Callable

import numpy as np

from .animation import animation_from_bvh, global_positions
from .atomic import check_writable_dir
from .bvh import BVH, format_bvh
from .errors import SinMDMError
from .generate import GenerationResult
from .model import MotionModel


def _npz_bytes(model: MotionModel, features: np.ndarray, clip: BVH) -> bytes:
    buffer = io.BytesIO()
    positions = global_positions(animation_from_bvh(clip)) * model.codec.scale
    np.savez_compressed(buffer, features=features, positions_m=positions.astype(np.float32),
                        joints=np.array(clip.skeleton.names), fps=model.codec.fps)
    return buffer.getvalue()


def write_outputs(
    model: MotionModel,
    result: GenerationResult,
    out_dir: str | os.PathLike,
    name: str = "sample",
    fmt: str = "bvh",
    npz: bool = False,
    preview: bool = False,
    force: bool = False,
) -> list[Path]:
    """Write every clip (and extras); all files appear together or not at all."""
    if fmt not in ("bvh", "glb"):
        raise SinMDMError(f"unknown format '{fmt}': use bvh or glb")
    directory = check_writable_dir(out_dir)
    planned: list[tuple[Path, Callable[[Path], None]]] = []
    for seed, features, clip in zip(result.seeds, result.features, result.clips):
        stem = directory / f"{name}_{seed:04d}"
        if fmt == "bvh":
            text = format_bvh(clip)
            planned.append((stem.with_suffix(".bvh"), lambda p, text=text: p.write_text(text, encoding="utf-8")))
        else:
            from ..preview.gltf import write_glb

            planned.append((stem.with_suffix(".glb"), lambda p, clip=clip: write_glb(clip, p)))
        if npz:
            data = _npz_bytes(model, features, clip)
            planned.append((stem.with_suffix(".npz"), lambda p, data=data: p.write_bytes(data)))
    if preview:
        from ..preview.render import render_preview

        planned.append((directory / f"{name}_preview.gif", lambda p: render_preview(result.clips, p)))
    existing = [str(p) for p, _ in planned if p.exists()]
    if existing and not force:
        raise SinMDMError(f"{existing[0]} exists; pass --force to overwrite (or choose another --out)")
    temporary: list[tuple[Path, Path]] = []
    try:
        for path, write in planned:
            tmp = path.with_name(f".{path.stem}.part{path.suffix}")  # writers choose the format by suffix
            write(tmp)
            temporary.append((tmp, path))
        for tmp, path in temporary:
            os.replace(tmp, path)
    except OSError as exc:
        raise SinMDMError(f"cannot write into {directory}: {exc.strerror}") from None
    finally:
        for tmp, _ in temporary:
            tmp.unlink(missing_ok=True)
    return [path for path, _ in planned]
