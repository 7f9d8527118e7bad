"""RMSE, mean vertex error and Hausdorff distance against hand-built cases and brute force."""

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from loosefit.errors import InputError
from loosefit.metrics.errors import (error_parts_mm, hausdorff_mm, hausdorff_per_frame, mean_vertex_error_mm, rmse_mm,
                                     vertex_errors)


def test_rmse_is_the_root_of_the_mean_square_not_the_mean():
    gt = np.zeros((2, 2, 3))
    pred = gt.copy()
    pred[:, 0] = [0.003, 0.0, 0.0]  # 3 mm
    pred[:, 1] = [0.0, 0.0, 0.004]  # 4 mm
    assert rmse_mm(pred, gt) == pytest.approx(np.sqrt((9 + 16) / 2))
    assert mean_vertex_error_mm(pred, gt) == pytest.approx(3.5)
    same = gt + [0.003, 0.004, 0.0]  # every vertex off by 5 mm: both agree
    assert rmse_mm(same, gt) == pytest.approx(5.0) and mean_vertex_error_mm(same, gt) == pytest.approx(5.0)
    assert vertex_errors(pred[0], gt[0]).shape == (1, 2)  # a single (V, 3) frame


def test_hausdorff_against_brute_force_and_by_hand():
    rng = np.random.default_rng(0)
    gt = rng.normal(size=(4, 100, 3))
    pred = gt + rng.normal(0, 0.05, gt.shape)
    ref = []
    for t in range(4):
        d = cdist(pred[t], gt[t])
        ref.append(max(d.min(1).max(), d.min(0).max()))
    assert np.allclose(hausdorff_per_frame(pred, gt), ref)
    assert hausdorff_mm(pred, gt) == pytest.approx(1000 * np.mean(ref))
    # One vertex 1 m away from everything dominates; the sets' correspondence is ignored.
    a = np.array([[[0.0, 0, 0], [0, 0, 0]]])
    b = np.array([[[0.0, 0, 0], [1, 0, 0]]])
    assert hausdorff_mm(a, b) == pytest.approx(1000.0)
    assert hausdorff_mm(b[:, ::-1], b) == 0.0 and rmse_mm(b[:, ::-1], b) > 0


def test_mismatched_or_bad_inputs():
    with pytest.raises(InputError, match="shape"):
        rmse_mm(np.zeros((2, 5, 3)), np.zeros((2, 6, 3)))
    with pytest.raises(InputError, match="NaN"):
        rmse_mm(np.full((1, 2, 3), np.nan), np.zeros((1, 2, 3)))


def test_error_parts_split_a_constant_offset_from_a_swing():
    rng = np.random.default_rng(0)
    T, V = 40, 30
    gt = rng.normal(size=(T, V, 3))
    # a constant offset of 3 cm along x: all of it is the mean shape's error
    parts = error_parts_mm(gt + np.array([0.03, 0.0, 0.0]), gt)
    assert parts["mean_shape"] == pytest.approx(30.0) and parts["motion"] == pytest.approx(0.0, abs=1e-9)
    # a swing of amplitude a (cos over whole periods, mean zero): RMS a / sqrt(2), none of it in the mean shape
    t = np.arange(T) / T
    swing = 0.04 * np.cos(2 * np.pi * 2 * t)[:, None, None] * np.array([0.0, 1.0, 0.0])
    parts = error_parts_mm(gt + swing, gt)
    assert parts["mean_shape"] == pytest.approx(0.0, abs=1e-9)
    assert parts["motion"] == pytest.approx(40.0 / np.sqrt(2))
    # any residual: the two parts are orthogonal, and the total is rmse_mm
    pred = gt + rng.normal(scale=0.02, size=gt.shape) + rng.normal(scale=0.05, size=(V, 3))
    parts = error_parts_mm(pred, gt)
    assert parts["total"] == pytest.approx(rmse_mm(pred, gt))
    assert parts["total"] ** 2 == pytest.approx(parts["mean_shape"] ** 2 + parts["motion"] ** 2)
    # a prediction that holds the simulation's mean still misses exactly the simulation's own motion
    still = np.broadcast_to(gt.mean(0), gt.shape)
    parts = error_parts_mm(still, gt)
    assert parts["motion"] == pytest.approx(parts["simulated_motion"]) and parts["mean_shape"] == pytest.approx(0.0, abs=1e-9)
