"""The runs' spread (loosefit.data.run_spread): the floor against a brute-force loop, stacking and its refusals."""

import numpy as np
import pytest

from loosefit.data.run_spread import floor_m, mean_run, mean_square_distance, stack_runs
from loosefit.errors import InputError


def test_floor_of_stacked_runs_equals_a_loop_over_runs_frames_and_vertices():
    rng = np.random.default_rng(3)
    base = rng.normal(0.0, 0.3, (4, 6, 3)).astype(np.float32)
    references = base + rng.normal(0.0, 0.01, (3, 4, 6, 3)).astype(np.float32)
    runs = stack_runs(base, references)
    assert runs.shape == (4, 4, 6, 3) and np.array_equal(runs[0], base) and np.array_equal(runs[1:], references)
    mean = np.zeros((4, 6, 3))
    for run in runs:
        mean += run.astype(np.float64) / len(runs)
    total = 0.0
    for k in range(4):
        for t in range(4):
            for i in range(6):
                total += sum((float(runs[k, t, i, c]) - mean[t, i, c]) ** 2 for c in range(3))
    np.testing.assert_allclose(mean_run(runs), mean, atol=1e-12)
    assert floor_m(runs) == pytest.approx(np.sqrt(total / (4 * 4 * 6)), rel=1e-9)
    assert mean_square_distance(runs[1], mean) == pytest.approx(
        np.mean(np.sum((runs[1] - mean) ** 2, -1)), rel=1e-12)


def test_mismatched_empty_or_not_finite_runs_are_refused():
    base = np.zeros((3, 5, 3), np.float32)
    with pytest.raises(InputError, match="to match the base run"):
        stack_runs(base, np.zeros((2, 3, 4, 3)))
    with pytest.raises(InputError, match="to match the base run"):
        stack_runs(base, np.zeros((0, 3, 5, 3)))
    bad = np.zeros((1, 3, 5, 3))
    bad[0, 1, 2, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        stack_runs(base, bad)
