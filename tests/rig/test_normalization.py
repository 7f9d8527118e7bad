"""Streaming statistics against the batch formulas, merging, normalising, files."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.errors import InputError
from loosefit.rig.normalization import NormalizationStats, RunningStats


def test_streaming_equals_batch_far_from_the_origin():
    rng = np.random.default_rng(0)
    # positions 1 km away with millimetre spread: E[x^2] - E[x]^2 would lose every digit in float64
    data = 1000.0 + 1e-3 * rng.normal(size=(1000, 7, 3))
    stats = RunningStats.empty((3,))
    start = 0
    for size in rng.integers(1, 200, 50):
        stats.update(data[start : start + size])
        start += size
        if start >= len(data):
            break
    seen = data[:start].reshape(-1, 3)
    assert stats.count == len(seen)
    np.testing.assert_allclose(stats.mean, seen.mean(0), rtol=1e-14)
    np.testing.assert_allclose(stats.std, seen.std(0), rtol=1e-9)


def test_merge_of_parts_is_the_whole():
    rng = np.random.default_rng(1)
    a, b = rng.normal(2.0, 3.0, (40, 4, 3)), rng.normal(-1.0, 0.5, (7, 4, 3))
    whole = RunningStats.empty((4, 3)).update(np.concatenate([a, b]))
    merged = RunningStats.empty((4, 3)).update(b).merge(RunningStats.empty((4, 3)).update(a))
    np.testing.assert_allclose(merged.mean, whole.mean, rtol=1e-12)
    np.testing.assert_allclose(merged.std, whole.std, rtol=1e-12)
    np.testing.assert_allclose(whole.mean, np.concatenate([a, b]).mean(0), rtol=1e-12)


def test_normalize_round_trips_numpy_and_torch():
    rng = np.random.default_rng(2)
    x = rng.normal(5.0, 2.0, (100, 3)).astype(np.float32)
    x[:, 2] = 4.0  # a constant feature is divided by 1, not 0
    stats = RunningStats.empty((3,)).update(x)
    y = stats.normalize(x)
    assert y.dtype == np.float32
    np.testing.assert_allclose(y[:, :2].mean(0), 0.0, atol=1e-5)
    np.testing.assert_allclose(y[:, :2].std(0), 1.0, atol=1e-5)
    np.testing.assert_allclose(y[:, 2], 0.0, atol=1e-6)
    np.testing.assert_allclose(stats.denormalize(y), x, atol=1e-5)
    t = torch.tensor(x, dtype=torch.float64)
    yt = stats.normalize(t)
    assert isinstance(yt, torch.Tensor) and yt.dtype == torch.float64
    np.testing.assert_allclose(yt.numpy(), y, atol=1e-5)


def test_named_statistics_file_round_trip_and_errors(tmp_path):
    stats = NormalizationStats()
    stats.add("body_rotation", np.random.default_rng(3).normal(size=(10, 31, 3)), (31, 3))
    stats.add("bone.translation", np.arange(12.0).reshape(4, 3), (3,))
    stats.save(tmp_path / "stats.npz")
    back = NormalizationStats.load(tmp_path / "stats.npz")
    assert sorted(back) == ["body_rotation", "bone.translation"]
    for name in stats:
        assert back[name].count == stats[name].count
        np.testing.assert_array_equal(back[name].mean, stats[name].mean)
        np.testing.assert_array_equal(back[name].std, stats[name].std)
    with pytest.raises(InputError, match="cannot take an array of shape"):
        stats.add("body_rotation", np.zeros((5, 30, 3)), (31, 3))
    with pytest.raises(InputError, match="NaN"):
        RunningStats.empty((2,)).update(np.array([[0.0, np.nan]]))
    with pytest.raises(InputError, match="no samples"):
        RunningStats.empty((2,)).std
    np.savez(tmp_path / "partial.npz", **{"x.mean": np.zeros(3)})
    with pytest.raises(InputError, match="partial.npz.*missing arrays"):
        NormalizationStats.load(tmp_path / "partial.npz")
