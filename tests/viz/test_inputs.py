"""Loading render inputs: mesh-sequence .npz, motion .npz and dataset sequences, with clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.motion.motion import Motion
from loosefit.viz.inputs import load_panels


def grid(n: int = 4, frames: int = 3):
    """A moving ``n x n`` grid: verts ``(frames, n*n, 3)`` and faces."""
    u, v = np.meshgrid(np.linspace(-0.2, 0.2, n), np.linspace(0.5, 0.9, n))
    rest = np.stack([u.ravel(), np.full(n * n, -0.2), v.ravel()], axis=1).astype(np.float32)
    verts = rest[None] + np.linspace(0, 0.1, frames, dtype=np.float32)[:, None, None]
    a = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + n], 1), np.stack([a + 1, a + n + 1, a + n], 1)])
    return verts, faces


def test_mesh_sequence_with_and_without_body(tmp_path):
    verts, faces = grid()
    body_verts, body_faces = grid(n=3)
    path = tmp_path / "pred.npz"
    np.savez(path, verts=verts, faces=faces, body_verts=body_verts, body_faces=body_faces, fps=30.0, joints=np.zeros((3, 2, 3)))
    (panel,) = load_panels(path)
    assert [t.label for t in panel] == ["body", "pred"]
    np.testing.assert_array_equal(panel[0].verts, body_verts)
    np.testing.assert_array_equal(panel[1].verts, verts)
    np.testing.assert_array_equal(panel[1].faces, faces)
    np.savez(path, verts=verts, faces=faces)
    (panel,) = load_panels(path)
    assert len(panel) == 1 and panel[0].verts.shape == (3, 16, 3)


@pytest.mark.parametrize(
    "arrays, message",
    [
        (lambda v, f, bv, bf: dict(verts=v), r"missing arrays \['faces'\]"),
        (lambda v, f, bv, bf: dict(verts=v, faces=f + 10), "verts/faces: faces index vertices 10..25, the mesh has 16"),
        (lambda v, f, bv, bf: dict(verts=v[0], faces=f), r"verts must have shape \(T, V, 3\), got \(16, 3\)"),
        (lambda v, f, bv, bf: dict(verts=v, faces=f, body_verts=bv), "has body_verts but no body_faces"),
        (lambda v, f, bv, bf: dict(verts=v, faces=f, body_verts=bv[:2], body_faces=bf), "with the 3 frames of verts"),
        (lambda v, f, bv, bf: dict(verts=v, faces=f, body_verts=bv, body_faces=bf[:, :2]), r"body_verts/body_faces: faces must have shape \(F, 3\)"),
        (lambda v, f, bv, bf: dict(poses=v), r"neither a mesh sequence .* it has arrays \['poses'\]"),
    ],
)
def test_mesh_sequence_errors_name_the_file(tmp_path, arrays, message):
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays(*grid(), *grid(n=3)))
    with pytest.raises(InputError, match=message) as err:
        load_panels(path)
    assert err.value.path == path


def test_unreadable_and_unsupported_inputs(tmp_path):
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    for name, message in [("junk.npz", "cannot read .npz"), ("missing.npz", "no such file"), ("walk.bvh", "unsupported input")]:
        if name == "walk.bvh":
            (tmp_path / name).write_text("HIERARCHY\n")
        with pytest.raises(InputError, match=message) as err:
            load_panels(tmp_path / name)
        assert err.value.path == tmp_path / name
    with pytest.raises(InputError, match="needs a sequence name"):
        load_panels(tmp_path)
    with pytest.raises(InputError, match="only applies to a dataset store"):
        load_panels(tmp_path / "junk.npz", sequence="s")


def bent_motion(body, frames: int = 2) -> Motion:
    motion = body.rest_motion(frames)
    motion.rotations[:, body.joint_names.index("LeftArm"), 1] = -0.8
    motion.rotations[:, body.joint_names.index("Spine"), 2] = np.linspace(0, 0.3, frames)
    motion.name = "raise"
    return motion


def test_motion_is_posed_on_the_body(tmp_path, body):
    motion = bent_motion(body)
    motion.save(tmp_path / "raise.npz")
    (panel,) = load_panels(tmp_path / "raise.npz", body=body)
    assert len(panel) == 1 and panel[0].label == "raise"
    np.testing.assert_array_equal(panel[0].verts, body.pose(motion).verts)
    np.testing.assert_array_equal(panel[0].faces, body.faces)
    wrong = Motion(motion.rotations[:, :5], motion.translation, rig="cmu_mb", name="short")
    wrong.save(tmp_path / "short.npz")
    with pytest.raises(InputError, match="has 5 joints, rig 'cmu_mb' has 31") as err:
        load_panels(tmp_path / "short.npz", body=body)
    assert err.value.path == tmp_path / "short.npz"


def test_dataset_sequence_on_the_posed_body(tmp_path, body):
    from loosefit.data.store import DatasetStore
    from loosefit.garment import Garment

    verts, faces = grid(frames=2)
    store = DatasetStore.create(tmp_path / "data.zarr")
    store.add_garment("g", Garment(verts=verts[0], faces=faces, pinned=np.zeros(16, bool), kind="skirt", params={}, name="g"))
    shape = np.array([0.5, 0.5, 0.5, 0.5, 0.5, 0.5], np.float32)
    store.add_body("b", shape)
    motion = bent_motion(body)
    store.add_motion("m", motion)
    store.write_sequence("s1", verts, "g", "b", "m", sim_params={}, stats={}, split="train")
    (panel,) = load_panels(tmp_path / "data.zarr", sequence="s1", body=body)
    assert [t.label for t in panel] == ["body", "s1"]
    np.testing.assert_array_equal(panel[1].verts, verts)
    np.testing.assert_array_equal(panel[1].faces, faces)
    np.testing.assert_allclose(panel[0].verts, body.pose(motion, shape=shape).verts, atol=1e-6)
    with pytest.raises(InputError, match="s2"):
        load_panels(tmp_path / "data.zarr", sequence="s2", body=body)
