"""Reference runs: the mean of a few perturbed simulations of one sequence and the floor it sets.

Contact-rich cloth is chaotic: the same garment on the same motion, started 10 micrometres apart,
ends centimetres apart. A dataset stores such reference runs beside the base run of a test sequence
(:meth:`loosefit.data.store.DatasetStore.references`); here ``runs (N, T, V, 3)`` metres stacks the
base run first and the ``K = N - 1`` reference runs after it, vertex ``i`` of every run the same vertex.

With ``m = mean_k runs[k]`` (the mean run) and ``|.|`` the Euclidean norm of a vertex:

- floor (m) = ``sqrt(mean_{k,t,i} |runs[k,t,i] - m[t,i]|^2)``: the runs' RMS spread around their mean.
- RMSE against the base (m) = ``sqrt(mean_{t,i} |pred[t,i] - runs[0,t,i]|^2)``, as every benchmark reports.
- RMSE against the mean (m) = ``sqrt(mean_{t,i} |pred[t,i] - m[t,i]|^2)``.
- RMSE against the mean, corrected (m) = ``sqrt(max(0, e^2 - floor^2 / (N - 1)))`` with ``e`` the RMSE against
  the mean: the same with the mean's own spread removed (below).

Why the floor bounds a deterministic predictor: a model sees the motion, never the invisible start
noise, so for each input it outputs one mesh ``p`` while the ground truth is any of the runs. For every
``p`` the mean squared error over the runs splits exactly as
``mean_k |p - runs[k]|^2 = |p - m|^2 + floor^2`` (the cross term sums to zero about the mean), so the mean
run minimises it, and no ``p`` scores below the floor on average over the runs. A network trained on
single runs learns the conditional mean of the simulator, ``mu``, and its RMSE against one run cannot go
much below the floor however long it trains.

The mean of ``N`` runs is not ``mu`` itself: with ``sigma^2`` the variance of one run about ``mu``,
``E|m - mu|^2 = sigma^2 / N``, while the plug-in spread has ``E floor^2 = (N - 1) / N sigma^2``. So the ideal
predictor ``p = mu`` scores ``sqrt(floor^2 / (N - 1))`` on average against the mean, not zero (0.5 floor for the
base and 4 reference runs), and ``E e^2 = |p - mu|^2 + floor^2 / (N - 1)`` for any ``p`` that does not see the
noise. The corrected figure subtracts that term: an unbiased estimate of the squared distance to ``mu``, clipped
at zero; it says how close a model is to the best it can do. For the same reason the spread of the runs around
``mu`` is larger than the floor by ``sqrt(N / (N - 1))`` on average (1.12 for 4 reference runs and the base).
"""

from __future__ import annotations

from dataclasses import dataclass

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


def _mean_square(a: np.ndarray, b: np.ndarray) -> float:
    """Mean over frames and vertices of the squared Euclidean distance of ``a`` and ``b`` ``(T, V, 3)``."""
    d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
    return float(np.mean(np.sum(d * d, axis=-1)))


def floor_m(runs, mean: np.ndarray | None = None) -> float:
    """The floor (metres): the RMS distance of ``runs (N, T, V, 3)`` from their mean run (``mean``,
    computed when None). Zero for a single run."""
    runs = check_runs(runs)
    mean = mean_run(runs) if mean is None else mean
    return float(np.sqrt(np.mean([_mean_square(run, mean) for run in runs])))


def corrected_rmse(rmse_vs_mean, floor, runs: int) -> float:
    """The RMSE against the mean of ``runs`` runs with the mean's own spread removed:
    ``sqrt(max(0, rmse_vs_mean^2 - floor^2 / (runs - 1)))``, in the unit of its arguments (see the module
    docstring); ``runs`` >= 2 (the base and at least one reference run)."""
    if runs < 2:
        raise InputError(f"the correction needs at least 2 runs, got {runs}")
    return float(np.sqrt(max(0.0, rmse_vs_mean**2 - floor**2 / (runs - 1))))


