"""The command line end to end: each verb writes what it says, and bad input exits 2 with the file named."""

import json

import numpy as np
import pytest
import trimesh

from loosefit.cli import main
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.motion import Motion


def test_body_motion_garment_render(tmp_path, body, capsys):
    m = tmp_path / "spin.npz"
    assert main(["motion", "generate", "--kind", "spin", "--seconds", "0.5", "--seed", "3", "--out", str(m)]) == 0
    motion = Motion.load(m)
    assert motion.num_frames == 15 and motion.rig == "cmu_mb"

    assert main(["body", "--motion", str(m), "--out", str(tmp_path / "body.npz")]) == 0
    seq = MeshSequence.load(tmp_path / "body.npz")
    assert seq.verts.shape == (15, body.num_verts, 3)
    assert np.abs(seq.verts - body.pose(motion).verts).max() < 1e-6

    assert main(["body", "--shape", "height=0.9", "--out", str(tmp_path / "tall.obj")]) == 0
    tall = trimesh.load(tmp_path / "tall.obj", process=False)
    assert tall.vertices[:, 2].max() > body.rest_verts()[:, 2].max() + 0.05

    g = tmp_path / "skirt.obj"
    assert main(["garment", "make", "--kind", "skirt", "--seed", "2", "--edge-length", "0.04", "--out", str(g)]) == 0
    assert g.exists() and (tmp_path / "skirt.json").exists()

    png = tmp_path / "frame.png"
    assert main(["render", str(tmp_path / "body.npz"), "--out", str(png), "--width", "64", "--height", "48"]) == 2
    assert "one frame" in capsys.readouterr().err  # a PNG holds one frame; 15 were given
    assert main(["render", str(tmp_path / "body.npz"), "--out", str(tmp_path / "body.gif"),
                 "--width", "64", "--height", "48", "--backend", "matplotlib"]) == 0
    assert (tmp_path / "body.gif").stat().st_size > 0


def test_evaluate_writes_tables(tmp_path, capsys):
    rng = np.random.default_rng(0)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    gt = rng.normal(size=(5, 4, 3)).astype(np.float32)
    MeshSequence(gt, faces).save(tmp_path / "gt.npz")
    MeshSequence(gt + np.float32(0.01), faces).save(tmp_path / "pred.npz")  # every vertex off by 1 cm in x, y, z
    assert main(["evaluate", str(tmp_path / "pred.npz"), str(tmp_path / "gt.npz"), "--out", str(tmp_path)]) == 0
    overall = json.loads((tmp_path / "metrics.json").read_text())["overall"]
    assert overall["rmse_mm"] == pytest.approx(10 * np.sqrt(3), rel=1e-4)
    assert overall["mean_vertex_error_mm"] == pytest.approx(10 * np.sqrt(3), rel=1e-4)
    assert overall["sted"] < 1e-6  # a translation keeps every edge length
    assert "17.32" in capsys.readouterr().out and (tmp_path / "metrics.csv").exists()


@pytest.mark.parametrize(
    "argv, message",
    [
        (["motion", "import", "{tmp}/missing.bvh", "--out", "{tmp}/m.npz"], "missing.bvh"),
        (["body", "--shape", "tallness=2", "--out", "{tmp}/b.obj"], "tallness"),
        (["info", "{tmp}/nothing.zarr"], "nothing.zarr"),
    ],
)
def test_bad_input_exits_2_naming_the_problem(tmp_path, capsys, argv, message):
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    assert message in capsys.readouterr().err


def test_prepare_settings_overrides_are_checked_before_the_store_is_opened(tmp_path, capsys):
    store = tmp_path / "none.zarr"
    assert main(["prepare", str(store), "--set", "bone=3"]) == 2
    err = capsys.readouterr().err
    assert "unknown key 'bone'" in err and "'bones'" in err and "'influences'" in err  # the allowed keys
    assert main(["prepare", str(store), "--set", "influences=many"]) == 2
    assert "'influences': expected an integer" in capsys.readouterr().err
    assert not store.exists()
