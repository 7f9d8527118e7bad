"""STED, the spatio-temporal edge difference of Vasa and Skala (2011), between two mesh sequences.

Vasa, L. and Skala, V., "A perception correlated comparison method for dynamic meshes", IEEE TVCG
17(2), 2011. ``gt`` is the reference ("original") sequence, ``pred`` the distorted one; both
``(T, V, 3)`` on the same triangles. STED is dimensionless and invariant to rigid motion of the whole
sequence; its spatial part is also invariant to uniform scaling.

Spatial part. For every mesh edge ``e`` in frame ``t`` with reference length ``l_e`` and predicted
length ``l'_e``, the relative edge difference is ``ed_e = |l'_e - l_e| / l_e``. For every vertex ``v``
take the topological neighbourhood ``N(v)``: the edges whose two endpoints are both at most ``rings``
edges away from ``v``. The local deviation is the ``l_e``-weighted standard deviation of ``ed`` in
``N(v)``::

    avg(v) = sum_{e in N(v)} l_e ed_e / sum l_e
    dev(v) = sqrt( sum_{e in N(v)} l_e (ed_e - avg(v))^2 / sum l_e )

``STED_s`` is the mean of ``dev`` over all vertices and frames. A uniform local stretch costs
nothing; uneven stretching (wrinkles in the wrong place, jagged surfaces) does.

Temporal part. Positions are divided by the bounding-box diagonal of the reference's first frame.
Each vertex's move between consecutive frames is a temporal edge of length
``lt = sqrt(dt^2 + |x(t+1) - x(t)|^2)``, where ``dt`` is a fictional distance between frames that
keeps the length non-zero for still vertices. With ``ted = |lt' - lt| / lt``, ``STED_t`` is the mean
of ``ted`` over all vertices and the ``T - 1`` frame pairs: wrong speeds and jitter cost.

Combination: ``STED = sqrt(STED_s^2 + c^2 STED_t^2)``.

Parameters used by default, and why: ``rings = 1`` (the 1-ring patch around each vertex),
``dt = 0.3`` (in units of the reference's bounding-box diagonal) and ``c = 0.5``. VirtualBones
(Pan et al. 2022), whose evaluation loosefit reproduces, reports STED without stating its
parameters, so loosefit falls back on the setting recalled from the original paper's parameter
study; the original text was not available to check it against. Absolute values may therefore
differ from published tables; comparisons between methods within loosefit all use one setting,
and every value can be overridden. Note that with ``dt = 0.3`` the temporal part is small for
per-frame moves much shorter than ``dt`` (1 cm of random jitter on a sphere of 0.5 m radius gives
``STED_t`` ~ 1e-3 against ``STED_s`` ~ 0.1), so the spatial part dominates the combination.

Aggregation: one sequence gives one ``STED_s`` (mean over its frames and vertices) and one ``STED_t``
(mean over its frame pairs and vertices); :func:`sted` combines those two means.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from loosefit.errors import InputError
from loosefit.geometry.laplacian import adjacency, check_mesh, edges
from loosefit.metrics.errors import check_pair

DEFAULT_RINGS = 1
DEFAULT_DT = 0.3
DEFAULT_C = 0.5


@dataclass(frozen=True)
class StedResult:
    """``spatial`` (STED_s), ``temporal`` (STED_t) and ``combined`` = sqrt(s^2 + c^2 t^2), all dimensionless."""

    spatial: float
    temporal: float
    combined: float


def edge_neighbourhoods(faces: np.ndarray, num_verts: int, rings: int = DEFAULT_RINGS) -> tuple[np.ndarray, sp.csr_matrix]:
    """Edges ``(E, 2)`` and the 0/1 membership matrix ``(V, E)``: edge ``e`` is in ``N(v)`` when both its
    endpoints lie within ``rings`` edges of ``v``."""
    if int(rings) != rings or rings < 1:
        raise InputError(f"STED neighbourhood rings must be an integer >= 1, got {rings}")
    e = edges(faces)
    step = (adjacency(faces, num_verts) + sp.identity(num_verts, format="csr")).astype(bool)
    reach = sp.identity(num_verts, format="csr", dtype=bool)
    for _ in range(int(rings)):
        reach = (reach @ step).astype(bool)
    E = len(e)
    incidence = sp.csr_matrix((np.ones(2 * E), (np.r_[e[:, 0], e[:, 1]], np.r_[np.arange(E), np.arange(E)])), shape=(num_verts, E))
    endpoints_inside = reach.astype(np.float64) @ incidence  # (V, E): 0, 1 or 2 endpoints within reach
    member = (endpoints_inside >= 2).astype(np.float64)
    member.eliminate_zeros()
    return e, member.tocsr()


def sted_spatial_per_frame(pred: np.ndarray, gt: np.ndarray, faces: np.ndarray, rings: int = DEFAULT_RINGS) -> np.ndarray:
    """``(T,)`` spatial STED of each frame: the mean over vertices of the local deviation ``dev(v)``."""
    pred, gt = check_pair(pred, gt)
    _, faces = check_mesh(gt, faces)
    e, member = edge_neighbourhoods(faces, gt.shape[1], rings)
    length = np.linalg.norm(gt[:, e[:, 0]] - gt[:, e[:, 1]], axis=-1)  # (T, E)
    length_p = np.linalg.norm(pred[:, e[:, 0]] - pred[:, e[:, 1]], axis=-1)
    # Zero-length reference edges carry zero weight, so their undefined ratio never counts.
    ed = np.divide(np.abs(length_p - length), length, out=np.zeros_like(length), where=length > 0)
    # The variance as E[x^2] - E[x]^2 of x = ed minus the frame's mean: the same variance, without the
    # cancellation of two near-equal squares (a uniform stretch of 20 % left ~1e-9 of rounding in dev).
    shift = (length * ed).sum(1, keepdims=True) / np.maximum(length.sum(1, keepdims=True), np.finfo(float).tiny)
    ed = ed - shift
    w_sum = member @ length.T  # (V, T)
    w_ed = member @ (length * ed).T
    w_ed2 = member @ (length * ed * ed).T
    valid = w_sum > 0
    avg = np.divide(w_ed, w_sum, out=np.zeros_like(w_ed), where=valid)
    var = np.divide(w_ed2, w_sum, out=np.zeros_like(w_ed), where=valid) - avg * avg
    dev = np.sqrt(np.clip(var, 0.0, None))
    counted = valid.sum(0)
    if (counted == 0).any():
        raise InputError("STED needs a mesh with at least one non-degenerate edge in every frame")
    return (dev * valid).sum(0) / counted


def sted_temporal(pred: np.ndarray, gt: np.ndarray, dt: float = DEFAULT_DT) -> float:
    """Temporal STED: mean relative difference of the temporal edge lengths (see the module docstring)."""
    pred, gt = check_pair(pred, gt)
    if len(gt) < 2:
        raise InputError(f"the temporal part of STED needs at least 2 frames, got {len(gt)}")
    if not dt > 0:
        raise InputError(f"STED dt must be positive, got {dt}")
    lo, hi = gt[0].min(0), gt[0].max(0)
    scale = float(np.linalg.norm(hi - lo))
    if scale <= 0:
        raise InputError("STED needs a reference mesh with a non-zero bounding box")
    step = np.linalg.norm(np.diff(gt, axis=0), axis=-1) / scale  # (T-1, V)
    step_p = np.linalg.norm(np.diff(pred, axis=0), axis=-1) / scale
    lt = np.sqrt(dt * dt + step * step)
    lt_p = np.sqrt(dt * dt + step_p * step_p)
    return float(np.mean(np.abs(lt_p - lt) / lt))


def sted(
    pred: np.ndarray,
    gt: np.ndarray,
    faces: np.ndarray,
    rings: int = DEFAULT_RINGS,
    dt: float = DEFAULT_DT,
    c: float = DEFAULT_C,
) -> StedResult:
    """STED of ``pred (T, V, 3)`` against the reference ``gt (T, V, 3)`` on ``faces (F, 3)``; needs ``T >= 2``."""
    spatial = float(sted_spatial_per_frame(pred, gt, faces, rings).mean())
    temporal = sted_temporal(pred, gt, dt)
    return StedResult(spatial, temporal, combine(spatial, temporal, c))


def combine(spatial: float, temporal: float, c: float = DEFAULT_C) -> float:
    """``sqrt(STED_s^2 + c^2 STED_t^2)``."""
    return float(np.sqrt(spatial * spatial + c * c * temporal * temporal))
