"""Plausibility: what an animator sees and the paper's metrics cannot (they read
rotations and contact bits, not root motion). Per sample, against the clip, at
30 fps in metres: root steps (teleports), speed distribution, walking against the
facing direction, pace (how far the character travels in a second, against the clip), turning
and spinning (how fast the character's heading changes, over a second and at its fastest,
against the clip's), foot skating and bobbing (horizontal and vertical speed of planted feet),
how high the feet lift (a model that shuffles), floor penetration and jitter, and a one-line
verdict (bobbing is reported, not judged: the cleanup holds ankles, not toes, at their height).

Joints are the REFERENCE codec's (trajectory joint, contacts, up axis), found by
name in each sample, so other systems' outputs are scored the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..runtime.animation import animation_from_bvh
from ..runtime.bvh import BVH
from ..runtime.contacts import contact_labels
from ..runtime.features import MotionCodec, build_codec, resample_animation
from ..runtime.heading import MOVING_SPEED, horizontal_axis, moving_axis, yaw
from ..runtime.kinematics import forward_kinematics

FPS = 30.0
FLOOR_TOLERANCE = 0.01  # m below the clip's floor before a joint counts as in it
# Verdict thresholds: beyond these an animator sees the flaw at playback speed.
TELEPORT_RATIO = 1.5  # largest root step vs the clip's largest
BACKWARD_POINTS = 0.05  # share of frames walking backwards beyond the most any half of the clip has
SKATING_RATIO, SKATING_SLACK_CM_S = 1.5, 2.0
# Feet that never stop: planted (slow and near the floor) on less than this share of the frames the
# clip's feet are. Skating is measured on planted frames only, so a model whose feet glide along with
# the body at its speed scored "plausible": a whole-clip Xia normal model's feet moved at 0.1 m/s or
# more on 90 % of frames (its clip's: 0.005), coverage 100 %, global diversity 1.57 (BENCHMARKS.md).
PLANTED_RATIO = 0.5
PENETRATION_CM = 2.0
# Feet that shuffle: the contact joints lift (their 95th height percentile above their 5th) less than
# this share of the clip's. The Z-up walk's kept step-400 checkpoint (at lr 1e-4, 100 % / 1.40 at its
# check) lifted its feet 4.0 cm as sampled where the clip lifts them 10.9; the same run's weights
# 600 steps later, 8.6 cm; nothing else here saw it (BENCHMARKS.md, "Feet that shuffle"). Judged
# only where the clip's feet lift at least LIFT_FLOOR of the character's size: an idle's few
# millimetres are no gait.
LIFT_RATIO = 0.7
LIFT_FLOOR = 0.03
JITTER_RATIO = 2.0
# Turning: the distance between the sample's and the clip's distributions of heading change
# per second (over 1 s windows, signed: a clip that only turns left allows no right turns).
# Beyond the floor, or beyond twice what the clip's halves differ by (an idle that turns
# either way allows more), the path is not the clip's: a walk in a circle gone straight.
TURN_WINDOW_S = 1.0
TURN_FLOOR_DEG_S = 10.0
TURN_HALVES_FACTOR = 2.0
# Pace: the distance between the sample's and the clip's distributions of travel per second (the
# trajectory joint's horizontal displacement over 1 s windows: the sway within a step cancels).
# Beyond the floor, a share of the clip's own pace, or twice what the clip's halves differ by, the
# character walks visibly slower or faster than the clip: an early walk checkpoint travelled 0.66 m/s
# against the clip's 0.87 with shorter strides, at 100 % coverage and 1.38 global diversity
# (BENCHMARKS.md, "Checks that sample as `sample` does").
PACE_WINDOW_S = 1.0
PACE_FLOOR_M_S, PACE_SHARE, PACE_HALVES_FACTOR = 0.1, 0.15, 2.0
# Spinning: the fastest heading change over SPIN_WINDOW_S, against the clip's fastest. Where windows
# of different headings meet, a world-frame walk whipped round at 200-800 deg/s (its clip: 82).
SPIN_WINDOW_S = 0.25
SPIN_RATIO, SPIN_FLOOR_DEG_S = 2.0, 90.0
# A step this many times the median of its neighbours (3 frames each side) is a jump out of
# the motion (a teleport); a fast step among fast steps is a motion faster than the clip's.
JUMP_CONTRAST = 3.0
# A root step under this share of the character's size per frame is never a teleport:
# the floor under the clip's own steps, so a clip whose root barely moves (an idle)
# does not turn a few millimetres of sway into a "500x" jump.
STEP_FLOOR = 0.005


@dataclass(frozen=True)
class Track:
    positions: np.ndarray  # (T, J, 3) metres, the reference's joints by name
    root_rotations: np.ndarray  # (T, 3, 3) global rotation of the trajectory joint


def track(bvh: BVH, names: list[str], scale: float) -> Track:
    animation = resample_animation(animation_from_bvh(bvh), FPS)
    rotations, positions = forward_kinematics(animation.rotations, animation.translations,
                                              animation.skeleton.parents)
    index = [bvh.skeleton.index(n) for n in names]
    return Track(positions[:, index] * scale, rotations[:, index[0]])


def _horizontal(up: int) -> list[int]:
    return [a for a in range(3) if a != up]


def root_steps(t: Track) -> np.ndarray:
    return np.linalg.norm(np.diff(t.positions[:, 0], axis=0), axis=-1)


def step_contrast(steps: np.ndarray, frame: int, reach: int = 3) -> float:
    """steps[frame] against the median of the steps within `reach` frames of it."""
    around = np.concatenate([steps[max(0, frame - reach) : frame], steps[frame + 1 : frame + 1 + reach]])
    return _ratio(float(steps[frame]), float(np.median(around))) if len(around) else 1.0


def forward_axis(t: Track, up: int) -> np.ndarray | None:
    """The trajectory joint's local axis the clip travels along (None if it stands)."""
    return moving_axis(t.root_rotations[1:], np.diff(t.positions[:, 0], axis=0) * FPS, up)


