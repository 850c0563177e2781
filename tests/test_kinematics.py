"""Forward kinematics and end sites."""

from __future__ import annotations

import numpy as np
import pytest

from sinmdm.runtime.kinematics import end_site_positions, forward_kinematics
from sinmdm.runtime.rotations import euler_to_matrix


def rot_z(angle: float) -> np.ndarray:
    return euler_to_matrix(np.array([angle, 0.0, 0.0]), "ZYX")


def test_three_joint_chain_by_hand() -> None:
    parents = [-1, 0, 1]
    rotations = np.stack([rot_z(np.pi / 2), rot_z(np.pi / 2), np.eye(3)])
    translations = np.array([[1.0, 2.0, 3.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    global_rotations, positions = forward_kinematics(rotations, translations, parents)
    # Root at (1, 2, 3) facing +y; joint 1 one unit along the root's x (= world +y);
    # joint 2 two units along joint 1's x, which is turned 180 degrees (= world -x).
    np.testing.assert_allclose(positions, [[1, 2, 3], [1, 3, 3], [-1, 3, 3]], atol=1e-15)
    np.testing.assert_allclose(global_rotations[2], rot_z(np.pi), atol=1e-15)

    ends = end_site_positions(global_rotations, positions, [(2, np.array([0.0, 0.5, 0.0])), (0, None)])
    np.testing.assert_allclose(ends, [[-1, 2.5, 3], [1, 2, 3]], atol=1e-15)


def naive_fk(rotations: np.ndarray, translations: np.ndarray, parents: list[int]) -> tuple[np.ndarray, np.ndarray]:
    frames, joints = translations.shape[:2]
    g_rot = np.zeros((frames, joints, 3, 3))
    g_pos = np.zeros((frames, joints, 3))
    for f in range(frames):
        for j in range(joints):
            p = parents[j]
            if p == -1:
                g_rot[f, j] = rotations[f, j]
                g_pos[f, j] = translations[f, j]
            else:
                g_rot[f, j] = g_rot[f, p].dot(rotations[f, j])
                g_pos[f, j] = g_pos[f, p] + g_rot[f, p].dot(translations[f, j])
    return g_rot, g_pos


def random_motion(seed: int, frames: int, joints: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    rotations = euler_to_matrix(rng.uniform(-np.pi, np.pi, (frames, joints, 3)), "YXZ")
    translations = rng.normal(size=(frames, joints, 3))
    return rotations, translations


def test_matches_naive_loop_with_several_roots() -> None:
    parents = [-1, 0, 1, 1, -1, 4, 0, 6, 5, -1]
    rotations, translations = random_motion(1, 12, len(parents))
    g_rot, g_pos = forward_kinematics(rotations, translations, parents)
    n_rot, n_pos = naive_fk(rotations, translations, parents)
    np.testing.assert_allclose(g_rot, n_rot, atol=1e-13)
    np.testing.assert_allclose(g_pos, n_pos, atol=1e-13)

    end_sites = [(3, np.array([0.1, 0.2, 0.3])), (8, None), (9, [0.0, 0.0, 1.0])]
    ends = end_site_positions(g_rot, g_pos, end_sites)
    assert ends.shape == (12, 3, 3)
    np.testing.assert_allclose(ends[:, 0], n_pos[:, 3] + np.einsum("fab,b->fa", n_rot[:, 3], [0.1, 0.2, 0.3]), atol=1e-13)
    np.testing.assert_allclose(ends[:, 1], n_pos[:, 8], atol=1e-15)
    np.testing.assert_allclose(ends[:, 2], n_pos[:, 9] + n_rot[:, 9, :, 2], atol=1e-13)


def test_broadcast_rest_offsets_and_extra_leading_dims() -> None:
    parents = [-1, 0, 1, 0]
    rotations, _ = random_motion(2, 6, 4)
    offsets = np.random.default_rng(3).normal(size=(4, 3))
    g_rot, g_pos = forward_kinematics(rotations, offsets, parents)  # one set of offsets for all frames
    n_rot, n_pos = naive_fk(rotations, np.broadcast_to(offsets, (6, 4, 3)), parents)
    np.testing.assert_allclose(g_pos, n_pos, atol=1e-13)

    batched_rot, batched_pos = forward_kinematics(rotations.reshape(2, 3, 4, 3, 3), offsets, parents)
    np.testing.assert_allclose(batched_rot.reshape(6, 4, 3, 3), n_rot, atol=1e-13)
    np.testing.assert_allclose(batched_pos.reshape(6, 4, 3), n_pos, atol=1e-13)


def test_rejects_bad_input() -> None:
    rotations, translations = random_motion(4, 2, 3)
    with pytest.raises(ValueError):
        forward_kinematics(rotations, translations, [-1, 2, 0])  # parent after child
    with pytest.raises(ValueError):
        forward_kinematics(rotations, translations, [-1, 0])  # wrong joint count


def test_no_end_sites() -> None:
    rotations, translations = random_motion(5, 4, 2)
    g_rot, g_pos = forward_kinematics(rotations, translations, [-1, 0])
    assert end_site_positions(g_rot, g_pos, []).shape == (4, 0, 3)
