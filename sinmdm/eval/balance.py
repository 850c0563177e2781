"""The balance a model's samples strike against their clip, and the sampling settings
chosen by it. Numpy only: the training watch scores torch weights with it, `sinmdm
calibrate` an exported model.

Balance = min(coverage / 95, global diversity / 1.3, 3 / jitter ratio, allowed turning / turning
distance, allowed pace / pace distance, the planted term below): every term must hold, so a
copying model (coverage 100, diversity 1.0: 0.77) and a drifting one (coverage 75,
diversity 1.9: 0.79) both lose to the paper's own row (98.1 / 1.55: 1.03). Unlike the
paper's harmonic mean, extra diversity cannot buy back lost coverage, and neither can
buy back samples that shake (the walk's frame-norm check at 97 % / 1.60 with 5.2x the
clip's jerk: 0.58, below its GroupNorm check at 91 % / 1.17 / 2.5x: 0.90). A clip too
static to reach 1.3 is scored by its diversity once coverage holds. The turning term is the
plausibility verdict's (its floor, or twice what the clip's halves differ by, over the distance
between the samples' and the clip's heading change per second): a walk in a circle whose samples
go straight or spin is not in balance, whatever its coverage (the heading-frame walk's frame-norm
check at 100 % / 1.73 turned 15.9 deg/s away from the clip: 0.63, below its GroupNorm check at
100 % / 1.30 / 8.1 deg/s: 1.00; BENCHMARKS.md, "Turning"). The pace term is the same for the
distance travelled per second: an early walk checkpoint whose cleaned, smoothed samples scored
100 % / 1.38 walked 0.21 m/s slower than the clip (allowed: 0.13). Samples that teleport
(the root jumps more than 1.5x the clip's largest step) are never kept. The planted term (checks
with the cleanup only) is the verdict's: feet planted on at least PLANTED_RATIO of the share of
frames the clip's are. Whole-clip Xia normal's frame-norm stage won the balance at 1.05 while its
feet glided along with the body (planted on 12 % of frames, the clip's on 48 %); its GroupNorm
stage planted them on 29 % (BENCHMARKS.md, "Feet that never plant"). How high the feet lift
(`foot_lift_ratio`, against the clip's) is logged with every check but is not a term: as one, it
made the idle keep later weights of lower coverage (79.9 % against 87.6 %) whose feet shuffled
as much (0.55x against 0.45x the clip's), and no longer stall into the stage that put it in the
band (BENCHMARKS.md, "Feet that shuffle").
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from ..runtime.bvh import BVH
from ..runtime.errors import SinMDMError
from ..runtime.generate import generate
from ..runtime.model import MotionModel
from ..runtime.options import SamplingOptions
from ..runtime.rig import PLAUSIBLE_HUMANOID_METRES
from . import metrics
from .motion_features import eval_features, protocol_for
from .plausibility import (JITTER_RATIO, PACE_FLOOR_M_S, PLANTED_RATIO, TELEPORT_RATIO, TURN_FLOOR_DEG_S, pace_allowed, plausibility,
                           turning_allowed)

COVERAGE_BAND = 95.0  # % : below this the model drifts from the clip
DIVERSITY_BAND = 1.3  # global diversity: below this the model copies
# Samples (20 steps, no cleanup) shaking more than this many times the clip's own jerk
# are visibly noisy: every GroupNorm check of the benchmark clips stayed within 0.4-3.7x once
# past its first check, the frame-norm walk that "won" the band ran at 4.3-13x and walked a
# jagged path (BENCHMARKS.md). Above it, the balance falls as LIMIT / jitter.
JITTER_LIMIT = 3.0
# Sampling settings tried, most expensive first: (steps, hop as a share of the window).
# The cheapest whose balance stays within BALANCE_TOLERANCE of the first becomes the
# model's default (export metadata, `sinmdm-run sample`). 10 steps kept the balance of
# the walk and the demo (12 samples: 0.908 and 0.662 against 0.884 and 0.658 at 50 / 32)
# but not the crab's (0.387 against 0.462); no overlap (hop = window) was tried and left
# out: the walk's jitter rose to 9x the clip's and the crab's root jumped 3.4x (BENCHMARKS.md).
SAMPLING_CANDIDATES = ((50, 0.5), (30, 0.5), (20, 0.5), (20, 0.75), (10, 0.75))
BALANCE_TOLERANCE = 0.02
# Frames of smoothing (runtime.smoothing) tried in turn on the chosen setting while its
# samples shake more than the clip, each kept when the balance holds (within
# BALANCE_TOLERANCE of the unsmoothed setting's). Samples that already shake no more than
# the clip get no more: smoothing them takes out motion the clip has. 2 frames is not
# tried: on the walk it cut the forearm's speed peaks by a quarter (1 frame: under a
# tenth) and its global diversity by 0.09, beyond what the balance sees on a model short
# of coverage (docs/smoothing_walk.png, BENCHMARKS.md).
SMOOTH_CANDIDATES = (1.0,)
# Smoothing is also kept, beyond BALANCE_TOLERANCE, when it takes samples judged jittery (above the
# verdict's JITTER_RATIO) to below it for at most this much global diversity: the balance sees jitter
# only past JITTER_LIMIT. The heading-frame walk's checks: jitter 2.35x -> 1.32x for 0.036 of
# diversity (balance 1.014 -> 0.986); on its 20 benchmark samples 3.14x -> 1.63x, 0 -> 17 of 20
# plausible, global diversity 1.236 -> 1.215 (BENCHMARKS.md, "Turning, spins and the heading frame").
SMOOTH_DIVERSITY_COST = 0.05


def balance(coverage: float, global_diversity: float, jitter_ratio: float | None = None,
            turning_distance: float | None = None, turning_allowed: float = TURN_FLOOR_DEG_S,
            pace_distance: float | None = None, pace_allowed: float = PACE_FLOOR_M_S,
            planted_share: float | None = None, planted_needed: float | None = None) -> float:
    """The weakest of the band ratios, jitter's, turning's, pace's and the feet's planted share's
    included when they are known."""
    ratios = [coverage / COVERAGE_BAND, global_diversity / DIVERSITY_BAND]
    if jitter_ratio:
        ratios.append(JITTER_LIMIT / jitter_ratio)
    if turning_distance:
        ratios.append(turning_allowed / turning_distance)
    if pace_distance:
        ratios.append(pace_allowed / pace_distance)
    if planted_share is not None and planted_needed:
        ratios.append(planted_share / planted_needed)
    return float(min(ratios))


def scores_balance(scores: dict, jitter: bool = True) -> float:
    """`balance` of a scores dict (`ClipScorer.score`); `jitter=False`: as if the samples were calm."""
    return balance(scores["coverage"], scores["global_diversity"], scores["jitter_ratio"] if jitter else None,
                   scores.get("turning_distance_deg_s"), scores.get("turning_allowed_deg_s", TURN_FLOOR_DEG_S),
                   scores.get("pace_distance_m_s"), scores.get("pace_allowed_m_s", PACE_FLOOR_M_S),
                   scores.get("planted_share"), scores.get("planted_needed"))


def in_band(scores: dict) -> bool:
    return (scores["coverage"] >= COVERAGE_BAND and scores["global_diversity"] >= DIVERSITY_BAND
            and scores.get("jitter_ratio", 0.0) <= JITTER_LIMIT
            and scores.get("turning_distance_deg_s", 0.0) <= scores.get("turning_allowed_deg_s", TURN_FLOOR_DEG_S)
            and scores.get("pace_distance_m_s", 0.0) <= scores.get("pace_allowed_m_s", PACE_FLOOR_M_S)
            and scores.get("planted_share", 1.0) >= (scores.get("planted_needed") or 0.0))


def keepable(scores: dict) -> bool:
    return scores["root_step_max_ratio"] <= TELEPORT_RATIO


def eval_preset(reference: BVH) -> str:
    """The paper's protocol for a Mixamo skeleton whose units the paper's rule reads right, the
    project's own for any other. The rule (1/100 when the Hips OFFSET y exceeds 10) assumes a
    Y-up export with the hips at the top: on the walk with a static root and Z-up it read a 1.8 m
    figure as 180 m, so that only feet the cleanup holds exactly still counted as planted, and
    cleaned samples scored 1.51 in global diversity where raw ones scored 0.89 (BENCHMARKS.md)."""
    try:
        size = protocol_for(reference, "mixamo24").character_size
    except SinMDMError:
        return "default"
    low, high = PLAUSIBLE_HUMANOID_METRES
    return "mixamo24" if low <= size <= high else "default"


@dataclass(frozen=True)
class CheckSettings:
    samples: int = 6
    steps: int = 20  # respaced DDPM steps of the check's sampler
    hop: int | None = None  # None: half a window
    seed: int = 0
    # Sample with the foot cleanup, as `sample` does: an early checkpoint that labels a foot in contact on
    # every frame looks fine without it and loses coverage with it (BENCHMARKS.md, 2026-12-06)
    cleanup: bool = False


class ClipScorer:
    """Scores samples of a model against its clip: the paper's metrics, the plausibility
    aggregate and the balance. Samples are drawn with fixed seeds, no foot cleanup (unless the
    settings ask for it) and no smoothing (unless asked), so two scorings differ by the weights or
    the sampler settings only."""

    def __init__(self, reference: BVH, settings: CheckSettings = CheckSettings(), frames: int | None = None,
                 fps: float = 30.0, window: int = 64):
        self.reference, self.settings = reference, settings
        clip_frames = int(round(reference.frames / reference.fps * fps))
        self.frames = frames or max(clip_frames, 2 * window)
        self.preset = eval_preset(reference)
        self.protocol = protocol_for(reference, self.preset)
        self.reference_features = eval_features(reference, self.protocol)

    def check(self, model: MotionModel, steps: int | None = None, hop: int | None = None, smooth: float = 0.0) -> dict:
        began = time.perf_counter()
        options = SamplingOptions(count=self.settings.samples, seed=self.settings.seed, steps=steps or self.settings.steps,
                                  hop=hop or self.settings.hop, cleanup=self.settings.cleanup, smooth=smooth)
        result = generate(model, self.frames, options)
        return {**self.score(result.clips), "check_seconds": round(time.perf_counter() - began, 2)}

    def check_as_sampled(self, model: MotionModel, steps: int | None = None, hop: int | None = None,
                         to_beat: float | None = None) -> dict:
        """`check`, and where its samples shake past JITTER_LIMIT, the same samples smoothed by
        SMOOTH_CANDIDATES[0] when calibration would keep that smoothing (`smoothing_kept`): the
        balance of what the checkpoint gives once calibrated, not of its raw samples. Without it
        an early checkpoint that shakes loses to a later one that copies, though one frame of
        smoothing would calm it (Xia proud, BENCHMARKS.md). The smoothed pass is skipped where
        even calm samples could not beat `to_beat` (the best balance so far): smoothing only lifts
        the jitter term."""
        raw = {**self.check(model, steps, hop), "smooth": 0.0}
        if raw["jitter_ratio"] <= JITTER_LIMIT or (to_beat is not None and scores_balance(raw, jitter=False) <= to_beat):
            return raw
        sigma = SMOOTH_CANDIDATES[0]
        smoothed = {**self.check(model, steps, hop, smooth=sigma), "smooth": sigma}
        smoothed["check_seconds"] = round(raw["check_seconds"] + smoothed["check_seconds"], 2)
        return smoothed if smoothing_kept(raw, smoothed) else raw

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
            "turning_distance_deg_s": round(float(aggregate.get("turning_distance_deg_s", 0.0)), 2),
            "turning_allowed_deg_s": round(turning_allowed(aggregate.get("clip_turning_halves_deg_s", 0.0)), 2),
            "pace_distance_m_s": round(float(aggregate.get("pace_distance_m_s", 0.0)), 3),
            "pace_allowed_m_s": round(pace_allowed(aggregate.get("clip_pace_m_s", 0.0),
                                                   aggregate.get("clip_pace_halves_m_s", 0.0)), 3),
            "implausible": int(aggregate.get("implausible", 0)),
        }
        # Judged only on cleaned samples: raw ones shake past the contact speed where the model slows a
        # foot (the walk's raw samples are planted on 15 % of frames, cleaned on 31 %, its clip on 37 %).
        if self.settings.cleanup and "planted_share" in aggregate:
            scores["planted_share"] = round(float(aggregate["planted_share"]), 3)
            scores["planted_needed"] = round(PLANTED_RATIO * float(aggregate["clip_planted_share"]), 3)
        if aggregate.get("lift_judged"):
            scores["foot_lift_ratio"] = round(float(aggregate["foot_lift_cm"]) / float(aggregate["clip_foot_lift_cm"]), 3)
        scores["balance"] = round(scores_balance(scores), 4)
        return scores


def smoothing_kept(before: dict, smoothed: dict, unsmoothed_balance: float | None = None) -> bool:
    """Whether smoothing is worth keeping: the balance holds (within BALANCE_TOLERANCE of the
    unsmoothed setting's), or it calms samples judged jittery for at most SMOOTH_DIVERSITY_COST
    of global diversity; never when the smoothed samples teleport."""
    reference = before["balance"] if unsmoothed_balance is None else unsmoothed_balance
    calmed = (before["jitter_ratio"] > JITTER_RATIO >= smoothed["jitter_ratio"]
              and smoothed["global_diversity"] >= before["global_diversity"] - SMOOTH_DIVERSITY_COST)
    return keepable(smoothed) and (smoothed["balance"] >= reference - BALANCE_TOLERANCE or calmed)


def choose_sampling(model: MotionModel, scorer: ClipScorer, window: int) -> dict:
    """Try SAMPLING_CANDIDATES on `model` (the scorer's seeds), choose the cheapest that
    keeps the balance, then SMOOTH_CANDIDATES on it while its samples shake more than the
    clip: {"steps", "hop", "smooth", "scores", "trials"}."""
    trials = []
    for steps, share in SAMPLING_CANDIDATES:
        hop = max(1, int(round(window * share)))
        scores = scorer.check(model, steps=steps, hop=hop)
        trials.append({"steps": steps, "hop": hop, "smooth": 0.0, "cost": steps / share, **scores})
    reference = trials[0]["balance"]
    fine = [t for t in trials if t["balance"] >= reference - BALANCE_TOLERANCE and keepable(t)] or trials[:1]
    chosen = min(fine, key=lambda t: t["cost"])
    unsmoothed = chosen["balance"]
    for sigma in SMOOTH_CANDIDATES:
        if chosen["jitter_ratio"] <= 1.0:
            break
        smoothed = {**chosen, "smooth": sigma, **scorer.check(model, steps=chosen["steps"], hop=chosen["hop"], smooth=sigma)}
        trials.append(smoothed)
        if not smoothing_kept(chosen, smoothed, unsmoothed):
            break
        chosen = smoothed
    return {"steps": chosen["steps"], "hop": chosen["hop"], "smooth": chosen["smooth"], "scores": {k: chosen[k] for k in (
        "coverage", "global_diversity", "local_diversity", "jitter_ratio", "turning_distance_deg_s", "pace_distance_m_s",
        "balance", "eval_preset") if k in chosen}, "trials": trials}
