"""The embedding API: generate motions with a loaded model and write them.

    from sinmdm.runtime import load_model, generate, SamplingOptions, write_bvh
    model = load_model("walk_w64.onnx")
    result = generate(model, 300, SamplingOptions(count=4, seed=7))
    for seed, clip in zip(result.seeds, result.clips):
        write_bvh(f"walk_{seed}.bvh", clip)
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .bvh import BVH
from .cleanup import cleaned_legs
from .heap import release_free_heap
from .model import MotionModel
from .options import SamplingOptions
from .sampler import Guide, cycle_displacement, fit_guide, sample_features
from .smoothing import smooth_frames


@dataclass
class GenerationResult:
    features: np.ndarray  # (count, frames, F)
    clips: list[BVH]
    seeds: list[int]
    seconds: float
    options: SamplingOptions  # as sampled: the model's defaults filled in
    loop_displacement: np.ndarray | None = None  # loops: (count, 2) root metres per cycle, codec.horizontal_axes


def generate(
    model: MotionModel,
    frames: int,
    options: SamplingOptions = SamplingOptions(),
    *,
    loop: bool = False,
    guide: Guide | None = None,
    start: np.ndarray | None = None,
    progress: Callable[[int, int], None] | None = None,
    adjust: Callable[[np.ndarray], np.ndarray] | None = None,
) -> GenerationResult:
    """Sample `options.count` motions of `frames` frames; clip i is reproducible alone with
    seed `options.seed + i`. `loop`: a seamless cycle of `frames` frames (at least one window),
    the last frame flowing into the first, the root moving by `GenerationResult.loop_displacement`
    per cycle. The sampled features are smoothed over frames (`options.smooth`; a guide's kept
    features stay exact), then `adjust` maps the (count, frames, F) features to the ones decoded
    and returned."""
    began = time.perf_counter()
    options = options.resolve(model, frames, loop)
    features = sample_features(model, frames, options, guide=guide, progress=progress, loop=loop)
    release_free_heap(features.size)
    keep = None if guide is None else guide.keep
    features = smooth_frames(features, options.smooth, wrap=loop, keep=kept_features(keep, features.shape[1:]), out=features)
    if adjust is not None:
        features = adjust(features)
    origin = model.start_position if start is None else start
    displacement = cycle_displacement(model.codec, features) if loop else None
    clips = [decode_clip(model, f, origin, options.cleanup, None if displacement is None else displacement[i], keep)
             for i, f in enumerate(features)]
    release_free_heap(features.size)
    return GenerationResult(features, clips, options.seeds, time.perf_counter() - began, options,
                            loop_displacement=displacement)


def decode_clip(model: MotionModel, features: np.ndarray, start: np.ndarray | None, cleanup: bool = True,
                loop_displacement: np.ndarray | None = None, keep: np.ndarray | None = None) -> BVH:
    """One sample's features (frames, F) as a BVH clip, its contacts cleaned up when asked
    (except where `keep`, a guide's (F, frames) kept features, holds the legs)."""
    legs = None
    if cleanup:
        legs = cleaned_legs(model.codec, features, start, loop_displacement, kept_features(keep, features.shape))
    return model.codec.decode_bvh(features, start, replaced=legs)


def kept_features(keep: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray | None:
    """A guide's (F, frames) kept features as a (frames, F) view of one sample's `shape`."""
    return None if keep is None else np.broadcast_to(fit_guide(keep, shape[0]), shape[::-1]).T
