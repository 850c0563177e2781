"""What a clip's skeleton is, whatever its layout: which joint carries the character
through the world, which static joints sit above it only as a frame of reference
(a `joint_Root` at the floor, an `Armature` node, a 0-channel dummy), and which
world axis is up. Everything is read from the clip itself, never from names.

- Trajectory joint: the first joint (file order) with position channels that moves
  while every joint above it stays still. A static reference root is skipped; a
  root that carries the motion is chosen, as before.
- Up axis (Y or Z): the floor is where the lowest joint of each frame rests. Along
  the true up axis that lowest point is planted (still) and its height barely
  changes; along a horizontal axis it wanders with the travel and the limbs. On the
  shared clips the two criteria separate Y from Z by 10x or more (BENCHMARKS.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .animation import Animation, global_positions, rest_positions
from .bvh import Skeleton
from .contacts import joint_speeds
from .errors import SinMDMError
from .kinematics import forward_kinematics

AXIS_NAMES = "xyz"
UP_CANDIDATES = (1, 2)  # Y-up (most tools) or Z-up (Blender, 3ds Max exports)
STATIC_POSITION = 1e-4  # share of the character's size a static joint may move
STATIC_ANGLE = 1e-4  # radians a static joint may turn
PLANTED_SPEED = 0.3  # sizes per second: the lowest joint counts as planted below this
PLAUSIBLE_HUMANOID_METRES = (0.5, 5.0)


@dataclass(frozen=True)
class Rig:
    trajectory_joint: int | None
    fixed_joints: tuple[int, ...]  # static ancestors of the trajectory joint, kept exactly
    up_axis: int  # world axis index: 1 = Y, 2 = Z
    height_axis: int  # the axis of the trajectory joint's parent frame that points up
    reasons: tuple[str, ...]  # why, in words, for `inspect`


def parse_up(up: str | None) -> int | None:
    if up in (None, "", "auto"):
        return None
    if up.lower() in ("y", "z"):
        return AXIS_NAMES.index(up.lower())
    raise SinMDMError(f"unknown up axis '{up}': use y, z or auto")


def static_joints(animation: Animation, size: float) -> np.ndarray:
    """(J,) True for joints whose local rotation and translation never change."""
    if animation.frames < 2:
        return np.ones(animation.skeleton.num_joints, dtype=bool)
    still = np.ptp(animation.translations, axis=0).max(axis=1) <= STATIC_POSITION * size
    relative = np.swapaxes(animation.rotations[:1], -1, -2) @ animation.rotations  # (T, J, 3, 3)
    angles = np.arccos(np.clip((np.trace(relative, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0))
    return still & (angles.max(axis=0) <= STATIC_ANGLE)


def ancestors(skeleton: Skeleton, joint: int) -> list[int]:
    chain, parent = [], int(skeleton.parents[joint])
    while parent >= 0:
        chain.append(parent)
        parent = int(skeleton.parents[parent])
    return chain[::-1]


def find_trajectory_joint(animation: Animation, size: float, name: str | None = None) -> tuple[int | None, str]:
    """(joint, reason): see the module docstring; `name` overrides (--root)."""
    skeleton = animation.skeleton
    if name is not None:
        joint = skeleton.index(name)
        if not skeleton.position_channels(joint):
            raise SinMDMError(f"--root {name}: that joint has no position channels, it cannot carry the motion")
        return joint, f"{name} (--root)"
    positioned = [j for j in range(skeleton.num_joints) if skeleton.position_channels(j)]
    if not positioned:
        return None, "no joint has position channels: the motion stays in place"
    static = static_joints(animation, size)
    for j in positioned:
        above = ancestors(skeleton, j)
        if not static[j] and all(static[a] for a in above):
            skipped = [skeleton.names[a] for a in above if skeleton.position_channels(a) or skeleton.channels[a]]
            why = f"{skeleton.names[j]}: the first joint with position channels that moves"
            return j, why + (f" ({', '.join(skipped)} above it: static, kept as is)" if skipped else "")
    return positioned[0], f"{skeleton.names[positioned[0]]}: nothing moves, the first joint with position channels"


UP_EVIDENCE = 2.0  # the feet must be this much steadier along one axis to decide by them


def detect_up_axis(positions: np.ndarray, fps: float, size: float) -> tuple[int, str]:
    """(axis, reason) from world positions (T, J, 3): the axis along which the lowest
    joint of each frame is planted and stays at one height."""
    scores = {}
    for axis in UP_CANDIDATES:
        height = positions[..., axis]
        lowest = height.argmin(axis=1)
        wobble = float(np.std(height.min(axis=1))) / size
        speed = joint_speeds(positions, fps)[np.arange(len(height)), lowest]
        planted = float(np.mean(speed < PLANTED_SPEED * size))
        scores[axis] = wobble / max(planted, 0.05)
    best, other = sorted(scores, key=scores.get)
    ratio = scores[other] / max(scores[best], 1e-12)
    if ratio < UP_EVIDENCE:  # too little motion to tell (a still or very short clip): the taller axis
        extent = np.ptp(positions.mean(axis=0), axis=0)
        best = max(UP_CANDIDATES, key=lambda a: extent[a])
        return best, (f"{AXIS_NAMES[best].upper()}: the feet say too little ({ratio:.1f}x), "
                      "the taller axis of the mean pose")
    return best, (f"{AXIS_NAMES[best].upper()}: the feet rest at one height along it "
                  f"({min(ratio, 999):.0f}x steadier than {AXIS_NAMES[other].upper()})")


def parent_height_axis(animation: Animation, joint: int | None, up_axis: int) -> int:
    """The axis of `joint`'s parent frame that points along world up (the frame its
    position channels are written in)."""
    if joint is None or animation.skeleton.parents[joint] < 0:
        return up_axis
    rotations, _ = forward_kinematics(animation.rotations[0], animation.translations[0],
                                      animation.skeleton.parents)
    up_in_parent = rotations[animation.skeleton.parents[joint]].T[:, up_axis]
    return int(np.argmax(np.abs(up_in_parent)))


def analyse_rig(animation: Animation, scale: float, root: str | None = None, up: str | None = None) -> Rig:
    """Trajectory joint, fixed joints and up axis of a clip (`root`, `up` override)."""
    skeleton = animation.skeleton
    size = skeleton_extent(skeleton)
    joint, why_root = find_trajectory_joint(animation, size, root)
    static = static_joints(animation, size)
    fixed = tuple(a for a in ancestors(skeleton, joint) if static[a]) if joint is not None else ()
    forced = parse_up(up)
    if forced is not None:
        up_axis, why_up = forced, f"{AXIS_NAMES[forced].upper()} (--up)"
    else:
        up_axis, why_up = detect_up_axis(global_positions(animation), animation.fps, size)
    reasons = (f"trajectory joint {why_root}", f"up axis {why_up}")
    return Rig(joint, fixed, up_axis, parent_height_axis(animation, joint, up_axis), reasons)


def skeleton_extent(skeleton: Skeleton) -> float:
    """The rest pose's largest extent in file units (End Sites included), never zero."""
    points = rest_positions(skeleton)
    if skeleton.end_sites:
        ends = [points[p] + (0 if o is None else o) for p, o in skeleton.end_sites]
        points = np.concatenate([points, np.asarray(ends)], axis=0)
    return float(max(np.ptp(points, axis=0).max(), 1e-6))


def units_warning(size_m: float, humanoid: bool) -> str | None:
    low, high = PLAUSIBLE_HUMANOID_METRES
    if humanoid and not low <= size_m <= high:
        return (f"the figure measures {size_m:.2f} m as read, implausible for a humanoid: "
                f"pass --units (m, cm, mm, in, ft or metres per unit)")
    return None
