"""Surface metrics from SwinGar (Li et al. 2024, Sec. V): E_dist, E_norm and Laplacian consistency.

- ``E_dist`` (cm): average vertex distance ``100 * mean_{t,i} |pred_ti - gt_ti|`` (the mean vertex
  error of :mod:`loosefit.metrics.errors`, in centimetres as SwinGar reports it).
- ``E_norm`` (degrees): average facet angular deviation, ``mean_{t,f} acos(n'_tf . n_tf)`` between the
  unit face normals of prediction and ground truth. Faces of zero area in either mesh have no
  normal and are left out of the mean.
- Laplacian consistency deviation: for one mesh before (``L^C``) and after (``L``) a correction such as
  collision removal, ``d_cons = |diag(L) - diag(L^C)|`` per vertex, with half-cotangent weights
  (dimensionless), averaged over a chosen vertex set (SwinGar: the vertices the correction moved)
  and over frames.
"""

from __future__ import annotations

import numpy as np

from loosefit.errors import InputError
from loosefit.geometry.laplacian import check_mesh, cotangent_laplacian_diagonal
from loosefit.geometry.normals import cross, face_cross
from loosefit.metrics.errors import check_pair, vertex_errors


def e_dist_cm(pred: np.ndarray, gt: np.ndarray) -> float:
    """SwinGar's E_dist: mean per-vertex Euclidean distance over all frames and vertices, centimetres."""
    return float(100.0 * vertex_errors(pred, gt).mean())


def face_normal_deviation_deg(pred: np.ndarray, gt: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Angle ``(T, F)`` in degrees between predicted and true face normals; NaN where either face is degenerate."""
    pred, gt = check_pair(pred, gt)
    _, faces = check_mesh(gt, faces)
    c_p, c_g = face_cross(pred, faces), face_cross(gt, faces)  # length = twice the area
    ok = (np.linalg.norm(c_p, axis=-1) > 2e-14) & (np.linalg.norm(c_g, axis=-1) > 2e-14)
    # atan2 of |c_p x c_g| and c_p . c_g is the angle between the normals, accurate near 0 and 180
    # degrees (unlike acos) and independent of the two lengths.
    angle = np.degrees(np.arctan2(np.linalg.norm(cross(c_p, c_g), axis=-1), (c_p * c_g).sum(-1)))
    return np.where(ok, angle, np.nan)


def e_norm_deg(pred: np.ndarray, gt: np.ndarray, faces: np.ndarray) -> float:
    """SwinGar's E_norm: mean face-normal angular deviation over all non-degenerate faces and frames, degrees."""
    angle = face_normal_deviation_deg(pred, gt, faces)
    if np.isnan(angle).all():
        raise InputError("E_norm: every face is degenerate")
    return float(np.nanmean(angle))


def laplacian_consistency(before: np.ndarray, after: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Per-vertex deviation ``|diag(L_after) - diag(L_before)|`` ``(T, V)`` (or ``(V,)`` for one frame)."""
    single = np.ndim(before) == 2
    before, after = check_pair(before, after)
    d = np.abs(cotangent_laplacian_diagonal(after, faces) - cotangent_laplacian_diagonal(before, faces))
    return d[0] if single else d


def mean_laplacian_consistency(before: np.ndarray, after: np.ndarray, faces: np.ndarray, vertices=None) -> float:
    """Mean of :func:`laplacian_consistency` over ``vertices`` (indices, or a ``(V,)``/``(T, V)`` boolean
    mask; all vertices when ``None``) and frames."""
    d = np.atleast_2d(laplacian_consistency(before, after, faces))
    if vertices is None:
        return float(d.mean())
    sel = np.asarray(vertices)
    if sel.dtype == bool:
        if sel.shape not in (d.shape, d.shape[1:]):
            raise InputError(f"vertex mask of shape {sel.shape} does not match {d.shape}")
        mask = np.broadcast_to(sel, d.shape)
    else:
        if sel.size and (sel.min() < 0 or sel.max() >= d.shape[1]):
            raise InputError(f"vertex indices outside [0, {d.shape[1]})")
        mask = np.zeros(d.shape, dtype=bool)
        mask[:, sel] = True
    if not mask.any():
        raise InputError("Laplacian consistency: the vertex set is empty")
    return float(d[mask].mean())
