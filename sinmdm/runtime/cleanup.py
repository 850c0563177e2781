"""Foot-contact cleanup: pin planted joints where the model says they touch the floor.

Sampled motion carries its own contact labels (one feature channel per contact
joint). `cleanup_contacts` turns them into horizontal targets and bends the legs
with numpy IK so that planted joints stop sliding:

1. Intervals: runs of frames with label > 0.5 (unless the joint travels further than
   `MAX_SLIDE` over the run: a label on a swinging limb) or where the joint moves
   slower than the codec's contact speed, at least `MIN_CONTACT_FRAMES` long, and
   never higher than `CONTACT_HEIGHT` above the joint's resting height; a labelled run's ends
   where the joint still moves fast (`FAST_ENDS`) are left out.
   Inside a run the joint's target is its position averaged over the run, height
   included: a planted foot neither slides nor bobs (sampled feet rise and fall by
   about 10 cm/s while planted, 15x the crab clip's own: BENCHMARKS.md). A joint planted
   while the joint above it on the foot is (the ball under a planted ankle) is pinned where
   the ankle's pin carries it over the frames they share, so the pins stay a foot apart.
   The IK offset (target - position) eases out after a run and in before the next one
   over about `EASE_FRAMES`, the smoothest curve that meets the pins (banded.fit_smooth),
   so a foot lands and lifts off at its sampled speed and nothing pops; a pin that lowers
   the joint lets go over `LOWER_EASE` instead, so that it does not hold down the swing. Where a leg
   cannot reach its pin with the knee no straighter than sampled, the hips are lowered
   (hips_drop) rather than the knee locked straight.
2. Legs: contact joints on one chain (Mixamo's Foot, ToeBase, Toe_End) form one
   leg. Its effector is the highest of them, moved up past short end bones (a toe
   whose bone is shorter than half the bone above it hands over to the ankle).
   A two-bone analytic solve on the effector's two nearest rotating ancestors
   ("hip" and "knee") moves the effector to its target while keeping its world
   orientation, so the joints below it translate rigidly with it; each lower
   contact joint is then aimed at its own target by its nearest rotating ancestor
   (the ankle for a toe), turning at most `PIVOT_TURN`: uncapped, a toe whose pin lies
   behind it swung round by up to 180 degrees, bent far past anything the clip does
   (BENCHMARKS.md); what the cap leaves slides a little. A leg with only a toe planted
   (heel off) is pinned by the ankle's translation, a fully planted foot by both steps:
   that is why this beats solving only the highest or only the lowest joint (whichever
   is not solved for keeps sliding while the other is planted).
3. Many-jointed legs (a crab's five joints from body to tip): one damped-least-squares
   solve over the whole chain, the smallest turns that reach the target, shared by
   every joint. Bending only the last two joints turned them 4x as far from the
   sampled pose, and the paper's metrics read those rotations (BENCHMARKS.md).

Only local rotations of joints with three rotation channels change: bone lengths
are exact, joints outside the solved legs do not move, and a motion without
contacts comes back unchanged. Everything is vectorised over frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .animation import Animation
from .contacts import contact_labels
from .kinematics import chain_kinematics, forward_kinematics, positions_by_chunks
from .rig import ancestors
from .banded import fit_smooth
from .smoothing import smooth_frames

CONTACT_THRESHOLD = 0.5  # a label above this is "in contact"
MIN_CONTACT_FRAMES = 2  # shorter runs are noise
# The offsets that pin a joint ease in before a contact run and out after it over about EASE_FRAMES
# (contact_offsets). A cosine fade of the offset at the run's edge over 4 frames started and stopped
# the feet within a frame and made their jerk 2-4x the sampled feet's (BENCHMARKS.md).
EASE_FRAMES = 3.0
# A pin that lowers a joint eases out over about LOWER_EASE frames instead: the labels come on while
# a toe is still descending (at 7 cm on a walk), so its pin lowers those frames, and over EASE_FRAMES
# that lowering reached back into a swing of 8 frames and cut its top: the cleaned walk's feet lifted
# 0.72x the clip's against 0.86x sampled, a Z-up walk's 0.37x against 0.73x (BENCHMARKS.md).
LOWER_EASE = 1.0
PIN_WEIGHT, FREE_WEIGHT = 1e4, 1e-3  # how strongly the fit holds the pins inside a run, and zero outside
FADED = 1e-3  # a weight below this is none: frames far from any contact stay untouched
LIFT_EASE = 2.0  # frames (Gaussian sigma) over which a raise off the floor eases in and out
SHORT_BONE = 0.5  # an end bone shorter than this share of the bone above it is a toe, not a shin
ROOT_CORRECTION = True  # slow the root to its planted feet before the IK (plain samples only: see slow_root)
ROOT_SMOOTHING = 9  # frames of the correction's smoothing window (0.3 s at 30 fps)
GROW_PASSES = 2  # extra passes that pin the frames a pass slowed down (see cleanup_contacts)
# A contact joint more than this share of the character's size above its resting height is not on
# the floor, however slowly it moves or whatever its label says: at the top of a raised knee the
# idle's foot was pinned 40 cm in the air and the knee jumped 13 cm in a frame when the pin moved
# to the floor. In the clips 98-100 % of the frames their feet are slow on lie within it.
CONTACT_HEIGHT = 0.05
# A labelled run's first and last frames where the joint moves faster than this many times the
# codec's contact speed are not planted: the label came on before the foot landed or stayed on
# after it lifted, and pinning those frames held the foot back up to 15 cm, so that the knee
# caught up by 35 degrees in a frame (a walk; the clip's own fastest is 13). At 1x the feet slid
# more (Xia proud 0.22 -> 0.33 cm/s).
FAST_ENDS = 2.0
MAX_SLIDE = 0.25  # a "contact" over which the joint travels further (share of the character's size) is a label error
# A leg with this many rotating joints above its effector (an arthropod's, not a human's hip-knee
# or hip-joint-hip-knee) is solved as one chain by damped least squares: the smallest rotations
# that reach the target, shared by every joint, instead of two joints bent far from the model's pose.
CHAIN_JOINTS = 4
CHAIN_ITERATIONS = 6
CHAIN_DAMPING = 0.02  # share of the chain's reach: keeps a straight chain's solve finite
CHAIN_REACH = 0.98  # share of the chain's reach a target is pulled back to
CHAIN_STEP = 0.3  # radians: the largest turn of one joint in one iteration (the linearisation's range)
HINGE_BENT = np.radians(20.0)  # a knee bent less than this is solved about its thigh's shared hinge axis (_hinge_axes)
PIVOT_TURN = 0.5  # radians (29 deg): the largest turn an ankle or a toe makes to aim the contact below it
# A pin further from the hip than the sampled leg reaches locked the knee straight (180 deg, where the
# clips never pass 175-177) on 5-12 % of frames, and it snapped back bent when the pin let go: the
# cleanup's knees shook 7x more than the sampled ones (BENCHMARKS.md). The hips are lowered instead,
# just enough for every pinned foot to be reached with the knee no straighter than the model sampled
# it or than STRAIGHT_REACH of the leg's full reach (a knee of about 170 deg), whichever is straighter.
STRAIGHT_REACH = 0.996
DROP_EASE = 2.0  # frames (Gaussian sigma) over which the hips' drop eases in and out
MAX_DROP = 0.15  # share of the leg's reach: the hips drop no further (a pin that far is left short)
_EPS = 1e-9


# ------------------------------------------------------------------ rotations
def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (zero where v is ~0) and norms."""
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(norm > _EPS, v / np.maximum(norm, _EPS), 0.0), norm[..., 0]


