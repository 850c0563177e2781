"""A training run that watches its own quality.

Every `check_every` steps the EMA weights sample a few motions with a fast sampler
(the runtime's own loop, the denoiser called in torch), which are scored against the
clip with the paper's metrics and the plausibility metrics. The checkpoint with the
best *balance* is kept as `best.pt`; once the balance has not improved for `patience`
checks after reaching the band, training stops.

Balance = min(coverage / 95, global diversity / 1.3, 3 / jitter ratio): every term must hold, so a
copying model (coverage 100, diversity 1.0: 0.77) and a drifting one (coverage 75,
diversity 1.9: 0.79) both lose to the paper's own row (98.1 / 1.55: 1.03). Unlike the
paper's harmonic mean, extra diversity cannot buy back lost coverage, and neither can
buy back samples that shake (the walk's frame-norm check at 97 % / 1.60 with 5.2x the
clip's jerk: 0.58, below its GroupNorm check at 91 % / 1.17 / 2.5x: 0.90). A clip too
static to reach 1.3 is scored by its diversity once coverage holds, which picks the
most varied checkpoint that still covers the clip. A check whose samples teleport
(the root jumps more than 1.5x the clip's largest step) is never kept.

The checks always use the same seeds, so two checks differ by the weights only, and
sample without the foot cleanup: they judge the weights, not the post-process.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
import torch

from ..eval import metrics
from ..eval.motion_features import MIXAMO24_JOINTS, eval_features, protocol_for, resolve_joints
from ..eval.plausibility import TELEPORT_RATIO, plausibility
from ..runtime.bvh import BVH
from ..runtime.errors import SinMDMError
from ..runtime.generate import generate
from ..runtime.options import SamplingOptions
from ..runtime.model import MotionModel

PEAKED, COPYING = "peaked", "copying"  # why a watched run stopped early
COVERAGE_BAND = 95.0  # % : below this the model drifts from the clip
DIVERSITY_BAND = 1.3  # global diversity: below this the model copies
# Check samples (20 steps, no cleanup) shaking more than this many times the clip's own jerk
# are visibly noisy: every GroupNorm check of the benchmark clips stayed within 0.4-3.7x once
# past its first check, the frame-norm walk that "won" the band ran at 4.3-13x and walked a
# jagged path (BENCHMARKS.md). Above it, the balance falls as LIMIT / jitter.
JITTER_LIMIT = 3.0
# Sampling settings tried on the kept weights, most expensive first: (steps, hop as a share
# of the window). The cheapest whose balance stays within BALANCE_TOLERANCE of the first
# becomes the model's default (export metadata, `sinmdm-run sample`).
SAMPLING_CANDIDATES = ((50, 0.5), (30, 0.5), (20, 0.5), (20, 0.75))
BALANCE_TOLERANCE = 0.02


def balance(coverage: float, global_diversity: float, jitter_ratio: float | None = None) -> float:
    """The watched score (module docstring): the weakest of the band ratios, jitter's
    included when it is known."""
    ratios = [coverage / COVERAGE_BAND, global_diversity / DIVERSITY_BAND]
    if jitter_ratio:
        ratios.append(JITTER_LIMIT / jitter_ratio)
    return float(min(ratios))


def in_band(scores: dict) -> bool:
    return (scores["coverage"] >= COVERAGE_BAND and scores["global_diversity"] >= DIVERSITY_BAND
            and scores.get("jitter_ratio", 0.0) <= JITTER_LIMIT)


@dataclass(frozen=True)
class CheckSettings:
    samples: int = 6
    steps: int = 20  # respaced DDPM steps of the check's sampler
    hop: int | None = None  # None: half a window
    seed: int = 0


class TorchWindowDenoiser:
    """The runtime's denoiser interface (x_t (N, F, W), t (N,) -> x0 numpy) on torch weights."""

    def __init__(self, module: torch.nn.Module, window: int, device: torch.device):
        self.module, self.window, self.device = module, window, device

    @torch.no_grad()
    def __call__(self, x_t: np.ndarray, t: np.ndarray) -> np.ndarray:
        x = torch.from_numpy(np.ascontiguousarray(x_t, dtype=np.float32)).to(self.device)
        steps = torch.from_numpy(np.asarray(t, dtype=np.float32)).to(self.device)
        return self.module(x, steps).float().cpu().numpy()


def eval_preset(reference: BVH) -> str:
    """The paper's protocol for a Mixamo skeleton, the project's own for any other."""
    try:
        resolve_joints(reference.skeleton, MIXAMO24_JOINTS, "contains")
    except SinMDMError:
        return "default"
    return "mixamo24"


