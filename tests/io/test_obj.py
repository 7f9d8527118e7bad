"""OBJ reading: vertices and triangles back from write_obj and from hand-written files in other dialects."""

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.io.obj import read_obj, write_obj


def test_read_obj_inverts_write_obj(tmp_path):
    rng = np.random.default_rng(0)
    verts = rng.normal(size=(50, 3)).astype(np.float32)
    faces = np.argsort(rng.random((80, 50)), axis=1)[:, :3]
    write_obj(tmp_path / "m.obj", verts, faces, header="fps 30")
    back_verts, back_faces = read_obj(tmp_path / "m.obj")
    assert back_verts.dtype == np.float32 and back_faces.dtype == np.int64
    assert (np.abs(back_verts - verts) <= 6e-7 * np.abs(verts)).all()  # 7 significant digits, then float32
    assert np.array_equal(back_faces, faces)


def test_read_obj_dialects(tmp_path):
    text = """# other tool
o thing
v 0 0 0
v 1 0 0
vt 0 0
vn 0 0 1
v 0 1 0
v 1 1 0.5
usemtl cloth
f 1/1/1 2/1/1 3/1/1
f 2//1 4//1 3//1
f -3 -1 -2
"""
    (tmp_path / "d.obj").write_text(text)
    verts, faces = read_obj(tmp_path / "d.obj")
    assert np.array_equal(verts, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.5]])
    assert np.array_equal(faces, [[0, 1, 2], [1, 3, 2], [1, 3, 2]])


@pytest.mark.parametrize(
    "text, problem",
    [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 4 3\n", "line 5: face with 4 corners"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "outside"),
        ("v 0 0\n", "line 1: vertex with 2 coordinates"),
        ("v 0 0 x\n", "malformed"),
    ],
)
def test_read_obj_errors_name_the_file(tmp_path, text, problem):
    (tmp_path / "bad.obj").write_text(text)
    with pytest.raises(InputError, match=f"bad.obj: .*{problem}"):
        read_obj(tmp_path / "bad.obj")
