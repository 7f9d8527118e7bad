"""JointNet's bone output statistics (:func:`loosefit.models.jointnet.bone_output_statistics`) against a
frame-by-frame, bone-by-bone NumPy computation on small sequences of different lengths (no store): the mean
and std of the Euler angles and of the offsets ``R c + T - c`` of the bones' rest positions."""

from __future__ import annotations

import numpy as np
import torch

from loosefit.geometry.rotations import axis_angle_to_matrix, matrix_to_euler
from loosefit.models.dataset import SequenceData
from loosefit.models.jointnet import MIN_OUTPUT_STD, JointNetConfig, bone_output_statistics

CENTRES = np.array([[0.1, 0.2, 0.9], [-0.3, 0.0, 0.5], [0.0, 0.25, 0.3]], np.float32)


def sequence(T: int, seed: int, still: bool = False) -> SequenceData:
    rng = np.random.default_rng(seed)
    aa = rng.normal(0, 0.4, (T, 3, 3)) + [0.1 * seed, 0, 0]
    aa[:, 2] = 0.0  # the third bone never turns
    rot = axis_angle_to_matrix(torch.from_numpy(aa)).numpy().astype(np.float32)
    trans = (rng.normal(0, 0.05 * (1 + seed), (T, 3, 3))).astype(np.float32)
    if still:
        trans[:] = 0.0
    return SequenceData(f"s{seed}", "m", "b", {}, None, np.zeros((T, 11)), np.zeros((T, 2, 6)), None, None,
                        np.zeros((T, 4, 3)), np.zeros((T, 4, 3)), rot, trans, None, None, None)


def test_bone_output_statistics_against_brute_force():
    order = JointNetConfig().euler_order
    seqs = [sequence(5, 0), sequence(8, 1), sequence(2, 2)]
    stats = bone_output_statistics(seqs, CENTRES, order)
    euler, offset = [], []
    for s in seqs:
        for t in range(s.num_frames):
            R = s.bone_rot[t].astype(np.float64)
            euler.append(matrix_to_euler(torch.from_numpy(R), order).numpy())
            offset.append([R[b] @ CENTRES[b] + s.bone_trans[t, b] - CENTRES[b] for b in range(3)])
    euler, offset = np.array(euler), np.array(offset)  # (frames, B, 3)
    for name, values in (("euler", euler), ("offset", offset)):
        mean = values.mean(0)
        std = np.sqrt(((values - mean) ** 2).mean(0))
        assert stats[f"{name}_mean"].shape == (3, 3)
        np.testing.assert_allclose(stats[f"{name}_mean"], mean, rtol=0, atol=1e-6)
        np.testing.assert_allclose(stats[f"{name}_std"], np.maximum(std, MIN_OUTPUT_STD), rtol=1e-5, atol=1e-7)
    # the third bone never turns: its Euler std is floored, its offsets still spread (the translations)
    np.testing.assert_allclose(stats["euler_std"][2], MIN_OUTPUT_STD)
    assert (stats["offset_std"][2] > 0.02).all()


def test_a_turning_bone_moves_its_rest_position_not_its_translation_alone():
    """A bone turned by a quarter turn about z with no translation: its rest position ``c`` goes to ``R c``,
    so the offset ``R c - c`` is nonzero (a statistic of the translations alone would read zero)."""
    s = sequence(3, 0, still=True)
    s.bone_rot[:] = axis_angle_to_matrix(torch.tensor([0.0, 0.0, np.pi / 2])).numpy()
    stats = bone_output_statistics([s], CENTRES, JointNetConfig().euler_order)
    Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(stats["offset_mean"], CENTRES @ Rz.T - CENTRES, atol=1e-6)
