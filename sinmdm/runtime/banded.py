"""Weighted smoothing over frames: the least-squares fit of a signal to targets that are
trusted per frame, with penalties on its first and second differences (a discrete smoothing
spline, critically damped where both are given: it eases into its targets without ringing).
Its normal equations are pentadiagonal; they are solved in O(frames) by a banded LDL^T
(numpy has no banded solver, and the runtime depends on numpy alone)."""

from __future__ import annotations

import numpy as np


def second_difference_bands(frames: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The diagonal, first and second off-diagonals of D^T D, D the (frames-2, frames) second difference."""
    rows = np.arange(max(frames - 2, 0))  # row r of D is (1, -2, 1) at frames r, r+1, r+2
    d0 = np.bincount(rows, minlength=frames) + 4.0 * np.bincount(rows + 1, minlength=frames) + np.bincount(rows + 2, minlength=frames)
    d1 = -2.0 * (np.bincount(rows, minlength=frames - 1) + np.bincount(rows + 1, minlength=frames - 1))[: max(frames - 1, 0)]
    d2 = np.ones(max(frames - 2, 0))
    return d0, d1, d2


def first_difference_bands(frames: int) -> tuple[np.ndarray, np.ndarray]:
    """The diagonal and first off-diagonal of E^T E, E the (frames-1, frames) first difference."""
    d0 = np.full(frames, 2.0)
    d0[[0, -1]] = 1.0
    return d0, -np.ones(max(frames - 1, 0))


def fit_smooth(targets: np.ndarray, weights: np.ndarray, smoothness: float, stiffness: float = 0.0) -> np.ndarray:
    """(T, K) x minimising sum_t weights[t] |x[t] - targets[t]|^2 + stiffness * sum |x[t+1] - x[t]|^2
    + smoothness * sum |x[t-1] - 2 x[t] + x[t+1]|^2. `weights` (T,) must be positive."""
    targets = np.asarray(targets, dtype=np.float64)
    frames = len(targets)
    if frames < 3 or smoothness <= 0:
        return targets.copy()
    d0, d1, d2 = second_difference_bands(frames)
    e0, e1 = first_difference_bands(frames)
    a0 = (np.asarray(weights, dtype=np.float64) + smoothness * d0 + stiffness * e0).tolist()
    a1, a2 = (smoothness * d1 + stiffness * e1).tolist(), (smoothness * d2).tolist()
    # A = L diag(d) L^T with L unit lower triangular, bands l1 (i+1, i) and l2 (i+2, i).
    d, l1, l2 = [0.0] * frames, [0.0] * frames, [0.0] * frames
    for i in range(frames):
        di = a0[i]
        if i >= 1:
            di -= l1[i - 1] ** 2 * d[i - 1]
        if i >= 2:
            di -= l2[i - 2] ** 2 * d[i - 2]
        d[i] = di
        if i + 1 < frames:
            l1[i] = (a1[i] - (l2[i - 1] * l1[i - 1] * d[i - 1] if i >= 1 else 0.0)) / di
        if i + 2 < frames:
            l2[i] = a2[i] / di
    rhs = np.asarray(weights, dtype=np.float64)[:, None] * targets.reshape(frames, -1)
    z = rhs.copy()
    for i in range(1, frames):  # L z = rhs
        z[i] -= l1[i - 1] * z[i - 1]
        if i >= 2:
            z[i] -= l2[i - 2] * z[i - 2]
    x = z / np.asarray(d)[:, None]
    for i in range(frames - 2, -1, -1):  # L^T x = z / d
        x[i] -= l1[i] * x[i + 1]
        if i + 2 < frames:
            x[i] -= l2[i] * x[i + 2]
    return x.reshape(targets.shape)
