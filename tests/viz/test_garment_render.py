"""``loosefit render G.obj``: a garment mesh on the body at rest, or skinned to it along a motion; the same
picture as the mesh-sequence .npz of the same meshes."""

from __future__ import annotations

import imageio.v3 as imageio
import numpy as np
import pytest

from loosefit.cli import main
from loosefit.garment import make_garment
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.sim.attach import body_lbs
from loosefit.viz.inputs import load_panels
from loosefit.viz.render import render_frames
from loosefit.viz.scene import Camera

SIZE = ["--width", "160", "--height", "120", "--backend", "matplotlib"]


@pytest.fixture(scope="module")
def skirt(body, tmp_path_factory):
    """A skirt template saved as loosefit writes garments (OBJ and sidecar): ``(garment, path)``."""
    g = make_garment("skirt", body, seed=2, edge_length=0.05)
    path = tmp_path_factory.mktemp("garment") / "skirt.obj"
    g.save(path)
    return g, path


def as_npz(path, garment_verts, faces, body_verts, body_faces):
    MeshSequence(garment_verts, faces, 30.0, {"body_verts": body_verts, "body_faces": body_faces}).save(path)
    return path


def same_tracks(a, b):
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.verts, y.verts)
        np.testing.assert_array_equal(x.faces, y.faces)


def test_garment_on_the_rest_body(tmp_path, body, skirt):
    g, obj = skirt
    npz = as_npz(tmp_path / "skirt.npz", g.verts[None], g.faces, body.rest_verts()[None], body.faces)
    (panel,) = load_panels(obj)
    same_tracks(panel, load_panels(npz)[0])
    assert [t.label for t in panel] == ["body", "skirt"]
    assert main(["render", str(obj), "--out", str(tmp_path / "obj.png"), *SIZE]) == 0
    assert main(["render", str(npz), "--out", str(tmp_path / "npz.png"), *SIZE]) == 0
    image = imageio.imread(tmp_path / "obj.png")[..., :3].astype(int)
    assert np.abs(image - imageio.imread(tmp_path / "npz.png")[..., :3]).max() <= 1
    assert (image.min(-1) < 200).mean() > 0.05  # not blank: the body and the skirt fill part of it
    # The skirt's front, seen from the front: garment blue where it projects, body colour without it.
    camera = Camera((0.0, -4.0, 0.95), (0.0, 0.0, 0.95))
    with_skirt = render_frames([panel], (160, 120), camera, backend="matplotlib", titles=[""])[0].astype(int)
    bare = render_frames([panel[:1]], (160, 120), camera, backend="matplotlib", titles=[""])[0].astype(int)
    front = g.verts[np.argsort(g.verts[:, 1])[:10]]  # the ten nearest the camera
    for col, row in camera.project(front, (160, 120))[0]:
        r, gr, b = with_skirt[int(row), int(col)]
        assert b > r + 40 and b > gr + 20, (r, gr, b)
        assert not np.array_equal(with_skirt[int(row), int(col)], bare[int(row), int(col)])


def test_garment_follows_the_motion(tmp_path, body, skirt, capsys):
    g, obj = skirt
    motion = body.rest_motion(4)
    motion.translation[:, 0] += np.float32([0.0, 0.1, 0.2, 0.3])  # walks 30 cm along +X
    motion.rotations[:, body.joint_names.index("LeftUpLeg"), 0] = np.float32([0.0, -0.2, -0.4, -0.6])
    motion.name = "step"
    motion.save(tmp_path / "step.npz")
    (panel,) = load_panels(obj, motion=tmp_path / "step.npz")
    lbs = body_lbs(g.verts, body, motion)
    npz = as_npz(tmp_path / "posed.npz", lbs, g.faces, body.pose(motion).verts, body.faces)
    same_tracks(panel, load_panels(npz)[0])
    assert panel[0].label == "step" and panel[1].verts.shape == (4, g.num_verts, 3)
    # The waistband moves with the hips: 30 cm along +X at frame 3.
    waist = g.verts[:, 2] > g.verts[:, 2].max() - 0.02
    np.testing.assert_allclose(panel[1].verts[3, waist] - g.verts[waist], [[0.3, 0.0, 0.0]] * int(waist.sum()),
                               atol=2e-3)
    png = tmp_path / "frame.png"
    assert main(["render", str(obj), "--motion", str(tmp_path / "step.npz"), "--out", str(png)] + SIZE) == 2
    assert "--frame K" in capsys.readouterr().err  # four frames, one PNG
    assert main(["render", str(obj), "--motion", str(tmp_path / "step.npz"), "--frame", "3", "--out", str(png)]
                + SIZE) == 0
    expected = render_frames(load_panels(npz), size=(160, 120), frames=[3], backend="matplotlib",
                             titles=["step + skirt"])[0]  # the .npz's title would be its own labels
    assert np.abs(imageio.imread(png)[..., :3].astype(int) - expected).max() <= 1


def test_bad_garment_inputs_name_the_file(tmp_path, body, skirt, capsys):
    g, obj = skirt
    cm = tmp_path / "cm.obj"  # a mesh from another tool: centimetres, never imported
    cm.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in (g.verts * 100).tolist())
                  + "".join(f"f {a} {b} {c}\n" for a, b, c in (g.faces + 1).tolist()))
    assert main(["render", str(cm), "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert f"{cm}: the garment is not on the body's rest pose: its largest side is" in err
    assert "loosefit garment import" in err and "Traceback" not in err
    npz = as_npz(tmp_path / "s.npz", g.verts[None], g.faces, body.rest_verts()[None], body.faces)
    assert main(["render", str(npz), "--motion", str(obj), "--out", str(tmp_path / "x.png")]) == 2
    assert "--motion poses a garment mesh" in capsys.readouterr().err
    shifted = tmp_path / "shifted.obj"
    shifted.write_text("".join(f"v {x + 3.0} {y} {z}\n" for x, y, z in g.verts.tolist())
                       + "".join(f"f {a} {b} {c}\n" for a, b, c in (g.faces + 1).tolist()))
    assert main(["render", str(shifted), "--out", str(tmp_path / "x.png")]) == 2
    assert "m away from the body" in capsys.readouterr().err
    assert main(["render", str(obj), "--motion", str(tmp_path / "missing.npz"), "--out", str(tmp_path / "x.png")]) == 2
    assert f"{tmp_path / 'missing.npz'}: motion file not found" in capsys.readouterr().err
