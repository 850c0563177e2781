"""Foot contacts for any skeleton: which joints touch the floor, and when.

A joint is a contact joint when it comes down to the floor and rests there:
its lowest height is near the clip's floor and, for a good share of the clip,
it is both at that height and nearly still. That finds a humanoid's feet and
toes, a crab's leg tips and an elephant's feet without any name database.
"""

from __future__ import annotations

import numpy as np

# Fractions of the character's size (its rest-pose extent).
NEAR_FLOOR = 0.10  # a contact joint's lowest point lies this close to the floor
AT_REST_HEIGHT = 0.03  # a planted joint is this close to its own lowest height
MIN_PLANTED_SHARE = 0.15  # ... in at least this share of the frames
NEVER_MOVES = 1e-4  # a joint whose world position spans less than this never leaves its spot
# A contact joint's resting height: this percentile of its height while it is labelled in
# contact (the labels are by speed alone, so a foot slowing at the top of a swing counts too;
# the low end is where it rests).
FLOOR_PERCENTILE = 10
# The paper's 0.018 m/frame at 30 fps for a ~1.8 m Mixamo character, as a share of size per second.
SPEED_PER_SIZE = 0.018 * 30 / 1.8


def default_contact_speed(size: float) -> float:
    """Speed threshold (units/s) below which a joint counts as planted."""
    return SPEED_PER_SIZE * size


def joint_speeds(positions: np.ndarray, fps: float) -> np.ndarray:
    """(T, J) speed per frame in units/s; frame 0 copies frame 1."""
    speed = np.linalg.norm(np.diff(positions, axis=0), axis=-1) * fps
    if len(speed) == 0:
        return np.zeros(positions.shape[:2])
    return np.concatenate([speed[:1], speed], axis=0)


def contact_labels(positions: np.ndarray, fps: float, threshold: float) -> np.ndarray:
    """(T, J) 1.0 where a joint moves slower than `threshold` units/s; frame 0 is
    always 'no contact', as in the reference implementation."""
    labels = (joint_speeds(positions, fps) < threshold).astype(np.float32)
    labels[:1] = 0.0
    return labels


def detect_contact_joints(positions: np.ndarray, fps: float, size: float, up_axis: int = 1) -> list[int]:
    """Indices of joints that touch the floor and rest there. positions: (T, J, 3)."""
    height = positions[..., up_axis]
    floor = np.percentile(height.min(axis=1), 2)
    lowest = height.min(axis=0)
    near_floor = lowest - floor < NEAR_FLOOR * size
    planted = (height - lowest < AT_REST_HEIGHT * size) & (
        joint_speeds(positions, fps) < default_contact_speed(size)
    )
    planted_share = planted.mean(axis=0)
    # A static reference root lying on the floor is not a foot.
    moves = np.ptp(positions, axis=0).max(axis=1) > NEVER_MOVES * size
    return [int(j) for j in np.flatnonzero(near_floor & moves & (planted_share >= MIN_PLANTED_SHARE))]


def resting_heights(positions: np.ndarray, fps: float, speed: float, up_axis: int = 1) -> tuple[float, ...]:
    """(C,) each contact joint's resting height in the clip (MotionCodec.contact_floors):
    FLOOR_PERCENTILE of its height on the frames it moves slower than `speed` (its lowest
    height where it never does). positions (T, C, 3), metres."""
    height, labels = positions[..., up_axis], contact_labels(positions, fps, speed) > 0
    return tuple(float(np.percentile(height[labels[:, c], c], FLOOR_PERCENTILE)) if labels[:, c].any()
                 else float(height[:, c].min()) for c in range(height.shape[1]))