def headings(t: Track, axis: np.ndarray, up: int) -> np.ndarray:
    """(T,) radians, unwrapped: the yaw of the trajectory joint's `axis` (+ = counter-clockwise
    seen from above)."""
    return np.unwrap(yaw(np.einsum("tab,b->ta", t.root_rotations, axis), up))


def turning_rates(heading: np.ndarray, window_s: float = TURN_WINDOW_S) -> np.ndarray:
    """Heading change over each `window_s` window of (T,) `headings`, in degrees per second;
    empty for a motion shorter than a window."""
    frames = max(int(round(window_s * FPS)), 1)
    if len(heading) <= frames:
        return np.zeros(0)
    return np.degrees(heading[frames:] - heading[:-frames]) / (frames / FPS)


def paces(t: Track, up: int, window_s: float = PACE_WINDOW_S) -> np.ndarray:
    """Horizontal displacement of the trajectory joint over each `window_s` window, in m/s;
    empty for a motion shorter than a window."""
    frames = max(int(round(window_s * FPS)), 1)
    if len(t.positions) <= frames:
        return np.zeros(0)
    ground = t.positions[:, 0][:, _horizontal(up)]
    return np.linalg.norm(ground[frames:] - ground[:-frames], axis=-1) / (frames / FPS)


def fastest_turn(heading: np.ndarray) -> tuple[float, int]:
    """(deg/s, frame): the fastest heading change over SPIN_WINDOW_S, and where it ends."""
    rates = np.abs(turning_rates(heading, SPIN_WINDOW_S))
    if not len(rates):
        return 0.0, 0
    return float(rates.max()), int(rates.argmax()) + max(int(round(SPIN_WINDOW_S * FPS)), 1)


def backward_frames(t: Track, forward: np.ndarray | None, up: int) -> np.ndarray:
    """(T-1,) bool: frames on which the trajectory joint moves against its facing direction."""
    if forward is None:
        return np.zeros(max(len(t.positions) - 1, 0), dtype=bool)
    velocity = np.diff(t.positions[:, 0], axis=0) * FPS
    velocity[:, up] = 0.0
    facing = np.einsum("tab,b->ta", t.root_rotations[1:], forward)
    facing[:, up] = 0.0
    moving = np.linalg.norm(velocity, axis=-1) > MOVING_SPEED
    return moving & (np.sum(velocity * facing, axis=-1) < 0)


