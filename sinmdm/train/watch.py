"""A training run that watches its own quality.

Every `check_every` steps the EMA weights sample a few motions with a fast sampler
(the runtime's own loop, the denoiser called in torch), which are scored against the
clip with the paper's metrics and the plausibility metrics. The checkpoint with the
best *balance* is kept as `best.pt`; once the balance has not improved for `patience`
checks, training stops when the best is in the band (peaked), when the model covers the clip
but copies it (copying) or when it is losing coverage short of the band (stalled); the trainer
then spends what is left on a fallback stage (trainer._fallback_stages).

Balance (`sinmdm.eval.balance`) = min(coverage / 95, global diversity / 1.3, 3 / jitter
ratio, and the turning and pace terms): a copying model and a drifting one both lose to the
paper's own row. A check whose samples teleport is never kept.

The checks always use the same seeds, so two checks differ by the weights only. By default
they sample without the foot cleanup: they judge the weights, not the post-process. With
`CheckSettings.cleanup` they judge what `sample` will give: the cleanup on, and samples that
shake past the balance's limit smoothed where calibration would smooth them.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import asdict, dataclass

import numpy as np
import torch

from ..eval.balance import COVERAGE_BAND, CheckSettings, ClipScorer, choose_sampling, in_band, keepable
from ..runtime.bvh import BVH
from ..runtime.model import MotionModel

PEAKED, COPYING, STALLED = "peaked", "copying", "stalled"  # why a watched run stopped early
# Coverage points a run short of the band may lose from its best check before it is STALLED. The checks'
# 6 samples move coverage by up to 3.5 points between neighbouring checks of a run that is still learning
# (the crab's); the Mixamo idle lost 5-8 points from its best (step 400) by step 1,000-1,200 while its
# diversity fell too, and never came back in 2,800 steps (BENCHMARKS.md).
STALL_DROP = 5.0


def stop_reason(stopped: str | None) -> str:
    """PEAKED, COPYING or STALLED from a run's "stopped" text ("" while it trains on)."""
    return (stopped or "").split(":")[0]


class TorchWindowDenoiser:
    """The runtime's denoiser interface (x_t (N, F, W), t (N,) -> x0 numpy) on torch weights."""

    def __init__(self, module: torch.nn.Module, window: int, device: torch.device):
        self.module, self.window, self.device = module, window, device

    @torch.no_grad()
    def __call__(self, x_t: np.ndarray, t: np.ndarray) -> np.ndarray:
        x = torch.from_numpy(np.ascontiguousarray(x_t, dtype=np.float32)).to(self.device)
        steps = torch.from_numpy(np.asarray(t, dtype=np.float32)).to(self.device)
        return self.module(x, steps).float().cpu().numpy()


class QualityWatch:
    """Scores a run's current weights against its clip (a ClipScorer on torch weights)."""

    def __init__(self, reference: BVH, codec, alphas_cumprod: np.ndarray, window: int, receptive_field: int,
                 start: np.ndarray, settings: CheckSettings = CheckSettings(), frames: int | None = None,
                 source_fps: float | None = None, graph_metadata: dict | None = None):
        if source_fps:  # the clip's real frame rate (--source-fps) for every metric
            reference = BVH(reference.skeleton, 1.0 / source_fps, reference.values, reference.path)
        self.scorer = ClipScorer(reference, settings, frames, codec.fps, window)
        self.codec, self.alphas, self.window, self.receptive_field, self.start = (
            codec, np.asarray(alphas_cumprod, dtype=np.float64), window, receptive_field, start)
        self.metadata = graph_metadata or {"velocity_unit": "frame"}  # what the exported model will say of its graph

    @property
    def frames(self) -> int:
        return self.scorer.frames

    def model(self, module: torch.nn.Module, device: torch.device) -> MotionModel:
        denoiser = TorchWindowDenoiser(module, self.window, device)
        return MotionModel(codec=self.codec, alphas_cumprod=self.alphas, receptive_field=self.receptive_field,
                           trained_window=self.window, denoisers={self.window: denoiser}, metadata=self.metadata,
                           start_position=np.asarray(self.start, dtype=np.float64))

    def check(self, module: torch.nn.Module, device: torch.device, steps: int | None = None,
              hop: int | None = None, to_beat: float | None = None) -> dict:
        """Scores of samples from `module` (eval mode is restored to what it was); `to_beat`: the
        best balance so far (`ClipScorer.check_as_sampled`)."""
        with _evaluating(module):
            model = self.model(module, device)
            if self.scorer.settings.cleanup:
                return self.scorer.check_as_sampled(model, steps, hop, to_beat)
            return self.scorer.check(model, steps, hop)


@contextmanager
def _evaluating(module: torch.nn.Module):
    training = module.training
    module.eval()
    try:
        yield
    finally:
        module.train(training)


@dataclass
class WatchState:
    """What the watch remembers across checks (saved in the checkpoint: resume is exact)."""

    best_step: int = 0
    best: dict | None = None
    since_best: int = 0  # checks without improvement since the best
    checks: int = 0

    def update(self, step: int, scores: dict) -> bool:
        """Record a check; True when it is the new best."""
        self.checks += 1
        if keepable(scores) and (self.best is None or scores["balance"] > self.best["balance"]):
            self.best, self.best_step, self.since_best = dict(scores), step, 0
            return True
        self.since_best += 1
        return False

    def should_stop(self, patience: int, latest: dict) -> str | None:
        """Why training should end now (None: go on). After `patience` checks without
        improvement: PEAKED when the best is in the band; COPYING when the model already
        covers the clip (coverage in band) but its diversity keeps falling below the band:
        more steps only copy more (a walk under GroupNorm, BENCHMARKS.md); STALLED when a
        model short of the band has lost coverage since its best (STALL_DROP): it narrows onto
        parts of the clip instead of learning the rest. A model still short of the clip's
        coverage and not losing it trains on."""
        if self.best is None or self.since_best < patience:
            return None
        if in_band(self.best):
            return PEAKED
        if latest["coverage"] >= COVERAGE_BAND:
            return COPYING
        if latest["coverage"] <= self.best["coverage"] - STALL_DROP:
            return STALLED
        return None

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict | None) -> "WatchState":
        return cls(**data) if data else cls()


def sampling_defaults(watch: QualityWatch, module: torch.nn.Module, device: torch.device) -> dict:
    """The cheapest sampling settings that keep the kept weights' balance (`choose_sampling`)."""
    with _evaluating(module):
        return choose_sampling(watch.model(module, device), watch.scorer, watch.window)
