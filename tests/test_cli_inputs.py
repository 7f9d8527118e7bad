"""Bad input to the command line: a clear one-line error and exit status 2, never a traceback, never code
run from a file, never an option or a value silently ignored; outputs are checked before the work."""

from __future__ import annotations

import struct
import zipfile

import numpy as np
import pytest

from loosefit.cli import main
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.motion import Motion


def _error(capsys, argv, verb) -> str:
    """Run ``loosefit argv``; it must exit 2 with a ``loosefit VERB: error: ...`` line (the last of stderr: libraries
    may warn before it) and no traceback; returns that line."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and err.splitlines()[-1].startswith(f"loosefit {verb}: error: "), err
    return err.splitlines()[-1]


def _usage_error(capsys, argv, option) -> str:
    """An argparse usage error (exit 2) about ``option``, without a traceback."""
    with pytest.raises(SystemExit) as exc:
        main([str(a) for a in argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}: " in err and "Traceback" not in err, err
    return err


@pytest.fixture
def a_file(tmp_path):
    path = tmp_path / "plain.txt"
    path.write_text("keep me")
    return path


PLAN = """\
name: p
garments:
  skirt: {template: skirt, edge_length: 0.05}
motions:
  walk: {procedural: walk, seconds: 1}
"""


@pytest.mark.parametrize("option, value, key", [
    ("--set", "backend=foo", "sim_params"),
    ("--params", "params.yaml", "sim_params"),
    ("--shape", "height=0.8", "shapes"),
    ("--joint-map", "cc", "the joint_map of a file motion"),
])
def test_one_sequence_options_are_refused_with_a_plan(tmp_path, capsys, option, value, key):
    plan = tmp_path / "plan.yaml"
    plan.write_text(PLAN)
    err = _error(capsys, ["simulate", plan, "--out", tmp_path / "d.zarr", option, value], "simulate")
    assert f"plan.yaml: options for one sequence (--garment, --motion), not for a plan: {option}; " in err
    assert f"{option} -> {key}" in err
    assert not (tmp_path / "d.zarr").exists()


def test_duplicate_keys_in_plans_params_and_joint_maps(tmp_path, capsys):
    plan = tmp_path / "plan.yaml"
    plan.write_text(PLAN + "  walk: {procedural: spin, seconds: 1}\n")  # the second `walk` would win silently
    err = _error(capsys, ["simulate", plan, "--out", tmp_path / "d.zarr"], "simulate")
    assert f"{plan}: duplicate key 'walk' on line 6 (first on line 5)" in err
    assert not (tmp_path / "d.zarr").exists()
    params = tmp_path / "params.yaml"
    params.write_text("bending: 1.0e-4\nframe_steps: 4\nbending: 1.0\n")
    err = _error(capsys, ["simulate", "--garment", tmp_path / "g.obj", "--motion", tmp_path / "m.npz",
                          "--params", params, "--out", tmp_path / "s.npz"], "simulate")
    assert f"{params}: duplicate key 'bending' on line 3 (first on line 1)" in err

    from loosefit.errors import InputError
    from loosefit.motion.joint_map import load_joint_map

    joint_map = tmp_path / "map.yaml"
    joint_map.write_text("joints:\n  Hips: pelvis\n  LeftUpLeg: l_hip\n  Hips: root\n")
    with pytest.raises(InputError, match=r"map.yaml: cannot read joint map: duplicate key 'Hips' on line 4 "
                                         r"\(first on line 2\)"):
        load_joint_map(joint_map)


def _outputs(tmp_path, a_file):
    """Each verb with an output in a place nobody can write (the tests run as root, which permissions do not stop)."""
    bad = a_file / "out"
    return {
        "body": ["body", "--out", f"{bad}.obj"],
        "motion generate": ["motion", "generate", "--kind", "walk", "--out", f"{bad}.npz"],
        "motion import": ["motion", "import", tmp_path / "clip.bvh", "--out", f"{bad}.npz"],
        "garment make": ["garment", "make", "--kind", "skirt", "--out", f"{bad}.obj"],
        "garment import": ["garment", "import", tmp_path / "g.obj", "--out", "/proc/loosefit/g.obj"],
        "render": ["render", tmp_path / "seq.npz", "--out", f"{bad}.mp4"],
        "render folder": ["render", tmp_path / "seq.npz", "--out", "/proc/frames"],
        "evaluate": ["evaluate", tmp_path / "p.npz", tmp_path / "g.npz", "--out", bad],
        "simulate": ["simulate", "--garment", tmp_path / "g.obj", "--motion", tmp_path / "m.npz", "--out", f"{bad}.npz"],
        "simulate plan": ["simulate", tmp_path / "plan.yaml", "--out", "/proc/d.zarr"],
        "train": ["train", "--method", "jointnet", "--data", tmp_path / "d.zarr", "--out", a_file],
        "train collision": ["train", "--method", "collision", "--data", tmp_path / "d.zarr", "--out", bad],
        "animate": ["animate", tmp_path / "run", "--motion", tmp_path / "m.npz", "--out", f"{bad}.glb"],
        "animate several": ["animate", tmp_path / "run", "--motion", tmp_path / "m.npz", "--motion",
                            tmp_path / "n.npz", "--out", "/proc/anim"],
        "view": ["view", tmp_path / "seq.npz", "--export", "/proc/page"],
    }


@pytest.mark.parametrize("case", ["body", "motion generate", "motion import", "garment make", "garment import",
                                  "render", "render folder", "evaluate", "simulate", "simulate plan", "train",
                                  "train collision", "animate", "animate several", "view"])
def test_unwritable_outputs_are_refused_before_the_work(tmp_path, a_file, capsys, case):
    argv = _outputs(tmp_path, a_file)[case]
    out = argv[argv.index("--export" if case == "view" else "--out") + 1]
    err = _error(capsys, argv, argv[0])  # the inputs do not even exist: the output is checked first
    assert f"error: {out}: cannot write here: " in err
    assert a_file.read_text() == "keep me"


def _flip_a_data_byte(path, member):
    """Flip one byte of ``member``'s stored data in the .npz ``path`` (zip reports a bad CRC or deflate stream)."""
    with zipfile.ZipFile(path) as z:
        info = z.getinfo(f"{member}.npy")
    data = bytearray(path.read_bytes())
    name_len, extra_len = struct.unpack("<HH", data[info.header_offset + 26 : info.header_offset + 30])
    data[info.header_offset + 30 + name_len + extra_len + 30] ^= 0xFF
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("how", ["flipped byte", "truncated"])
def test_damaged_npz_files_name_the_file(tmp_path, capsys, how):
    rng = np.random.default_rng(0)
    seq, motion = tmp_path / "seq.npz", tmp_path / "motion.npz"
    MeshSequence(rng.normal(size=(3, 40, 3)), [[0, 1, 2], [0, 2, 3]]).save(seq)
    Motion(rng.normal(scale=0.1, size=(3, 31, 3)), np.zeros((3, 3)), 30.0).save(motion)
    good = tmp_path / "good.npz"
    MeshSequence(rng.normal(size=(3, 40, 3)), [[0, 1, 2], [0, 2, 3]]).save(good)
    for path, member in ((seq, "verts"), (motion, "rotations")):
        if how == "truncated":
            path.write_bytes(path.read_bytes()[:300])
        else:
            _flip_a_data_byte(path, member)
    cases = [
        (["motion", "import", motion, "--out", tmp_path / "m.npz"], motion),
        (["animate", tmp_path / "run", "--motion", motion, "--out", tmp_path / "a.npz"], motion),
        (["render", motion, "--out", tmp_path / "r.gif"], motion),
        (["evaluate", seq, good, "--out", tmp_path / "e"], seq),
        (["evaluate", good, good, "--body", seq, "--out", tmp_path / "e"], seq),
        (["render", seq, "--out", tmp_path / "r.gif"], seq),
        (["view", seq, "--export", tmp_path / "page"], seq),
    ]
    for argv, bad in cases:
        err = _error(capsys, argv, argv[0])
        assert f"error: {bad}: " in err and ("damaged" in err or "CRC" in err), err
    assert not any((tmp_path / name).exists() for name in ("m.npz", "a.npz", "e", "r.gif", "page"))


