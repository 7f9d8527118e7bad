"""The motion-feature statistics of :meth:`GarmentSequences.feature_stats` against a brute-force NumPy
computation over sequences of different lengths (small arrays, no store): per feature, over every frame of
every sequence, the std floored per group."""

from __future__ import annotations

import numpy as np
import pytest

from loosefit.models.dataset import STD_FLOOR, GarmentSequences, SequenceData


def sequences(lengths=(5, 9, 3), R: int = 11, J: int = 4, seed: int = 0) -> list[SequenceData]:
    """Sequences whose features differ in mean and spread from one to the next, one joint channel still."""
    rng = np.random.default_rng(seed)
    out = []
    for k, T in enumerate(lengths):
        root = (rng.normal(k, 0.5 + k, (T, R))).astype(np.float32)
        joints = (rng.normal(0.3 * k, 0.2 + 0.1 * k, (T, J - 1, 6))).astype(np.float32)
        joints[:, 0, 0] = 0.7  # a joint channel that never moves: its std is floored
        root[:, 3] = 0.001 * rng.normal(size=T)  # a root feature that barely moves
        out.append(SequenceData(f"s{k}", "m", "b", {}, None, root, joints, None, None, np.zeros((T, 2, 3)),
                                np.zeros((T, 2, 3)), None, None, None, None, None))
    return out


def brute_force(seqs: list[SequenceData], key: str) -> tuple[np.ndarray, np.ndarray]:
    x = np.concatenate([getattr(s, key) for s in seqs]).astype(np.float64)
    flat = x.reshape(len(x), -1)
    mean = np.array([np.mean(flat[:, i]) for i in range(flat.shape[1])])
    std = np.array([np.sqrt(np.mean((flat[:, i] - mean[i]) ** 2)) for i in range(flat.shape[1])])
    return mean.reshape(x.shape[1:]), np.maximum(std, STD_FLOOR[key]).reshape(x.shape[1:])


def test_feature_statistics_are_per_feature_over_every_frame_of_every_sequence():
    data = object.__new__(GarmentSequences)  # only the loaded sequences matter here
    data.sequences = sequences()
    stats = data.feature_stats()
    for key in ("root", "joints"):
        mean, std = brute_force(data.sequences, key)
        assert stats[key][0].dtype == np.float32 and stats[key][0].shape == mean.shape
        np.testing.assert_allclose(stats[key][0], mean, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(stats[key][1], std, rtol=1e-6, atol=1e-7)
    assert stats["joints"][1][0, 0] == pytest.approx(STD_FLOOR["joints"])  # the still channel: floored
    assert stats["root"][1][3] == pytest.approx(STD_FLOOR["root"])
    # statistics of the first sequence alone, or of the sequences' means, would be others
    first = brute_force(data.sequences[:1], "root")
    assert np.abs(first[0] - stats["root"][0]).max() > 0.3


def test_normalised_training_features_are_standardised():
    """Normalised by their own statistics, the training features have mean 0 and std 1 (unfloored channels)."""
    data = object.__new__(GarmentSequences)
    data.sequences = sequences(seed=1)
    stats = data.feature_stats()
    x = np.concatenate([s.joints for s in data.sequences]).astype(np.float64)
    z = (x - stats["joints"][0]) / stats["joints"][1]
    moving = np.ones(x.shape[1:], bool)
    moving[0, 0] = False
    np.testing.assert_allclose(z.mean(0)[moving], 0, atol=1e-5)
    np.testing.assert_allclose(z.std(0)[moving], 1, atol=1e-5)


def test_multi_garment_statistics_pool_every_frame_of_every_garment():
    """SwinGar's :meth:`MultiGarmentData.feature_stats`: the same statistics over the frames of all garments."""
    from loosefit.models.multi_garment import MultiGarmentData

    garments = []
    for seed, lengths in ((2, (4, 7)), (3, (6,))):
        g = object.__new__(GarmentSequences)
        g.sequences = sequences(lengths, seed=seed)
        garments.append(g)
    data = object.__new__(MultiGarmentData)
    data.sequences = garments
    stats = data.feature_stats()
    every = [s for g in garments for s in g.sequences]
    for key in ("root", "joints"):
        mean, std = brute_force(every, key)
        np.testing.assert_allclose(stats[key][0], mean, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(stats[key][1], std, rtol=1e-6, atol=1e-7)
    assert np.abs(brute_force(garments[0].sequences, "root")[0] - stats["root"][0]).max() > 0.1
