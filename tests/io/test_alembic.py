"""Alembic through Blender: bit-exact round trips of garment and body, frame rate, single frames, errors."""

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.io.alembic import read_alembic, write_alembic
from tests.io.conftest import random_sequence


def test_round_trip_is_exact(tmp_path):
    seq = random_sequence(fps=29.97)
    write_alembic(tmp_path / "a.abc", seq)
    assert (tmp_path / "a.abc").read_bytes()[:5] == b"Ogawa"
    back = read_alembic(tmp_path / "a.abc")
    assert np.array_equal(back.verts, seq.verts) and np.array_equal(back.faces, seq.faces) and back.fps == 29.97
    assert np.array_equal(back.extra["body_verts"], seq.extra["body_verts"])
    assert np.array_equal(back.extra["body_faces"], seq.extra["body_faces"])
    assert [p.name for p in tmp_path.iterdir()] == ["a.abc"]  # no temporary file or cache left behind


def test_single_frame(tmp_path):
    seq = random_sequence(frames=1, fps=30.0)
    seq.extra.clear()
    write_alembic(tmp_path / "one.abc", seq)
    back = read_alembic(tmp_path / "one.abc")
    assert np.array_equal(back.verts, seq.verts) and back.fps == 30.0 and back.extra == {}


def test_bad_files_name_the_file(tmp_path):
    (tmp_path / "junk.abc").write_bytes(b"junk" * 10)
    with pytest.raises(InputError, match="junk.abc: Blender cannot read it as an Alembic archive"):
        read_alembic(tmp_path / "junk.abc")
    (tmp_path / "empty.abc").write_bytes(b"")
    with pytest.raises(InputError, match="empty.abc: cannot read Alembic file"):
        read_alembic(tmp_path / "empty.abc")
