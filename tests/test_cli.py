"""The command line end to end: each verb writes what it says, and bad input exits 2 with the file named."""

import json

import imageio.v3 as imageio
import numpy as np
import pytest
import trimesh
import torch

from loosefit.cli import main
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.motion import Motion
from loosefit.viz.inputs import load_panels
from loosefit.viz.render import render_frames


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
    assert "--frame K" in capsys.readouterr().err  # a PNG holds one frame; 15 were given
    assert main(["render", str(tmp_path / "body.npz"), "--out", str(png), "--frame", "14", "--width", "64",
                 "--height", "48", "--backend", "matplotlib"]) == 0
    last = render_frames(load_panels(tmp_path / "body.npz"), size=(64, 48), frames=[14], backend="matplotlib")[0]
    assert np.array_equal(imageio.imread(png)[..., :3], last)  # the frame asked for, as render_frames draws it
    assert main(["render", str(tmp_path / "body.npz"), "--out", str(png), "--frame", "15"]) == 2
    assert "out of range" in capsys.readouterr().err
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


def test_evaluate_measures_the_surface_inside_a_body_at_a_given_depth(tmp_path, capsys):
    """A triangle across a unit box (its corners outside, its centroid 0.3 m deep, two edge midpoints 75 and 95 mm
    deep): at --surface-depth 0.08 one midpoint and the centroid count, half the samples."""
    from tests.metrics.conftest import TRIANGLE

    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    faces = np.array([[0, 1, 2]])
    MeshSequence(np.repeat(TRIANGLE[None], 2, 0).astype(np.float32), faces).save(tmp_path / "tri.npz")
    MeshSequence(np.repeat(np.asarray(box.vertices)[None], 2, 0).astype(np.float32), np.asarray(box.faces)).save(
        tmp_path / "box.npz")
    assert main(["evaluate", str(tmp_path / "tri.npz"), str(tmp_path / "tri.npz"), "--body", str(tmp_path / "box.npz"),
                 "--surface-depth", "0.08", "--out", str(tmp_path)]) == 0
    doc = json.loads((tmp_path / "metrics.json").read_text())
    assert doc["settings"]["surface_depth"] == 0.08
    assert doc["overall"]["collision_pct"] == 0.0 and doc["overall"]["surface_inside_pct"] == pytest.approx(50.0)
    assert doc["overall"]["deepest_mm"] == pytest.approx(300.0, abs=0.01)
    assert "surface >80mm %" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exc:
        main(["evaluate", str(tmp_path / "tri.npz"), str(tmp_path / "tri.npz"), "--surface-depth", "-1"])
    assert exc.value.code == 2 and "--surface-depth: must be a number >= 0" in capsys.readouterr().err


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


