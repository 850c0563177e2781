"""Rotation math and frame-rate resampling, checked against scipy."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from sinmdm.runtime import rotations as rot
from sinmdm.runtime.resample import resample_count, resample_linear, resample_quaternions, resample_times

ORDERS = rot.TAIT_BRYAN_ORDERS
BATCH = (7, 5)


def random_angles(seed: int, shape: tuple[int, ...] = BATCH) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-np.pi, np.pi, shape + (3,))


def random_quats(seed: int, shape: tuple[int, ...] = BATCH) -> np.ndarray:
    q = np.random.default_rng(seed).normal(size=shape + (4,))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def to_scipy(q: np.ndarray) -> Rotation:
    """(..., 4) wxyz -> flat scipy Rotation."""
    return Rotation.from_quat(q.reshape(-1, 4)[:, [1, 2, 3, 0]])


def from_scipy(r: Rotation, shape: tuple[int, ...]) -> np.ndarray:
    return r.as_quat()[:, [3, 0, 1, 2]].reshape(shape + (4,))


def assert_same_rotation(q: np.ndarray, p: np.ndarray, atol: float = 1e-12) -> None:
    np.testing.assert_allclose(np.abs(np.sum(q * p, axis=-1)), 1.0, atol=atol)


# --------------------------------------------------------------------------- Euler


@pytest.mark.parametrize("order", ORDERS)
def test_euler_to_matrix_matches_scipy(order: str) -> None:
    angles = random_angles(1)
    expected = Rotation.from_euler(order, angles.reshape(-1, 3)).as_matrix().reshape(BATCH + (3, 3))
    np.testing.assert_allclose(rot.euler_to_matrix(angles, order), expected, atol=1e-14)


@pytest.mark.parametrize("order", ORDERS)
def test_euler_to_quat_matches_scipy(order: str) -> None:
    angles = random_angles(2)
    expected = from_scipy(Rotation.from_euler(order, angles.reshape(-1, 3)), BATCH)
    assert_same_rotation(rot.euler_to_quat(angles, order), expected)


@pytest.mark.parametrize("order", ORDERS)
def test_matrix_and_quat_to_euler_match_scipy(order: str) -> None:
    q = random_quats(3)
    expected = to_scipy(q).as_euler(order).reshape(BATCH + (3,))
    np.testing.assert_allclose(rot.quat_to_euler(q, order), expected, atol=1e-12)
    np.testing.assert_allclose(rot.matrix_to_euler(rot.quat_to_matrix(q), order), expected, atol=1e-12)


@pytest.mark.parametrize("order", ORDERS)
def test_euler_round_trip_in_canonical_range(order: str) -> None:
    angles = random_angles(4)
    angles[..., 1] /= 2  # middle angle in (-pi/2, pi/2): the decomposition is unique
    np.testing.assert_allclose(rot.matrix_to_euler(rot.euler_to_matrix(angles, order), order), angles, atol=1e-12)
    np.testing.assert_allclose(rot.quat_to_euler(rot.euler_to_quat(angles, order), order), angles, atol=1e-12)


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("middle", [np.pi / 2, -np.pi / 2, np.pi / 2 - 1e-9, -np.pi / 2 + 1e-11, np.pi / 2 + 1e-7])
def test_matrix_to_euler_at_gimbal_lock(order: str, middle: float) -> None:
    angles = random_angles(5)
    angles[..., 1] = middle
    m = rot.euler_to_matrix(angles, order)
    recovered = rot.matrix_to_euler(m, order)
    np.testing.assert_allclose(rot.euler_to_matrix(recovered, order), m, atol=1e-9)
    assert np.all(np.abs(recovered) <= np.pi + 1e-12)


def test_unknown_order_is_rejected() -> None:
    for order in ("xyz", "ZYZ", "XY", "ABC"):
        with pytest.raises(ValueError):
            rot.euler_to_matrix(np.zeros(3), order)


def test_float32_input_gives_float64() -> None:
    angles = random_angles(6).astype(np.float32)
    assert rot.euler_to_matrix(angles, "ZYX").dtype == np.float64
    assert rot.euler_to_quat(angles, "ZYX").dtype == np.float64


# --------------------------------------------------------------------------- quaternions


def test_quat_matrix_round_trip_matches_scipy() -> None:
    q = random_quats(10)
    m = rot.quat_to_matrix(q)
    np.testing.assert_allclose(m, to_scipy(q).as_matrix().reshape(BATCH + (3, 3)), atol=1e-14)
    back = rot.matrix_to_quat(m)
    assert np.all(back[..., 0] >= 0)
    assert_same_rotation(back, q)


def test_matrix_to_quat_on_every_shepperd_branch() -> None:
    # Identity and half-turns about each axis pick each of the four branches.
    matrices = np.stack([np.eye(3), np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1])])
    expected = np.eye(4)
    np.testing.assert_allclose(rot.matrix_to_quat(matrices), expected, atol=1e-15)
    near_half_turns = Rotation.from_rotvec(np.random.default_rng(11).normal(size=(50, 3)) * 1e-3 + [np.pi, 0, 0])
    assert_same_rotation(rot.matrix_to_quat(near_half_turns.as_matrix()), from_scipy(near_half_turns, (50,)))


def test_quat_multiply_conjugate_rotate_match_scipy() -> None:
    a, b = random_quats(12), random_quats(13)
    expected = from_scipy(to_scipy(a) * to_scipy(b), BATCH)
    assert_same_rotation(rot.quat_multiply(a, b), expected)
    identity = rot.quat_multiply(a, rot.quat_conjugate(a))
    np.testing.assert_allclose(identity, np.broadcast_to([1.0, 0, 0, 0], identity.shape), atol=1e-14)

    v = np.random.default_rng(14).normal(size=BATCH + (3,))
    expected_v = to_scipy(a).apply(v.reshape(-1, 3)).reshape(v.shape)
    np.testing.assert_allclose(rot.quat_rotate(a, v), expected_v, atol=1e-13)
    # Broadcasting one rotation over many vectors.
    np.testing.assert_allclose(rot.quat_rotate(a[0, 0], v), to_scipy(a[0, 0]).apply(v.reshape(-1, 3)).reshape(v.shape), atol=1e-13)


def test_quat_normalize() -> None:
    q = random_quats(15) * 3.7
    np.testing.assert_allclose(np.linalg.norm(rot.quat_normalize(q), axis=-1), 1.0, atol=1e-15)


def test_quat_slerp_matches_scipy() -> None:
    q0, q1 = random_quats(16, (40,)), random_quats(17, (40,))
    t = np.random.default_rng(18).uniform(0, 1, 40)
    ours = rot.quat_slerp(q0, q1, t)
    for n in range(40):
        slerp = Slerp([0.0, 1.0], to_scipy(np.stack([q0[n], q1[n]])))
        assert_same_rotation(ours[n], from_scipy(slerp([t[n]]), ()), atol=1e-12)


def test_quat_slerp_shortest_path_and_nearly_equal() -> None:
    q0 = random_quats(19, (10,))
    # -q1 is the same rotation: slerp must take the short way and stay constant.
    halfway = rot.quat_slerp(q0, -q0, 0.5)
    assert_same_rotation(halfway, q0)
    tiny = Rotation.from_rotvec(np.full((10, 3), 1e-12))
    q1 = from_scipy(to_scipy(q0) * tiny, (10,))
    out = rot.quat_slerp(q0, q1, 0.3)
    assert np.all(np.isfinite(out))
    assert_same_rotation(out, q0)
    # Endpoints are exact.
    q1 = random_quats(20, (10,))
    assert_same_rotation(rot.quat_slerp(q0, q1, 0.0), q0, atol=1e-15)
    assert_same_rotation(rot.quat_slerp(q0, q1, 1.0), q1, atol=1e-15)


def test_quat_fix_sign() -> None:
    q = random_quats(21, (30, 4))
    q = np.cumsum(q * 0.05, axis=0) + [1.0, 0, 0, 0]
    q = rot.quat_normalize(q)
    flipped = q * np.where(np.random.default_rng(22).random((30, 4, 1)) < 0.5, -1.0, 1.0)
    fixed = rot.quat_fix_sign(flipped)
    assert np.all(np.sum(fixed[1:] * fixed[:-1], axis=-1) > 0)
    assert_same_rotation(fixed, q)
    # Time on another axis.
    fixed_t1 = rot.quat_fix_sign(np.swapaxes(flipped, 0, 1), axis=1)
    np.testing.assert_allclose(np.swapaxes(fixed_t1, 0, 1), fixed)
    assert rot.quat_fix_sign(q[:1]).shape == (1, 4, 4)
    assert rot.quat_fix_sign(q[:0]).shape == (0, 4, 4)


# --------------------------------------------------------------------------- 6D


def test_6d_round_trip_and_layout() -> None:
    m = rot.quat_to_matrix(random_quats(23))
    d6 = rot.matrix_to_6d(m)
    assert d6.shape == BATCH + (6,)
    np.testing.assert_array_equal(d6[..., :3], m[..., 0, :])
    np.testing.assert_array_equal(d6[..., 3:], m[..., 1, :])
    np.testing.assert_allclose(rot.sixd_to_matrix(d6), m, atol=1e-14)


def test_6d_gram_schmidt_on_perturbed_input() -> None:
    m = rot.quat_to_matrix(random_quats(24))
    rng = np.random.default_rng(25)
    d6 = rot.matrix_to_6d(m) * rng.uniform(0.5, 2.0, BATCH + (1,)) + rng.normal(scale=0.05, size=BATCH + (6,))
    out = rot.sixd_to_matrix(d6)
    identity = np.broadcast_to(np.eye(3), out.shape)
    np.testing.assert_allclose(out @ np.swapaxes(out, -1, -2), identity, atol=1e-13)
    np.testing.assert_allclose(np.linalg.det(out), 1.0, atol=1e-13)
    # Row 0 keeps the direction of the first input vector; row 1 stays in the span of both.
    a = d6[..., :3] / np.linalg.norm(d6[..., :3], axis=-1, keepdims=True)
    np.testing.assert_allclose(out[..., 0, :], a, atol=1e-14)
    np.testing.assert_allclose(np.sum(out[..., 2, :] * d6[..., 3:], axis=-1), 0.0, atol=1e-13)
    assert np.all(np.sum(out[..., 1, :] * d6[..., 3:], axis=-1) > 0)
    # Close to the unperturbed rotation.
    assert np.max(np.abs(out - m)) < 0.3


# --------------------------------------------------------------------------- unwrap


def max_jump(angles: np.ndarray) -> float:
    return float(np.max(np.abs(np.diff(angles, axis=0))))


@pytest.mark.parametrize("order", ORDERS)
def test_unwrap_euler_across_plus_minus_pi(order: str) -> None:
    t = np.linspace(0, 1, 200)
    curve = np.stack([np.pi * 0.9 + 2.0 * t, 0.3 * np.sin(6 * t), -np.pi * 0.8 - 1.5 * t], axis=-1)[:, None, :]
    wrapped = rot.matrix_to_euler(rot.euler_to_matrix(curve, order), order)
    assert max_jump(wrapped) > 5  # the input really has 2 pi jumps
    unwrapped = rot.unwrap_euler(wrapped, order)
    assert max_jump(unwrapped) < 0.05
    np.testing.assert_allclose(unwrapped, curve, atol=1e-10)


@pytest.mark.parametrize("order", ORDERS)
def test_unwrap_euler_through_alternate_solution(order: str) -> None:
    # The middle angle leaves [-pi/2, pi/2]: the canonical decomposition flips to
    # the twin solution (a + pi, pi - b, c + pi), and unwrap must undo that.
    t = np.linspace(0, 1, 300)
    curve = np.stack([0.4 * np.sin(3 * t), 1.2 + 0.8 * t, 0.5 * t - 0.2], axis=-1)
    curve = np.stack([curve, curve[:, [2, 1, 0]] * [1, -1, 1]], axis=1)  # (T, 2, 3), crossing +-pi/2
    m = rot.euler_to_matrix(curve, order)
    canonical = rot.matrix_to_euler(m, order)
    assert max_jump(canonical) > 2
    unwrapped = rot.unwrap_euler(canonical, order)
    assert max_jump(unwrapped) < 0.05
    np.testing.assert_allclose(rot.euler_to_matrix(unwrapped, order), m, atol=1e-12)
    np.testing.assert_allclose(unwrapped, curve, atol=1e-10)


def test_unwrap_euler_is_fast() -> None:
    angles = random_angles(26, (1300, 65))
    start = time.perf_counter()
    out = rot.unwrap_euler(angles, "ZXY")
    elapsed = time.perf_counter() - start
    assert out.shape == angles.shape
    np.testing.assert_allclose(rot.euler_to_matrix(out, "ZXY"), rot.euler_to_matrix(angles, "ZXY"), atol=1e-12)
    assert elapsed < 0.5


# --------------------------------------------------------------------------- resampling


def test_resample_count_and_times() -> None:
    assert resample_count(101, 60, 30) == 51
    assert resample_count(100, 60, 30) == 50  # 99 / 2 = 49.5 -> 49 + 1
    assert resample_count(121, 30, 24) == 97
    assert resample_count(10, 30, 30) == 10
    assert resample_count(11, 30, 60) == 21
    assert resample_count(1, 30, 24) == 1
    for frames, src, dst in [(1300, 120, 30), (77, 29.97, 24), (5, 24, 60), (1001, 30, 29.97)]:
        assert resample_count(frames, src, dst) == int(np.floor((frames - 1) * dst / src + 1e-9)) + 1
        times = resample_times(frames, src, dst)
        assert len(times) == resample_count(frames, src, dst)
        assert times[-1] <= frames - 1
    np.testing.assert_array_equal(resample_times(9, 30, 24), np.arange(7) * 1.25)


def test_resample_60_to_30_is_exact() -> None:
    rng = np.random.default_rng(27)
    x = rng.normal(size=(101, 3, 2))
    np.testing.assert_allclose(resample_linear(x, 60, 30), x[::2], atol=1e-15)
    q = rot.quat_fix_sign(rot.quat_normalize(np.cumsum(random_quats(28, (101, 4)) * 0.1, axis=0) + [1.0, 0, 0, 0]))
    np.testing.assert_allclose(resample_quaternions(q, 60, 30), q[::2], atol=1e-14)


def test_resample_30_to_24_slerp_matches_scipy() -> None:
    q = random_quats(29, (61, 3))
    out = resample_quaternions(q, 30, 24)
    times = resample_times(61, 30, 24)
    assert out.shape == (len(times), 3, 4)
    for joint in range(3):
        expected = from_scipy(Slerp(np.arange(61.0), to_scipy(q[:, joint]))(times), (len(times),))
        assert_same_rotation(out[:, joint], expected)
    # Output signs are continuous.
    assert np.all(np.sum(out[1:] * out[:-1], axis=-1) >= 0)


def test_resample_linear_30_to_24() -> None:
    x = np.arange(61.0)[:, None] * [1.0, -2.0]
    np.testing.assert_allclose(resample_linear(x, 30, 24), resample_times(61, 30, 24)[:, None] * [1.0, -2.0], atol=1e-12)


def test_resample_same_rate_copies() -> None:
    x = np.random.default_rng(30).normal(size=(5, 4))
    out = resample_linear(x, 30, 30)
    np.testing.assert_array_equal(out, x)
    assert out is not x
    q = random_quats(31, (5,))
    np.testing.assert_array_equal(resample_quaternions(q, 30, 30), q)
