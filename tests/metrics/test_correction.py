import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.metrics.correction import CorrectionStats


def _sequences(seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for frames in (3, 5):
        gt, base, corr, part = (rng.normal(scale=0.05, size=(frames, 7, 3)) for _ in range(4))
        out.append((gt, base, corr, part))
    return out


def test_pooled_sums_match_a_brute_force_computation():
    stats = CorrectionStats()
    seqs = _sequences()
    for s in seqs:
        stats.add(*s)
    y, b, c, h = (np.concatenate([s[k] for s in seqs]) for k in range(4))
    summary = stats.summary()

    def rms_mm(x):
        return 1e3 * np.sqrt((x**2).sum(-1).mean())

    assert summary["samples"] == 8 * 7
    assert summary["base_rmse_mm"] == pytest.approx(rms_mm(y - b))
    assert summary["corrected_rmse_mm"] == pytest.approx(rms_mm(y - b - c))
    assert summary["ideal_rmse_mm"] == pytest.approx(rms_mm(y - b - h))
    assert summary["correction_rms_mm"] == pytest.approx(rms_mm(c))
    assert summary["with_part_mm2"] == pytest.approx(1e6 * (c * h).sum(-1).mean())
    assert summary["with_rest_mm2"] == pytest.approx(1e6 * (c * (y - b - h)).sum(-1).mean())
    assert summary["part_explained"] == pytest.approx(1 - ((c - h) ** 2).sum() / (h**2).sum())
    # the best scale minimises the error over a fine grid of scales
    scales = np.linspace(-2, 2, 4001)
    errors = [rms_mm(y - b - s * c) for s in scales]
    assert summary["best_scale"] == pytest.approx(scales[int(np.argmin(errors))], abs=1e-3)
    assert summary["best_scale_rmse_mm"] == pytest.approx(min(errors), rel=1e-6)
    # the identity of the module doc: the change of the squared error splits into three terms
    change = summary["corrected_rmse_mm"] ** 2 - summary["base_rmse_mm"] ** 2
    assert change == pytest.approx(summary["correction_rms_mm"] ** 2 - 2 * summary["with_part_mm2"]
                                   - 2 * summary["with_rest_mm2"])


def test_closed_form_cases():
    gt, base, _, part = _sequences(1)[0]
    exact = CorrectionStats()
    exact.add(gt, base, part, part)  # the correction is exactly the part it should supply
    s = exact.summary()
    assert s["part_explained"] == pytest.approx(1.0)
    assert s["corrected_rmse_mm"] == pytest.approx(s["ideal_rmse_mm"])
    double = CorrectionStats()
    double.add(gt, base, 2 * (gt - base), part)  # twice the whole error: half of it is right
    s = double.summary()
    assert s["best_scale"] == pytest.approx(0.5)
    assert s["best_scale_rmse_mm"] == pytest.approx(0.0, abs=1e-4)  # from a difference of sums: rounding
    assert s["corrected_rmse_mm"] == pytest.approx(s["base_rmse_mm"])


def test_bad_input_is_refused():
    stats = CorrectionStats()
    gt, base, corr, part = _sequences()[0]
    with pytest.raises(InputError, match="no vertex samples"):
        stats.summary()
    with pytest.raises(InputError, match="shape"):
        stats.add(gt, base, corr[:, :5], part)
    bad = corr.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        stats.add(gt, base, bad, part)
    assert stats.count == 0  # nothing half-added
