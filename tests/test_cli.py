"""The command line end to end: each verb writes what it says, and bad input exits 2 with the file named."""

import json

import numpy as np
import pytest
import trimesh
import torch

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


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the error on a machine without CUDA")
def test_cuda_without_cuda_and_bad_nproc_are_clear_errors(tiny_store, tmp_path, capsys):
    common = ["--data", str(tiny_store), "--garment", "skirt+average", "--set", "train.progress=false"]
    assert main(["train", "--method", "jointnet", "--out", str(tmp_path / "jn"), "--device", "cuda", *common]) == 2
    assert "device 'cuda' was asked for but CUDA is not available" in capsys.readouterr().err
    assert not (tmp_path / "jn" / "checkpoints" / "last.pt").exists()
    assert main(["train", "--method", "jointnet", "--out", str(tmp_path / "jn2"), "--nproc", "0", *common]) == 2
    assert "--nproc must be >= 1" in capsys.readouterr().err
    assert main(["train", "--method", "body-lbs", "--out", str(tmp_path / "lbs"), *common[:4]]) == 0
    motion = tmp_path / "walk.npz"
    assert main(["motion", "generate", "--kind", "walk", "--seconds", "0.2", "--out", str(motion)]) == 0
    capsys.readouterr()
    assert main(["animate", str(tmp_path / "lbs"), "--motion", str(motion), "--out", str(tmp_path / "a.npz"),
                 "--device", "cuda"]) == 2
    assert "CUDA is not available" in capsys.readouterr().err
