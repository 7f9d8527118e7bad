"""Vertex position errors between a predicted and a ground-truth mesh sequence with the same vertices.

All functions take ``pred`` and ``gt`` of shape ``(T, V, 3)`` (or ``(V, 3)`` for one frame), metres,
with vertex ``i`` of ``pred`` corresponding to vertex ``i`` of ``gt``. With ``e_ti = ||pred_ti - gt_ti||``:

- RMSE (mm) = ``1000 * sqrt(mean_{t,i} e_ti^2)``: the root of the mean *squared Euclidean* per-vertex
  error, pooled over every vertex of every frame.
- mean vertex error (mm) = ``1000 * mean_{t,i} e_ti``: what several papers (e.g. SwinGar's E_dist, in
  cm) call "RMSE" or "average vertex distance". ``RMSE >= mean vertex error``, equal only when all
  errors are the same.
- Hausdorff (mm): per frame, the symmetric Hausdorff distance between the two vertex sets
  ``max(max_i min_j |p_i - g_j|, max_j min_i |g_j - p_i|)`` (correspondence ignored), then the mean over
  frames.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from loosefit.errors import InputError


def check_pair(pred: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(T, V, 3)`` float64 copies of ``pred`` and ``gt``; :class:`InputError` unless shapes match and values are finite."""
    pred = np.asarray(pred, dtype=np.float64)
    gt = np.asarray(gt, dtype=np.float64)
    if pred.ndim == 2 and gt.ndim == 2:
        pred, gt = pred[None], gt[None]
    if pred.shape != gt.shape or pred.ndim != 3 or pred.shape[2] != 3 or pred.shape[1] == 0:
        raise InputError(f"prediction {pred.shape} and ground truth {gt.shape} must both have shape (T, V, 3)")
    if not (np.isfinite(pred).all() and np.isfinite(gt).all()):
        raise InputError("prediction or ground truth contains NaN or infinite positions")
    return pred, gt


def vertex_errors(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Euclidean per-vertex errors ``(T, V)`` float64, metres."""
    pred, gt = check_pair(pred, gt)
    return np.linalg.norm(pred - gt, axis=-1)


def rmse_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    """Root of the mean squared per-vertex Euclidean error over all frames and vertices, millimetres."""
    e = vertex_errors(pred, gt)
    return float(1000.0 * np.sqrt(np.mean(e * e)))


def mean_vertex_error_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    """Mean per-vertex Euclidean error over all frames and vertices, millimetres."""
    return float(1000.0 * vertex_errors(pred, gt).mean())


def hausdorff_per_frame(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Symmetric Hausdorff distance ``(T,)`` float64 in metres between the vertex sets of each frame."""
    pred, gt = check_pair(pred, gt)
    out = np.empty(len(pred))
    for t in range(len(pred)):
        d_pg = cKDTree(gt[t]).query(pred[t])[0].max()
        d_gp = cKDTree(pred[t]).query(gt[t])[0].max()
        out[t] = max(d_pg, d_gp)
    return out


def hausdorff_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    """Mean over frames of the per-frame symmetric vertex-set Hausdorff distance, millimetres."""
    return float(1000.0 * hausdorff_per_frame(pred, gt).mean())


def error_parts_mm(pred: np.ndarray, gt: np.ndarray) -> dict[str, float]:
    """A sequence's RMSE split into its two orthogonal parts, millimetres, for ``pred`` and ``gt`` ``(T, V, 3)``
    given in the garment's own moving frame (:func:`loosefit.motion.heading.to_canonical`; in the world the mean
    over a walk would mix places). With the residual ``r_ti = pred_ti - gt_ti`` and its mean over the frames
    ``b_i``:

    - ``mean_shape``: ``sqrt(mean_i |b_i|^2)``, how far the sequence's average garment is from the simulation's
      (a constant error: the wrong drape for the motion as a whole);
    - ``motion``: ``sqrt(mean_{t,i} |r_ti - b_i|^2)``, the error of the movement about that average (the swing);
    - ``total``: the RMSE, with ``total^2 = mean_shape^2 + motion^2`` exactly (the frames' deviations from a mean
      sum to zero);
    - ``simulated_motion``: ``sqrt(mean_{t,i} |g_ti - mean_t g_ti|^2)``, how much the simulation moves about its
      own average: what a prediction that does not move at all would leave as ``motion``.
    """
    pred, gt = check_pair(pred, gt)
    r = pred - gt
    b = r.mean(0)
    g = gt - gt.mean(0)
    mm = lambda sq: float(1000.0 * np.sqrt(sq))  # noqa: E731
    return {"total": mm((r * r).sum(-1).mean()), "mean_shape": mm((b * b).sum(-1).mean()),
            "motion": mm(((r - b) ** 2).sum(-1).mean()), "simulated_motion": mm((g * g).sum(-1).mean())}
