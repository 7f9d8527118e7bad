"""Diffusion (Laplacian) smoothing and the low/high-frequency split ``G = G_LF + G_HF``.

One smoothing iteration moves every vertex a fraction ``coefficient`` (lambda) of the way to the
mean of its neighbours: ``x <- x + lambda * (mean_{j in N(i)} x_j - x_i)`` (explicit diffusion with
the uniform graph Laplacian; stable for ``0 < lambda <= 1``). Vertices on an open border (hem,
neckline, sleeve) use only their neighbours along the border by default (``boundary="along"``), so
openings are smoothed as curves instead of being pulled into the garment and shrinking it.

Presets, from the papers loosefit reproduces:

- ``"tailornet"``: lambda 0.15, 80 iterations, border vertices along the border (TailorNet's
  training-data pipeline). VirtualBones (Pan et al. 2022, Sec. 4.1) splits low and high frequency
  "similar to TailorNet" without giving its own numbers, so ``"virtualbones"`` is the same setting.
- ``"fitgar"``: lambda 0.12, 40 iterations (FitGar, Li et al. 2023, Sec. 5.1: "0.12 diffusion
  coefficient and 40 iterations"), same operator.

The operator depends on connectivity only, so one sparse matrix smooths every frame of a
``(T, V, 3)`` sequence at once, and ``G_HF = G - G_LF`` is linear in ``G``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from loosefit.errors import InputError
from loosefit.geometry.laplacian import adjacency, boundary_edges, check_mesh

BOUNDARY_MODES = ("along", "free", "fixed")


@dataclass(frozen=True)
class SmoothingPreset:
    """A named smoothing setting: ``coefficient`` (lambda per iteration), ``iterations``, ``source`` (citation)."""

    name: str
    coefficient: float
    iterations: int
    source: str


PRESETS: dict[str, SmoothingPreset] = {
    "tailornet": SmoothingPreset("tailornet", 0.15, 80, "TailorNet (Patel et al. 2020) training-data smoothing"),
    "virtualbones": SmoothingPreset("virtualbones", 0.15, 80, "VirtualBones (Pan et al. 2022) Sec. 4.1, following TailorNet"),
    "fitgar": SmoothingPreset("fitgar", 0.12, 40, "FitGar (Li et al. 2023) Sec. 5.1"),
}


def get_preset(preset: str | SmoothingPreset) -> SmoothingPreset:
    """A :class:`SmoothingPreset` by name (``"tailornet"``, ``"virtualbones"``, ``"fitgar"``) or as given."""
    if isinstance(preset, SmoothingPreset):
        return preset
    if preset not in PRESETS:
        raise InputError(f"unknown smoothing preset {preset!r}, choose one of {sorted(PRESETS)}")
    return PRESETS[preset]


def smoothing_operator(
    faces: np.ndarray, num_verts: int, coefficient: float, boundary: str = "along", fixed: np.ndarray | None = None
) -> sp.csr_matrix:
    """The one-iteration matrix ``S = I + lambda * L_n`` ``(V, V)`` float64 with rows of ``L_n`` summing to zero.

    ``L_n`` row ``i`` is ``mean_{j in N(i)} (x_j - x_i)`` over the mesh neighbours. ``boundary`` chooses
    the neighbours of border vertices: ``"along"`` (border neighbours only), ``"free"`` (all
    neighbours, plain uniform smoothing) or ``"fixed"`` (border vertices do not move). Vertices
    where ``fixed (V,)`` bool is true do not move either (a garment's pinned waist band: smoothing
    along the waist ring would shrink it into the body).
    """
    if not 0.0 < coefficient <= 1.0:
        raise InputError(f"smoothing coefficient must be in (0, 1] for stable diffusion, got {coefficient}")
    if boundary not in BOUNDARY_MODES:
        raise InputError(f"boundary mode must be one of {BOUNDARY_MODES}, got {boundary!r}")
    A = adjacency(faces, num_verts).tolil()
    if boundary != "free":
        b = boundary_edges(faces)
        on_border = np.unique(b)
        if boundary == "fixed":
            for i in on_border:
                A.rows[i], A.data[i] = [], []
        else:
            border = sp.coo_matrix((np.ones(2 * len(b)), (np.r_[b[:, 0], b[:, 1]], np.r_[b[:, 1], b[:, 0]])), shape=A.shape).tolil()
            for i in on_border:
                A.rows[i], A.data[i] = border.rows[i], border.data[i]
    if fixed is not None:
        fixed = np.asarray(fixed, bool)
        if fixed.shape != (num_verts,):
            raise InputError(f"fixed vertices must be a ({num_verts},) mask, got shape {fixed.shape}")
        for i in np.flatnonzero(fixed):
            A.rows[i], A.data[i] = [], []
    A = A.tocsr()
    degree = np.asarray(A.sum(1)).ravel()
    inv = np.divide(1.0, degree, out=np.zeros_like(degree), where=degree > 0)
    # Isolated (or fixed) vertices get an all-zero row: they stay where they are.
    L = sp.diags(inv) @ A - sp.diags((degree > 0).astype(np.float64))
    return (sp.identity(num_verts, format="csr") + coefficient * L).tocsr()


def diffusion_smooth(verts: np.ndarray, faces: np.ndarray, coefficient: float, iterations: int, boundary: str = "along",
                     fixed: np.ndarray | None = None) -> np.ndarray:
    """Apply ``iterations`` explicit diffusion steps to ``verts (V, 3)`` or ``(T, V, 3)``; returns float32, same
    shape. ``fixed (V,)`` bool: vertices that keep their positions."""
    verts, faces = check_mesh(verts, faces)
    if int(iterations) != iterations or iterations < 0:
        raise InputError(f"smoothing iterations must be a non-negative integer, got {iterations}")
    V = verts.shape[-2]
    S = smoothing_operator(faces, V, coefficient, boundary, fixed)
    # Vertices first so that all frames and coordinates are columns of one sparse product.
    x = np.moveaxis(np.asarray(verts, np.float64).reshape((-1, V, 3)), 1, 0).reshape(V, -1)
    for _ in range(int(iterations)):
        x = S @ x
    return np.moveaxis(x.reshape(V, -1, 3), 0, 1).reshape(verts.shape).astype(np.float32)


def frequency_split(
    verts: np.ndarray, faces: np.ndarray, preset: str | SmoothingPreset = "virtualbones", boundary: str = "along",
    fixed: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Split ``verts (V, 3)`` or ``(T, V, 3)`` into ``(low, high)`` float32 with ``low + high = verts``.

    ``low`` is ``verts`` smoothed with the preset's coefficient and iterations (``fixed (V,)`` bool
    vertices unmoved, so ``high`` is zero there), ``high`` the residual.
    """
    p = get_preset(preset)
    low = diffusion_smooth(verts, faces, p.coefficient, p.iterations, boundary, fixed)
    high = (np.asarray(verts, np.float64) - low).astype(np.float32)
    return low, high
