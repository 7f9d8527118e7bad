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

Two bounded measures of surface quality beside them (prediction against the simulation, frame by frame; the
papers' E_norm and Laplacian consistency are unbounded and a few crumpled triangles hide in their means):

- collapsed share (%): of the ``(frame, triangle)`` pairs, those whose predicted area is below
  :data:`COLLAPSE_AREA` (20 %) of the same triangle's area in the simulated frame, or whose predicted normal points
  against the simulated one (``n'_tf . n_tf < 0``: flipped). A triangle of zero area in the prediction counts (it
  has collapsed); one of zero area in both does not (nothing collapsed). Between 0 and 100.
- roughness (degrees): ``mean_{t,e} |theta'_te - theta_te|`` over the interior edges ``e`` (shared by exactly
  two triangles) and frames, ``theta`` the signed angle between the edge's two face normals (0 flat, positive
  folding one way, negative the other, so a crease folded the wrong way counts twice its angle), the difference
  wrapped into [0, 180]. Between 0 and 180.
- bend ratio: how folded the prediction is, as a multiple of the simulation, ``sum_{t,e} |theta'_te| /
  sum_{t,e} |theta_te|`` (the mean unsigned dihedral angle of the prediction over the simulation's). 1 is as folded
  as the simulation; a smooth, averaged prediction scores below it, a crumpled or lumpy one above it. Unlike the
  roughness it does not ask the folds to be where the simulation's are (no deterministic model can place chaotic
  wrinkles), only that the surface is not more crumpled than cloth.
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


#: A predicted triangle smaller than this fraction of its simulated area has collapsed.
COLLAPSE_AREA = 0.2


def collapsed_faces(pred: np.ndarray, gt: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(T, F)`` bool: the predicted triangle is smaller than :data:`COLLAPSE_AREA` of the simulated one in the
    same frame, or its normal points against the simulated normal.

    Args:
        pred, gt: ``(T, V, 3)`` (or ``(V, 3)``) predicted and simulated vertices, metres.
        faces: ``(F, 3)`` triangles of both.
    """
    pred, gt = check_pair(pred, gt)
    _, faces = check_mesh(gt, faces)
    c_p, c_g = face_cross(pred, faces), face_cross(gt, faces)  # length = twice the area
    # Products, not quotients and unit normals: a zero-area triangle compares without a NaN.
    small = np.linalg.norm(c_p, axis=-1) < COLLAPSE_AREA * np.linalg.norm(c_g, axis=-1)
    return small | ((c_p * c_g).sum(-1) < 0)


def collapsed_pct(pred: np.ndarray, gt: np.ndarray, faces: np.ndarray) -> float:
    """Percentage of ``(frame, triangle)`` pairs of ``pred`` that collapsed or flipped (:func:`collapsed_faces`),
    between 0 and 100."""
    return float(100.0 * collapsed_faces(pred, gt, faces).mean())


def interior_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The edges shared by exactly two triangles: ``edge (Ei, 2)`` int64 vertex pairs ``(i, j)``, ``i < j``, and
    ``pair (Ei, 2)`` int64 the two triangles of each (the first in face order first). Border edges have one
    triangle and non-manifold ones more than two: neither has one dihedral angle."""
    faces = np.asarray(faces, np.int64)
    corner = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(len(faces)), 3)
    unique, inverse, counts = np.unique(corner, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(inverse, kind="stable")
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])  # where each edge's corners begin in ``order``
    two = np.flatnonzero(counts == 2)
    pair = np.sort(np.stack([owner[order[start[two]]], owner[order[start[two] + 1]]], 1), axis=1)
    return unique[two], pair


def dihedral_angles_deg(verts: np.ndarray, faces: np.ndarray, edge: np.ndarray, pair: np.ndarray) -> np.ndarray:
    """Signed angle ``(..., Ei)`` in degrees, in [-180, 180], between the normals of the two triangles ``pair``
    of each edge ``edge`` (:func:`interior_edges`), measured about the edge's direction ``verts[j] - verts[i]``:
    0 where the two are coplanar, the sign telling which way the surface folds. A degenerate triangle or edge gives
    0 or 180, never NaN.

    Args:
        verts: ``(..., V, 3)`` vertex positions, metres.
        faces: ``(F, 3)`` triangles.
    """
    verts = np.asarray(verts, np.float64)
    c = face_cross(verts, np.asarray(faces, np.int64))
    c1, c2 = c[..., pair[:, 0], :], c[..., pair[:, 1], :]
    direction = verts[..., edge[:, 1], :] - verts[..., edge[:, 0], :]
    direction = direction / np.maximum(np.linalg.norm(direction, axis=-1, keepdims=True), 1e-300)
    # Both normals are perpendicular to the shared edge, so c1 x c2 lies along it: its component there is
    # |c1 x c2| with the fold's sign.
    return np.degrees(np.arctan2((cross(c1, c2) * direction).sum(-1), (c1 * c2).sum(-1)))


def dihedral_pair_deg(pred: np.ndarray, gt: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The signed dihedral angles ``(T, Ei)`` degrees of ``pred`` and of ``gt`` (:func:`dihedral_angles_deg`) at
    every interior edge (:func:`interior_edges`, in its order) and frame."""
    pred, gt = check_pair(pred, gt)
    _, faces = check_mesh(gt, faces)
    edge, pair = interior_edges(faces)
    return dihedral_angles_deg(pred, faces, edge, pair), dihedral_angles_deg(gt, faces, edge, pair)


def roughness_from_dihedrals(theta_pred: np.ndarray, theta_gt: np.ndarray) -> np.ndarray:
    """``|theta_pred - theta_gt|`` wrapped into [0, 180] degrees (a fold of 170 against one of -170 is 20 apart)."""
    d = np.abs(theta_pred - theta_gt)
    return np.minimum(d, 360.0 - d)


def roughness_per_edge_deg(pred: np.ndarray, gt: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(T, Ei)`` degrees in [0, 180]: ``|theta_pred - theta_gt|`` of every interior edge (:func:`interior_edges`,
    in its order) and frame, ``theta`` the signed dihedral angle (:func:`dihedral_angles_deg`), the difference
    wrapped (a fold of 170 degrees against one of -170 is 20 degrees apart)."""
    return roughness_from_dihedrals(*dihedral_pair_deg(pred, gt, faces))


def bend_ratio(pred: np.ndarray, gt: np.ndarray, faces: np.ndarray) -> float | None:
    """How folded ``pred`` is as a multiple of ``gt``: ``sum |theta_pred| / sum |theta_gt|`` over interior edges and
    frames (module doc); None where the simulation is flat everywhere (no fold to compare with)."""
    theta_pred, theta_gt = dihedral_pair_deg(pred, gt, faces)
    sim = float(np.abs(theta_gt).sum())
    return float(np.abs(theta_pred).sum()) / sim if sim > 0 else None


def roughness_deg(pred: np.ndarray, gt: np.ndarray, faces: np.ndarray) -> float:
    """Mean of :func:`roughness_per_edge_deg` over interior edges and frames, degrees in [0, 180].

    Raises:
        InputError: the mesh has no interior edge (a single triangle, a soup).
    """
    d = roughness_per_edge_deg(pred, gt, faces)
    if d.shape[1] == 0:
        raise InputError("roughness: the mesh has no edge shared by two triangles")
    return float(d.mean())
