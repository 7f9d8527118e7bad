"""OBJ-sequence folders: round trip within the 7-digit text precision, layout, atomic replacement, errors."""

import numpy as np
import pytest
import trimesh

from loosefit.errors import InputError
from loosefit.io import obj_sequence
from loosefit.io.obj_sequence import read_obj_sequence, write_obj_sequence
from tests.io.conftest import random_sequence


def _close(a, b):
    """Equal within 7 significant digits (then float32): |a - b| <= 6e-7 |b|."""
    return a.shape == b.shape and bool((np.abs(a - b) <= 6e-7 * np.abs(b)).all())


def test_round_trip_and_layout(tmp_path):
    seq = random_sequence(fps=29.97)
    write_obj_sequence(tmp_path / "anim", seq)
    names = sorted(p.name for p in (tmp_path / "anim").iterdir())
    assert names == sorted([f"frame_{t:05d}.obj" for t in range(10)] + [f"body_{t:05d}.obj" for t in range(10)])
    back = read_obj_sequence(tmp_path / "anim")
    assert _close(back.verts, seq.verts) and np.array_equal(back.faces, seq.faces) and back.fps == 29.97
    assert _close(back.extra["body_verts"], seq.extra["body_verts"]) and np.array_equal(back.extra["body_faces"], seq.extra["body_faces"])
    # every frame is a plain OBJ another reader opens
    mesh = trimesh.load(tmp_path / "anim" / "frame_00007.obj", process=False, maintain_order=True)
    assert _close(mesh.vertices.astype(np.float32), seq.verts[7]) and np.array_equal(mesh.faces, seq.faces)
    assert (tmp_path / "anim" / "frame_00003.obj").read_text().startswith("# loosefit mesh sequence frame 3\n# fps 29.97\n")
    assert [p.name for p in tmp_path.iterdir()] == ["anim"]  # no temporary folder left behind


def test_rewrite_replaces_all_frames(tmp_path):
    write_obj_sequence(tmp_path / "anim", random_sequence(frames=10))
    shorter = random_sequence(seed=1, frames=4)
    shorter.extra.clear()
    write_obj_sequence(tmp_path / "anim", shorter)
    assert sorted(p.name for p in (tmp_path / "anim").iterdir()) == [f"frame_{t:05d}.obj" for t in range(4)]
    back = read_obj_sequence(tmp_path / "anim")
    assert _close(back.verts, shorter.verts) and back.extra == {}


def test_failed_write_keeps_the_old_folder(tmp_path, monkeypatch):
    old = random_sequence(frames=3)
    write_obj_sequence(tmp_path / "anim", old)
    calls = []

    def failing_write_obj(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise OSError("disk full")

    monkeypatch.setattr(obj_sequence, "write_obj", failing_write_obj)
    with pytest.raises(OSError, match="disk full"):
        write_obj_sequence(tmp_path / "anim", random_sequence(seed=1, frames=5))
    monkeypatch.undo()
    assert _close(read_obj_sequence(tmp_path / "anim").verts, old.verts)
    assert [p.name for p in tmp_path.iterdir()] == ["anim"]


def test_refuses_to_replace_a_foreign_folder(tmp_path):
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "todo.txt").write_text("keep me")
    with pytest.raises(InputError, match="notes: .*todo.txt"):
        write_obj_sequence(tmp_path / "notes", random_sequence())
    assert (tmp_path / "notes" / "todo.txt").read_text() == "keep me"
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match="file: exists and is not a folder"):
        write_obj_sequence(tmp_path / "file", random_sequence())


def test_read_errors_name_the_folder_or_file(tmp_path):
    write_obj_sequence(tmp_path / "gap", random_sequence(frames=4))
    (tmp_path / "gap" / "frame_00002.obj").unlink()
    with pytest.raises(InputError, match="gap: frame files are not numbered 0..2: frame_00002.obj is missing"):
        read_obj_sequence(tmp_path / "gap")
    write_obj_sequence(tmp_path / "topo", random_sequence(frames=3))
    (tmp_path / "topo" / "frame_00001.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match="frame_00001.obj: topology differs from frame_00000.obj"):
        read_obj_sequence(tmp_path / "topo")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="empty: no frame_"):
        read_obj_sequence(tmp_path / "empty")
    write_obj_sequence(tmp_path / "bodies", random_sequence(frames=3))
    (tmp_path / "bodies" / "body_00002.obj").unlink()
    with pytest.raises(InputError, match="bodies: 3 garment frames but 2 body frames"):
        read_obj_sequence(tmp_path / "bodies")