def test_motion_map_import_with_it_and_cut(tmp_path, body, capsys):
    """An unknown skeleton: import refuses it naming `loosefit motion map`; the map it writes imports
    the file, cut by --start / --seconds to the same frames as the whole import; a map with an unknown
    key lists the allowed ones; --help documents the YAML format; generate cuts too."""
    from loosefit.motion.bvh import write_bvh
    from loosefit.motion.procedural import generate
    from tests.motion.test_retarget import smooth_motion, to_bvh

    bvh, out = tmp_path / "odd.bvh", tmp_path / "m.npz"
    names = [f"bone{j:02d}" for j in range(body.num_joints)]
    write_bvh(bvh, to_bvh(body, smooth_motion(body, 60.0, seconds=1.0), names=names, up="y", scale=100.0))
    assert main(["motion", "import", str(bvh), "--out", str(out)]) == 2
    assert "loosefit motion map FILE.bvh --out MAP.yaml" in capsys.readouterr().err and not out.exists()
    assert main(["motion", "map", str(bvh), "--out", str(tmp_path / "map.yaml")]) == 0
    assert "check it, then pass it with --joint-map" in capsys.readouterr().out
    assert main(["motion", "import", str(bvh), "--joint-map", str(tmp_path / "map.yaml"), "--out", str(out)]) == 0
    whole = Motion.load(out)
    assert main(["motion", "import", str(bvh), "--joint-map", str(tmp_path / "map.yaml"), "--start", "0.2",
                 "--seconds", "0.5", "--out", str(out)]) == 0
    part = Motion.load(out)
    assert part.num_frames == 15 and np.array_equal(part.rotations, whole.rotations[6:21])
    assert main(["motion", "import", str(bvh), "--joint-map", str(tmp_path / "map.yaml"), "--start", "0.9",
                 "--seconds", "0.5", "--out", str(out)]) == 2
    assert "past the end of the motion (1.03333 s" in capsys.readouterr().err
    (tmp_path / "bad.yaml").write_text("joints: {Hips: bone00}\nup_axis: y\n")
    assert main(["motion", "import", str(bvh), "--joint-map", str(tmp_path / "bad.yaml"), "--out", str(out)]) == 2
    assert "unknown keys ['up_axis']; the allowed keys are name, target_rig, joints, ignore" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["motion", "map", "--help"])
    assert "ignore: [prop_*" in capsys.readouterr().out

    assert main(["motion", "generate", "--kind", "walk", "--seconds", "0.5", "--start", "1", "--out", str(out)]) == 0
    assert np.array_equal(Motion.load(out).rotations, generate("walk", 1.5, 0, body).rotations[30:45])


def test_every_verb_reading_a_bvh_takes_a_joint_map():
    from loosefit.cli import build_parser

    parser = build_parser()
    for argv in (["body", "--motion", "x.bvh", "--out", "b.npz"], ["motion", "import", "x.bvh", "--out", "m.npz"],
                 ["animate", "run", "--motion", "x.bvh", "--out", "a.npz"], ["simulate", "--garment", "g.obj",
                 "--motion", "x.bvh", "--out", "s.npz"]):
        assert parser.parse_args(argv + ["--joint-map", "map.yaml"]).joint_map == "map.yaml"


def test_render_holds_the_last_frame_of_shorter_sequences(tmp_path):
    """Two sequences of 4 and 10 frames side by side: 10 frames, the short one standing still after its 4th."""
    import imageio.v3 as iio

    faces = np.array([[0, 1, 2]])
    tri = np.array([[0.0, 0, 0], [0.3, 0, 0], [0.0, 0, 0.3]], np.float32)
    short = tri + np.arange(4, dtype=np.float32)[:, None, None] * [0.0, 0.0, 0.05]
    long = tri + np.arange(10, dtype=np.float32)[:, None, None] * [0.0, 0.0, 0.05]
    MeshSequence(short, faces).save(tmp_path / "short.npz")
    MeshSequence(long, faces).save(tmp_path / "long.npz")
    frames = tmp_path / "frames"
    assert main(["render", str(tmp_path / "short.npz"), str(tmp_path / "long.npz"), "--out", str(frames),
                 "--width", "64", "--height", "48", "--backend", "matplotlib"]) == 0
    images = [iio.imread(p) for p in sorted(frames.glob("*.png"))]
    assert len(images) == 10
    left = [im[:, :64] for im in images]
    assert not np.array_equal(left[2], left[3]) and all(np.array_equal(left[3], im) for im in left[4:])
    assert not np.array_equal(images[3][:, 64:], images[9][:, 64:])


def test_prepare_settings_overrides_are_checked_before_the_store_is_opened(tmp_path, capsys):
    store = tmp_path / "none.zarr"
    assert main(["prepare", str(store), "--set", "bone=3"]) == 2
    err = capsys.readouterr().err
    assert "unknown key 'bone'" in err and "'bones'" in err and "'influences'" in err  # the allowed keys
    assert main(["prepare", str(store), "--set", "influences=many"]) == 2
    assert "'influences': expected an integer" in capsys.readouterr().err
    assert not store.exists()
