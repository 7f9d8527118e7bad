"""The floor and the RMSE against the mean run (:mod:`loosefit.metrics.reference`) against brute force on runs
whose spreads around their mean differ from run to run and from frame to frame: the floor pools the squared
distances of every run, frame and vertex before the root, never a mean of per-run or per-frame RMS values."""

from __future__ import annotations

import numpy as np
import pytest

from loosefit.metrics.reference import References, corrected_rmse, floor_m, mean_run


def runs(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = rng.normal(0, 0.2, (5, 7, 3))
    spread = np.array([0.001, 0.02, 0.005, 0.04])[:, None, None, None] * np.geomspace(0.2, 2, 5)[None, :, None, None]
    return base + spread * rng.normal(size=(4, 5, 7, 3))


def test_floor_pools_every_run_frame_and_vertex():
    r = runs()
    m = r.mean(0)
    sq = np.sum((r - m) ** 2, -1)  # (N, T, V)
    pooled = np.sqrt(sq.mean())
    assert np.allclose(mean_run(r), m, rtol=0, atol=1e-15)
    assert floor_m(r) == pytest.approx(pooled, rel=1e-12)
    assert abs(np.sqrt(sq.mean((1, 2))).mean() - pooled) > 0.05 * pooled  # per-run RMS averaged differs
    assert abs(np.sqrt(sq.mean((0, 2))).mean() - pooled) > 0.05 * pooled  # per-frame RMS averaged differs


def test_scores_against_base_and_mean_with_the_floor_removed():
    r = runs(1)
    refs = References(r[0], r[1:])
    pred = r.mean(0) + np.random.default_rng(2).normal(0, 0.01, r.shape[1:]) * np.linspace(0.1, 3, 5)[:, None, None]
    score = refs.score(pred)
    m = r.mean(0)
    rmse_base = 1000 * np.sqrt(np.sum((pred - r[0]) ** 2, -1).mean())
    rmse_mean = 1000 * np.sqrt(np.sum((pred - m) ** 2, -1).mean())
    floor = 1000 * np.sqrt(np.sum((r - m) ** 2, -1).mean())
    assert score.rmse_mm == pytest.approx(rmse_base, rel=1e-12)
    assert score.rmse_vs_mean_mm == pytest.approx(rmse_mean, rel=1e-12)
    assert score.floor_mm == pytest.approx(floor, rel=1e-12)
    assert score.references == 3
    assert score.rmse_vs_mean_corrected_mm == pytest.approx(np.sqrt(max(0.0, rmse_mean**2 - floor**2 / 3)), rel=1e-12)
    assert corrected_rmse(1.0, 3.0, 4) == 0.0
