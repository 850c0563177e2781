"""Rotation math in plain numpy, vectorised over arbitrary leading dimensions.

Conventions (shared by the whole package):

- Quaternions are ``(..., 4)`` arrays ordered (w, x, y, z), Hamilton product.
- Rotation matrices are ``(..., 3, 3)`` and act on column vectors: ``v' = R @ v``.
- Euler angles are ``(..., 3)`` in radians. ``order`` is a 3-letter uppercase
  string of axes as written in a BVH CHANNELS line: "ZYX" means the channels are
  Zrotation Yrotation Xrotation and ``R = Rz(a0) @ Ry(a1) @ Rx(a2)`` (intrinsic,
  identical to scipy's ``Rotation.from_euler("ZYX", angles)``). Only the six
  Tait-Bryan orders are supported.
- The 6D representation is the first two ROWS of the rotation matrix flattened
  as [row0, row1]; decoding orthonormalises them with Gram-Schmidt.

All functions return float64 arrays (float32 input is accepted).
"""

from __future__ import annotations

import numpy as np

TAIT_BRYAN_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
_AXIS_INDEX = {"X": 0, "Y": 1, "Z": 2}


def _f64(x: np.ndarray) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


FRAME_CHUNK = 1024  # frames per call of `by_frame_chunks`: a 10-minute motion's temporaries stay small (2048: +25 MB at its peak, no faster)


def by_frame_chunks(fn, *arrays: np.ndarray, chunk: int = FRAME_CHUNK, out: np.ndarray | None = None) -> np.ndarray:
    """fn(*chunks) over `arrays` (each (T, ...)) in chunks along axis 0, the results
    concatenated (into `out` when given), for per-frame math whose temporaries would
    otherwise be several copies of the whole motion."""
    frames = len(arrays[0])
    if out is None and frames <= chunk:
        return fn(*arrays)
    for start in range(0, frames, chunk):
        part = fn(*(a[start : start + chunk] for a in arrays))
        if out is None:
            out = np.empty((frames,) + part.shape[1:], dtype=part.dtype)
        out[start : start + chunk] = part
    return out


def _axis_indices(order: str) -> tuple[int, int, int]:
    if order not in TAIT_BRYAN_ORDERS:
        raise ValueError(f"unsupported Euler order {order!r}; expected one of {', '.join(TAIT_BRYAN_ORDERS)}")
    return tuple(_AXIS_INDEX[axis] for axis in order)  # type: ignore[return-value]


