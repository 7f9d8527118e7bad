"""OBJ and mesh-sequence files round-trip exactly; bad files give errors naming the file."""

import numpy as np
import pytest
import trimesh

from loosefit.errors import InputError
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.io.obj import write_obj


def test_obj_round_trip_through_trimesh(tmp_path):
    rng = np.random.default_rng(0)
    verts = rng.normal(size=(50, 3)).astype(np.float32)
    faces = rng.integers(0, 50, size=(80, 3))
    write_obj(tmp_path / "m.obj", verts, faces, header="test mesh")
    mesh = trimesh.load(tmp_path / "m.obj", process=False, maintain_order=True)
    assert np.abs(mesh.vertices - verts).max() < 1e-6
    assert (mesh.faces == faces).all()
    assert (tmp_path / "m.obj").read_text().startswith("# test mesh\n")


def test_mesh_sequence_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    seq = MeshSequence(rng.normal(size=(4, 10, 3)), [[0, 1, 2], [2, 3, 4]], fps=24.0, extra={"joints": np.ones((4, 2, 3))})
    seq.save(tmp_path / "s.npz")
    back = MeshSequence.load(tmp_path / "s.npz")
    assert np.array_equal(back.verts, seq.verts) and np.array_equal(back.faces, seq.faces)
    assert back.fps == 24.0 and np.array_equal(back.extra["joints"], np.ones((4, 2, 3)))


def test_mesh_sequence_errors_name_the_file(tmp_path):
    np.savez(tmp_path / "nofaces.npz", verts=np.zeros((1, 3, 3)))
    with pytest.raises(InputError, match="nofaces.npz.*missing"):
        MeshSequence.load(tmp_path / "nofaces.npz")
    np.savez(tmp_path / "range.npz", verts=np.zeros((1, 3, 3)), faces=np.array([[0, 1, 3]]))
    with pytest.raises(InputError, match="range.npz.*outside"):
        MeshSequence.load(tmp_path / "range.npz")
    (tmp_path / "junk.npz").write_bytes(b"junk")
    with pytest.raises(InputError, match="junk.npz"):
        MeshSequence.load(tmp_path / "junk.npz")
