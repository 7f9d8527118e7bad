"""export_animation / read_animation: every format round-trips positions, faces, fps and body; bad input is refused."""

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.io.export import export_animation, export_files, read_animation
from loosefit.io.obj import read_obj
from loosefit.io.pc2 import read_pc2

# (output name, tolerance in metres): 0 = bit-exact float32; glTF adds one float32 rounding, OBJ is 7-digit text
FORMATS = [
    ("a.npz", 0.0),
    ("a.usdc", 0.0),
    ("a.usda", 0.0),
    ("a.glb", 1e-6),
    ("a.abc", 0.0),
    ("a.pc2", 0.0),
    ("frames", 1e-6),
    ("frames/", 1e-6),
]


def _arrays(seed=0, frames=10, verts=50):
    """Random garment ``(frames, verts, 3)`` within 1 m of the origin, triangles, and a 20-vertex body."""
    rng = np.random.default_rng(seed)
    garment = rng.uniform(-1, 1, size=(frames, verts, 3)).astype(np.float32)
    faces = np.argsort(rng.random((80, verts)), axis=1)[:, :3]
    body = rng.uniform(-1, 1, size=(frames, 20, 3)).astype(np.float32)
    body_faces = np.argsort(rng.random((30, 20)), axis=1)[:, :3]
    return garment, faces, body, body_faces


@pytest.mark.parametrize("name, tolerance", FORMATS)
def test_every_format_round_trips(tmp_path, name, tolerance):
    verts, faces, body, body_faces = _arrays()
    written = export_animation(tmp_path / name, verts, faces, fps=25.0, body_verts=body, body_faces=body_faces)
    back = read_animation(written)
    assert back.verts.dtype == np.float32 and back.verts.shape == verts.shape
    assert np.abs(back.verts - verts).max() <= tolerance
    assert np.abs(back.extra["body_verts"] - body).max() <= tolerance
    assert np.array_equal(back.faces, faces) and np.array_equal(back.extra["body_faces"], body_faces)
    assert back.fps == 25.0


@pytest.mark.parametrize("name", ["a.npz", "a.usdc", "a.glb", "a.pc2", "frames"])
def test_without_body(tmp_path, name):
    verts, faces, _, _ = _arrays(seed=1, frames=3)
    back = read_animation(export_animation(tmp_path / name, verts, faces))
    assert back.extra == {} and back.fps == 30.0 and np.abs(back.verts - verts).max() <= 1e-6


def test_pc2_pair_layout(tmp_path):
    verts, faces, body, body_faces = _arrays()
    export_animation(tmp_path / "anim.pc2", verts, faces, 30.0, body, body_faces)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim.obj", "anim.pc2", "anim_body.obj", "anim_body.pc2"]
    frames, _, _ = read_pc2(tmp_path / "anim.pc2")
    assert np.array_equal(frames, verts)
    rest, rest_faces = read_obj(tmp_path / "anim.obj")
    assert np.abs(rest - verts[0]).max() < 1e-6 and np.array_equal(rest_faces, faces)
    assert sorted(p.name for p in export_files(tmp_path / "anim.pc2", body=True)) == sorted(
        p.name for p in tmp_path.iterdir())  # what a caller checks before the work is what is written
    (tmp_path / "anim.obj").unlink()
    with pytest.raises(InputError, match="anim.pc2: a .pc2 file holds no triangles; expected them in anim.obj"):
        read_animation(tmp_path / "anim.pc2")


@pytest.mark.parametrize("name", ["a.npz", "a.glb", "frames"])
def test_export_files_of_one_file_formats(tmp_path, name):
    verts, faces, body, body_faces = _arrays()
    export_animation(tmp_path / name, verts, faces, 30.0, body, body_faces)
    assert [p.name for p in export_files(tmp_path / name, body=True)] == [p.name for p in tmp_path.iterdir()]


@pytest.mark.parametrize(
    "change, problem",
    [
        (lambda a: a["verts"].__setitem__((2, 7, 1), np.nan), r"garment verts are not finite \(NaN or inf\) at frame 2, vertex 7"),
        (lambda a: a.update(faces=a["faces"] + 1), r"garment faces index vertices outside \[0, 50\): min 1, max 50"),
        (lambda a: a.update(faces=a["faces"].astype(float)), "garment faces must be integer triangles"),
        (lambda a: a.update(verts=a["verts"][0]), r"garment verts must have shape \(T, V, 3\)"),
        (lambda a: a.update(fps=0.0), "fps must be a positive number"),
        (lambda a: a.update(body_faces=None), "body_verts and body_faces go together"),
        (lambda a: a.update(body_verts=a["body_verts"][:4]), "body has 4 frames, garment 10"),
        (lambda a: a.update(body_faces=a["body_faces"] - 1), r"body faces index vertices outside \[0, 20\)"),
    ],
)
def test_bad_input_is_refused_and_nothing_written(tmp_path, change, problem):
    verts, faces, body, body_faces = _arrays()
    arguments = dict(verts=verts, faces=faces, fps=30.0, body_verts=body, body_faces=body_faces)
    change(arguments)
    with pytest.raises(InputError, match=f"out.glb: {problem}"):
        export_animation(tmp_path / "out.glb", **arguments)
    assert list(tmp_path.iterdir()) == []


def test_unknown_or_missing_paths(tmp_path):
    verts, faces, _, _ = _arrays()
    with pytest.raises(InputError, match=r"anim.fbx: unknown animation format '.fbx'; use one of .npz, .usdc"):
        export_animation(tmp_path / "anim.fbx", verts, faces)
    (tmp_path / "anim.fbx").write_bytes(b"x")
    with pytest.raises(InputError, match="anim.fbx: unknown animation format"):
        read_animation(tmp_path / "anim.fbx")
    with pytest.raises(InputError, match="nothing.glb: no such animation file or folder"):
        read_animation(tmp_path / "nothing.glb")