def axis_matrix(axis: int, angle: np.ndarray) -> np.ndarray:
    """Elementary rotation about coordinate axis `axis` by `angle` (..., ) -> (..., 3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros(angle.shape + (3, 3))
    u, v = (axis + 1) % 3, (axis + 2) % 3
    m[..., axis, axis] = 1.0
    m[..., u, u] = c
    m[..., v, v] = c
    m[..., u, v] = -s
    m[..., v, u] = s
    return m


def _axis_quat(axis: int, angle: np.ndarray) -> np.ndarray:
    q = np.zeros(angle.shape + (4,))
    q[..., 0] = np.cos(angle / 2)
    q[..., 1 + axis] = np.sin(angle / 2)
    return q


# --------------------------------------------------------------------------- Euler


def euler_to_matrix(angles: np.ndarray, order: str) -> np.ndarray:
    """(..., 3) radians -> (..., 3, 3); R = R_order[0](a0) @ R_order[1](a1) @ R_order[2](a2)."""
    i, j, k = _axis_indices(order)
    angles = _f64(angles)
    return axis_matrix(i, angles[..., 0]) @ axis_matrix(j, angles[..., 1]) @ axis_matrix(k, angles[..., 2])


def euler_to_quat(angles: np.ndarray, order: str) -> np.ndarray:
    """(..., 3) radians -> (..., 4) unit quaternions (sign as produced by the product)."""
    i, j, k = _axis_indices(order)
    angles = _f64(angles)
    return quat_multiply(
        quat_multiply(_axis_quat(i, angles[..., 0]), _axis_quat(j, angles[..., 1])),
        _axis_quat(k, angles[..., 2]),
    )


def quat_to_euler(q: np.ndarray, order: str) -> np.ndarray:
    """(..., 4) quaternions (any non-zero norm) -> (..., 3) radians.

    Bernardes & Viollet (2022), the algorithm scipy uses: the middle angle is in
    [-pi/2, pi/2], the others in [-pi, pi]. It stays accurate at gimbal lock,
    where the last angle is set to 0.
    """
    first, middle, last = _axis_indices(order)
    q = _f64(q)
    # The paper is written for extrinsic sequences; the intrinsic order "ABC"
    # equals extrinsic "CBA" with reversed angles, hence i = last axis.
    i, j, k = last, middle, first
    sign = (i - j) * (j - k) * (k - i) // 2  # +1 for cyclic (even) permutations
    w, v = q[..., 0], q[..., 1:]
    a = w - v[..., j]
    b = v[..., i] + sign * v[..., k]
    c = v[..., j] + w
    d = sign * v[..., k] - v[..., i]

    middle_angle = 2.0 * np.arctan2(np.hypot(c, d), np.hypot(a, b))
    half_sum = np.arctan2(b, a)
    half_diff = np.arctan2(d, c)
    # In the intrinsic reading the sum goes to the first angle, the difference to the last.
    first_angle = half_sum + half_diff
    last_angle = half_sum - half_diff

    # At gimbal lock only a +- c is defined; put everything into the first angle.
    # The threshold is tiny so that snapping to a lock changes R by < 1e-10.
    eps = 1e-10
    at_zero = np.abs(middle_angle) <= eps
    at_pi = np.abs(middle_angle - np.pi) <= eps
    first_angle = np.where(at_zero, 2.0 * half_sum, np.where(at_pi, 2.0 * half_diff, first_angle))
    last_angle = np.where(at_zero | at_pi, 0.0, last_angle)

    angles = np.stack([sign * first_angle, middle_angle - np.pi / 2, last_angle], axis=-1)
    return _wrap_to_pi(angles)


def matrix_to_euler(m: np.ndarray, order: str) -> np.ndarray:
    """(..., 3, 3) -> (..., 3) radians; exact round trip also at gimbal lock."""
    return quat_to_euler(matrix_to_quat(m), order)


def _wrap_to_pi(angles: np.ndarray) -> np.ndarray:
    return np.where(angles > np.pi, angles - 2 * np.pi, np.where(angles < -np.pi, angles + 2 * np.pi, angles))


def unwrap_euler(angles: np.ndarray, order: str, out: np.ndarray | None = None,
                 previous: np.ndarray | None = None) -> np.ndarray:
    """Make Euler curves (T, ..., 3) continuous along time axis 0.

    Every Tait-Bryan triple (a, b, c) has a twin (a + pi, pi - b, c + pi) giving
    the same rotation, and each angle is free up to multiples of 2 pi. Frame 0 is
    kept; every later frame takes whichever of the two solutions, shifted per
    component by multiples of 2 pi, lies closest (L2) to the previous frame.
    `out` (float64, angles' shape) may be `angles` itself: each frame is read before it is written.
    `previous` (..., 3): the unwrapped frame before these (a long curve unwrapped a chunk
    at a time), so frame 0 is unwrapped against it too.
    """
    _axis_indices(order)  # validate; the twin formula is the same for all orders
    angles = _f64(angles)
    if angles.ndim < 2 or angles.shape[-1] != 3:
        raise ValueError(f"expected angles of shape (T, ..., 3), got {angles.shape}")
    out = np.empty_like(angles) if out is None else out
    if len(angles) == 0:
        return out
    two_pi, half_turns = 2 * np.pi, np.array([np.pi, 0.0, np.pi])
    if previous is None:
        prev = angles[0]
        out[0] = prev
    else:
        prev = np.asarray(previous, dtype=np.float64)
    for t in range(0 if previous is not None else 1, len(angles)):
        twin = angles[t] + half_turns
        twin[..., 1] = np.pi - angles[t][..., 1]
        direct = angles[t] + two_pi * np.round((prev - angles[t]) / two_pi)
        twin = twin + two_pi * np.round((prev - twin) / two_pi)
        use_twin = np.sum((twin - prev) ** 2, axis=-1) < np.sum((direct - prev) ** 2, axis=-1)
        prev = np.where(use_twin[..., None], twin, direct)
        out[t] = prev
    return out


# --------------------------------------------------------------------------- quaternions


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b (rotation b first, then a); broadcasts leading dims."""
    a, b = _f64(a), _f64(b)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """The inverse rotation for unit quaternions."""
    return _f64(q) * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    q = _f64(q)
    return q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), eps)


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v (..., 3) by unit quaternions q (..., 4); broadcasts leading dims."""
    q, v = _f64(q), _f64(v)
    w, u = q[..., :1], q[..., 1:]
    uv = np.cross(u, v)
    return v + 2.0 * (w * uv + np.cross(u, uv))


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) -> (..., 3, 3); q is normalised first."""
    w, x, y, z = np.moveaxis(quat_normalize(q), -1, 0)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.stack(
        [
            1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
            2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
            2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
        ],
        axis=-1,
    )
    return m.reshape(m.shape[:-1] + (3, 3))


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 4) unit quaternions with w >= 0.

    Shepperd's method: of the four algebraically equivalent formulas, use the one
    whose leading term (built from the largest of trace, m00, m11, m22) is largest.
    """
    m = _f64(m)
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    trace = m00 + m11 + m22
    # Each candidate is 4 * q_n * q for the quaternion component q_n it leads with.
    candidates = np.stack(
        [
            np.stack([1 + trace, m21 - m12, m02 - m20, m10 - m01], axis=-1),
            np.stack([m21 - m12, 1 + m00 - m11 - m22, m01 + m10, m02 + m20], axis=-1),
            np.stack([m02 - m20, m01 + m10, 1 - m00 + m11 - m22, m12 + m21], axis=-1),
            np.stack([m10 - m01, m02 + m20, m12 + m21, 1 - m00 - m11 + m22], axis=-1),
        ],
        axis=-2,
    )
    choice = np.argmax(np.stack([trace, m00, m11, m22], axis=-1), axis=-1)
    q = np.take_along_axis(candidates, choice[..., None, None], axis=-2)[..., 0, :]
    q = quat_normalize(q)
    return np.where(q[..., :1] < 0, -q, q)


def quat_slerp(q0: np.ndarray, q1: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """Shortest-path spherical interpolation; t is a scalar or broadcasts with q's leading dims."""
    q0, q1 = quat_normalize(q0), quat_normalize(q1)
    t = _f64(t)[..., None]
    q1 = np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0, -q1, q1)
    # Angle between the 4-vectors; atan2 form stays accurate when q0 ~ q1.
    theta = 2.0 * np.arctan2(
        np.linalg.norm(q0 - q1, axis=-1, keepdims=True), np.linalg.norm(q0 + q1, axis=-1, keepdims=True)
    )
    sin_theta = np.sin(theta)
    small = sin_theta < 1e-9
    safe = np.where(small, 1.0, sin_theta)
    w0 = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    w1 = np.where(small, t, np.sin(t * theta) / safe)
    return quat_normalize(w0 * q0 + w1 * q1)