def rmse_m(pred, target) -> float:
    """RMSE (metres) of ``pred`` against ``target`` ``(T, V, 3)``: the root of the mean squared Euclidean
    distance over frames and vertices."""
    pred, target = np.asarray(pred), np.asarray(target)
    if pred.shape != target.shape or pred.ndim != 3 or pred.shape[-1] != 3:
        raise InputError(f"prediction {pred.shape} and target {target.shape} must both have shape (T, V, 3)")
    return float(np.sqrt(_mean_square(pred, target)))


@dataclass(frozen=True)
class ReferenceScore:
    """A prediction scored against a sequence's runs, millimetres: ``rmse_mm`` against the base run,
    ``rmse_vs_mean_mm`` against the mean run, ``floor_mm`` of the runs; ``references``: reference runs
    beside the base (``N - 1``); ``rmse_vs_mean_corrected_mm``: :func:`corrected_rmse`."""

    rmse_mm: float
    rmse_vs_mean_mm: float
    floor_mm: float
    references: int

    @property
    def rmse_vs_mean_corrected_mm(self) -> float:
        return corrected_rmse(self.rmse_vs_mean_mm, self.floor_mm, self.references + 1)

    def as_dict(self) -> dict:
        return {"rmse_mm": self.rmse_mm, "rmse_vs_mean_mm": self.rmse_vs_mean_mm,
                "rmse_vs_mean_corrected_mm": self.rmse_vs_mean_corrected_mm, "floor_mm": self.floor_mm,
                "references": self.references}


class References:
    """The runs of one sequence, base first, with their mean and floor computed once.

    Args:
        base: the base run ``(T, V, 3)`` metres (the stored sequence).
        references: the reference runs ``(K, T, V, 3)`` (K >= 1).
    """

    def __init__(self, base, references):
        base, references = np.asarray(base), np.asarray(references)
        if references.ndim != 4 or references.shape[1:] != base.shape or len(references) == 0:
            raise InputError(f"references must have shape (K >= 1, *{base.shape}) to match the base run, "
                             f"got {references.shape}")
        self.base = base
        runs = check_runs(np.concatenate([base[None], references]))
        self.count = len(references)
        self.mean = mean_run(runs)
        self.floor_m = floor_m(runs, self.mean)

    @property
    def floor_mm(self) -> float:
        return 1000.0 * self.floor_m

    def score(self, pred) -> ReferenceScore:
        """``pred (T, V, 3)`` metres against the base run and the mean run, beside the floor."""
        return ReferenceScore(1000.0 * rmse_m(pred, self.base), 1000.0 * rmse_m(pred, self.mean), self.floor_mm,
                              self.count)


class BandedReferences:
    """The runs of one sequence split into a smooth and a detail band, each with its own mean and floor.

    A model's error can be chaos it cannot predict or a shape it gets wrong; splitting by frequency says in
    which part of the garment it is. With the split of ``loosefit prepare`` (the rig's smoothing,
    :func:`loosefit.geometry.smoothing.frequency_split`) the ``"low"`` band is the smooth garment (VirtualBones'
    bones, paper Sec. 3.2) and ``"high"`` the wrinkles. ``split`` must be linear with ``low + high = x``, so the
    band of an error is the error of the band: ``low(pred) - low(run)``.

    Args:
        base: the base run ``(T, V, 3)`` metres.
        references: the reference runs ``(K, T, V, 3)`` (K >= 1).
        split: ``x (T, V, 3) -> (low, high)``, each ``(T, V, 3)``.
    """

    BANDS = ("all", "low", "high")

    def __init__(self, base, references, split):
        self.split = split
        parts = [split(run) for run in (np.asarray(base), *np.asarray(references))]
        self.bands = {"all": References(base, references)}
        for i, band in enumerate(self.BANDS[1:]):
            self.bands[band] = References(parts[0][i], np.stack([p[i] for p in parts[1:]]))

    def score(self, pred) -> dict[str, ReferenceScore]:
        """``pred (T, V, 3)`` metres scored in every band (:data:`BANDS`) against the base and the mean run."""
        low, high = self.split(np.asarray(pred))
        return {"all": self.bands["all"].score(pred), "low": self.bands["low"].score(low),
                "high": self.bands["high"].score(high)}
