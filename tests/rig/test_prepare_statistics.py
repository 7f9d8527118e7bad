"""What ``prepare`` reports and stores about a rig against brute force, on a small store written by the test
(one skirt on the Anny body, two training sequences of different lengths whose frames move differently, no
simulator): the reported RMSEs pool the squared skinning errors of every frame of every sequence, and each
normalisation statistic is the mean and std of its quantity over every training frame."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.data.store import DatasetStore
from loosefit.geometry.rotations import matrix_to_axis_angle
from loosefit.geometry.smoothing import frequency_split
from loosefit.rig.prepare import prepare
from loosefit.rig.prepared import load_bone_transforms, load_rig, prepared_split, read_stats

GARMENT = "skirt+average"


@pytest.fixture(scope="module")
def store(body, tmp_path_factory):
    """Training sequences ``walk`` (12 frames) and ``sway`` (7 frames): the garment skinned to its nearest body
    vertex, plus a ripple whose amplitude grows along each sequence (frames differ in how well bones fit)."""
    from loosefit.garment import make_garment
    from loosefit.geometry.lbs import linear_blend_skinning
    from loosefit.models.fitgar_inputs import pose_motion
    from loosefit.motion.procedural import generate

    path = tmp_path_factory.mktemp("prepare-stats") / "store.zarr"
    s = DatasetStore.create(path)
    s.add_body("average", body.shape.to_array())
    garment = make_garment("skirt", body, seed=0, edge_length=0.06)
    s.add_garment(GARMENT, garment)
    nearest = np.linalg.norm(garment.verts[:, None] - body.rest_verts()[None], axis=-1).argmin(1)
    weights = torch.from_numpy(body.skinning_weights()[nearest]).double()
    for k, (name, seconds) in enumerate((("walk", 0.4), ("sway", 0.25))):
        motion = generate(name, seconds, k, body)
        s.add_motion(name, motion)
        posed = pose_motion(body.rest_joints(), body.parents, motion)
        skinned = linear_blend_skinning(torch.from_numpy(garment.verts).double(), weights,
                                        torch.from_numpy(posed.transforms)).numpy()
        T = len(skinned)
        amplitude = np.linspace(0.001, 0.03, T)[:, None] * (1 + k)
        ripple = amplitude * np.sin(20.0 * skinned[..., 2] + 7.0 * skinned[..., 0])
        verts = skinned + np.stack([ripple, -ripple, 0.3 * ripple], -1)
        s.write_sequence(f"{GARMENT}+{name}+default", verts.astype(np.float32), garment=GARMENT, body="average",
                         motion=name, sim_params={}, stats={}, split="train")
    s.close()
    prepare(path, bones=3, body=body, progress=False, iterations=2, transform_iterations=2, max_solve_frames=6,
            descriptor_samples=8)
    return DatasetStore.open(path, mode="r")


def frames(store) -> list[dict]:
    """Per training sequence: full frames, their low-frequency part and the stored bone transforms (float64)."""
    _, smoothing, fixed = prepared_split(store, GARMENT)
    faces = store.garment(GARMENT).faces
    out = []
    for name in store.sequence_names(split="train"):
        full = np.asarray(store.sequence(name).verts[:], np.float32)
        lf = frequency_split(full, faces, smoothing, fixed=fixed)[0]
        R, T = load_bone_transforms(store, GARMENT, name)
        out.append({"full": full.astype(np.float64), "lf": lf.astype(np.float64), "R": R, "T": T})
    return out


def test_reported_rmse_pools_every_frame_of_every_sequence(store):
    rig = load_rig(store, GARMENT)
    sq_lf, sq_full = [], []
    for f in frames(store):
        skinned = rig.skin(f["R"], f["T"]).astype(np.float64)
        sq_lf.append(((skinned - f["lf"]) ** 2).sum(-1).ravel())
        sq_full.append(((skinned - f["full"]) ** 2).sum(-1).ravel())
    attrs = store.read_attrs(f"garments/{GARMENT}/rig")
    lf = np.concatenate(sq_lf)
    assert attrs["rmse_lf_mm"] == pytest.approx(1e3 * np.sqrt(lf.mean()), rel=1e-6)
    assert attrs["rmse_full_mm"] == pytest.approx(1e3 * np.sqrt(np.concatenate(sq_full).mean()), rel=1e-6)
    per_frame = np.concatenate([np.sqrt(s.reshape(-1, rig.num_verts).mean(1)) for s in sq_lf]).mean()
    assert abs(1e3 * per_frame - attrs["rmse_lf_mm"]) > 1e-3 * attrs["rmse_lf_mm"]  # the data tell them apart
    assert attrs["rmse_full_mm"] > attrs["rmse_lf_mm"]  # the ripple is not in the low-frequency mesh


def check(stat, values: np.ndarray):
    """``stat`` (RunningStats) is the mean and population std over the leading axis of ``values``."""
    assert stat.count == len(values)
    np.testing.assert_allclose(stat.mean, values.mean(0), rtol=1e-6, atol=1e-8)  # float32 inputs
    np.testing.assert_allclose(stat.std, values.std(0), rtol=1e-5, atol=1e-8)


def test_rig_statistics_are_those_of_their_quantities(store):
    stats = read_stats(store, GARMENT)
    fs = frames(store)
    B = fs[0]["R"].shape[1]
    full = np.concatenate([f["full"] for f in fs])
    lf = np.concatenate([f["lf"] for f in fs])
    check(stats["garment_verts"], full.reshape(-1, 3))
    check(stats["lf_verts"], lf.reshape(-1, 3))
    check(stats["hf_offset"], (full - lf).reshape(-1, 3))
    check(stats["hf_offset_vertex"], full - lf)
    check(stats["bone_translation"], np.concatenate([f["T"] for f in fs]).astype(np.float64))
    rot = np.concatenate([f["R"] for f in fs]).astype(np.float64)
    check(stats["bone_rotation"], matrix_to_axis_angle(rot).numpy().reshape(-1, B, 3))
    # the offsets spread far less than the vertices: the two statistics cannot be confused
    assert (stats["hf_offset"].std < 0.5 * stats["garment_verts"].std).all()


def test_dataset_statistics_of_the_training_motions(store):
    stats = read_stats(store)
    rot, trans, vel = [], [], []
    for name in store.sequence_names(split="train"):
        q = store.sequence(name)
        m = store.motion(q.motion)
        n = q.num_frames
        rot.append(m.rotations[:n])
        trans.append(m.translation[:n])
        vel.append(np.concatenate([np.zeros((1, 3)), np.diff(m.translation[:n], axis=0)]))
    check(stats["body_rotation"], np.concatenate(rot).astype(np.float64))
    check(stats["body_translation"], np.concatenate(trans).astype(np.float64))
    check(stats["body_velocity"], np.concatenate(vel).astype(np.float64))
    fs = frames(store)  # one garment: the dataset's pooled garment statistics are its own
    check(stats["garment_verts"], np.concatenate([f["full"] for f in fs]).reshape(-1, 3))
    check(stats["hf_offset"], np.concatenate([f["full"] - f["lf"] for f in fs]).reshape(-1, 3))
