"""A light temporal smoothing of sampled features before they are decoded.

Most of the jitter in sampled motion is in the model's output, not the decoding: a few
denoising steps leave frame-to-frame noise that the clip does not have (a sampled walk's
joints shake 2.8x as much as the clip's at 10 steps, 2.3x at 50). A Gaussian over frames
with a sigma of one frame removes most of it and leaves the paper's metrics within their
run-to-run spread (BENCHMARKS.md, "Where the jitter comes from")."""

from __future__ import annotations

import math

import numpy as np

MAX_SMOOTH = 10.0  # frames; beyond this the filter erases the motion itself
TRUNCATE = 4.0  # sigmas each side, as scipy.ndimage's gaussian_filter1d


def gaussian_weights(sigma: float) -> np.ndarray:
    """The normalised kernel (2r+1,) of a Gaussian of `sigma` frames, r = ceil(4 sigma)."""
    radius = max(1, math.ceil(TRUNCATE * sigma))
    offsets = np.arange(-radius, radius + 1, dtype=np.float64)
    weights = np.exp(-0.5 * (offsets / sigma) ** 2)
    return weights / weights.sum()


def smooth_frames(features: np.ndarray, sigma: float, wrap: bool = False, keep: np.ndarray | None = None,
                  out: np.ndarray | None = None) -> np.ndarray:
    """(count, frames, F) features smoothed over frames by a Gaussian of `sigma` frames: the
    ends extended by their own frame, or (`wrap`, a loop) by the other end so the cycle
    stays seamless. `keep` ((frames, F), 1 = kept) holds a guide's kept features exactly.
    One sample at a time, into `out` (may be `features`): a long motion needs one sample's
    copies, not the whole batch's."""
    if sigma <= 0:
        return features
    weights = gaussian_weights(sigma)
    radius = len(weights) // 2
    out = np.empty_like(features) if out is None else out
    for i, sample in enumerate(features):
        padded = np.pad(sample, ((radius, radius), (0, 0)), mode="wrap" if wrap else "edge")
        smoothed = np.zeros_like(sample)
        for k, weight in enumerate(weights):
            smoothed += sample.dtype.type(weight) * padded[k : k + len(sample)]
        out[i] = smoothed if keep is None else keep * sample + (1 - keep) * smoothed
    return out
