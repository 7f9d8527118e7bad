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

from loosefit.data.run_spread import floor_m, mean_run, mean_square_distance, stack_runs
from loosefit.errors import InputError


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
    return float(np.sqrt(mean_square_distance(pred, target)))


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
        runs = stack_runs(base, references)
        self.base = np.asarray(base)
        self.count = len(runs) - 1
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