def _skew(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) matrices [v]x with [v]x w = v x w."""
    x, y, z = np.moveaxis(v, -1, 0)
    zero = np.zeros_like(x)
    return np.stack([zero, -z, y, z, zero, -x, -y, x, zero], axis=-1).reshape(v.shape + (3,))


def axis_angle_matrix(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(..., 3, 3) Rodrigues rotations about unit axes (..., 3); a zero axis gives identity."""
    k = _skew(axis)
    s, c = np.sin(angle)[..., None, None], np.cos(angle)[..., None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def _angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angle between vectors, accurate near 0 and pi."""
    return np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.sum(u * v, axis=-1))


def rotation_between(u: np.ndarray, v: np.ndarray, fraction: np.ndarray | float = 1.0,
                     limit: float = np.inf) -> np.ndarray:
    """The shortest rotation turning direction u towards v, by `fraction` of the way and
    at most `limit` radians."""
    axis, _ = _unit(np.cross(u, v))
    return axis_angle_matrix(axis, np.minimum(_angle(u, v) * fraction, limit))


def _apply_world(local: np.ndarray, parent_global: np.ndarray, world: np.ndarray) -> np.ndarray:
    """New local rotation of a joint whose global rotation is pre-multiplied by `world`
    while its parent's global rotation stays `parent_global`."""
    return np.swapaxes(parent_global, -1, -2) @ world @ parent_global @ local


# ------------------------------------------------------------------ contacts
def contact_intervals(labels: np.ndarray, threshold: float = CONTACT_THRESHOLD,
                      min_frames: int = MIN_CONTACT_FRAMES) -> list[tuple[int, int]]:
    """(start, stop) frame ranges where labels (T,) exceed `threshold` for >= min_frames."""
    on = np.concatenate([[0], (np.asarray(labels) > threshold).astype(np.int8), [0]])
    edges = np.diff(on)
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(s), int(e)) for s, e in zip(starts, stops) if e - s >= min_frames]


def contact_mask(labels: np.ndarray, threshold: float = CONTACT_THRESHOLD,
                 min_frames: int = MIN_CONTACT_FRAMES) -> np.ndarray:
    """(T,) bool: frames inside a contact interval."""
    mask = np.zeros(len(labels), dtype=bool)
    for start, stop in contact_intervals(labels, threshold, min_frames):
        mask[start:stop] = True
    return mask


def near_floor(positions: np.ndarray, up: int, floors: np.ndarray | None, reach: float) -> np.ndarray:
    """(T, C) bool: contact joints (T, C, 3) no higher than `reach` above their resting heights
    `floors` (C,) (None: each joint's lowest 5 % of frames in this motion)."""
    heights = positions[..., up]
    rest = np.percentile(heights, 5, axis=0) if floors is None else np.asarray(floors)
    return heights <= rest + reach


def drop_slides(inside: np.ndarray, positions: np.ndarray, up_axis: int, limit: float) -> np.ndarray:
    """`inside` (T,) without the runs over which the joint's horizontal positions (T, 3)
    spread further than `limit`: a label on a swinging limb, not a planted one."""
    out = inside.copy()
    horizontal = [a for a in range(3) if a != up_axis]
    for start, stop in contact_intervals(inside, min_frames=1):
        if np.ptp(positions[start:stop][:, horizontal], axis=0).max() > limit:
            out[start:stop] = False
    return out


def trim_fast_ends(inside: np.ndarray, positions: np.ndarray, limit: float) -> np.ndarray:
    """`inside` (T,) with each run's first frames cut while the joint (positions (T, 3)) moves
    on faster than `limit` per frame, and its last frames while it arrives faster: a label
    switched on before the foot lands or left on after it lifts."""
    out = inside.copy()
    step = np.linalg.norm(np.diff(positions, axis=0), axis=-1)  # step[t]: frame t to t + 1
    for start, stop in contact_intervals(inside, min_frames=1):
        while start < stop and start < len(step) and step[start] > limit:
            out[start] = False
            start += 1
        while stop > start and stop >= 2 and step[stop - 2] > limit:
            out[stop - 1] = False
            stop -= 1
        if stop - start < MIN_CONTACT_FRAMES:
            out[start:stop] = False
    return out


