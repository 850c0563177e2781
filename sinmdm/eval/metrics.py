"""Evaluation metrics of SinMDM on the Mixamo benchmark (numpy only).

A motion is a float array ``(frames, features)`` (per frame: 6D rotations of the
chosen joints plus contact labels, built by the caller). ``d(a_i, b_k)`` is the
Euclidean distance between two frames and the cost of aligning ``n`` frames of
``a`` starting at ``i`` with ``n`` frames of ``b`` starting at ``k`` is the
diagonal window sum ``W_n(i, k) = sum_{m<n} d(a_{i+m}, b_{k+m})``.

Definitions (reference notes, section 6; GANimator's evaluation code as shipped
in SinMDM/SinMDM ``data_utils/mixamo/evaluations/{perwindow_nn,patched_nn}.py``,
``eval/eval_mixamo.py`` and the kernel PeizhuoLi/ganimator-eval-kernel
``src/main.cpp``):

- coverage (%, higher better): fraction of reference windows of 30 frames,
  starts ``0 .. T_ref - 31``, whose best match among all sample windows has
  mean cost ``W_30 / 30 < 2.0``.
- global diversity (higher better): tile the sample into consecutive segments
  of length >= 30, each aligned with a same-length reference segment; the
  minimal total cost (dynamic programming) divided by the sample length.
- local diversity (higher better): mean over sample windows of 15 frames,
  starts ``0 .. L - 16``, of the best-match mean cost ``min_k W_15 / 15``.
- inter diversity (higher better): mean over consecutive pairs of samples of
  ``||x_i - x_{i-1}||_F / frames`` (cyclic, as in the authors' loop).
- intra diversity diff (lower better): per sample, ``||w_1 - w_2||_F / 15`` for
  two random 15-frame windows, minus the same on the reference; absolute
  value; mean over samples.
- harmonic mean: normalise each metric by its maximum (100 for coverage, else
  the 90th percentile of the column, ``np.percentile`` linear interpolation),
  lower-is-better scores become ``(max - s) / max``; ``HM = E / sum(1 / s_i)``.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence

import numpy as np
import numpy.typing as npt

__all__ = [
    "frame_distances",
    "coverage",
    "coverage_many",
    "covered_windows",
    "global_diversity",
    "local_diversity",
    "inter_diversity",
    "intra_diversity_diff",
    "evaluate",
    "harmonic_mean",
]

FloatArray = npt.NDArray[np.float64]
RandomSource = int | np.random.Generator | np.random.RandomState

COVERAGE_WINDOW = 30
COVERAGE_THRESHOLD = 2.0
MIN_SEGMENT = 30
LOCAL_WINDOW = 15
INTRA_WINDOW = 15


def _as_motion(motion: npt.ArrayLike) -> FloatArray:
    array = np.asarray(motion, dtype=np.float64)
    if array.ndim != 2:
        raise ValueError(f"a motion must be (frames, features), got shape {array.shape}")
    return array


def frame_distances(a: npt.ArrayLike, b: npt.ArrayLike) -> FloatArray:
    """Euclidean distance between every frame of ``a`` and every frame of ``b``: (len(a), len(b))."""
    a, b = _as_motion(a), _as_motion(b)
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"feature counts differ: {a.shape[1]} vs {b.shape[1]}")
    # Distances are translation invariant; centring shrinks the norms and with
    # them the cancellation error of the ||a||^2 + ||b||^2 - 2ab expansion.
    centre = b.mean(axis=0)
    a, b = a - centre, b - centre
    a_sq, b_sq = np.einsum("ij,ij->i", a, a), np.einsum("ij,ij->i", b, b)
    squared = a @ b.T
    squared *= -2.0
    squared += a_sq[:, None]
    squared += b_sq[None, :]
    np.maximum(squared, 0.0, out=squared)
    # Near-coincident frames lose every significant digit to cancellation
    # (sqrt turns a 1e-16 residue into 1e-8); recompute those few exactly so
    # that a copied frame costs exactly 0.
    rows, cols = np.nonzero(squared <= 1e-8 * (a_sq[:, None] + b_sq[None, :]))
    for start in range(0, rows.size, 1 << 16):
        r, c = rows[start : start + (1 << 16)], cols[start : start + (1 << 16)]
        squared[r, c] = np.einsum("ij,ij->i", a[r] - b[c], a[r] - b[c])
    return np.sqrt(squared, out=squared)


def _diagonal_window_sums(distances: FloatArray, max_length: int) -> Iterator[tuple[int, FloatArray]]:
    """Yield ``(n, W_n)`` for n = 1 .. max_length, ``W_n[i, k] = sum_{m<n} D[i+m, k+m]``.

    ``W_n`` has shape ``(L - n + 1, T - n + 1)`` and is updated in place
    (``W_{n+1} = W_n + D[n:, n:]``, the authors' ``prepare_group_cost``
    recurrence), so memory stays O(L * T) and a yielded array is only valid
    until the next step.
    """
    sums = distances.copy()
    yield 1, sums
    for n in range(1, max_length):
        sums = sums[:-1, :-1]
        sums += distances[n:, n:]
        yield n + 1, sums


def _window_sums(distances: FloatArray, length: int) -> FloatArray:
    """``W_length`` alone (shape ``(L - length + 1, T - length + 1)``)."""
    for _, sums in _diagonal_window_sums(distances, length):
        pass
    return sums


def _check_length(name: str, frames: int, needed: int) -> None:
    if frames < needed:
        raise ValueError(f"{name} has {frames} frames, needs at least {needed}")


def _covered_from_distances(distances: FloatArray, window: int, threshold: float) -> npt.NDArray[np.bool_]:
    sample_frames, reference_frames = distances.shape
    _check_length("sample", sample_frames, window)
    _check_length("reference", reference_frames, window + 1)
    # The authors loop `for i in range(len(reference) - tmin)`: the last
    # reference window is never scored, while the best match is taken over
    # every sample window (unmatched starts are +inf in their table).
    best_cost = _window_sums(distances, window).min(axis=0)[: reference_frames - window] / window
    return best_cost < threshold


def _coverage_from_distances(distances: FloatArray, window: int, threshold: float) -> float:
    return 100.0 * float(np.mean(_covered_from_distances(distances, window, threshold)))


def _local_from_distances(distances: FloatArray, window: int) -> float:
    sample_frames, reference_frames = distances.shape
    _check_length("sample", sample_frames, window + 1)
    _check_length("reference", reference_frames, window)
    # Same `range(L - tmin)` loop as coverage: sample window starts 0 .. L - window - 1.
    best_cost = _window_sums(distances, window).min(axis=1)[: sample_frames - window] / window
    return float(best_cost.mean())


def _global_from_distances(distances: FloatArray, min_segment: int) -> float:
    """Minimal tiling cost / sample length (GANimator's ``nn_dp``), in O(L * T) memory.

    The authors' DP lets a segment have any length >= min_segment. Only lengths
    in [min_segment, 2 * min_segment - 1] are needed: a segment of length
    n >= 2 * min_segment aligned at reference start k splits into lengths
    min_segment and n - min_segment >= min_segment aligned at k and
    k + min_segment, and the two window sums add up to exactly the same
    diagonal sum (group_cost[l, i, k] = group_cost[l, j, k] + group_cost[j, i, k
    + j - l]); repeating the split tiles any segment with allowed lengths, so the
    DP optimum is unchanged (equal, not merely bounded). Only the value is
    returned, so the authors' tie-breaking (first strict improvement, which only
    affects their label traceback) does not matter.
    """
    sample_frames, reference_frames = distances.shape
    _check_length("sample", sample_frames, min_segment)
    _check_length("reference", reference_frames, min_segment)
    longest = min(2 * min_segment - 1, sample_frames, reference_frames)
    lengths = np.arange(min_segment, longest + 1)
    # best_segment[j, s]: cheapest alignment of sample[s : s + lengths[j]].
    best_segment = np.full((lengths.size, sample_frames + 1), np.inf)
    for n, sums in _diagonal_window_sums(distances, longest):
        if n >= min_segment:
            best_segment[n - min_segment, : sample_frames - n + 1] = sums.min(axis=1)
    best_prefix = np.full(sample_frames + 1, np.inf)
    best_prefix[0] = 0.0
    for end in range(min_segment, sample_frames + 1):
        usable = lengths <= end
        starts = end - lengths[usable]
        best_prefix[end] = np.min(best_prefix[starts] + best_segment[np.flatnonzero(usable), starts])
    return float(best_prefix[sample_frames] / sample_frames)


def covered_windows(
    reference: npt.ArrayLike,
    sample: npt.ArrayLike,
    window: int = COVERAGE_WINDOW,
    threshold: float = COVERAGE_THRESHOLD,
) -> npt.NDArray[np.bool_]:
    """(T_in - window,) which reference windows the sample reproduces: `coverage` window by window."""
    return _covered_from_distances(frame_distances(sample, reference), window, threshold)


def coverage(
    reference: npt.ArrayLike,
    sample: npt.ArrayLike,
    window: int = COVERAGE_WINDOW,
    threshold: float = COVERAGE_THRESHOLD,
) -> float:
    """Percentage of reference windows reproduced (mean cost < threshold) somewhere in the sample."""
    return _coverage_from_distances(frame_distances(sample, reference), window, threshold)


def coverage_many(
    reference: npt.ArrayLike,
    samples: Sequence[npt.ArrayLike],
    window: int = COVERAGE_WINDOW,
    threshold: float = COVERAGE_THRESHOLD,
) -> float:
    """Mean coverage (%) over samples (the authors average per-sample coverages)."""
    return float(np.mean([coverage(reference, sample, window, threshold) for sample in samples]))


def global_diversity(reference: npt.ArrayLike, sample: npt.ArrayLike, min_segment: int = MIN_SEGMENT) -> float:
    """Per-frame cost of the cheapest tiling of the sample by reference segments of >= min_segment frames."""
    return _global_from_distances(frame_distances(sample, reference), min_segment)


def local_diversity(reference: npt.ArrayLike, sample: npt.ArrayLike, window: int = LOCAL_WINDOW) -> float:
    """Mean over sample windows of the mean per-frame cost of their nearest reference window."""
    return _local_from_distances(frame_distances(sample, reference), window)


def _mean_frame_distance(motion_a: FloatArray, motion_b: FloatArray) -> float:
    # avg_per_frame_dist(norm='fro'): Frobenius norm of the difference / frames.
    return float(np.linalg.norm(motion_b - motion_a) / motion_a.shape[0])


def inter_diversity(samples: Sequence[npt.ArrayLike]) -> float:
    """Mean of ||x_i - x_{i-1}||_F / frames over the samples.

    The authors compare ``all_samples[i]`` with ``all_samples[i - 1]`` for every
    i, so the pair (first, last) is included (cyclic). Samples of different
    lengths are compared on their common leading frames.
    """
    motions = [_as_motion(sample) for sample in samples]
    if not motions:
        raise ValueError("no samples")
    distances = []
    for current, previous in zip(motions, motions[-1:] + motions[:-1]):
        frames = min(current.shape[0], previous.shape[0])
        distances.append(_mean_frame_distance(current[:frames], previous[:frames]))
    return float(np.mean(distances))


def _random_state(rng_or_seed: RandomSource) -> np.random.Generator | np.random.RandomState:
    if isinstance(rng_or_seed, (np.random.Generator, np.random.RandomState)):
        return rng_or_seed
    # An integer seeds the legacy generator: the authors call fixseed(seed)
    # (np.random.seed) and then np.random.randint.
    return np.random.RandomState(rng_or_seed)


def _random_starts(
    rng: np.random.Generator | np.random.RandomState, highs: Sequence[int], trials: int
) -> npt.NDArray[np.int64]:
    """Window-start pairs in [0, high) of shape (len(highs), trials, 2), one draw call like the authors'."""
    bounds = np.asarray(highs, dtype=np.int64)
    # A scalar bound when all bounds agree reproduces np.random.randint(high, size=(n, 2)).
    high: int | npt.NDArray[np.int64] = int(bounds[0]) if np.all(bounds == bounds[0]) else bounds[:, None, None]
    size = (bounds.size, trials, 2)
    if isinstance(rng, np.random.Generator):
        return rng.integers(0, high, size=size)
    return rng.randint(high, size=size)


