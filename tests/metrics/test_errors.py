"""RMSE, mean vertex error and Hausdorff distance against hand-built cases and brute force."""

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from loosefit.errors import InputError
from loosefit.metrics.errors import hausdorff_mm, hausdorff_per_frame, mean_vertex_error_mm, rmse_mm, vertex_errors


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
