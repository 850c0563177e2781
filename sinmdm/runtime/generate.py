"""The embedding API: generate motions with a loaded model and write them.

    from sinmdm.runtime import load_model, generate, GenerationRequest, write_bvh
    model = load_model("walk_w64.onnx")
    result = generate(model, GenerationRequest(frames=300, count=4, seed=7))
    for seed, clip in zip(result.seeds, result.clips):
        write_bvh(f"walk_{seed}.bvh", clip)
"""

from __future__ import annotations

import io
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from .animation import animation_from_bvh, animation_to_bvh, global_positions
from .atomic import check_writable_dir
from .bvh import BVH, format_bvh
from .cleanup import cleanup_contacts
from .errors import SinMDMError
from .model import MotionModel
from .sampler import DEFAULT_STEPS, EDGE_MARGIN, Guide, cycle_displacement, fit_guide, sample_features


@dataclass(frozen=True)
class GenerationRequest:
    frames: int
    count: int = 1
    seed: int = 0
    sampler: str = "ddpm"
    steps: int | None = DEFAULT_STEPS
    eta: float = 0.0
    hop: int | None = None
    # a seamless cycle of `frames` frames (at least one window): the last frame flows into
    # the first, the root moving by `GenerationResult.loop_displacement` per cycle
    loop: bool = False
    cleanup: bool = True  # pin the contact joints where the model predicts contacts (cleanup.py)
    margin: int = EDGE_MARGIN  # frames sampled beyond each end and cut off (0: the paper's sampler)


@dataclass
class GenerationResult:
    features: np.ndarray  # (count, frames, F)
    clips: list[BVH]
    seeds: list[int]
    seconds: float
    loop_displacement: np.ndarray | None = None  # loops: (count, 2) root metres per cycle, codec.horizontal_axes


def generate(
    model: MotionModel,
    request: GenerationRequest,
    guide: Guide | None = None,
    start: np.ndarray | None = None,
    progress: Callable[[int, int], None] | None = None,
    adjust: Callable[[np.ndarray], np.ndarray] | None = None,
) -> GenerationResult:
    """Sample `request.count` motions; clip i is reproducible alone with seed `request.seed + i`.
    `adjust` maps the sampled (count, frames, F) features to the ones decoded and returned."""
    began = time.perf_counter()
    features = sample_features(
        model, request.frames, count=request.count, seed=request.seed, sampler=request.sampler,
        steps=request.steps, eta=request.eta, hop=request.hop, guide=guide, progress=progress,
        loop=request.loop, margin=request.margin,
    )
    if adjust is not None:
        features = adjust(features)
    origin = model.start_position if start is None else start
    displacement = cycle_displacement(model.codec, features) if request.loop else None
    keep = None if guide is None else guide.keep
    clips = [decode_clip(model, f, origin, request.cleanup, None if displacement is None else displacement[i], keep)
             for i, f in enumerate(features)]
    seeds = [request.seed + i for i in range(request.count)]
    return GenerationResult(features, clips, seeds, time.perf_counter() - began, loop_displacement=displacement)


def decode_clip(model: MotionModel, features: np.ndarray, start: np.ndarray | None, cleanup: bool = True,
                loop_displacement: np.ndarray | None = None, keep: np.ndarray | None = None) -> BVH:
    """One sample's features (frames, F) as a BVH clip, its contacts cleaned up when asked
    (except where `keep`, a guide's (F, frames) kept features, holds the legs)."""
    animation = model.codec.decode(features, start)
    if cleanup:
        kept = None if keep is None else np.broadcast_to(fit_guide(keep, len(features)), features.shape[::-1]).T
        animation = cleanup_contacts(animation, model.codec, features, loop_displacement, kept)
    return animation_to_bvh(animation)


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
