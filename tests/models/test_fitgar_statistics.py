"""FitGar's normalisation statistics and output scales (:func:`loosefit.models.fitgar_data.frame_statistics`)
against a brute-force NumPy computation on small synthetic frames of different vertex counts (no store)."""

from __future__ import annotations

import numpy as np
import pytest

from loosefit.models.fitgar_data import STD_FLOOR, frame_statistics


def items(seed: int = 0) -> list[dict]:
    """Frames of garments with 5 and 8 vertices, 4 joints, 6 body vertices; the coarse displacement (decimetres),
    the detail (millimetres) and the relative features (metres, per axis) spread differently."""
    rng = np.random.default_rng(seed)
    out = []
    for V in (5, 8, 5):
        anchor = rng.normal(0, 0.3, (V, 3))
        smooth = anchor + rng.normal(0, 0.1, (V, 3))
        out.append({"anchor": anchor, "smooth": smooth, "verts": smooth + rng.normal(0, 0.004, (V, 3)),
                    "joints": rng.normal(0, 0.5, (4, 3)), "body_rel": rng.normal(0, [0.1, 0.2, 0.5], (6, 3)),
                    "garment_rel": rng.normal(0.1, [0.3, 0.1, 0.2], (V, 3))})
    return out


def test_frame_statistics_against_brute_force():
    its = items()
    shapes = np.array([[0.1, 2.0], [0.3, -1.0], [0.2, 0.5]])
    alphas = np.array([[0.5, 0.0, 1.0], [-0.5, 0.0, 2.0], [0.0, 0.0, 0.0]])
    stats = frame_statistics(its, shapes, alphas)
    rel = np.concatenate([np.concatenate([it["body_rel"], it["garment_rel"]]) for it in its])
    np.testing.assert_allclose(stats["rel_mean"], rel.mean(0), rtol=1e-6)
    np.testing.assert_allclose(stats["rel_std"], rel.std(0), rtol=1e-6)
    dist = [np.linalg.norm(it["smooth"][v] - it["joints"][j]) for it in its for v in range(len(it["smooth"]))
            for j in range(4)]
    assert float(stats["dist_mean"]) == pytest.approx(np.mean(dist), rel=1e-6)
    assert float(stats["dist_std"]) == pytest.approx(np.std(dist), rel=1e-6)
    np.testing.assert_allclose(stats["shape_mean"], shapes.mean(0), rtol=1e-6)
    np.testing.assert_allclose(stats["shape_std"], shapes.std(0), rtol=1e-6)
    np.testing.assert_allclose(stats["alpha_mean"], alphas.mean(0), rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(stats["alpha_std"], np.maximum(alphas.std(0), STD_FLOOR), rtol=1e-6)
    assert stats["alpha_std"][1] == pytest.approx(STD_FLOOR)  # a factor that never changes: floored

    def rms(a: str, b: str) -> float:
        return float(np.sqrt(np.mean([np.sum((it[a][v] - it[b][v]) ** 2) for it in its for v in range(len(it[a]))])))

    assert float(stats["coarse_scale"]) == pytest.approx(rms("smooth", "anchor"), rel=1e-6)
    assert float(stats["detail_scale"]) == pytest.approx(rms("verts", "smooth"), rel=1e-6)
    assert float(stats["full_scale"]) == pytest.approx(rms("verts", "anchor"), rel=1e-6)
    assert stats["detail_scale"] < 0.2 * stats["coarse_scale"]  # millimetres against decimetres
    assert all(v.dtype == np.float32 for v in stats.values())