class QualityWatch:
    """Scores a run's current weights against its clip."""

    def __init__(self, reference: BVH, codec, alphas_cumprod: np.ndarray, window: int, receptive_field: int,
                 start: np.ndarray, settings: CheckSettings = CheckSettings(), frames: int | None = None,
                 source_fps: float | None = None):
        if source_fps:  # the clip's real frame rate (--source-fps) for every metric
            reference = BVH(reference.skeleton, 1.0 / source_fps, reference.values, reference.path)
        self.reference, self.settings = reference, settings
        self.codec, self.alphas, self.window, self.receptive_field, self.start = (
            codec, np.asarray(alphas_cumprod, dtype=np.float64), window, receptive_field, start)
        clip_frames = int(round(reference.frames / reference.fps * codec.fps))
        self.frames = frames or max(clip_frames, 2 * window)
        self.preset = eval_preset(reference)
        self.protocol = protocol_for(reference, self.preset)
        self.reference_features = eval_features(reference, self.protocol)

    def model(self, module: torch.nn.Module, device: torch.device) -> MotionModel:
        denoiser = TorchWindowDenoiser(module, self.window, device)
        return MotionModel(codec=self.codec, alphas_cumprod=self.alphas, receptive_field=self.receptive_field,
                           trained_window=self.window, denoisers={self.window: denoiser}, metadata={},
                           start_position=np.asarray(self.start, dtype=np.float64))

    def check(self, module: torch.nn.Module, device: torch.device, steps: int | None = None,
              hop: int | None = None) -> dict:
        """Scores of samples from `module` (eval mode is restored to what it was)."""
        began = time.perf_counter()
        training = module.training
        module.eval()
        try:
            options = SamplingOptions(count=self.settings.samples, seed=self.settings.seed,
                                      steps=steps or self.settings.steps, hop=hop or self.settings.hop, cleanup=False)
            result = generate(self.model(module, device), self.frames, options)
        finally:
            module.train(training)
        return {**self.score(result.clips), "check_seconds": round(time.perf_counter() - began, 2)}

    def score(self, clips: list[BVH]) -> dict:
        features = [eval_features(c, self.protocol) for c in clips]
        paper = metrics.evaluate(self.reference_features, features)
        aggregate = plausibility(self.reference, clips).get("aggregate") or {}
        scores = {
            "coverage": round(paper["coverage"], 2),
            "global_diversity": round(paper["global_diversity"], 4),
            "local_diversity": round(paper["local_diversity"], 4),
            "eval_preset": self.preset,
            "root_step_max_ratio": round(float(aggregate.get("root_step_max_ratio", 0.0)), 3),
            "foot_skating_cm_s": round(float(aggregate.get("foot_skating_cm_s", 0.0)), 2),
            "jitter_ratio": round(float(aggregate.get("jitter_ratio", 0.0)), 3),
            "implausible": int(aggregate.get("implausible", 0)),
        }
        scores["balance"] = round(balance(scores["coverage"], scores["global_diversity"], scores["jitter_ratio"]), 4)
        return scores


def keepable(scores: dict) -> bool:
    return scores["root_step_max_ratio"] <= TELEPORT_RATIO


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
        more steps only copy more (a walk under GroupNorm, BENCHMARKS.md). A model still
        short of the clip's coverage trains on."""
        if self.best is None or self.since_best < patience:
            return None
        if in_band(self.best):
            return PEAKED
        if latest["coverage"] >= COVERAGE_BAND:
            return COPYING
        return None

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict | None) -> "WatchState":
        return cls(**data) if data else cls()


def sampling_defaults(watch: QualityWatch, module: torch.nn.Module, device: torch.device) -> dict:
    """Try SAMPLING_CANDIDATES on the kept weights (the check's seeds) and choose the
    cheapest that keeps the balance."""
    trials = []
    for steps, share in SAMPLING_CANDIDATES:
        hop = max(1, int(round(watch.window * share)))
        scores = watch.check(module, device, steps=steps, hop=hop)
        trials.append({"steps": steps, "hop": hop, "cost": steps / share, **scores})
    reference = trials[0]["balance"]
    fine = [t for t in trials if t["balance"] >= reference - BALANCE_TOLERANCE and keepable(t)] or trials[:1]
    chosen = min(fine, key=lambda t: t["cost"])
    return {"steps": chosen["steps"], "hop": chosen["hop"], "scores": {k: chosen[k] for k in (
        "coverage", "global_diversity", "local_diversity", "balance", "eval_preset")}, "trials": trials}
