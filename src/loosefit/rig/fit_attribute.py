"""FitGar's fit attribute: factor analysis of garment-to-body distances (Li, Shi, Kanai 2023, Sec. 4.1).

For a garment and a body in the rest pose, each garment vertex's distance to its closest body vertex
says how loosely the garment sits there. Garments have different vertex counts, so each pair's
distances are brought to one common length ``n`` (FitGar: the smallest vertex count among the
training garments) by an even selection of vertices: vertices are taken in a seeded random order
and kept when no kept vertex lies within the radius ``r = sqrt(A / (C n))`` (``A`` the garment's
area), with the integer ``C`` raised from 1 until at least ``n`` are kept; the first ``n`` kept
count. Factor analysis (scikit-learn, SVD solver) of the ``(pairs, n)`` matrix gives ``F`` factors;
the fit attribute of a pair is its factor vector ``alpha (F,)``, the posterior mean of the factors.

Two choices the paper leaves open, made here:

- Order of the ``n`` selected distances. Garments with different meshes have no vertex
  correspondence, so the selected distances are sorted ascending: the vector is then the garment's
  distance distribution over its surface (its quantile function), comparable across any meshes. A
  garment with fewer than ``n`` vertices is resampled to ``n`` quantiles by linear interpolation.
- Sign of each factor: flipped so that its loadings sum to a positive number, so a larger value
  means a looser garment overall.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from loosefit.errors import InputError
from loosefit.geometry.features import nearest_body_vertex
from loosefit.io.npz import load_npz, save_npz

#: Factors kept unless told otherwise (FitGar feeds the first one to its coarse network).
DEFAULT_FACTORS = 4


def body_distances(garment_verts: np.ndarray, body_verts: np.ndarray) -> np.ndarray:
    """``(Vg,)`` float32 distance from each garment vertex to its closest body vertex, metres (rest pose)."""
    g = np.asarray(garment_verts, np.float64)
    b = np.asarray(body_verts, np.float64)
    nearest = nearest_body_vertex(g, b)
    return np.linalg.norm(g - b[nearest], axis=1).astype(np.float32)


def even_selection(verts: np.ndarray, faces: np.ndarray, count: int, seed: int = 0) -> np.ndarray:
    """Indices of up to ``count`` vertices spread evenly over the surface (the radius rejection above).

    Returns ``min(count, V)`` distinct indices, in the order they were kept.
    """
    verts = np.asarray(verts, np.float64)
    faces = np.asarray(faces, np.int64)
    V = len(verts)
    if count >= V:
        return np.arange(V)
    e1 = verts[faces[:, 1]] - verts[faces[:, 0]]
    e2 = verts[faces[:, 2]] - verts[faces[:, 0]]
    area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1).sum()
    order = np.random.default_rng(seed).permutation(V)
    tree = cKDTree(verts)
    C = 1
    while True:
        radius = np.sqrt(area / (C * count))
        kept = _poisson_keep(tree, verts, order, radius)
        if len(kept) >= count:
            return np.asarray(kept[:count], np.int64)
        C += 1


def _poisson_keep(tree: cKDTree, verts: np.ndarray, order: np.ndarray, radius: float) -> list[int]:
    """Vertices in ``order`` that have no previously kept vertex within ``radius``."""
    blocked = np.zeros(len(verts), bool)
    kept = []
    neighbours = tree.query_ball_point(verts[order], radius)
    for i, near in zip(order, neighbours):
        if not blocked[i]:
            kept.append(int(i))
            blocked[near] = True
    return kept


def distance_vector(
    garment_verts: np.ndarray, faces: np.ndarray, body_verts: np.ndarray, length: int, seed: int = 0
) -> np.ndarray:
    """The fixed-length distance vector ``d* (length,)`` float64 of one garment-body pair, sorted ascending."""
    if length < 2:
        raise InputError(f"distance vector length must be at least 2, got {length}")
    d = body_distances(garment_verts, body_verts).astype(np.float64)
    picked = np.sort(d[even_selection(garment_verts, faces, length, seed)])
    if len(picked) == length:
        return picked
    # Fewer vertices than the length: the same distribution read at ``length`` evenly spaced quantiles.
    return np.interp(np.linspace(0.0, 1.0, length), np.linspace(0.0, 1.0, len(picked)), picked)


@dataclass
class FitAttributeModel:
    """A fitted factor analysis of distance vectors: ``d* - mean ~ components.T @ alpha + noise``.

    Attributes:
        mean: ``(n,)`` float64 mean distance vector, metres.
        components: ``(F, n)`` float64 factor loadings.
        noise_variance: ``(n,)`` float64 per-element noise variance.
        seed: seed of the even vertex selection (part of the model: keep it for new pairs).
        info: how it was fitted (pairs, log-likelihood...), JSON values.
    """

    mean: np.ndarray
    components: np.ndarray
    noise_variance: np.ndarray
    seed: int = 0
    info: dict = field(default_factory=dict)

    @property
    def length(self) -> int:
        return len(self.mean)

    @property
    def num_factors(self) -> int:
        return len(self.components)

    @classmethod
    def fit(cls, vectors: np.ndarray, factors: int = DEFAULT_FACTORS, seed: int = 0) -> "FitAttributeModel":
        """Factor analysis (scikit-learn, LAPACK SVD) of ``vectors (pairs, n)`` from :func:`distance_vector`.

        ``factors`` is capped at the number of pairs minus one (at least 1).
        """
        from sklearn.decomposition import FactorAnalysis

        X = np.asarray(vectors, np.float64)
        if X.ndim != 2 or len(X) < 2 or not np.isfinite(X).all():
            raise InputError(f"the fit attribute needs finite distance vectors of 2 pairs or more, got shape {X.shape}")
        F = max(1, min(int(factors), len(X) - 1, X.shape[1]))
        fa = FactorAnalysis(n_components=F, svd_method="lapack", random_state=seed).fit(X)  # FitGar Eq. 3
        W = fa.components_.copy()
        W *= np.where(W.sum(1, keepdims=True) < 0, -1.0, 1.0)
        info = {"pairs": int(len(X)), "factors_requested": int(factors), "log_likelihood": float(fa.loglike_[-1]),
                "iterations": int(fa.n_iter_)}
        return cls(fa.mean_.copy(), W, fa.noise_variance_.copy(), seed, info)

    def transform(self, vectors: np.ndarray) -> np.ndarray:
        """Fit attributes ``(P, F)`` float32 of distance vectors ``(P, n)``: the factors' posterior mean
        ``(I + W Psi^-1 W^T)^-1 W Psi^-1 (d* - mean)``."""
        X = np.atleast_2d(np.asarray(vectors, np.float64))
        if X.shape[1] != self.length:
            raise InputError(f"distance vectors must have length {self.length}, got {X.shape[1]}")
        Wpsi = self.components / self.noise_variance
        cov = np.linalg.inv(np.eye(self.num_factors) + Wpsi @ self.components.T)
        return ((X - self.mean) @ Wpsi.T @ cov).astype(np.float32)

    def attribute(self, garment_verts: np.ndarray, faces: np.ndarray, body_verts: np.ndarray) -> np.ndarray:
        """The fit attribute ``alpha (F,)`` float32 of a new garment-body pair in the rest pose."""
        d = distance_vector(garment_verts, faces, body_verts, self.length, self.seed)
        return self.transform(d[None])[0]

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The model as named arrays (seed and info as JSON text), for files and stores."""
        return {
            "mean": self.mean,
            "components": self.components,
            "noise_variance": self.noise_variance,
            "meta": np.array(json.dumps({"seed": self.seed, "info": self.info})),
        }

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> "FitAttributeModel":
        """The inverse of :meth:`to_arrays`."""
        missing = sorted({"mean", "components", "noise_variance", "meta"} - set(arrays))
        if missing:
            raise InputError(f"fit attribute model is missing arrays {missing}")
        meta = json.loads(str(arrays["meta"]))
        model = cls(np.asarray(arrays["mean"], np.float64), np.asarray(arrays["components"], np.float64),
                    np.asarray(arrays["noise_variance"], np.float64), int(meta["seed"]), meta["info"])
        W = model.components
        if W.ndim != 2 or W.shape[1] != model.length or model.noise_variance.shape != model.mean.shape:
            raise InputError(f"fit attribute model arrays disagree: mean {model.mean.shape}, components "
                             f"{model.components.shape}, noise variance {model.noise_variance.shape}")
        return model

    def save(self, path: str | Path) -> None:
        """Write the model to an ``.npz`` file, atomically."""
        save_npz(path, self.to_arrays())

    @classmethod
    def load(cls, path: str | Path) -> "FitAttributeModel":
        """Read a model written by :meth:`save`; a bad file raises :class:`InputError` naming it."""
        arrays = load_npz(path, "a fit attribute model")
        try:
            return cls.from_arrays(arrays)
        except (ValueError, KeyError) as e:
            raise InputError(f"cannot read a fit attribute model: {e}", Path(path)) from None