def _intra_diversity(motion: FloatArray, start_pairs: npt.NDArray[np.int64], window: int) -> float:
    """Mean over start pairs (a, b) of ||motion[a:a+window] - motion[b:b+window]||_F / window."""
    return float(
        np.mean([_mean_frame_distance(motion[a : a + window], motion[b : b + window]) for a, b in start_pairs])
    )


def intra_diversity_diff(
    reference: npt.ArrayLike,
    samples: Sequence[npt.ArrayLike],
    rng_or_seed: RandomSource = 0,
    window: int = INTRA_WINDOW,
    trials: int = 1,
) -> float:
    """Mean over samples of |intra(sample) - intra(reference)|, intra = ||w_1 - w_2||_F / window.

    As in eval/eval_mixamo.py: sample window starts are ``randint(L - window)``
    and reference starts ``randint(T_ref - 1 - window)`` (their
    ``n_frames // 2 - 1 - tmin`` with ``n_frames = 2 * T_ref``), all sample
    pairs drawn first, then one independent reference pair per sample. The
    authors use one pair per sample (``trials=1``); more trials average the
    intra diversities before the difference. The notes take the absolute
    difference per sample, then the mean (the authors only log both means).
    """
    reference_motion = _as_motion(reference)
    motions = [_as_motion(sample) for sample in samples]
    if not motions:
        raise ValueError("no samples")
    if trials < 1:
        raise ValueError("trials must be >= 1")
    for motion in motions:
        _check_length("sample", motion.shape[0], window + 1)
    _check_length("reference", reference_motion.shape[0], window + 2)
    rng = _random_state(rng_or_seed)
    sample_starts = _random_starts(rng, [motion.shape[0] - window for motion in motions], trials)
    reference_starts = _random_starts(rng, [reference_motion.shape[0] - 1 - window] * len(motions), trials)

    differences = [
        abs(_intra_diversity(motion, starts, window) - _intra_diversity(reference_motion, ref_starts, window))
        for motion, starts, ref_starts in zip(motions, sample_starts, reference_starts)
    ]
    return float(np.mean(differences))


