"""VirtualBones' normalisation statistics (:func:`loosefit.models.virtualbones.output_statistics`) against a
brute-force NumPy computation on small canonical sequences of different lengths and a two-bone rig (no
store): the bones' mean positions and pooled position std, the high-frequency offsets' std, the
low-frequency mesh's mean and std."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.models.dataset import SequenceData
from loosefit.models.virtualbones import MIN_OFFSET_STD, output_statistics
from loosefit.rig.virtual_bones import VirtualBoneRig

BONE_REST = np.array([[0.1, 0.2, 0.9], [-0.3, 0.0, 0.5]])


def rig() -> VirtualBoneRig:
    rest = np.array([[0.0, 0.0, 1.0], [0.2, 0.0, 0.9], [0.0, 0.3, 0.7], [-0.4, 0.0, 0.5]])
    return VirtualBoneRig(rest, np.array([[0, 1, 2], [1, 3, 2]]), np.array([[0, 1], [0, 1], [1, 0], [1, 0]]),
                          np.array([[0.8, 0.2], [0.6, 0.4], [0.7, 0.3], [1.0, 0.0]]), BONE_REST)


def sequence(T: int, seed: int) -> SequenceData:
    """Bones turning by up to a radian about random axes and moving apart, vertices with offsets whose
    spread differs per axis and per sequence."""
    rng = np.random.default_rng(seed)
    rot = axis_angle_to_matrix(torch.from_numpy(rng.normal(0, 0.6, (T, 2, 3)))).numpy().astype(np.float32)
    trans = (rng.normal(0, 0.1, (T, 2, 3)) + [[0.5, 0, 0], [0, -0.2, 0.1]]).astype(np.float32)
    lf = (rng.normal(0, 0.2, (T, 4, 3)) + [0.1 * seed, 0.0, 1.0]).astype(np.float32)
    verts = (lf + rng.normal(0, 1, (T, 4, 3)) * [0.002, 0.004, 0.01 * (1 + seed)]).astype(np.float32)
    return SequenceData(f"s{seed}", "m", "b", {}, None, np.zeros((T, 11)), np.zeros((T, 2, 6)), None, None,
                        verts, lf, rot, trans, None, None, None)


def test_statistics_against_brute_force():
    seqs = [sequence(6, 0), sequence(11, 1), sequence(3, 2)]
    stats = output_statistics(seqs, rig())
    rot = np.concatenate([s.bone_rot for s in seqs]).astype(np.float64)
    trans = np.concatenate([s.bone_trans for s in seqs]).astype(np.float64)
    # where each bone's rest centroid went, frame by frame and bone by bone
    positions = np.array([[rot[t, b] @ BONE_REST[b].astype(np.float32) + trans[t, b] for b in range(2)]
                          for t in range(len(rot))])
    mean = positions.mean(0)
    np.testing.assert_allclose(stats["position_mean"], mean, rtol=0, atol=1e-6)
    # per axis: sqrt of the mean over bones of each bone's variance about its own mean
    var = ((positions - mean) ** 2).mean(0)  # (B, 3)
    np.testing.assert_allclose(stats["position_std"], np.sqrt(var.mean(0)), rtol=1e-5)
    offsets = np.concatenate([s.verts - s.lf for s in seqs]).astype(np.float64).reshape(-1, 3)
    np.testing.assert_allclose(stats["offset_std"], offsets.std(0), rtol=1e-4)
    lf = np.concatenate([s.lf for s in seqs]).astype(np.float64)
    np.testing.assert_allclose(stats["lf_mean"], lf.reshape(-1, 3).mean(0), rtol=0, atol=1e-6)
    assert stats["lf_std"].shape == () and float(stats["lf_std"]) == pytest.approx(lf.std(), rel=1e-5)
    # the offsets' spread differs per axis (z largest): one std for all axes would not match
    assert stats["offset_std"][2] > 2 * stats["offset_std"][0]
    assert all(v.dtype == np.float32 for v in stats.values())


def test_still_outputs_get_the_floors():
    s = sequence(4, 0)
    s.verts = s.lf.copy()  # no high-frequency offsets at all
    stats = output_statistics([s], rig())
    np.testing.assert_allclose(stats["offset_std"], MIN_OFFSET_STD)