def test_evaluate_refuses_bad_and_mismatched_frame_rates(tmp_path, capsys):
    verts, faces = np.random.default_rng(0).normal(size=(4, 4, 3)), [[0, 1, 2], [0, 2, 3]]
    for name, fps in (("gt", 30.0), ("pred60", 60.0), ("neg", -30.0), ("zero", 0.0)):
        MeshSequence(verts, faces, fps).save(tmp_path / f"{name}.npz")
    err = _error(capsys, ["evaluate", tmp_path / "pred60.npz", tmp_path / "gt.npz", "--out", tmp_path / "e"], "evaluate")
    assert f"{tmp_path / 'pred60.npz'}: prediction at 60 fps, ground truth {tmp_path / 'gt.npz'} at 30 fps" in err
    for name in ("neg", "zero"):
        err = _error(capsys, ["evaluate", tmp_path / f"{name}.npz", tmp_path / f"{name}.npz", "--out", tmp_path / "e"],
                     "evaluate")
        assert f"{name}.npz: frame rate must be a positive number, got {-30 if name == 'neg' else 0} fps" in err
    err = _error(capsys, ["evaluate", tmp_path / "gt.npz", tmp_path / "gt.npz", "--body", tmp_path / "pred60.npz",
                          "--out", tmp_path / "e"], "evaluate")
    assert "pred60.npz: body at 60 fps, ground truth" in err
    assert not (tmp_path / "e").exists()
    assert main([str(a) for a in ["evaluate", tmp_path / "gt.npz", tmp_path / "gt.npz", "--out", tmp_path / "e"]]) == 0


