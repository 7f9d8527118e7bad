"""Garment.save / Garment.load round trip and the errors of a bad garment file."""

import json

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.garment import Garment


def _garment():
    rng = np.random.default_rng(0)
    verts = rng.normal(size=(5, 3)).astype(np.float32) * np.float32(0.3)
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4]])
    pinned = np.array([True, False, True, False, False])
    params = {"length": 0.123456789012345, "seed": 3, "hem_phases": [0.1, 2.0 / 3.0]}
    return Garment(verts=verts, faces=faces, pinned=pinned, kind="skirt", params=params, name="g")


def test_round_trip_is_exact(tmp_path):
    g = _garment()
    g.save(tmp_path / "g.obj")
    assert (tmp_path / "g.json").is_file()
    back = Garment.load(tmp_path / "g.obj")
    assert np.array_equal(back.verts, g.verts) and back.verts.dtype == np.float32
    assert np.array_equal(back.faces, g.faces) and back.faces.dtype == np.int64
    assert np.array_equal(back.pinned, g.pinned)
    assert back.params == g.params and back.kind == "skirt" and back.name == "g"


def test_missing_or_bad_sidecar(tmp_path):
    g = _garment()
    g.save(tmp_path / "g.obj")
    (tmp_path / "g.json").unlink()
    with pytest.raises(InputError, match="g.obj: garment sidecar g.json is missing"):
        Garment.load(tmp_path / "g.obj")
    g.save(tmp_path / "g.obj")
    meta = json.loads((tmp_path / "g.json").read_text())
    meta["pinned"] = [99]
    (tmp_path / "g.json").write_text(json.dumps(meta))
    with pytest.raises(InputError, match="pinned vertex id is out of range"):
        Garment.load(tmp_path / "g.obj")
    (tmp_path / "g.json").write_text("{not json")
    with pytest.raises(InputError, match="unreadable garment sidecar"):
        Garment.load(tmp_path / "g.obj")


def test_bad_garments(tmp_path):
    with pytest.raises(InputError, match="saved as .obj"):
        _garment().save(tmp_path / "g.ply")
    with pytest.raises(InputError, match="out of range"):
        Garment(np.zeros((3, 3)), np.array([[0, 1, 3]]), np.zeros(3, bool), "skirt")
    with pytest.raises(InputError, match="pinned must be"):
        Garment(np.zeros((3, 3)), np.array([[0, 1, 2]]), np.zeros(4, bool), "skirt")
    with pytest.raises(InputError, match="no such garment file"):
        Garment.load(tmp_path / "none.obj")
