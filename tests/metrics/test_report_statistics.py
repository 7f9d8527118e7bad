"""The evaluation report's numbers against their definitions, computed by brute force on sequences whose
frames differ (each frame's error scaled apart) and whose lengths and vertex counts differ: per sequence,
RMSE pools every vertex of every frame and the Hausdorff distance is a per-frame mean; overall, every figure
pools frames x vertices (or frames), so it is neither a mean of the sequences' figures nor a per-frame average."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from loosefit.metrics.report import SequencePair, evaluate_sequence, overall_row


def grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    """A flat ``n x n`` grid of vertices 5 cm apart and its triangles."""
    x, y = np.meshgrid(np.arange(n) * 0.05, np.arange(n) * 0.05)
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], 1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + n], 1), np.stack([a + 1, a + n + 1, a + n], 1)])
    return verts, faces


def pair(name: str, n: int, T: int, seed: int) -> SequencePair:
    rng = np.random.default_rng(seed)
    verts, faces = grid(n)
    gt = verts + np.cumsum(rng.normal(0, 0.01, (T, len(verts), 3)), 0)
    scale = np.geomspace(0.002, 0.03, T)[:, None, None] * (1 + seed)  # frames far apart in error
    pred = gt + scale * rng.normal(size=gt.shape)
    return SequencePair(name, pred, gt, faces)


PAIRS = [pair("a", 4, 6, 0), pair("b", 6, 3, 1), pair("c", 3, 9, 2)]


def errors(p: SequencePair) -> np.ndarray:
    return np.linalg.norm(p.pred - p.gt, axis=-1)  # (T, V)


def test_per_sequence_rows_against_their_definitions():
    for p in PAIRS:
        row = evaluate_sequence(p)
        e = errors(p)
        pooled = 1000 * np.sqrt((e**2).mean())
        assert abs(pooled - 1000 * np.sqrt((e**2).mean(1)).mean()) > 0.05 * pooled  # per-frame RMS differs
        assert row["rmse_mm"] == pytest.approx(pooled, rel=1e-9)
        assert row["mean_vertex_error_mm"] == pytest.approx(1000 * e.mean(), rel=1e-9)
        assert row["e_dist_cm"] == pytest.approx(100 * e.mean(), rel=1e-9)
        hausdorff = []
        for t in range(len(p.gt)):
            d = cdist(p.pred[t], p.gt[t])
            hausdorff.append(max(d.min(1).max(), d.min(0).max()))
        assert row["hausdorff_mm"] == pytest.approx(1000 * np.mean(hausdorff), rel=1e-9)
        assert row["hausdorff_mm"] < 1000 * max(hausdorff) * 0.95  # a per-frame mean, not the worst frame
        assert (row["frames"], row["vertices"]) == p.gt.shape[:2]


def test_overall_row_pools_every_frame_and_vertex_of_every_sequence():
    rows = [evaluate_sequence(p) for p in PAIRS]
    overall = overall_row(rows)
    every = np.concatenate([errors(p).ravel() for p in PAIRS])
    assert overall["rmse_mm"] == pytest.approx(1000 * np.sqrt((every**2).mean()), rel=1e-9)
    assert overall["mean_vertex_error_mm"] == pytest.approx(1000 * every.mean(), rel=1e-9)
    assert overall["e_dist_cm"] == pytest.approx(100 * every.mean(), rel=1e-9)
    # neither a mean of the sequences' RMSE nor one weighted by frames alone
    by_frames = np.sqrt(sum(r["rmse_mm"] ** 2 * r["frames"] for r in rows) / sum(r["frames"] for r in rows))
    assert abs(overall["rmse_mm"] - by_frames) > 0.02 * overall["rmse_mm"]
    assert abs(overall["rmse_mm"] - np.mean([r["rmse_mm"] for r in rows])) > 0.02 * overall["rmse_mm"]
    hausdorff = [r["hausdorff_mm"] * r["frames"] for r in rows]
    assert overall["hausdorff_mm"] == pytest.approx(sum(hausdorff) / sum(r["frames"] for r in rows), rel=1e-9)
    assert overall["frames"] == sum(len(p.gt) for p in PAIRS)


def test_overall_collision_and_surface_shares_weigh_frames_by_their_counts():
    """Shares pool the counted items: collision by frames x vertices, surface by frames x samples, collapsed by
    frames x faces, the deepest point is the deepest of all (rows as :func:`evaluate_sequence` makes them)."""
    rows = [evaluate_sequence(p) for p in PAIRS]
    for r, pct, surface, deepest in zip(rows, (10.0, 40.0, 0.0), (1.0, 5.0, 2.0), (3.0, 11.0, 7.0)):
        r.update(collision_pct=pct, surface_inside_pct=surface, surface_samples=3 * r["faces"], deepest_mm=deepest)
    overall = overall_row(rows)
    colliding = sum(r["collision_pct"] / 100 * r["frames"] * r["vertices"] for r in rows)
    assert overall["collision_pct"] == pytest.approx(100 * colliding / sum(r["frames"] * r["vertices"] for r in rows))
    inside = sum(r["surface_inside_pct"] / 100 * r["frames"] * r["surface_samples"] for r in rows)
    assert overall["surface_inside_pct"] == pytest.approx(
        100 * inside / sum(r["frames"] * r["surface_samples"] for r in rows))
    assert overall["deepest_mm"] == 11.0
    collapsed = sum(r["collapsed_pct"] * r["frames"] * r["faces"] for r in rows)
    assert overall["collapsed_pct"] == pytest.approx(collapsed / sum(r["frames"] * r["faces"] for r in rows))