def evaluate(reference: npt.ArrayLike, samples: Sequence[npt.ArrayLike], seed: int = 0) -> dict[str, float]:
    """All five Mixamo metrics; coverage/global/local are means over the samples."""
    reference_motion = _as_motion(reference)
    motions = [_as_motion(sample) for sample in samples]
    if not motions:
        raise ValueError("no samples")
    per_sample = []
    for motion in motions:
        distances = frame_distances(motion, reference_motion)  # shared by the three reference metrics
        per_sample.append(
            (
                _coverage_from_distances(distances, COVERAGE_WINDOW, COVERAGE_THRESHOLD),
                _global_from_distances(distances, MIN_SEGMENT),
                _local_from_distances(distances, LOCAL_WINDOW),
            )
        )
    coverage_mean, global_mean, local_mean = np.mean(per_sample, axis=0)
    return {
        "coverage": float(coverage_mean),
        "global_diversity": float(global_mean),
        "local_diversity": float(local_mean),
        "inter_diversity": inter_diversity(motions),
        "intra_diversity_diff": intra_diversity_diff(reference_motion, motions, seed),
    }


def harmonic_mean(
    rows: Sequence[Mapping[str, float]] | npt.ArrayLike,
    higher_is_better: Sequence[bool],
    maxima: Sequence[float | None],
) -> list[float]:
    """Harmonic mean of normalised scores, one value per row (paper, "Metrics").

    ``rows`` is a list of dicts (columns in the key order of the first row) or
    a 2-D array (rows x metrics). A ``None`` maximum is the 90th percentile of
    that column over the given rows with numpy's default linear interpolation,
    which reproduces the published Gangnam-table values. A normalised score of
    0 makes the harmonic mean 0 (its limit).
    """
    if len(rows) and isinstance(rows[0], Mapping):
        keys = list(rows[0])
        table = np.array([[row[key] for key in keys] for row in rows], dtype=np.float64)
    else:
        table = np.asarray(rows, dtype=np.float64)
    if table.ndim != 2 or table.shape[1] != len(higher_is_better) or table.shape[1] != len(maxima):
        raise ValueError("rows, higher_is_better and maxima disagree on the number of metrics")
    column_max = np.array(
        [np.percentile(table[:, j], 90) if m is None else m for j, m in enumerate(maxima)], dtype=np.float64
    )
    normalised = np.where(higher_is_better, table / column_max, (column_max - table) / column_max)
    with np.errstate(divide="ignore"):
        reciprocal_sum = np.sum(1.0 / normalised, axis=1)
    values = np.where(np.any(normalised == 0, axis=1), 0.0, table.shape[1] / reciprocal_sum)
    return [float(v) for v in values]
