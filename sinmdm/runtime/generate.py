"""The embedding API: generate motions with a loaded model and write them.

    from sinmdm.runtime import load_model, generate, GenerationRequest, write_bvh
    model = load_model("walk_w64.onnx")
    result = generate(model, GenerationRequest(frames=300, count=4, seed=7))
    for seed, clip in zip(result.seeds, result.clips):
        write_bvh(f"walk_{seed}.bvh", clip)
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .animation import animation_to_bvh
from .bvh import BVH
from .cleanup import cleanup_contacts
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
