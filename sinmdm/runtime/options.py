"""The sampling options: one type from the CLI down to the sampler, validated once."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from .errors import OptionError
from .smoothing import MAX_SMOOTH

if TYPE_CHECKING:
    from .model import MotionModel

SAMPLERS = ("ddpm", "ddim")
DEFAULT_STEPS = 50
# Frames sampled beyond each end and cut off: a window's outermost frames are denoised
# without context (the UNet's padding), and on short-trained models the first and last
# 2-3 frames wobble (the height alternating by up to 16 cm). 0 is the paper's sampler.
EDGE_MARGIN = 8
MAX_COUNT = 10_000
MAX_SEED = 2**32 - 1
MAX_STEPS = 1000
MAX_MARGIN = 10_000
MAX_SECONDS = 3600.0  # longer motions need `force`
MAX_FRAMES = 2**31  # beyond any real motion; with `force` anything up to this is attempted
# The smoothing (frames of Gaussian sigma) of a model that carries no measured setting:
# one frame took a short-trained idle's samples from 8/8 jittery to 0/8 with the paper's
# metrics within 0.01 (BENCHMARKS.md, "Where the jitter comes from").
DEFAULT_SMOOTH = 1.0


def check_whole(option: str, value: int, low: int = 0, high: int | None = None) -> int:
    """A whole number in [low, high]."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise OptionError(option, f"must be a whole number, got {value!r}")
    if value < low or (high is not None and value > high):
        bounds = f"between {low} and {high}" if high is not None else f"at least {low}"
        raise OptionError(option, f"must be {bounds}, got {value}")
    return value


def check_number(option: str, value: float, low: float = 0.0, high: float | None = None,
                 below_high: bool = False) -> float:
    """A finite number in [low, high] ([low, high) when `below_high`)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise OptionError(option, f"must be a finite number, got {value!r}")
    over = high is not None and (value >= high if below_high else value > high)
    if value < low or over:
        bounds = f"at least {low:g}" if high is None else f"in [{low:g}, {high:g}{')' if below_high else ']'}"
        raise OptionError(option, f"must be {bounds}, got {value:g}")
    return float(value)


def check_length(frames: int, fps: float, force: bool = False) -> int:
    """`frames` of output, capped at MAX_SECONDS unless `force` (checked before any work)."""
    check_whole("frames", frames, 1, MAX_FRAMES)
    if frames > MAX_SECONDS * fps and not force:
        raise OptionError("force", f"needed for {frames} frames ({frames / fps / 60:.0f} minutes at {fps:g} fps, "
                                   f"over {MAX_SECONDS / 60:.0f} minutes)")
    return frames


def length_in_frames(fps: float, seconds: float | None = None, frames: int | None = None, force: bool = False) -> int:
    """The output length from seconds or frames (default 10 s), capped as `check_length`."""
    if seconds is not None and frames is not None:
        raise OptionError("seconds", "give seconds or frames, not both")
    if seconds is not None:
        if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not seconds > 0:
            raise OptionError("seconds", f"must be positive, got {seconds!r}")
        check_number("seconds", seconds, high=MAX_FRAMES / fps)
        return check_length(max(int(round(seconds * fps)), 1), fps, force)
    return check_length(int(round(10 * fps)) if frames is None else frames, fps, force)


@dataclass(frozen=True)
class SamplingOptions:
    """How to sample: shared by `generate`, every application and the CLI. Sample i of
    a crowd uses seed `seed + i` and reproduces on its own."""

    count: int = 1
    seed: int = 0
    sampler: str = "ddpm"  # ddpm (ancestral, respaced) or ddim (deterministic with eta 0)
    steps: int | None = None  # None: the model's measured setting (`resolve`); 1000: the paper's chain
    eta: float = 0.0  # DDIM noise
    hop: int | None = None  # frames between windows; None: the model's measured setting, else half a window
    margin: int = EDGE_MARGIN  # frames sampled beyond each end and cut off (0: the paper's sampler)
    cleanup: bool = True  # pin the contact joints where the model predicts contacts (cleanup.py)
    smooth: float | None = None  # Gaussian sigma over frames on the sampled features; None: the model's setting; 0: off (the paper)

    def __post_init__(self) -> None:
        check_whole("count", self.count, 1, MAX_COUNT)
        check_whole("seed", self.seed, 0, MAX_SEED)
        if self.sampler not in SAMPLERS:
            raise OptionError("sampler", f"unknown sampler {self.sampler!r}: use {' or '.join(SAMPLERS)}")
        if self.steps is not None:
            check_whole("steps", self.steps, 1, MAX_STEPS)
        check_number("eta", self.eta, high=1.0)
        if self.hop is not None:
            check_whole("hop", self.hop, 1)
        check_whole("margin", self.margin, 0, MAX_MARGIN)
        if not isinstance(self.cleanup, bool):
            raise OptionError("cleanup", f"must be True or False, got {self.cleanup!r}")
        if self.smooth is not None:
            check_number("smooth", self.smooth, high=MAX_SMOOTH)

    @property
    def seeds(self) -> list[int]:
        return [self.seed + i for i in range(self.count)]

    def resolve(self, model: "MotionModel", frames: int, loop: bool = False) -> "SamplingOptions":
        """These options with the model's defaults filled in (steps, hop, smooth) and checked
        against the model (its chain length, its window for `frames`). A loop takes at
        least DEFAULT_STEPS and half a window: the model's measured settings are chosen on
        plain samples, and at 20 steps a loop's wrap changes velocity 1.5x as much as the
        clip does from frame to frame, at 50 steps and half a window 0.6x (BENCHMARKS.md)."""
        if self.steps is not None:
            steps = self.steps
        else:
            steps = max(model.default_steps, DEFAULT_STEPS) if loop else model.default_steps
        if steps > len(model.alphas_cumprod):
            raise OptionError("steps", f"must be between 1 and {len(model.alphas_cumprod)}, got {steps}")
        hop = (None if loop else model.default_hop(frames)) if self.hop is None else self.hop
        smooth = model.default_smooth if self.smooth is None else self.smooth
        return replace(self, steps=steps, hop=hop, smooth=smooth)
