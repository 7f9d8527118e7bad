"""STED's temporal part and its combination against a frame-by-frame, vertex-by-vertex computation of their
definitions (:mod:`loosefit.metrics.sted`) on motions whose frames move by different amounts."""

from __future__ import annotations

import numpy as np
import pytest

from loosefit.metrics.sted import DEFAULT_C, DEFAULT_DT, combine, sted_temporal


def test_temporal_sted_is_the_mean_relative_change_of_the_temporal_edge_lengths():
    rng = np.random.default_rng(0)
    gt = np.cumsum(rng.normal(0, 0.02, (7, 5, 3)) * np.geomspace(0.1, 3, 7)[:, None, None], 0)
    pred = gt + rng.normal(0, 0.01, gt.shape) * np.linspace(0.2, 2, 7)[:, None, None]
    scale = np.linalg.norm(gt[0].max(0) - gt[0].min(0))
    ratios = []
    for t in range(6):
        for v in range(5):
            lt = np.sqrt(DEFAULT_DT**2 + (np.linalg.norm(gt[t + 1, v] - gt[t, v]) / scale) ** 2)
            lp = np.sqrt(DEFAULT_DT**2 + (np.linalg.norm(pred[t + 1, v] - pred[t, v]) / scale) ** 2)
            ratios.append(abs(lp - lt) / lt)  # relative to the simulation's length, not the prediction's
    assert sted_temporal(pred, gt) == pytest.approx(np.mean(ratios), rel=1e-12)
    assert sted_temporal(gt, gt) == 0.0
    # swapping prediction and ground truth changes the denominator: the measure is not symmetric
    assert abs(sted_temporal(gt, pred) - sted_temporal(pred, gt)) > 1e-3 * sted_temporal(pred, gt)


def test_combination():
    assert combine(0.3, 0.4, 1.0) == pytest.approx(0.5, rel=1e-15)
    assert combine(0.03, 0.2, DEFAULT_C) == pytest.approx(np.sqrt(0.03**2 + DEFAULT_C**2 * 0.04), rel=1e-15)