def backward_share(t: Track, forward: np.ndarray | None, up: int) -> float:
    frames = backward_frames(t, forward, up)
    return float(frames.mean()) if len(frames) else 0.0


def most_backward_half(t: Track, forward: np.ndarray | None, up: int) -> float:
    """The largest backward share over the clip's windows of half its length. A clip that
    walks one way in its first half and back and forth in its second (the crab's dance:
    8 % and 40 %) allows a recombination of its halves anywhere in that range; a clip that
    only walks forwards allows nothing."""
    frames = backward_frames(t, forward, up).astype(np.float64)
    if not len(frames):
        return 0.0
    length = max(len(frames) // 2, 1)
    sums = np.convolve(frames, np.ones(length), mode="valid")
    return float(sums.max() / length)


def planted(t: Track, contacts: list[int], speed: float, up: int, floor: float, size: float) -> np.ndarray:
    """(T, C) bool: the contact joints slow by the contact rule and near the clip's floor."""
    feet = t.positions[:, contacts]
    return contact_labels(feet, FPS, speed).astype(bool) & (feet[..., up] - floor < 0.05 * size)


def planted_speeds_cm_s(t: Track, contacts: list[int], still: np.ndarray, up: int) -> tuple[float, float]:
    """Mean horizontal (skating) and vertical (bobbing) speed of the contact joints on the
    frames where they are planted (`still`, from `planted`)."""
    if not contacts:
        return 0.0, 0.0
    velocity = np.diff(t.positions[:, contacts], axis=0) * FPS
    still = still[1:] & still[:-1]
    if not still.any():
        return 0.0, 0.0
    horizontal = np.linalg.norm(velocity[..., _horizontal(up)], axis=-1)
    return float(horizontal[still].mean() * 100), float(np.abs(velocity[..., up])[still].mean() * 100)


def foot_lift(t: Track, contacts: list[int], up: int) -> float:
    """How high the contact joints lift, in metres: the mean over them of their 95th height
    percentile above their 5th (each joint's own, so a foot resting a little high still counts)."""
    if not contacts:
        return 0.0
    heights = t.positions[:, contacts, up]
    return float((np.percentile(heights, 95, axis=0) - np.percentile(heights, 5, axis=0)).mean())


def share(mask: np.ndarray) -> float:
    """The share of True in `mask` (0 when it is empty: a clip without contacts)."""
    return float(mask.mean()) if mask.size else 0.0


def jerk(t: Track) -> float:
    return float(np.linalg.norm(np.diff(t.positions, n=3, axis=0), axis=-1).mean() * FPS**3) if len(t.positions) > 3 else 0.0


def wasserstein_1d(a: np.ndarray, b: np.ndarray) -> float:
    q = np.linspace(0, 1, 201)
    return float(np.abs(np.quantile(a, q) - np.quantile(b, q)).mean()) if len(a) and len(b) else 0.0


def _speeds(t: Track, up: int) -> np.ndarray:
    return np.linalg.norm(np.diff(t.positions[:, 0][:, _horizontal(up)], axis=0), axis=-1) * FPS


def _ratio(a: float, b: float) -> float:
    return float(a / b) if b > 1e-12 else (1.0 if a <= 1e-12 else float("inf"))


def joint_floors(ref: Track, floor: float, up: int) -> np.ndarray:
    """(J,) the height below which each joint counts as in the floor: the clip's floor, or
    lower where the clip itself puts that joint lower (the crab's clip dips a claw 4 cm
    through its floor): what the clip does is not a flaw of a sample, and the clip against
    itself stays neutral."""
    return np.minimum(floor, ref.positions[..., up].min(axis=0))


@dataclass(frozen=True)
class Reference:
    """The clip's own figures that every sample is scored against, computed once."""
    codec: MotionCodec
    contacts: list[int]  # indices into the tracks' joints
    floor: float
    joint_floors: np.ndarray  # (J,)
    forward: np.ndarray | None
    steps: np.ndarray  # (T-1,) root step per frame, metres
    speeds: np.ndarray  # (T-1,) horizontal root speed, m/s
    paces: np.ndarray  # (windows,) travel per second, m/s
    pace_halves_m_s: float  # distance between the clip's own halves' paces
    skating_cm_s: float
    bob_cm_s: float
    planted_share: float
    lift_m: float  # foot_lift of the clip
    lift_judged: bool  # the clip's feet lift at least LIFT_FLOOR of its size: a sample's lift is judged
    backward_share: float
    backward_half_max: float
    heading_axis: np.ndarray
    turning: np.ndarray  # (windows,) degrees per second
    turning_halves_deg_s: float  # distance between the clip's own halves' turning
    fastest_turn_deg_s: float
    jerk: float


def reference_figures(ref: Track, codec: MotionCodec, contacts: list[int]) -> Reference:
    up = codec.up_axis
    floor = float(np.percentile(ref.positions[..., up].min(axis=1), 2))
    forward = forward_axis(ref, up)
    still = planted(ref, contacts, codec.contact_speed, up, floor, codec.size)
    skating, bob = planted_speeds_cm_s(ref, contacts, still, up)
    axis = horizontal_axis(ref.root_rotations[1:], up) if forward is None else forward
    heading = headings(ref, axis, up)
    turning = turning_rates(heading)
    half = len(turning) // 2
    pace = paces(ref, up)
    lift = foot_lift(ref, contacts, up)
    return Reference(codec=codec, contacts=contacts, floor=floor, joint_floors=joint_floors(ref, floor, up),
                     forward=forward, steps=root_steps(ref), speeds=_speeds(ref, up), paces=pace,
                     pace_halves_m_s=wasserstein_1d(pace[:len(pace) // 2], pace[len(pace) // 2:]), skating_cm_s=skating, bob_cm_s=bob,
                     planted_share=share(still), lift_m=lift,
                     lift_judged=lift >= LIFT_FLOOR * codec.size,
                     backward_share=backward_share(ref, forward, up),
                     backward_half_max=most_backward_half(ref, forward, up), heading_axis=axis, turning=turning,
                     turning_halves_deg_s=wasserstein_1d(turning[:half], turning[half:]),
                     fastest_turn_deg_s=fastest_turn(heading)[0], jerk=jerk(ref))


def score_sample(ref: Reference, sample: Track) -> dict:
    codec = ref.codec
    up, size = codec.up_axis, codec.size
    steps = root_steps(sample)
    floor_step = STEP_FLOOR * size
    still = planted(sample, ref.contacts, codec.contact_speed, up, ref.floor, size)
    skate, bob = planted_speeds_cm_s(sample, ref.contacts, still, up)
    depth = ref.joint_floors - sample.positions[..., up]
    heading = headings(sample, ref.heading_axis, up)
    turning = turning_rates(heading)
    spin, spin_frame = fastest_turn(heading)
    pace = paces(sample, up)
    below = depth > FLOOR_TOLERANCE
    scores = {
        "root_step_max_ratio": _ratio(steps.max(initial=0), max(ref.steps.max(initial=0), floor_step)),
        "root_step_p99_ratio": _ratio(np.percentile(steps, 99) if len(steps) else 0,
                                      max(np.percentile(ref.steps, 99) if len(ref.steps) else 0, floor_step)),
        "worst_step_frame": int(steps.argmax()) + 1 if len(steps) else 0,
        "worst_step_contrast": step_contrast(steps, int(steps.argmax())) if len(steps) else 1.0,
        "speed_distance_m_s": wasserstein_1d(_speeds(sample, up), ref.speeds),
        "pace_m_s": float(pace.mean()) if len(pace) else 0.0,
        "clip_pace_m_s": float(ref.paces.mean()) if len(ref.paces) else 0.0,
        "clip_pace_halves_m_s": ref.pace_halves_m_s,
        "pace_distance_m_s": wasserstein_1d(pace, ref.paces),
        "backward_share": backward_share(sample, ref.forward, up),
        "clip_backward_share": ref.backward_share,
        "clip_backward_half_max": ref.backward_half_max,
        "turning_distance_deg_s": wasserstein_1d(turning, ref.turning),
        "turning_deg_s": float(turning.mean()) if len(turning) else 0.0,
        "clip_turning_deg_s": float(ref.turning.mean()) if len(ref.turning) else 0.0,
        "clip_turning_halves_deg_s": ref.turning_halves_deg_s,
        "fastest_turn_deg_s": spin,
        "fastest_turn_frame": spin_frame,
        "clip_fastest_turn_deg_s": ref.fastest_turn_deg_s,
        "foot_skating_cm_s": skate,
        "clip_foot_skating_cm_s": ref.skating_cm_s,
        "foot_bob_cm_s": bob,
        "clip_foot_bob_cm_s": ref.bob_cm_s,
        "planted_share": share(still),
        "clip_planted_share": ref.planted_share,
        "foot_lift_cm": foot_lift(sample, ref.contacts, up) * 100,
        "clip_foot_lift_cm": ref.lift_m * 100,
        "lift_judged": ref.lift_judged,
        "penetration_cm": float(depth[below].mean() * 100) if below.any() else 0.0,
        "penetration_share": float(below.any(axis=1).mean()),
        "jitter_ratio": _ratio(jerk(sample), ref.jerk),
    }
    scores["verdict"] = verdict(scores)
    return scores


def _percent(share: float) -> str:
    """A share as a percentage a reader can tell from zero: "0.3 %", not "0 %"."""
    return f"{100 * share:.1f} %" if 0 < share < 0.01 else f"{100 * share:.0f} %"


def turning_allowed(clip_halves_deg_s: float) -> float:
    """Degrees per second a sample's turning may be from the clip's before it is a flaw."""
    return max(TURN_FLOOR_DEG_S, TURN_HALVES_FACTOR * clip_halves_deg_s)


def pace_allowed(clip_pace_m_s: float, clip_halves_m_s: float) -> float:
    """Metres per second a sample's pace may be from the clip's before it is a flaw."""
    return max(PACE_FLOOR_M_S, PACE_SHARE * clip_pace_m_s, PACE_HALVES_FACTOR * clip_halves_m_s)


def verdict(s: dict) -> str:
    if s["root_step_max_ratio"] > TELEPORT_RATIO:
        if s.get("worst_step_contrast", np.inf) > JUMP_CONTRAST:
            return (f"teleports: root jumps {s['root_step_max_ratio']:.1f}x the clip's largest per-frame step "
                    f"at frame {s['worst_step_frame']}")
        return (f"root too fast: {s['root_step_max_ratio']:.1f}x the clip's fastest per-frame step, "
                f"at frame {s['worst_step_frame']}")
    allowed = max(s["clip_backward_share"], s.get("clip_backward_half_max", 0.0))
    if s["backward_share"] > allowed + BACKWARD_POINTS:
        return (f"walks backwards {100 * s['backward_share']:.0f} % of frames (clip: {100 * s['clip_backward_share']:.0f} %, "
                f"at most {100 * allowed:.0f} % in any half of it)")
    spin, clip_spin = s.get("fastest_turn_deg_s", 0.0), s.get("clip_fastest_turn_deg_s", 0.0)
    if spin > max(SPIN_RATIO * clip_spin, SPIN_FLOOR_DEG_S):
        return (f"spins: turns {spin:.0f} deg/s at frame {s['fastest_turn_frame']} "
                f"(the clip's fastest turn: {clip_spin:.0f} deg/s)")
    if s.get("turning_distance_deg_s", 0.0) > turning_allowed(s.get("clip_turning_halves_deg_s", 0.0)):
        return (f"turns unlike the clip: {round(s['turning_deg_s']):+d} deg/s on average (clip: {round(s['clip_turning_deg_s']):+d}), "
                f"{s['turning_distance_deg_s']:.0f} deg/s apart")
    if s.get("pace_distance_m_s", 0.0) > pace_allowed(s.get("clip_pace_m_s", 0.0), s.get("clip_pace_halves_m_s", 0.0)):
        pace, clip_pace = s["pace_m_s"], s["clip_pace_m_s"]
        return (f"travels {'slower' if pace < clip_pace else 'faster'} than the clip: {pace:.2f} m/s over a second "
                f"(clip: {clip_pace:.2f}), {s['pace_distance_m_s']:.2f} m/s apart")
    if s["penetration_cm"] > PENETRATION_CM:
        return f"sinks {s['penetration_cm']:.0f} cm into the floor on {_percent(s['penetration_share'])} of frames"
    if s.get("planted_share", 1.0) < PLANTED_RATIO * s.get("clip_planted_share", 0.0):
        return (f"feet glide: planted on {_percent(s['planted_share'])} of frames "
                f"(clip: {_percent(s['clip_planted_share'])})")
    if s.get("lift_judged") and s["foot_lift_cm"] < LIFT_RATIO * s["clip_foot_lift_cm"]:
        return f"feet shuffle: they lift {s['foot_lift_cm']:.0f} cm (clip: {s['clip_foot_lift_cm']:.0f})"
    if s["foot_skating_cm_s"] > SKATING_RATIO * s["clip_foot_skating_cm_s"] + SKATING_SLACK_CM_S:
        return f"feet slide {s['foot_skating_cm_s']:.1f} cm/s while planted (clip: {s['clip_foot_skating_cm_s']:.1f})"
    if s["jitter_ratio"] > JITTER_RATIO:
        return f"jittery: {s['jitter_ratio']:.1f}x the clip's jerk"
    return "plausible"


def plausibility(reference: BVH, samples: list[BVH], units: str | float = "auto") -> dict:
    """Per-sample scores and their aggregate (JSON-ready)."""
    codec = build_codec(reference, fps=FPS, units=units)
    if codec.trajectory_joint is None:
        return {"samples": [], "aggregate": None, "note": "the clip has no trajectory joint"}
    names = reference.skeleton.names
    wanted = [names[codec.trajectory_joint]] + [names[j] for j in codec.contact_joints] + [
        n for j, n in enumerate(names) if j != codec.trajectory_joint and j not in codec.contact_joints]
    contacts = list(range(1, 1 + len(codec.contact_joints)))
    ref = reference_figures(track(reference, wanted, codec.scale), codec, contacts)
    rows = [score_sample(ref, track(s, wanted, codec.scale)) for s in samples]
    aggregate = {
        "root_step_max_ratio": max(r["root_step_max_ratio"] for r in rows),
        "fastest_turn_deg_s": max(r["fastest_turn_deg_s"] for r in rows),
        **{k: float(np.mean([r[k] for r in rows])) for k in (
            "root_step_p99_ratio", "speed_distance_m_s", "pace_m_s", "pace_distance_m_s", "backward_share",
            "turning_distance_deg_s",
            "turning_deg_s", "foot_skating_cm_s",
            "foot_bob_cm_s", "planted_share", "foot_lift_cm", "penetration_cm", "penetration_share", "jitter_ratio")},
        "clip_backward_share": rows[0]["clip_backward_share"],
        "clip_backward_half_max": rows[0]["clip_backward_half_max"],
        "clip_pace_m_s": rows[0]["clip_pace_m_s"],
        "clip_pace_halves_m_s": rows[0]["clip_pace_halves_m_s"],
        "clip_turning_deg_s": rows[0]["clip_turning_deg_s"],
        "clip_turning_halves_deg_s": rows[0]["clip_turning_halves_deg_s"],
        "clip_fastest_turn_deg_s": rows[0]["clip_fastest_turn_deg_s"],
        "clip_foot_skating_cm_s": rows[0]["clip_foot_skating_cm_s"],
        "clip_foot_bob_cm_s": rows[0]["clip_foot_bob_cm_s"],
        "clip_planted_share": rows[0]["clip_planted_share"],
        "clip_foot_lift_cm": rows[0]["clip_foot_lift_cm"],
        "lift_judged": rows[0]["lift_judged"],
        "implausible": sum(r["verdict"] != "plausible" for r in rows),
    } if rows else None
    return {"samples": rows, "aggregate": aggregate,
            "trajectory_joint": names[codec.trajectory_joint], "up_axis": "xyz"[codec.up_axis]}
