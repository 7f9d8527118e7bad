"""The spread of a sequence's simulated runs around their mean: the floor a dataset reports for its reference runs.

``runs (N, T, V, 3)`` metres stacks the base run (the stored sequence) first and its ``K = N - 1`` reference runs
after it, vertex ``i`` of every run the same vertex. The floor is ``sqrt(mean_{k,t,i} |runs[k,t,i] - m[t,i]|^2)``
with ``m`` the mean run: why it bounds a deterministic model's error, and the scores beside it, are in
:mod:`loosefit.metrics.reference`.
"""

from __future__ import annotations

import numpy as np

from loosefit.errors import InputError


def check_runs(runs) -> np.ndarray:
    """``runs`` as a ``(N, T, V, 3)`` array (any float dtype kept); :class:`InputError` unless N >= 1 and finite."""
    runs = np.asarray(runs)
    if runs.ndim != 4 or runs.shape[-1] != 3 or min(runs.shape[:3]) == 0:
        raise InputError(f"runs must have shape (N, T, V, 3) with N, T, V >= 1, got {runs.shape}")
    if not np.isfinite(runs).all():
        raise InputError("runs contain NaN or infinite positions (a failed run cannot be a reference)")
    return runs


def mean_run(runs) -> np.ndarray:
    """The mean run ``(T, V, 3)`` float64 of ``runs (N, T, V, 3)`` metres."""
    runs = check_runs(runs)
    total = np.zeros(runs.shape[1:], np.float64)
    for run in runs:  # one float64 copy at a time, not N
        total += run
    return total / len(runs)


def mean_square_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Mean over frames and vertices of the squared Euclidean distance of ``a`` and ``b`` ``(T, V, 3)``."""
    d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
    return float(np.mean(np.sum(d * d, axis=-1)))


def floor_m(runs, mean: np.ndarray | None = None) -> float:
    """The floor (metres): the RMS distance of ``runs (N, T, V, 3)`` from their mean run (``mean``,
    computed when None). Zero for a single run."""
    runs = check_runs(runs)
    mean = mean_run(runs) if mean is None else mean
    return float(np.sqrt(np.mean([mean_square_distance(run, mean) for run in runs])))


def stack_runs(base, references) -> np.ndarray:
    """``runs (N, T, V, 3)``: the base run ``(T, V, 3)`` first, then the reference runs ``(K, T, V, 3)`` (K >= 1);
    :class:`InputError` when their shapes differ or a position is not finite."""
    base, references = np.asarray(base), np.asarray(references)
    if references.ndim != 4 or references.shape[1:] != base.shape or len(references) == 0:
        raise InputError(f"references must have shape (K >= 1, *{base.shape}) to match the base run, "
                         f"got {references.shape}")
    return check_runs(np.concatenate([base[None], references]))
