"""Normalisation statistics: streaming mean and standard deviation of network inputs and targets.

Data sets are read a sequence at a time, so statistics are accumulated in one pass with the
pairwise update of Chan, Golub and LeVeque (counts, means and sums of squared deviations are
merged, in float64), which stays exact where ``E[x^2] - E[x]^2`` would cancel catastrophically
(vertex positions far from the origin, say).

A statistic has a *feature shape*: every leading axis of what it is updated with counts as samples.
Joint rotations ``(T, J, 3)`` with feature shape ``(J, 3)`` give one mean per joint and axis;
vertex positions ``(T, V, 3)`` with feature shape ``(3,)`` pool all vertices of all frames.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.io.npz import load_npz, save_npz

#: Standard deviations below this are treated as 1 by :meth:`RunningStats.normalize` (constant features).
MIN_STD = 1e-6


@dataclass
class RunningStats:
    """Count, mean and sum of squared deviations of samples of one feature shape.

    Attributes:
        count: samples seen.
        mean: feature-shaped float64 mean.
        m2: feature-shaped float64 sum of squared deviations from the mean.
    """

    count: int
    mean: np.ndarray
    m2: np.ndarray

    @classmethod
    def empty(cls, shape: tuple[int, ...]) -> "RunningStats":
        """No samples yet, for features of ``shape``."""
        return cls(0, np.zeros(shape), np.zeros(shape))

    @property
    def shape(self) -> tuple[int, ...]:
        return self.mean.shape

    @property
    def std(self) -> np.ndarray:
        """Population standard deviation (float64, feature shaped)."""
        if self.count == 0:
            raise InputError("statistics of no samples: update them with data first")
        return np.sqrt(self.m2 / self.count)

    def update(self, x) -> "RunningStats":
        """Add samples ``x (..., *shape)``; returns ``self``."""
        x = np.asarray(x, np.float64)
        nd = len(self.shape)
        if x.shape[x.ndim - nd:] != self.shape or x.ndim < nd:
            raise InputError(f"statistics of features {self.shape} cannot take an array of shape {x.shape}")
        if not np.isfinite(x).all():
            raise InputError("statistics refuse NaN or infinite values")
        x = x.reshape((-1, *self.shape))
        if len(x) == 0:
            return self
        batch = RunningStats(len(x), x.mean(0), ((x - x.mean(0)) ** 2).sum(0))
        return self.merge(batch)

    def merge(self, other: "RunningStats") -> "RunningStats":
        """Fold ``other`` (statistics of other samples of the same shape) into ``self``; returns ``self``."""
        if other.shape != self.shape:
            raise InputError(f"cannot merge statistics of features {other.shape} into {self.shape}")
        n = self.count + other.count
        if other.count == 0:
            return self
        delta = other.mean - self.mean
        self.mean = self.mean + delta * (other.count / n)
        self.m2 = self.m2 + other.m2 + delta * delta * (self.count * other.count / n)
        self.count = n
        return self

    def scale(self) -> np.ndarray:
        """The divisor used by :meth:`normalize`: the standard deviation, 1 where it is below :data:`MIN_STD`."""
        std = self.std
        return np.where(std < MIN_STD, 1.0, std)

    def normalize(self, x):
        """``(x - mean) / scale`` for ``x (..., *shape)`` (NumPy or torch, same type and dtype back)."""
        return (x - _like(self.mean, x)) / _like(self.scale(), x)

    def denormalize(self, y):
        """The inverse of :meth:`normalize`."""
        return y * _like(self.scale(), y) + _like(self.mean, y)


def _like(values: np.ndarray, x):
    """``values`` as an array of ``x``'s library, dtype and device."""
    if isinstance(x, np.ndarray):
        return values.astype(x.dtype)
    import torch

    if isinstance(x, torch.Tensor):
        return torch.as_tensor(values, dtype=x.dtype, device=x.device)
    return values


class NormalizationStats(dict):
    """Named :class:`RunningStats` (``{"body_rotation": ..., "bone_translation": ...}``), saved together."""

    def add(self, name: str, x, feature_shape: tuple[int, ...]) -> None:
        """Update the statistic ``name`` with ``x (..., *feature_shape)``, creating it when new."""
        if name not in self:
            self[name] = RunningStats.empty(tuple(feature_shape))
        self[name].update(x)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """``<name>.count``, ``<name>.mean``, ``<name>.m2``, ``<name>.std`` per statistic."""
        out = {}
        for name, s in self.items():
            out[f"{name}.count"] = np.int64(s.count)
            out[f"{name}.mean"] = s.mean
            out[f"{name}.m2"] = s.m2
            out[f"{name}.std"] = s.std
        return out

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> "NormalizationStats":
        """The inverse of :meth:`to_arrays` (``std`` is recomputed, not read)."""
        stats = cls()
        names = {key.rsplit(".", 1)[0] for key in arrays}
        for name in sorted(names):
            missing = [f"{name}.{k}" for k in ("count", "mean", "m2") if f"{name}.{k}" not in arrays]
            if missing:
                raise InputError(f"normalisation statistics are missing arrays {missing}")
            stats[name] = RunningStats(int(arrays[f"{name}.count"]), np.asarray(arrays[f"{name}.mean"], np.float64),
                                       np.asarray(arrays[f"{name}.m2"], np.float64))
        return stats

    def save(self, path: str | Path) -> None:
        """Write to an ``.npz`` file, atomically."""
        save_npz(path, self.to_arrays())

    @classmethod
    def load(cls, path: str | Path) -> "NormalizationStats":
        """Read statistics written by :meth:`save`; a bad file raises :class:`InputError` naming it."""
        arrays = load_npz(path, "normalisation statistics")
        try:
            return cls.from_arrays(arrays)
        except ValueError as e:
            raise InputError(f"cannot read normalisation statistics: {e}", Path(path)) from None
