"""Sampling, shaped like k-diffusion's: a schedule (`Schedule`: respacing, the DDPM and
DDIM updates, q_sample), a denoiser callable `denoise(x_t, t) -> x0_hat` (for a model:
`WindowedDenoiser`, overlapping fixed windows blended into any length) and one loop
(`sample_loop`) with the applications' hooks (a composition mask applied to x0_hat,
ILVR harmonization applied to x_t). The faithful sampler is DDPM over all 1000 steps.

Arrays are (samples, features, frames). Each sample has its own random stream
(seed + i), so any sample of a crowd reproduces on its own.

Loops (`loop=True`): the sequence is a circle of T frames. The windows tile the
circle (those that cross the end take frames from the start), the cross-fade is
normalised on the circle, so every frame, the wrap included, is denoised in the
context of its neighbours across the seam. The result is a cycle of T frames:
frame T (not part of it) is frame 0 again, displaced by the cycle's root motion
(`cycle_displacement`: the sum of the root's per-frame velocities, frame 0's
being the step across the wrap), which a game engine applies once per cycle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .errors import OptionError, SinMDMError
from .graph_space import GraphSpace
from .heading import GuidedHeading, check_keep, close_the_turn
from .model import MotionModel
from .options import DEFAULT_STEPS, EDGE_MARGIN, SAMPLERS, SamplingOptions  # noqa: F401 (re-exported)
from .schedule import Schedule

HARMONIZE_STOP = 0.02  # ILVR guidance stops for the last 2 % of the schedule (t <= 20 of 1000)
# Windows per denoiser call: 32 keeps a 10-minute motion's peak memory at about half of
# 256's with no measurable cost in speed (BENCHMARKS.md, issue 16).
MAX_WINDOWS_PER_CALL = 32
# The sampler's state (x_t, x0_hat, noise) is float32, the graph's own precision: a 10-minute
# motion holds half the memory of float64, and the schedule's coefficients stay float64.
STATE_DTYPE = np.float32


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


def circular_window_starts(frames: int, window: int, hop: int) -> np.ndarray:
    """Window starts tiling a circle of `frames` (>= window) frames: K = ceil(frames / hop)
    starts spread evenly (exactly every `hop` when it divides `frames`), so that
    consecutive starts, the pair across the wrap included, are at most `hop` apart."""
    if frames < window:
        raise SinMDMError(f"a loop must be at least one window ({window} frames) long, got {frames}")
    count = -(-frames // hop)
    return (np.arange(count) * frames) // count


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


def _loop_denoiser(model: MotionModel, frames: int):
    """The window a loop of `frames` uses: the usual one when it fits in the loop,
    else the largest window that does."""
    denoiser = model.denoiser_for(frames)
    if denoiser.window <= frames:
        return denoiser
    fitting = [w for w in model.windows if w <= frames]
    if not fitting:
        shortest = model.windows[0]
        raise SinMDMError(
            f"--loop needs at least one window of the model: {shortest} frames "
            f"({shortest / model.codec.fps:.2f} s at {model.codec.fps:g} fps), got {frames}"
        )
    return model.denoisers[fitting[-1]]


class WindowedDenoiser:
    """x0_hat for whole sequences from a fixed-window graph: overlapping windows,
    all of them in one batched call per step, blended with cross-fades. With
    `loop` the sequence is circular: windows wrap around the end (modular frame
    indices) and the blend normaliser is computed on the circle."""

    def __init__(self, model: MotionModel, frames: int, hop: int | None = None, loop: bool = False):
        self.denoiser = _loop_denoiser(model, frames) if loop else model.denoiser_for(frames)
        self.window = self.denoiser.window
        self.loop = loop
        self.frames = frames if loop else max(frames, self.window)
        self.hop = hop or max(self.window // 2, 1)
        if not 1 <= self.hop <= self.window:
            raise OptionError("hop", f"must be between 1 and the window ({self.window}), got {self.hop}")
        if loop:
            self.starts = circular_window_starts(self.frames, self.window, self.hop)
        else:
            self.starts = window_starts(self.frames, self.window, self.hop)
        self.weights = blend_weights(self.window)
        self.index = (self.starts[:, None] + np.arange(self.window)[None, :]) % self.frames  # (K, W)
        # where each window's frames go: a slice, or modular indices for a window across the wrap
        self.spans = [
            slice(s, s + self.window) if s + self.window <= self.frames else self.index[k]
            for k, s in enumerate(self.starts)
        ]
        coverage = np.zeros(self.frames)
        for span in self.spans:
            coverage[span] += self.weights
        self.normaliser = 1.0 / coverage

    def __call__(self, x_t: np.ndarray, t: int) -> np.ndarray:
        samples, features, _ = x_t.shape
        per_call = max(1, MAX_WINDOWS_PER_CALL // samples)  # windows of every sample in one call
        steps = np.full(samples * per_call, float(t), dtype=np.float32)
        blended = np.zeros(x_t.shape, dtype=x_t.dtype)
        # A chunk of windows at a time: memory stays bounded by the chunk, not the length.
        for first in range(0, len(self.starts), per_call):
            chunk = range(first, min(first + per_call, len(self.starts)))
            windows = x_t[:, :, self.index[chunk.start : chunk.stop]]  # (N, F, k, W)
            batch = windows.transpose(0, 2, 1, 3).reshape(-1, features, self.window).astype(np.float32)
            out = self.denoiser(batch, steps[: len(batch)]).reshape(samples, len(chunk), features, self.window)
            for j, k in enumerate(chunk):
                blended[:, :, self.spans[k]] += out[:, j] * self.weights
        blended *= self.normaliser
        return blended


def cycle_displacement(codec, features: np.ndarray) -> np.ndarray:
    """(..., 2) metres: how far the trajectory joint moves per cycle of a loop, along
    its two horizontal axes (`codec.horizontal_axes`, in its parent's frame) from
    (..., frames, F) features: the sum of the per-frame root velocities, frame 0's
    being the step from the last frame across the wrap. Zeros without a trajectory joint."""
    features = np.asarray(features, dtype=np.float64)
    if codec.trajectory_joint is None:
        return np.zeros(features.shape[:-2] + (2,))
    dx, _, dz = codec.layout.indices(("root",))
    return np.stack([features[..., dx].sum(axis=-1), features[..., dz].sum(axis=-1)], axis=-1)


def fit_guide(array: np.ndarray | None, frames: int, before: int = 0) -> np.ndarray | None:
    """Pad (with zeros: 'not kept') or cut a (features, frames) guide array to `frames`,
    after `before` zero frames."""
    if array is None:
        return None
    if before:
        array = np.concatenate([np.zeros(array.shape[:-1] + (before,)), array], axis=-1)
    if array.shape[-1] >= frames:
        return array[..., :frames]
    pad = np.zeros(array.shape[:-1] + (frames - array.shape[-1],))
    return np.concatenate([array, pad], axis=-1)


def _as_state(array: np.ndarray | None) -> np.ndarray | None:
    return None if array is None else array.astype(STATE_DTYPE, copy=False)


Denoise = Callable[[np.ndarray, int], np.ndarray]  # (x_t (N, F, T), original timestep) -> x0_hat


NOISE_CHUNK = 1 << 20  # normals drawn at a time: a float32 draw never holds the float64 whole


def draw(streams: list[np.random.Generator], shape: tuple[int, ...], dtype=np.float64) -> np.ndarray:
    """One standard normal array per sample, each from its own stream: (N, *shape), the
    stream's float64 normals rounded to `dtype` (the same values whatever the dtype)."""
    out = np.empty((len(streams), *shape), dtype=dtype)
    for rng, flat in zip(streams, out.reshape(len(streams), -1)):
        for start in range(0, flat.size, NOISE_CHUNK):  # a stream's normals come in order: chunks change nothing
            flat[start : start + NOISE_CHUNK] = rng.standard_normal(min(NOISE_CHUNK, flat.size - start))
    return out


def sample_loop(
    denoise: Denoise,
    schedule: Schedule,
    x: np.ndarray,
    streams: list[np.random.Generator],
    sampler: str = "ddpm",
    eta: float = 0.0,
    compose: Callable[[np.ndarray], np.ndarray] | None = None,
    harmonize: Callable[[np.ndarray, int], np.ndarray] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> np.ndarray:
    """The reverse process over `schedule`'s chain, from x (N, F, T) at its last step to x0,
    with any denoiser. Per step: x0_hat = compose(denoise(x, t)); one noise draw per sample
    (not at the last step); the DDPM or DDIM update; then harmonize(x, step - 1) (not after
    the last step). Hooks that draw noise use the same per-sample streams, after the step's own."""
    total = len(schedule.timesteps)
    owned = False  # x is the caller's until the first update makes a new one
    for step in reversed(range(total)):
        x0 = denoise(x, int(schedule.timesteps[step]))
        if compose is not None:
            x0 = compose(x0)
        noise = draw(streams, x.shape[1:], x.dtype) if step > 0 else None
        if sampler == "ddpm":
            in_place = owned and x.shape == x0.shape and x.dtype == x0.dtype
            x = schedule.ddpm_step(step, x, x0, noise, out=x if in_place else None)
            owned = True
        else:
            x = schedule.ddim_step(step, x, x0, eta, noise)
        if harmonize is not None and step > 0:
            x = harmonize(x, step - 1)
        x0 = noise = None  # not held while the next denoise call builds its own (a long motion's peak)
        if progress:
            progress(total - step, total)
    return x


def ilvr(schedule: Schedule, reference: np.ndarray, region: np.ndarray, factor: int, stop_t: float,
         streams: list[np.random.Generator]) -> Callable[[np.ndarray, int], np.ndarray]:
    """ILVR's hook (Choi et al.): inside `region`, replace x's low frequencies by those of the
    reference noised to the same step, while the step's timestep is above `stop_t`."""

    def harmonize(x: np.ndarray, step: int) -> np.ndarray:
        if schedule.timesteps[step] <= stop_t:
            return x
        noisy_reference = schedule.q_sample(reference, step, draw(streams, x.shape[1:], x.dtype))
        return (x + region * (low_pass(noisy_reference, factor) - low_pass(x, factor))).astype(x.dtype, copy=False)

    return harmonize


def plan_sampling(model: MotionModel, frames: int, options: SamplingOptions, loop: bool = False
                  ) -> tuple[SamplingOptions, int, WindowedDenoiser, Schedule]:
    """What a sample of `frames` frames runs on: the options with the model's defaults
    filled in, the margin, the windowed denoiser and the (respaced) schedule."""
    if frames < 1:
        raise SinMDMError("the length must be at least 1 frame")
    options = options.resolve(model, frames, loop)
    margin = 0 if loop else options.margin
    denoise = WindowedDenoiser(model, frames + 2 * margin, options.hop, loop=loop)
    return options, margin, denoise, Schedule.from_alphas_cumprod(model.alphas_cumprod, options.steps)


def check_guide(model: MotionModel, guide: Guide) -> None:
    """Refuse, before any work, a guide the model's graph space cannot carry."""
    if model.graph_space.heading is not None:
        check_keep(model.graph_space.heading, guide.keep)


def sample_features(
    model: MotionModel,
    frames: int,
    options: SamplingOptions = SamplingOptions(),
    guide: Guide | None = None,
    progress: Callable[[int, int], None] | None = None,
    loop: bool = False,
) -> np.ndarray:
    """(count, frames, F) float32 motion features; with `loop`, a cycle of `frames`
    frames (at least one window) whose last frame flows into its first. `options.margin`
    frames are sampled before and after the motion (guides extended by 'not kept')
    and cut off; a loop has no ends and ignores it. A guide's reference may also be
    (count, features, frames): one per sample."""
    if loop and guide is not None:
        raise SinMDMError("loop cannot be combined with guides (applications): sample a loop without one")
    space = model.graph_space  # features <-> the graph's space
    heading = None
    if guide is not None and space.heading is not None:
        heading = GuidedHeading(space.heading, guide.reference, guide.keep, guide.harmonize)
        guide = Guide(heading.reference, heading.keep, heading.region, guide.factor)
    options, margin, denoise, schedule = plan_sampling(model, frames, options, loop)
    length = denoise.frames
    streams = [np.random.default_rng(options.seed + i) for i in range(options.count)]
    x = draw(streams, (model.graph_width, length), STATE_DTYPE)
    compose = harmonize = None
    if guide is not None:
        reference = np.asarray(guide.reference, dtype=np.float64)
        if space.graph_scale is not None:
            reference = reference * space.graph_scale[:, None]
        reference = _as_state(fit_guide(reference, length, margin))
        keep = _as_state(fit_guide(guide.keep, length, margin))
        region = _as_state(fit_guide(guide.harmonize, length, margin))
        if keep is not None:
            compose = lambda x0: x0 * (1.0 - keep) + reference * keep  # noqa: E731
        if region is not None:
            stop_t = HARMONIZE_STOP * len(model.alphas_cumprod)
            harmonize = ilvr(schedule, reference, region, guide.factor, stop_t, streams)
    x = sample_loop(denoise, schedule, x, streams, options.sampler, options.eta, compose, harmonize, progress)
    return to_features(x[:, :, margin : margin + frames], space, loop, heading)


def to_features(x: np.ndarray, space: GraphSpace, loop: bool = False, heading: GuidedHeading | None = None) -> np.ndarray:
    """(N, G, T) in the graph's space -> (N, T, F) float32 features. A heading-frame model's
    loop turns whole turns; its guided samples start facing as their reference (`heading`)."""
    if space.heading is not None and loop:
        x = close_the_turn(x, space.heading.fps)
    starts = None if heading is None else heading.starts(x)
    if space.heading is not None:
        return space.to_features(x.transpose(0, 2, 1), starts).astype(np.float32)
    if space.scale is not None:  # float32 division of the float32 state, as docs/runtime.md specifies for ports
        x = x / space.scale[:, None].astype(x.dtype)
    return x.transpose(0, 2, 1).astype(np.float32)