def quat_fix_sign(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs so consecutive quaternions along `axis` have non-negative dot products."""
    q = np.moveaxis(_f64(q), axis, 0)
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    # Flipping frame t-1 flips the sign of dot(t, t-1): signs accumulate.
    flips = np.cumprod(np.where(dots < 0, -1.0, 1.0), axis=0)
    signs = np.concatenate([np.ones((min(len(q), 1),) + q.shape[1:-1]), flips], axis=0)
    return np.moveaxis(q * signs[..., None], 0, axis)


# --------------------------------------------------------------------------- 6D


def matrix_to_6d(m: np.ndarray) -> np.ndarray:
    """(..., 3, 3) -> (..., 6): the first two rows, [row0, row1]."""
    m = _f64(m)
    return m[..., :2, :].reshape(m.shape[:-2] + (6,))


def sixd_to_matrix(d6: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """(..., 6) -> (..., 3, 3) by Gram-Schmidt on the two rows; third row = row0 x row1."""
    d6 = _f64(d6)
    a, b = d6[..., :3], d6[..., 3:]
    row0 = a / np.maximum(np.linalg.norm(a, axis=-1, keepdims=True), eps)
    b = b - np.sum(row0 * b, axis=-1, keepdims=True) * row0
    row1 = b / np.maximum(np.linalg.norm(b, axis=-1, keepdims=True), eps)
    return np.stack([row0, row1, np.cross(row0, row1)], axis=-2)
