"""Sampling: the DDPM loop (faithful: 1000 steps), respaced DDPM and DDIM, any
length from fixed windows, and the hooks the applications use (a composition
mask applied to x0_hat, ILVR harmonization applied to x_t).

Arrays are (samples, features, frames). Each sample has its own random stream
(seed + i), so any sample of a crowd reproduces on its own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .errors import SinMDMError
from .model import MotionModel
from .schedule import Schedule

SAMPLERS = ("ddpm", "ddim")
DEFAULT_STEPS = 50
HARMONIZE_STOP = 0.02  # ILVR guidance stops for the last 2 % of the schedule (t <= 20 of 1000)
MAX_WINDOWS_PER_CALL = 256


@dataclass(frozen=True)
class Guide:
    """What the applications hand the sampler. All arrays (features, frames) and
    broadcast over samples.

    compose: x0_hat <- x0_hat * (1 - keep) + reference * keep at every step.
    harmonize: x_{t-1} <- x + region * (phi(q_sample(reference)) - phi(x)) while t > 2 % of T.
    """

    reference: np.ndarray
    keep: np.ndarray | None = None
    harmonize: np.ndarray | None = None  # region mask for ILVR (1 everywhere = whole clip)
    factor: int = 2  # phi's down/up-sampling factor N


def window_starts(frames: int, window: int, hop: int) -> np.ndarray:
    """Window starts covering [0, frames): every `hop`, the last one flush with the end."""
    if frames <= window:
        return np.array([0])
    starts = list(range(0, frames - window + 1, hop))
    if starts[-1] != frames - window:
        starts.append(frames - window)
    return np.asarray(starts)


def blend_weights(window: int) -> np.ndarray:
    """A tent over the window: overlapping windows cross-fade linearly."""
    i = np.arange(window)
    return np.minimum(i + 0.5, window - i - 0.5)


def low_pass(x: np.ndarray, factor: int) -> np.ndarray:
    """phi(z) = up(down(z)) along frames: mean of `factor` frames, then linear upsampling."""
    if factor <= 1:
        return x
    frames = x.shape[-1]
    padded = frames + (-frames) % factor
    extended = np.concatenate([x, np.repeat(x[..., -1:], padded - frames, axis=-1)], axis=-1)
    coarse = extended.reshape(x.shape[:-1] + (padded // factor, factor)).mean(axis=-1)
    centres = (np.arange(coarse.shape[-1]) + 0.5) * factor - 0.5
    flat = coarse.reshape(-1, coarse.shape[-1])
    up = np.stack([np.interp(np.arange(frames), centres, row) for row in flat])
    return up.reshape(x.shape[:-1] + (frames,))


class WindowedDenoiser:
    """x0_hat for whole sequences from a fixed-window graph: overlapping windows,
    all of them in one batched call per step, blended with cross-fades."""

    def __init__(self, model: MotionModel, frames: int, hop: int | None = None):
        self.denoiser = model.denoiser_for(frames)
        self.window = self.denoiser.window
        self.frames = max(frames, self.window)
        self.hop = hop or max(self.window // 2, 1)
        if not 1 <= self.hop <= self.window:
            raise SinMDMError(f"hop must be between 1 and the window ({self.window}), got {self.hop}")
        self.starts = window_starts(self.frames, self.window, self.hop)
        self.weights = blend_weights(self.window)
        coverage = np.zeros(self.frames)
        for s in self.starts:
            coverage[s : s + self.window] += self.weights
        self.normaliser = 1.0 / coverage
        self.index = self.starts[:, None] + np.arange(self.window)[None, :]  # (K, W)

    def __call__(self, x_t: np.ndarray, t: int) -> np.ndarray:
        samples, features, _ = x_t.shape
        windows = x_t[:, :, self.index]  # (N, F, K, W)
        batch = windows.transpose(0, 2, 1, 3).reshape(-1, features, self.window).astype(np.float32)
        steps = np.full(len(batch), float(t), dtype=np.float32)
        out = np.concatenate([
            self.denoiser(batch[i : i + MAX_WINDOWS_PER_CALL], steps[i : i + MAX_WINDOWS_PER_CALL])
            for i in range(0, len(batch), MAX_WINDOWS_PER_CALL)
        ])
        out = out.reshape(samples, len(self.starts), features, self.window).astype(np.float64) * self.weights
        blended = np.zeros(x_t.shape)
        for k, s in enumerate(self.starts):
            blended[:, :, s : s + self.window] += out[:, k]
        return blended * self.normaliser


def _fit(array: np.ndarray | None, frames: int) -> np.ndarray | None:
    """Pad (with zeros: 'not kept') or cut a (features, frames) guide array to `frames`."""
    if array is None:
        return None
    if array.shape[-1] >= frames:
        return array[..., :frames]
    pad = np.zeros(array.shape[:-1] + (frames - array.shape[-1],))
    return np.concatenate([array, pad], axis=-1)


def sample_features(
    model: MotionModel,
    frames: int,
    count: int = 1,
    seed: int = 0,
    sampler: str = "ddpm",
    steps: int | None = DEFAULT_STEPS,
    eta: float = 0.0,
    hop: int | None = None,
    guide: Guide | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> np.ndarray:
    """(count, frames, F) float32 motion features."""
    if frames < 1:
        raise SinMDMError("the length must be at least 1 frame")
    if count < 1:
        raise SinMDMError("--count must be at least 1")
    if sampler not in SAMPLERS:
        raise SinMDMError(f"unknown sampler '{sampler}': use {' or '.join(SAMPLERS)}")
    if steps is not None and not 1 <= steps <= len(model.alphas_cumprod):
        raise SinMDMError(f"--steps must be between 1 and {len(model.alphas_cumprod)}")
    denoise = WindowedDenoiser(model, frames, hop)
    length = denoise.frames
    chain = Schedule.from_alphas_cumprod(model.alphas_cumprod, steps)
    c1, c2, log_var = chain.posterior()
    abar = chain.alphas_cumprod
    stop_t = HARMONIZE_STOP * len(model.alphas_cumprod)
    streams = [np.random.default_rng(seed + i) for i in range(count)]
    shape = (model.features, length)
    x = np.stack([rng.standard_normal(shape) for rng in streams])

    reference = keep = region = None
    if guide is not None:
        reference = _fit(np.asarray(guide.reference, dtype=np.float64), length)
        keep = _fit(guide.keep, length)
        region = _fit(guide.harmonize, length)

    total = len(chain.timesteps)
    for i in reversed(range(total)):
        x0 = denoise(x, int(chain.timesteps[i]))
        if keep is not None:
            x0 = x0 * (1.0 - keep) + reference * keep
        noise = np.stack([rng.standard_normal(shape) for rng in streams]) if i > 0 else None
        if sampler == "ddpm":
            x = c1[i] * x0 + c2[i] * x
            if i > 0:
                x = x + np.exp(0.5 * log_var[i]) * noise
        else:
            abar_prev = abar[i - 1] if i > 0 else 1.0
            eps = (x - np.sqrt(abar[i]) * x0) / np.sqrt(1.0 - abar[i])
            sigma = eta * np.sqrt((1 - abar_prev) / (1 - abar[i]) * (1 - abar[i] / abar_prev))
            x = np.sqrt(abar_prev) * x0 + np.sqrt(max(1 - abar_prev - sigma**2, 0.0)) * eps
            if i > 0 and sigma > 0:
                x = x + sigma * noise
        if region is not None and i > 0 and chain.timesteps[i - 1] > stop_t:
            ref_noise = np.stack([rng.standard_normal(shape) for rng in streams])
            noisy_ref = np.sqrt(abar[i - 1]) * reference + np.sqrt(1 - abar[i - 1]) * ref_noise
            x = x + region * (low_pass(noisy_ref, guide.factor) - low_pass(x, guide.factor))
        if progress:
            progress(total - i, total)
    return x[:, :, :frames].transpose(0, 2, 1).astype(np.float32)
