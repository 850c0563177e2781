"""Frame-rate resampling along time axis 0.

Output frame k sits at fractional source frame k * src_fps / dst_fps, and the
output covers the same duration as the input (the last output frame is at or
before the last input frame). Rotations are slerped (quaternions w, x, y, z);
everything else is interpolated linearly. Integer ratios reproduce source
frames exactly.
"""

from __future__ import annotations

import math

import numpy as np

from .rotations import matrix_to_quat, quat_fix_sign, quat_normalize, quat_slerp, quat_to_matrix


def resample_count(frames: int, src_fps: float, dst_fps: float) -> int:
    """Number of output frames spanning the same duration as `frames` source frames."""
    if src_fps <= 0 or dst_fps <= 0:
        raise ValueError(f"frame rates must be positive, got {src_fps} and {dst_fps}")
    if frames <= 0:
        return 0
    return math.floor((frames - 1) * dst_fps / src_fps + 1e-9) + 1


def resample_times(frames: int, src_fps: float, dst_fps: float) -> np.ndarray:
    """Fractional source-frame index of each output frame."""
    count = resample_count(frames, src_fps, dst_fps)
    # Clip guards the last sample against rounding just past the final frame.
    return np.minimum(np.arange(count) * (src_fps / dst_fps), max(frames - 1, 0))


def _neighbours(frames: int, src_fps: float, dst_fps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lower source index, upper source index and blend weight for each output frame."""
    times = resample_times(frames, src_fps, dst_fps)
    lower = np.floor(times + 1e-9).astype(np.int64)  # 1e-9: k * 2.0 style ratios land exactly
    lower = np.clip(lower, 0, max(frames - 1, 0))
    upper = np.minimum(lower + 1, frames - 1)
    weight = np.clip(times - lower, 0.0, 1.0)
    return lower, upper, weight


def resample_linear(x: np.ndarray, src_fps: float, dst_fps: float) -> np.ndarray:
    """Linear interpolation along axis 0 of (T, ...) data."""
    x = np.asarray(x, dtype=np.float64)
    if src_fps == dst_fps:
        return x.copy()
    lower, upper, weight = _neighbours(len(x), src_fps, dst_fps)
    weight = weight.reshape((-1,) + (1,) * (x.ndim - 1))
    return (1.0 - weight) * x[lower] + weight * x[upper]


def resample_quaternions(q: np.ndarray, src_fps: float, dst_fps: float) -> np.ndarray:
    """Slerp (T, ..., 4) quaternions between neighbouring source frames.

    Signs are made continuous along time, in the input and again in the output
    (downsampling fast motion can skip over the frames that kept them aligned).
    """
    q = np.asarray(q, dtype=np.float64)
    if src_fps == dst_fps:
        return q.copy()
    q = quat_fix_sign(quat_normalize(q), axis=0)
    lower, upper, weight = _neighbours(len(q), src_fps, dst_fps)
    weight = np.broadcast_to(weight.reshape((-1,) + (1,) * (q.ndim - 2)), (len(lower),) + q.shape[1:-1])
    return quat_fix_sign(quat_slerp(q[lower], q[upper], weight), axis=0)


def resample_rotations(m: np.ndarray, src_fps: float, dst_fps: float) -> np.ndarray:
    """Slerp (T, ..., 3, 3) rotation matrices (through quaternions, where slerp lives)."""
    m = np.asarray(m, dtype=np.float64)
    if src_fps == dst_fps:
        return m.copy()
    return quat_to_matrix(resample_quaternions(matrix_to_quat(m), src_fps, dst_fps))