def _run_means(runs: np.ndarray, positions: np.ndarray, frames: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Per run id (0..count-1): the mean of positions (T, 3) over the run's `frames` (T,) bool, and how many."""
    ids = runs[frames]
    counts = np.bincount(ids, minlength=count).astype(float)
    sums = np.stack([np.bincount(ids, positions[frames, k], minlength=count) for k in range(3)], axis=1)
    return sums / np.maximum(counts, 1.0)[:, None], counts


def contact_offsets(positions: np.ndarray, inside: np.ndarray, ease: float = EASE_FRAMES,
                    carried: np.ndarray | None = None, up: int | None = None,
                    floor: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """IK offsets of one joint: `anchor` (T, 3) and `weight` (T,) with the applied
    offset = weight * anchor. Inside an interval the anchor takes the joint to the
    interval's mean position (weight 1); around it the offset eases out and in over about
    `ease` frames, as the smoothest curve (least second differences) that meets the pins: the
    pinned joint arrives and leaves at the speed the sample has.
    `carried` (T, 3), NaN where unset: the offset of the planted joint above this one on
    the same foot (the ankle over the ball). A run that overlaps it is pinned where that
    offset carries the joint on the shared frames: pinned on their own means over their
    own runs, a sliding foot's ankle and ball land further apart than the foot is long.
    `up` (the up axis): outside the runs a lowering eases out over LOWER_EASE frames, a raise over `ease`.
    `floor` (a height along `up`, which it needs): no pin lies below it (the joint's resting height in
    the clip): a model that samples a planted foot low would otherwise pin it in the floor."""
    frames = len(positions)
    runs = np.cumsum(np.diff(np.concatenate([[False], inside]).astype(np.int8)) == 1) * inside  # 1.. per run, 0 outside
    means, _ = _run_means(runs, positions, np.ones(frames, dtype=bool), runs.max() + 1)
    if carried is not None:
        shared = inside & np.isfinite(carried).all(axis=1)
        moved, counts = _run_means(runs, positions + np.nan_to_num(carried), shared, len(means))
        means = np.where(counts[:, None] > 0, moved, means)
    if floor is not None:
        means[:, up] = np.maximum(means[:, up], floor)
    offset = np.where(inside[:, None], means[runs] - positions, 0.0)
    # One fit for the offsets and their weights: exact inside the runs, eased to nothing outside.
    trust = np.where(inside, PIN_WEIGHT, FREE_WEIGHT)
    fitted = _eased(np.concatenate([offset, inside[:, None].astype(np.float64)], axis=1), trust, ease)
    if up is not None:
        # the smaller lowering of the two easings, the larger raise
        fitted[:, up] = np.where(inside, fitted[:, up], np.maximum(fitted[:, up], _eased(offset[:, up:up + 1], trust,
                                                                                          LOWER_EASE)[:, 0]))
    weight = np.where(inside, 1.0, np.clip(fitted[:, 3], 0.0, 1.0))
    weight[weight < FADED] = 0.0
    anchor = np.where(weight[:, None] > 0, fitted[:, :3] / np.maximum(weight, FADED)[:, None], 0.0)
    anchor[inside] = offset[inside]  # exact pins (the fit meets them to 1e-4 of the offset)
    return anchor, weight


def _eased(values: np.ndarray, trust: np.ndarray, ease: float) -> np.ndarray:
    """values (T, K) fitted smoothly: held where `trust` is PIN_WEIGHT, eased to nothing over about
    `ease` frames elsewhere."""
    # FREE_WEIGHT * ease^4 sets how far the easing reaches; the first-difference term at critical
    # damping keeps it from ringing (the second differences alone overshoot past zero and back).
    smoothness = FREE_WEIGHT * ease**4
    return fit_smooth(values, trust, smoothness, 2.0 * math.sqrt(FREE_WEIGHT * smoothness))


def _cyclic_offsets(positions: np.ndarray, inside: np.ndarray, shift: np.ndarray, ease: float,
                    carried: np.ndarray | None = None, up: int | None = None,
                    floor: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """contact_offsets on a loop: the cycle tiled three times (moved by `shift` per cycle)
    so that intervals and fades wrap across the seam; the middle copy is returned."""
    frames = len(positions)
    tiled = np.concatenate([positions - shift, positions, positions + shift])
    anchor, weight = contact_offsets(tiled, np.tile(inside, 3), ease, None if carried is None else np.tile(carried, (3, 1)),
                                     up, floor)
    return anchor[frames : 2 * frames], weight[frames : 2 * frames]


# ------------------------------------------------------------------ legs
@dataclass(frozen=True)
class Leg:
    effector: int  # the joint the two-bone solve moves (keeping its world orientation)
    hip: int | None  # None: one-bone solve (the knee aims the effector)
    knee: int
    contacts: tuple[int, ...]  # positions in codec.contact_joints of this leg's contact joints, top first
    pivots: tuple[int | None, ...]  # per contact joint below the effector: the joint aiming it (None: not aimed)
    keep_orientation: bool = True  # the effector can rotate (three rotation channels) and has joints below it
    chain: tuple[int, ...] = ()  # a many-jointed leg: every rotating joint above the effector, top first


def _descendants(parents: np.ndarray, joint: int) -> set[int]:
    out = {joint}
    for j in range(joint + 1, len(parents)):
        if parents[j] in out:
            out.add(j)
    return out


def _pivot(animation: Animation, positions: np.ndarray, joint: int, movable: set[int]) -> int | None:
    """The nearest ancestor that can rotate (three rotation channels, allowed) and is
    not at the joint's own position."""
    size = np.ptp(positions[0], axis=0).max() + _EPS
    for j in reversed(ancestors(animation.skeleton, joint)):  # nearest first
        if j not in movable:
            return None
        if len(animation.skeleton.rotation_order(j)) == 3:
            if np.median(np.linalg.norm(positions[:, joint] - positions[:, j], axis=-1)) > 1e-4 * size:
                return j
    return None


def _bone(positions: np.ndarray, a: int, b: int) -> float:
    return float(np.median(np.linalg.norm(positions[:, a] - positions[:, b], axis=-1)))


def find_legs(animation: Animation, codec, positions: np.ndarray) -> list[Leg]:
    """Group the contact joints into legs (chains) and choose each leg's IK joints."""
    skeleton, parents = animation.skeleton, animation.skeleton.parents
    contacts = list(codec.contact_joints)
    frozen = set(codec.fixed_joints) | ({codec.trajectory_joint} if codec.trajectory_joint is not None else set())
    tops = [c for c in contacts if not set(ancestors(skeleton, c)) & set(contacts)]
    legs = []
    for top in tops:
        members = [k for k, c in enumerate(contacts) if c == top or top in ancestors(skeleton, c)]
        others = set(contacts) - {contacts[k] for k in members}

        def allowed(j: int) -> bool:  # rotating j moves no other leg, no root, nothing frozen
            below = _descendants(parents, j)
            return parents[j] >= 0 and j not in frozen and not below & (others | frozen)

        movable = {j for j in range(skeleton.num_joints) if allowed(j)}
        effector = top
        knee = _pivot(animation, positions, effector, movable)
        hip = None if knee is None else _pivot(animation, positions, knee, movable)
        # A short end bone (a toe) under a long one: solve the ankle, the toe follows rigidly.
        if (hip is not None and len(skeleton.rotation_order(knee)) == 3
                and _bone(positions, knee, effector) < SHORT_BONE * _bone(positions, hip, knee)):
            higher = _pivot(animation, positions, hip, movable)
            if higher is not None:
                effector, knee, hip = knee, hip, higher
        if knee is None:
            continue
        chain = [knee]
        while (higher := _pivot(animation, positions, chain[-1], movable)) is not None:
            chain.append(higher)
        # A tip with no joint below it has no orientation to keep: turning it would only move
        # the model's rotation away from what it sampled.
        keep = len(skeleton.rotation_order(effector)) == 3
        if len(chain) >= CHAIN_JOINTS:
            legs.append(Leg(effector, chain[1], chain[0], tuple(sorted(
                members, key=lambda k: len(ancestors(skeleton, contacts[k])))), (None,) * (len(members) - 1),
                keep, tuple(reversed(chain))))
            continue
        below = _descendants(parents, effector)
        ordered = tuple(sorted(members, key=lambda k: len(ancestors(skeleton, contacts[k]))))
        pivots = tuple(
            p if (p := _pivot(animation, positions, contacts[k], movable)) is not None and p in below else None
            for k in ordered if contacts[k] != effector
        )
        legs.append(Leg(effector, hip, knee, ordered, pivots, keep))
        # Many-jointed legs (a crab's) are short in their last two bones: a second solve one
        # joint higher reaches what the first could not (a human's hip is the root: no pass).
        higher = None if hip is None else _pivot(animation, positions, hip, movable)
        if higher is not None:
            legs.append(Leg(effector, higher, hip, ordered, (None,) * len(pivots), legs[-1].keep_orientation))
    return legs


# ------------------------------------------------------------------ IK
def _hinge_axes(a: np.ndarray, b: np.ndarray, c: np.ndarray, hip_global: np.ndarray) -> np.ndarray:
    """(T, 3) knee hinge axes (normal of the hip-knee-end plane). A knee bends about an axis fixed
    in its thigh: a leg bent less than HINGE_BENT takes (in part, all of it when straight) the
    axis its bent frames share, carried in the hip's frame. The plane of a nearly straight leg
    is noise: solved about it, the knee swung sideways for a frame (13 cm on the idle) and back."""
    cross = np.cross(c - a, b - a)
    axis, _ = _unit(cross)
    bend = _angle(b - a, c - b)
    shared, size = _unit(np.einsum("tba,tb->a", hip_global, cross))  # G^T cross, summed: weighted by how bent
    if size < _EPS:  # never bent: any axis across the leg
        fallback = np.eye(3)[np.argmin(np.abs(_unit(c - a)[0]), axis=-1)]
        return _unit(np.cross(c - a, fallback))[0]
    stable = np.einsum("tab,b->ta", hip_global, shared)
    own = np.clip(bend / HINGE_BENT, 0.0, 1.0)[:, None]
    return _unit(own * axis + (1.0 - own) * stable)[0]


def two_bone_ik(a: np.ndarray, b: np.ndarray, c: np.ndarray, target: np.ndarray,
                hinge: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (T, 3, 3) of the hip (about a) and the knee (about b) that bring the
    end c to `target`, clamped to the chain's reach; the knee bends about `hinge`.
    Apply the knee's first, then the hip's: c' = a + H (b - a + K (c - b))."""
    upper, lower = np.linalg.norm(b - a, axis=-1), np.linalg.norm(c - b, axis=-1)
    reach = np.maximum(upper + lower, _EPS)
    wanted = np.clip(np.linalg.norm(target - a, axis=-1), np.abs(upper - lower) + 1e-6 * reach, reach * (1 - 1e-6))
    den_hip = np.maximum(2 * upper * wanted, _EPS)
    den_knee = np.maximum(2 * upper * lower, _EPS)
    hip_now, knee_now = _angle(c - a, b - a), _angle(a - b, c - b)
    hip_want = np.arccos(np.clip((upper**2 + wanted**2 - lower**2) / den_hip, -1, 1))
    knee_want = np.arccos(np.clip((upper**2 + lower**2 - wanted**2) / den_knee, -1, 1))
    # The knee opens about the hinge; the hip turns the same plane back so the end keeps its
    # direction from the hip, then swings that direction onto the target.
    knee = axis_angle_matrix(hinge, knee_want - knee_now)
    bend_back = axis_angle_matrix(hinge, hip_want - hip_now)
    swing = rotation_between(c - a, target - a)
    return swing @ bend_back, knee


def _on_sphere(center: np.ndarray, current: np.ndarray, anchor: np.ndarray, up: int) -> np.ndarray:
    """The point at current's distance from `center` whose horizontal position is the
    anchor's (or as near as that distance allows), on current's side of center's height
    and never lower than the anchor: where a bone from `center` must point for its end to
    stand over its pin without being pushed into the floor (a toe swung towards its pin
    would otherwise dip by up to 5 cm) and without following the sampled toe's own rise
    and fall while planted."""
    radius = np.linalg.norm(current - center, axis=-1)
    flat = anchor - center
    flat[..., up] = 0.0
    direction, distance = _unit(flat)
    distance = np.minimum(distance, radius)
    side = np.where(current[..., up] >= center[..., up], 1.0, -1.0)
    lowest = np.clip(anchor[..., up] - center[..., up], -radius, radius)
    rise = np.maximum(side * np.sqrt(np.maximum(radius**2 - distance**2, 0.0)), lowest)
    distance = np.sqrt(np.maximum(radius**2 - rise**2, 0.0))
    point = center + direction * distance[..., None]
    point[..., up] = center[..., up] + rise
    return point


@dataclass(frozen=True)
class _Targets:
    positions: np.ndarray  # (T, J, 3) joint positions before cleanup
    anchors: np.ndarray  # (T, C, 3) horizontal offsets to each contact joint's target
    weights: np.ndarray  # (T, C) how much of the offset applies
    up: int
    floors: np.ndarray  # (C,) each contact joint's lowest pinned height


def _lower_contacts(leg: Leg, contacts: list[int]) -> list[int]:
    """The leg's contacts below its effector, top first: the ones `leg.pivots` aim, in order."""
    return [m for m in leg.contacts if contacts[m] != leg.effector]


def _leg_joints(leg: Leg) -> list[int]:
    """The joints whose local rotations solving `leg` may change."""
    return list(dict.fromkeys(j for j in (*leg.chain, leg.hip, leg.knee, leg.effector, *leg.pivots) if j is not None))


def _effector_shift(leg: Leg, contacts: list[int], anchors: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3) how far the leg's effector is to move and (T,) on which frames it has to: by its
    own offset where it is a contact, and otherwise by what its lower contacts ask."""
    frames = len(weights)
    top = leg.contacts[0] if contacts[leg.contacts[0]] == leg.effector else None
    lower = _lower_contacts(leg, contacts)
    low_w = weights[:, lower].sum(axis=1) if lower else np.zeros(frames)
    low_offset = np.einsum("tk,tkd->td", weights[:, lower], anchors[:, lower]) / np.maximum(low_w, 1.0)[:, None] \
        if lower else np.zeros((frames, 3))
    own_w = weights[:, top] if top is not None else np.zeros(frames)
    own = anchors[:, top] * own_w[:, None] if top is not None else 0.0
    return own + (1.0 - own_w)[:, None] * low_offset, (own_w > 0) | (low_w > 0)


def hips_drop(legs: list[Leg], contacts: list[int], targets: _Targets, loop: bool = False) -> np.ndarray:
    """(T,) how far (file units, along the up axis) to lower the hips so that every two-bone leg
    reaches its pinned effector with the knee no straighter than sampled or than STRAIGHT_REACH
    of the leg's reach; eased in and out over DROP_EASE frames, never less than needed."""
    p, up = targets.positions, targets.up
    need = np.zeros(len(p))
    for leg in legs:
        if leg.hip is None or leg.chain:
            continue
        shift, active = _effector_shift(leg, contacts, targets.anchors, targets.weights)
        a, b, c = p[:, leg.hip], p[:, leg.knee], p[:, leg.effector]
        reach = np.linalg.norm(b - a, axis=-1) + np.linalg.norm(c - b, axis=-1)
        allowed = np.maximum(np.linalg.norm(c - a, axis=-1), STRAIGHT_REACH * reach)
        apart = c + shift - a
        height = -apart[:, up]  # the hip's height above the pin
        apart[:, up] = 0.0
        flat = np.linalg.norm(apart, axis=-1)
        drop = height - np.sqrt(np.maximum(allowed**2 - flat**2, 0.0))
        need = np.maximum(need, np.where(active, np.clip(drop, 0.0, MAX_DROP * reach), 0.0))
    if not need.any():
        return need
    radius = int(math.ceil(2 * DROP_EASE))
    padded = np.pad(need, radius, mode="wrap" if loop else "edge")
    widened = np.lib.stride_tricks.sliding_window_view(padded, 2 * radius + 1).max(axis=1)
    return np.maximum(need, smooth_frames(widened[None, :, None], DROP_EASE, wrap=loop)[0, :, 0])


def lower_hips(animation: Animation, codec, drop: np.ndarray) -> None:
    """Lower the trajectory joint by `drop` (T,) along the up axis, in place on the animation's translations."""
    joint = codec.trajectory_joint
    offset = np.zeros((len(drop), 3))
    offset[:, codec.up_axis] = -drop
    parent = animation.skeleton.parents[joint]
    if parent >= 0:  # translations live in the parent's frame
        glob, _ = chain_kinematics(animation.rotations, animation.translations, animation.skeleton.parents, [parent])
        offset = np.einsum("tba,tb->ta", glob[:, 0], offset)
    animation.translations[:, joint] += offset


def _solve_leg(local: np.ndarray, translations: np.ndarray, parents: np.ndarray, leg: Leg, contacts: list[int],
               targets: _Targets, free: np.ndarray | float = 1.0, aim: bool = True) -> None:
    """Solve one leg in place on the local rotations (T, J, 3, 3); `free` (T,) scales the
    offsets (0 where an application keeps the leg's pose); `aim`: the lower contacts are aimed
    at their pins (off where the foot moves rigidly with its effector). Only `_leg_joints(leg)` change,
    and only on frames where the leg has an offset to reach."""
    anchors, weights = targets.anchors, targets.weights * np.reshape(free, (-1, 1))
    lower = _lower_contacts(leg, contacts)
    shift, active = _effector_shift(leg, contacts, anchors, weights)
    if not active.any():
        return
    e, k, h = leg.effector, leg.knee, leg.hip
    changed = _leg_joints(leg)
    before = local[:, changed]  # a copy (fancy index): restored on the frames without an offset
    if leg.chain:
        _solve_chain(local, translations, parents, leg, targets.positions[:, e] + shift)
        local[np.flatnonzero(~active)[:, None], changed] = before[~active]
        return
    chain = [j for j in (h, k, e) if j is not None]
    glob, pos = chain_kinematics(local, translations, parents, chain + [parents[j] for j in chain])
    at = {j: i for i, j in enumerate(chain)}
    parent_glob = {j: glob[:, len(chain) + i] for i, j in enumerate(chain)}
    target = targets.positions[:, e] + shift  # from the pose before cleanup: a second pass aims at the same spot
    if h is not None:
        hinge = _hinge_axes(pos[:, at[h]], pos[:, at[k]], pos[:, at[e]], glob[:, at[h]])
        hip_world, knee_world = two_bone_ik(pos[:, at[h]], pos[:, at[k]], pos[:, at[e]], target, hinge)
        local[:, h] = _apply_world(local[:, h], parent_glob[h], hip_world)
        if k != h:
            local[:, k] = _apply_world(local[:, k], parent_glob[k], knee_world)
        total = hip_world @ knee_world
    else:
        total = rotation_between(pos[:, at[e]] - pos[:, at[k]], target - pos[:, at[k]])
        local[:, k] = _apply_world(local[:, k], parent_glob[k], total)
    if leg.keep_orientation:  # keep the effector's world orientation: the joints below translate rigidly
        local[:, e] = _apply_world(local[:, e], parent_glob[e], np.swapaxes(total, -1, -2))
    for m, pivot in zip(lower if aim else [], leg.pivots):
        if pivot is None:
            continue
        joint = contacts[m]
        glob, pos = chain_kinematics(local, translations, parents, [pivot, joint, parents[pivot]])
        pin = targets.positions[:, joint] + anchors[:, m]
        # Before and after a run the pin is the sampled position moved by the run's offset: where the
        # sample swings through the floor and back, that lies deeper than the sample itself goes.
        pin[:, targets.up] = np.maximum(pin[:, targets.up], np.minimum(targets.positions[:, joint, targets.up], targets.floors[m]))
        goal = _on_sphere(pos[:, 0], pos[:, 1], pin, targets.up)
        aim = rotation_between(pos[:, 1] - pos[:, 0], goal - pos[:, 0], weights[:, m], PIVOT_TURN)
        local[:, pivot] = _apply_world(local[:, pivot], glob[:, 2], aim)
    still = np.flatnonzero(~active)
    local[still[:, None], changed] = before[still]


def _solve_chain(local: np.ndarray, translations: np.ndarray, parents: np.ndarray, leg: Leg,
                 target: np.ndarray) -> None:
    """Damped least squares over every joint of `leg.chain`, in place: per frame the
    smallest world rotations (by their summed squared angles) that bring the effector to
    `target` (T, 3), linearised and repeated CHAIN_ITERATIONS times. A rotation about a
    bone's own direction moves nothing, so none is added: no twist."""
    chain, e = list(leg.chain), leg.effector
    n = len(chain)
    joints = chain + [e] + [parents[j] for j in chain + [e]]
    glob, pos = chain_kinematics(local, translations, parents, joints)
    kept = glob[:, n]  # the effector's world orientation before the solve
    reach = np.linalg.norm(np.diff(pos[:, : n + 1], axis=1), axis=-1).sum(axis=1)  # (T,)
    damping = (CHAIN_DAMPING * reach) ** 2
    # Beyond the chain's reach the linearised steps swing about without end: aim at the
    # nearest point it can reach short of straight (where it cannot bend towards anything), or
    # at the leg's own extension if it is straighter than that: never further from the pin.
    toward, distance = _unit(target - pos[:, 0])
    extended = np.maximum(CHAIN_REACH * reach, np.linalg.norm(pos[:, n] - pos[:, 0], axis=-1))
    target = pos[:, 0] + toward * np.minimum(distance, extended)[:, None]
    for _ in range(CHAIN_ITERATIONS):
        lever = pos[:, n : n + 1] - pos[:, :n]  # (T, n, 3): each joint to the effector
        jacobian = np.concatenate(list(-_skew(lever[:, i]) for i in range(n)), axis=-1)  # (T, 3, 3n)
        error = target - pos[:, n]
        normal = jacobian @ np.swapaxes(jacobian, -1, -2) + damping[:, None, None] * np.eye(3)
        turn = np.einsum("tai,ta->ti", jacobian, np.linalg.solve(normal, error[..., None])[..., 0]).reshape(-1, n, 3)
        axis, angle = _unit(turn)
        angle = np.minimum(angle, CHAIN_STEP)
        # Deepest first, each against its parent's rotation of this pass: the turns compose
        # into the linearised sum of the joints' rotations about their own positions.
        for i in reversed(range(n)):
            local[:, chain[i]] = _apply_world(local[:, chain[i]], glob[:, n + 1 + i], axis_angle_matrix(axis[:, i], angle[:, i]))
        glob, pos = chain_kinematics(local, translations, parents, joints)
    if leg.keep_orientation:
        local[:, e] = np.swapaxes(glob[:, 2 * n + 1], -1, -2) @ kept


def cleaned_legs(codec, features: np.ndarray, start: np.ndarray | None = None,
                 loop_displacement: np.ndarray | None = None, keep: np.ndarray | None = None) -> Animation | None:
    """The contact cleanup of (T, F) `features` decoded from `start`, solved on the only
    joints it reads or moves (the contact joints and their ancestors): an animation on
    that sub-skeleton for `MotionCodec.decode_bvh(replaced=...)`, so that a long motion's
    other joints (arms, fingers) are never held whole. None when there are no contacts."""
    if not codec.contact_joints:
        return None
    joints = sorted({j for c in codec.contact_joints for j in (c, *ancestors(codec.skeleton, c))})
    legs, channels = codec.restricted(joints)
    features = np.asarray(features)[:, channels]
    keep = None if keep is None else np.asarray(keep)[:, channels]
    return cleanup_contacts(legs.decode(features, start), legs, features, loop_displacement, keep, in_place=True,
                            size=codec.size)


def cleanup_contacts(animation: Animation, codec, features: np.ndarray,
                     loop_displacement: np.ndarray | None = None, keep: np.ndarray | None = None,
                     in_place: bool = False, size: float | None = None) -> Animation:
    """The animation with its contact joints pinned where `features`' contact labels
    (T, F, the sampled features the animation was decoded from) say they touch the
    floor. `loop_displacement`: for a loop, the root's motion per cycle as
    `sampler.cycle_displacement` gives it (metres along `codec.horizontal_axes`),
    so that contacts across the seam are one interval and the loop stays seamless.
    `keep` (T, F) in [0, 1]: an application's kept features (`Guide.keep`); a leg whose
    rotations are kept is left as the application made it, by the kept share. `in_place`:
    the legs are solved in `animation`'s own rotations and its root moved in its own
    translations (a caller that owns a long motion saves a copy of each). `size`: the
    character's size in metres when `codec` is of part of it (default `codec.size`)."""
    channels = codec.layout.indices(("contact",))
    contacts = list(codec.contact_joints)
    if not contacts or not len(channels) or animation.frames < MIN_CONTACT_FRAMES:
        return animation
    labels = np.asarray(features)[: animation.frames, channels].astype(np.float64)
    inside = np.stack([contact_mask(labels[:, k]) for k in range(len(contacts))], axis=1)
    if not inside.any():
        return animation
    up = codec.up_axis
    parents = animation.skeleton.parents
    translations_in = animation.translations
    positions = positions_by_chunks(animation.rotations, animation.translations, parents)
    limit = MAX_SLIDE * (codec.size if size is None else size) / codec.scale
    reach = CONTACT_HEIGHT * (codec.size if size is None else size) / codec.scale
    floors = _floor_heights(codec)
    near = near_floor(positions[:, contacts], up, floors, reach)
    inside = np.stack([contact_mask(np.where(near[:, k], labels[:, k], 0.0)) for k in range(len(contacts))], axis=1)
    inside = np.stack([drop_slides(inside[:, k], positions[:, j], up, limit) for k, j in enumerate(contacts)], axis=1)
    fast = FAST_ENDS * codec.contact_speed / animation.fps / codec.scale
    inside = np.stack([trim_fast_ends(inside[:, k], positions[:, j], fast) for k, j in enumerate(contacts)], axis=1)
    # A foot the model moves slower than the codec's contact speed is planted too, labelled
    # or not: the labels miss the ends of many contacts, and those frames slide visibly.
    slow = contact_labels(positions[:, contacts] * codec.scale, animation.fps, codec.contact_speed).astype(bool) & near
    inside = inside | np.stack([contact_mask(slow[:, k]) for k in range(len(contacts))], axis=1)
    if ROOT_CORRECTION and loop_displacement is None and keep is None:
        animation = slow_root(animation, codec, positions, inside, in_place)
        positions = positions_by_chunks(animation.rotations, animation.translations, parents, out=positions)
    shift = _cycle_shift(codec, animation.rotations, animation.translations, loop_displacement)
    legs = find_legs(animation, codec, positions)
    free = [_free(codec, leg, keep) for leg in legs]
    # Only the legs' joints change: their pose before cleanup is what every pass starts from.
    changed = list(dict.fromkeys(j for leg in legs for j in _leg_joints(leg)))
    original = animation.rotations[:, changed]
    local = animation.rotations if in_place else animation.rotations.copy()
    # The hips are lowered where a leg cannot reach its pin; a guide's kept root is never moved.
    root = codec.trajectory_joint if keep is None else None
    if root is not None:
        if not in_place and animation.translations is translations_in:
            animation = Animation(animation.skeleton, animation.rotations, animation.translations.copy(), animation.fps)
        hips = animation.translations[:, root].copy()
    for _ in range(GROW_PASSES + 1):
        local[:, changed] = original
        if root is not None:
            animation.translations[:, root] = hips
        _pin(animation, local, codec, legs, free, positions, inside, shift, lower=root is not None)
        # Pinning a joint slows its neighbours on the chain (a planted ankle drags the ball of
        # the foot): frames the cleaned motion moves slower than the contact speed are planted
        # too, so the next pass pins them instead of letting them slide at the easing's speed.
        _, cleaned = chain_kinematics(local, animation.translations, parents, contacts)
        slow = contact_labels(cleaned * codec.scale, animation.fps, codec.contact_speed).astype(bool)
        slow &= near_floor(cleaned, up, floors, reach)
        grown = inside | np.stack([contact_mask(slow[:, k]) for k in range(len(contacts))], axis=1)
        grown = np.stack([drop_slides(grown[:, k], positions[:, j], up, limit) for k, j in enumerate(contacts)], axis=1)
        if (grown == inside).all():
            break
        inside = grown
    _lift_from_floor(animation, local, codec, legs, free, loop_displacement is not None)
    solved = local[:, changed]
    finite = np.isfinite(solved).all(axis=(-1, -2))  # never NaN: a joint whose solve failed keeps its pose
    local[:, changed] = np.where(finite[..., None, None], solved, original)
    return Animation(animation.skeleton, local, animation.translations, animation.fps)


def _lift_from_floor(animation: Animation, local: np.ndarray, codec, legs: list[Leg], free: list,
                     loop: bool = False) -> None:
    """In place on `local`: on every frame where a leg's contact joint lies below its resting
    height in the clip (`codec.contact_floors`), the leg's effector (an ankle) is raised by
    the deepest such depth, the foot keeping its orientation. A model's
    swinging toes dip through the floor (a short-trained walk: 2 cm on a fifth of its frames,
    mostly off its contacts, where no pin reaches). The raise falls to zero where the dip ends,
    so it blends itself in and out."""
    floors = _floor_heights(codec)
    if floors is None or not legs:
        return
    contacts, up = list(codec.contact_joints), codec.up_axis
    positions = positions_by_chunks(local, animation.translations, animation.skeleton.parents)
    depth = floors - positions[:, contacts, up]  # (T, C)
    for leg, leg_free in zip(legs, free):
        lift = np.maximum(depth[:, list(leg.contacts)].max(axis=1), 0.0)
        if not lift.any():
            continue
        # Eased in and out (the raise starts and ends with a kink otherwise: the jerk rose 8 % on Xia's walk).
        lift = np.maximum(lift, smooth_frames(lift[None, :, None], LIFT_EASE, wrap=loop)[0, :, 0])
        anchors, weights = np.zeros((len(local), len(contacts), 3)), np.zeros((len(local), len(contacts)))
        # Every contact of the leg asks for the same raise: the effector moves by it and its
        # lower contacts, carried rigidly with the foot, already stand where they aim.
        anchors[:, list(leg.contacts), up] = lift[:, None]
        weights[:, list(leg.contacts)] = (lift > 0)[:, None]
        targets = _Targets(positions, anchors, weights, up, np.full(len(contacts), -np.inf))
        _solve_leg(local, animation.translations, animation.skeleton.parents, leg, contacts, targets, leg_free, aim=False)


def _floor_heights(codec) -> np.ndarray | None:
    """(C,) each contact joint's resting height in the clip, file units; None when not recorded."""
    return None if codec.contact_floors is None else np.asarray(codec.contact_floors) / codec.scale


def _pin(animation: Animation, local: np.ndarray, codec, legs: list[Leg], free: list, positions: np.ndarray,
         inside: np.ndarray, shift: np.ndarray | None, lower: bool = False) -> None:
    """Every leg solved, in place on `local` (T, J, 3, 3), for the contact frames `inside` (T, C);
    `lower`: the hips lowered first (in place on the animation's translations) where a leg cannot
    reach its pin (hips_drop)."""
    up, contacts = codec.up_axis, list(codec.contact_joints)
    anchors, weights = np.zeros((animation.frames, len(contacts), 3)), np.zeros((animation.frames, len(contacts)))
    # Each lower contact (a ball) below the planted joint that aims it (an ankle): pinned where that joint's pin carries it.
    resting = _floor_heights(codec)
    above = {m: contacts.index(p) for leg in legs for m, p in zip(_lower_contacts(leg, contacts), leg.pivots) if p in contacts}
    for k in sorted(range(len(contacts)), key=lambda k: len(ancestors(animation.skeleton, contacts[k]))):  # top first
        if inside[:, k].any():
            carried = None
            if k in above:
                carried = np.where(inside[:, above[k], None], anchors[:, above[k]], np.nan)
            floor = None if resting is None else resting[k]
            if shift is None:
                anchors[:, k], weights[:, k] = contact_offsets(positions[:, contacts[k]], inside[:, k], carried=carried,
                                                               up=up, floor=floor)
            else:
                anchors[:, k], weights[:, k] = _cyclic_offsets(positions[:, contacts[k]], inside[:, k], shift, EASE_FRAMES,
                                                               carried, up, floor)
    pinned = positions[:, contacts, up] + anchors[..., up]
    floors = np.where(inside, pinned, np.inf).min(axis=0)
    targets = _Targets(positions, anchors, weights, up, floors)
    if lower:
        drop = hips_drop(legs, contacts, targets, loop=shift is not None)
        if drop.any():
            lower_hips(animation, codec, drop)
    for leg, leg_free in zip(legs, free):
        _solve_leg(local, animation.translations, animation.skeleton.parents, leg, contacts, targets, leg_free)


def slow_root(animation: Animation, codec, positions: np.ndarray, inside: np.ndarray,
              in_place: bool = False) -> Animation:
    """The animation with its trajectory joint moved back, frame by frame, by the mean
    horizontal slide of the contact joints planted in both frames: a body that glides
    over its planted feet (the commonest flaw of a drifting model) is slowed to them,
    so the legs need far smaller IK corrections (their rotations, which the paper's
    metrics compare with the clip's, stay near the model's)."""
    joint = codec.trajectory_joint
    if joint is None:
        return animation
    contacts = list(codec.contact_joints)
    feet = positions[:, contacts]  # (T, C, 3)
    both = (inside[1:] & inside[:-1]).astype(np.float64)  # (T-1, C)
    slide = np.diff(feet, axis=0)
    slide[..., codec.up_axis] = 0.0
    count = both.sum(axis=1, keepdims=True)
    step = -np.einsum("tc,tcd->td", both, slide) / np.maximum(count, 1.0)
    # A planted joint slides at most the contact speed (beyond it the label is doubtful), and
    # the correction is smoothed over ROOT_SMOOTHING frames: the root's speed never jumps.
    limit = codec.contact_speed / animation.fps / codec.scale
    norm = np.linalg.norm(step, axis=-1, keepdims=True)
    step = step * np.minimum(1.0, limit / np.maximum(norm, _EPS))
    kernel = np.hanning(ROOT_SMOOTHING + 2)[1:-1]
    kernel /= kernel.sum()
    step = np.stack([np.convolve(step[:, d], kernel, mode="same") for d in range(3)], axis=1)
    offset = np.concatenate([np.zeros((1, 3)), np.cumsum(step, axis=0)])  # world, file units
    parent = animation.skeleton.parents[joint]
    if parent >= 0:  # translations live in the parent's frame
        glob, _ = chain_kinematics(animation.rotations, animation.translations, animation.skeleton.parents, [parent])
        offset = np.einsum("tba,tb->ta", glob[:, 0], offset)
    translations = animation.translations if in_place else animation.translations.copy()
    translations[:, joint] += offset
    return Animation(animation.skeleton, animation.rotations, translations, animation.fps)


def _free(codec, leg: Leg, keep: np.ndarray | None) -> np.ndarray | float:
    """(T,) 1 - the largest kept share of the leg's solved rotations (1 without a guide)."""
    if keep is None:
        return 1.0
    names = {codec.skeleton.names[j] for j in (leg.hip, leg.knee, leg.effector, *leg.pivots) if j is not None}
    channels = codec.layout.indices(("rotation",), names)
    if not len(channels):
        return 1.0
    return 1.0 - np.clip(np.asarray(keep, dtype=np.float64)[:, channels].max(axis=1), 0.0, 1.0)


def _cycle_shift(codec, local: np.ndarray, translations: np.ndarray, displacement) -> np.ndarray | None:
    """World displacement (3,) in file units of a loop's cycle, or None for a plain clip."""
    if displacement is None or codec.trajectory_joint is None:
        return None
    step = np.zeros(3)
    h1, h2 = codec.horizontal_axes
    step[h1], step[h2] = np.asarray(displacement, dtype=np.float64)[:2] / codec.scale
    parent = codec.skeleton.parents[codec.trajectory_joint]
    if parent < 0:
        return step
    glob, _ = forward_kinematics(local[:1], translations[:1], codec.skeleton.parents)
    return glob[0, parent] @ step