@pytest.mark.parametrize("argv, option, message", [
    (["animate", "run", "--motion", "m.npz", "--out", "a.npz", "--threads", "-1"], "--threads", ">= 1, got -1"),
    (["animate", "run", "--motion", "m.npz", "--out", "a.npz", "--threads", "0"], "--threads", ">= 1, got 0"),
    (["view", "s.npz", "--port", "-1"], "--port", "in 0..65535, got -1"),
    (["view", "s.npz", "--port", "70000"], "--port", "in 0..65535, got 70000"),
    (["view", "s.npz", "--port", "http"], "--port", "expected an integer, got 'http'"),
    (["view", "s.npz", "--collision-frames", "-1"], "--collision-frames", ">= 0, got -1"),
    (["simulate", "p.yaml", "--out", "d.zarr", "--workers", "0"], "--workers", ">= 1, got 0"),
    (["render", "s.npz", "--out", "r.gif", "--fps", "-30"], "--fps", "positive number, got -30"),
    (["render", "s.npz", "--out", "r.gif", "--width", "0"], "--width", ">= 1, got 0"),
    (["motion", "generate", "--kind", "walk", "--out", "m.npz", "--seconds", "nan"], "--seconds", "positive"),
    (["motion", "import", "x.npz", "--out", "m.npz", "--start", "-1"], "--start", ">= 0, got -1"),
    (["garment", "make", "--kind", "skirt", "--out", "g.obj", "--edge-length", "0"], "--edge-length", "positive"),
])
def test_bad_numbers_are_usage_errors(capsys, argv, option, message):
    assert message in _usage_error(capsys, argv, option)


def test_one_triangle_is_no_garment(tmp_path, capsys):
    obj = tmp_path / "tri.obj"
    obj.write_text("v 0 0 0\nv 0.5 0 0\nv 0 0.5 0\nf 1 2 3\n")
    err = _error(capsys, ["garment", "import", obj, "--out", tmp_path / "g.obj"], "garment")
    assert f"{obj}: not a garment: 3 vertices, 1 faces with 1 opening(s)" in err
    err = _error(capsys, ["simulate", "--garment", obj, "--motion", tmp_path / "m.npz", "--out", tmp_path / "s.npz"],
                 "simulate")
    assert f"{obj}: not a garment" in err  # the garment is imported before the motion (absent here) is read
    assert not (tmp_path / "g.obj").exists() and not (tmp_path / "s.npz").exists()


def test_body_frame_outside_the_motion_is_refused(tmp_path, capsys):
    """``body --frame`` past the motion's last frame (the rest pose has one) is an error, not an IndexError."""
    assert main(["body", "--frame", "5", "--out", str(tmp_path / "b.obj")]) == 2
    assert "--frame 5 is outside the motion's frames 0..0" in capsys.readouterr().err
    assert not (tmp_path / "b.obj").exists()
