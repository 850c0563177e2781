"""BVH channel values <-> per-joint local rotations and translations.

An `Animation` holds, for every frame and joint, the local rotation (a 3x3
matrix; quaternions appear only where slerp needs them, in resampling and glTF)
and the local translation (the BVH offset, with any position
channels replacing the matching axes), in the file's units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .bvh import BVH, Skeleton
from .kinematics import forward_kinematics
from .rotations import (
    FRAME_CHUNK,
    axis_matrix,
    euler_to_matrix,
    matrix_to_euler,
    unwrap_euler,
)

AXES = "XYZ"


@dataclass(frozen=True)
class Animation:
    skeleton: Skeleton
    rotations: np.ndarray  # (T, J, 3, 3) local rotation matrices
    translations: np.ndarray  # (T, J, 3) local translations, file units
    fps: float

    @property
    def frames(self) -> int:
        return self.rotations.shape[0]


def nominal_fps(frame_time: float) -> float:
    """1 / frame_time, snapped to a whole number when the file rounded it
    (0.016667 s is 60 fps, not 59.9988)."""
    fps = 1.0 / frame_time
    whole = round(fps)
    return float(whole) if whole > 0 and abs(fps - whole) < 2e-4 * fps else fps


def _full_order(order: str) -> str:
    """Complete a partial rotation order (1 or 2 axes) with the missing axes."""
    return order + "".join(a for a in AXES if a not in order)


def _rotation_columns(skeleton: Skeleton, joint: int) -> list[int]:
    start = int(skeleton.channel_starts[joint])
    return [start + i for i, c in enumerate(skeleton.channels[joint]) if c.endswith("rotation")]


def _position_columns(skeleton: Skeleton, joint: int) -> list[tuple[int, int]]:
    """(column, axis index) of each position channel of a joint."""
    start = int(skeleton.channel_starts[joint])
    return [(start + i, AXES.index(c[0])) for i, c in enumerate(skeleton.channels[joint]) if c.endswith("position")]


def animation_from_bvh(bvh: BVH) -> Animation:
    skeleton, values = bvh.skeleton, bvh.values
    frames, joints = values.shape[0], skeleton.num_joints
    matrices = np.broadcast_to(np.eye(3), (frames, joints, 3, 3)).copy()
    translations = np.broadcast_to(skeleton.offsets, (frames, joints, 3)).copy()
    for j in range(joints):
        order = skeleton.rotation_order(j)
        angles = np.radians(values[:, _rotation_columns(skeleton, j)])
        if len(order) == 3:
            matrices[:, j] = euler_to_matrix(angles, order)
        elif order:
            m = np.eye(3)
            for axis, column in zip(order, angles.T):
                m = m @ axis_matrix(AXES.index(axis), column)
            matrices[:, j] = m
        for column, axis in _position_columns(skeleton, j):
            translations[:, j, axis] = values[:, column]
    return Animation(skeleton, matrices, translations, nominal_fps(bvh.frame_time))


def animation_to_bvh(animation: Animation) -> BVH:
    """Channel values on the animation's skeleton, Euler curves unwrapped."""
    return chunks_to_bvh(animation.skeleton, animation.fps, animation.frames,
                         lambda a, b: (animation.rotations[a:b], animation.translations[a:b]))


def chunks_to_bvh(skeleton: Skeleton, fps: float, frames: int, chunk_at, chunk: int = FRAME_CHUNK) -> BVH:
    """Channel values, Euler curves unwrapped, from `chunk_at(a, b)` -> (local rotations
    (b - a, J, 3, 3), translations (b - a, J, 3)) called for consecutive frame ranges: a
    long motion is never held whole as matrices, only as the BVH's own values."""
    values = np.zeros((frames, skeleton.num_channels))
    by_order: dict[str, list[int]] = {}
    for j in range(skeleton.num_joints):
        order = skeleton.rotation_order(j)
        if order:
            by_order.setdefault(order, []).append(j)
    previous: dict[str, np.ndarray] = {}
    for a in range(0, frames, chunk):
        b = min(a + chunk, frames)
        matrices, translations = chunk_at(a, b)
        for j in range(skeleton.num_joints):
            for column, axis in _position_columns(skeleton, j):
                values[a:b, column] = translations[:, j, axis]
        for order, joints in by_order.items():
            # Joints with fewer than three rotation channels keep only their own axes.
            full = _full_order(order)
            euler = matrix_to_euler(matrices[:, joints], full)
            euler = unwrap_euler(euler, full, out=euler, previous=previous.get(order))
            previous[order] = euler[-1].copy()
            euler = np.degrees(euler, out=euler)
            for k, j in enumerate(joints):
                values[a:b, _rotation_columns(skeleton, j)] = euler[:, k, : len(order)]
    return BVH(skeleton, 1.0 / fps, values)


def global_positions(animation: Animation) -> np.ndarray:
    """(T, J, 3) world positions of every joint, file units."""
    _, positions = forward_kinematics(animation.rotations, animation.translations, animation.skeleton.parents)
    return positions


def rest_positions(skeleton: Skeleton) -> np.ndarray:
    """(J, 3) joint positions of the offsets-only pose."""
    eye = np.broadcast_to(np.eye(3), (skeleton.num_joints, 3, 3))
    _, positions = forward_kinematics(eye, skeleton.offsets, skeleton.parents)
    return positions
