"""Forward kinematics for skeletons given as parent arrays.

Conventions: rotation matrices act on column vectors; `parents[j]` is the parent
of joint j, -1 for a root, and parents come before children (parents[j] < j).
A joint's local translation is its position relative to its parent, expressed in
the parent's frame (the BVH OFFSET, or the position channels where present).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .rotations import by_frame_chunks


def forward_kinematics(
    local_rotations: np.ndarray, local_translations: np.ndarray, parents: Sequence[int] | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(..., J, 3, 3) rotations and (..., J, 3) translations -> global rotations and positions.

    Roots take their local transform as global; a child j gets
    G_j = G_p @ L_j and P_j = P_p + G_p @ t_j. Vectorised over leading dims.
    """
    local_rotations = np.asarray(local_rotations, dtype=np.float64)
    local_translations = np.asarray(local_translations, dtype=np.float64)
    parents = np.asarray(parents, dtype=np.int64)
    num_joints = len(parents)
    if local_rotations.shape[-3:] != (num_joints, 3, 3) or local_translations.shape[-2:] != (num_joints, 3):
        raise ValueError(
            f"expected rotations (..., {num_joints}, 3, 3) and translations (..., {num_joints}, 3), "
            f"got {local_rotations.shape} and {local_translations.shape}"
        )
    leading = np.broadcast_shapes(local_rotations.shape[:-3], local_translations.shape[:-2])
    global_rotations = np.empty(leading + (num_joints, 3, 3))
    global_positions = np.empty(leading + (num_joints, 3))
    for j, p in enumerate(parents):
        if p < 0:
            global_rotations[..., j, :, :] = local_rotations[..., j, :, :]
            global_positions[..., j, :] = local_translations[..., j, :]
        elif p >= j:
            raise ValueError(f"joint {j} has parent {p}; parents must precede their children")
        else:
            parent_rotation = global_rotations[..., p, :, :]
            global_rotations[..., j, :, :] = parent_rotation @ local_rotations[..., j, :, :]
            global_positions[..., j, :] = global_positions[..., p, :] + np.einsum(
                "...ab,...b->...a", parent_rotation, local_translations[..., j, :]
            )
    return global_rotations, global_positions


def end_site_positions(
    global_rotations: np.ndarray,
    global_positions: np.ndarray,
    end_sites: Sequence[tuple[int, np.ndarray | Sequence[float] | None]],
) -> np.ndarray:
    """(..., E, 3) positions of end sites given as (parent joint, offset in the parent's frame).

    An offset of None puts the end site at its parent joint.
    """
    global_rotations = np.asarray(global_rotations, dtype=np.float64)
    global_positions = np.asarray(global_positions, dtype=np.float64)
    if not end_sites:
        return np.empty(global_positions.shape[:-2] + (0, 3))
    parent_index = np.array([parent for parent, _ in end_sites], dtype=np.int64)
    offsets = np.array([np.zeros(3) if offset is None else np.asarray(offset, dtype=np.float64) for _, offset in end_sites])
    return global_positions[..., parent_index, :] + np.einsum(
        "...eab,eb->...ea", global_rotations[..., parent_index, :, :], offsets
    )


def chain_kinematics(
    local_rotations: np.ndarray, local_translations: np.ndarray, parents: Sequence[int] | np.ndarray,
    joints: Sequence[int],
) -> tuple[np.ndarray, np.ndarray]:
    """Global rotations (..., K, 3, 3) and positions (..., K, 3) of the K `joints` only, by
    forward kinematics over them and their ancestors: a leg of a 65-joint rig costs its
    chain, not the whole skeleton (the fingers), at any length of motion."""
    parents = np.asarray(parents, dtype=np.int64)
    needed: set[int] = set()
    for joint in joints:
        while joint >= 0 and joint not in needed:
            needed.add(int(joint))
            joint = parents[joint]
    order = sorted(needed)
    at = {joint: i for i, joint in enumerate(order)}
    sub_parents = [at[parents[j]] if parents[j] >= 0 else -1 for j in order]
    glob, pos = forward_kinematics(np.asarray(local_rotations)[..., order, :, :],
                                   np.asarray(local_translations)[..., order, :], sub_parents)
    pick = [at[j] for j in joints]
    return glob[..., pick, :, :], pos[..., pick, :]


def positions_by_chunks(local_rotations: np.ndarray, local_translations: np.ndarray,
                        parents: Sequence[int] | np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """(T, J, 3) world positions (into `out` when given), forward kinematics a chunk of
    frames at a time: the global rotations of a long motion are never held whole."""
    return by_frame_chunks(lambda rotations, translations: forward_kinematics(rotations, translations, parents)[1],
                           local_rotations, local_translations, out=out)
