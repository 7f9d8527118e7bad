"""Root jumps: a far first frame (a rest pose put before the motion) dropped at import unless kept; later
jumps warned about with their frames; plans keep their frames."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from loosefit.motion.amass import export_amass
from loosefit.motion.bvh import import_bvh, write_bvh
from loosefit.motion.io import load_motion, read_motion
from loosefit.motion.jumps import MAX_ROOT_SPEED, far_first_frame, jump_frames
from loosefit.motion.motion import Motion
from tests.motion.test_retarget import smooth_motion, to_bvh

SRC = Path(__file__).parents[2] / "src"
# Where the prepended rest frame stands: 1.58 m from where the motion starts (47 m/s at 30 fps), as the
# converted CMU clips put a T-pose 1.7-2.2 m away.
AWAY = np.array([1.5, -0.5, 0.0])


def _prepended(motion: Motion, body) -> Motion:
    """``motion`` with a rest frame (every joint at rest) put before it, :data:`AWAY` from its first frame."""
    rot = np.concatenate([np.zeros((1,) + motion.rotations.shape[1:], np.float32), motion.rotations])
    trans = np.concatenate([(motion.translation[0] + AWAY)[None], motion.translation])
    return Motion(rot, trans, motion.fps, motion.rig, motion.joint_names, motion.name)


def _jump_records(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "loosefit.motion.jumps"]


@pytest.fixture
def clips(body, tmp_path):
    """``(motion, ordinary.bvh, rested.bvh)``: a smooth 1 s motion at 30 fps (walking 0.85 m/s), as BVH
    (Y up, centimetres), and the same with a far rest frame put before it."""
    motion = smooth_motion(body, 30.0)
    write_bvh(tmp_path / "ordinary.bvh", to_bvh(body, motion, up="y", scale=100.0))
    write_bvh(tmp_path / "rested.bvh", to_bvh(body, _prepended(motion, body), up="y", scale=100.0))
    return motion, tmp_path / "ordinary.bvh", tmp_path / "rested.bvh"


def test_speed_checks():
    root = np.zeros((5, 3))
    root[1:, 0] = 2.0  # frame 0 is 2 m away: 60 m/s at 30 fps
    assert far_first_frame(root, 30.0) == pytest.approx(60.0)
    assert far_first_frame(root[1:], 30.0) is None and far_first_frame(root[:1], 30.0) is None
    root[4, 0] = 2.0 + MAX_ROOT_SPEED / 30.0 * 1.01  # just beyond the limit
    assert jump_frames(root, 30.0).tolist() == [0, 3]
    root[4, 0] = 2.0 + MAX_ROOT_SPEED / 30.0 * 0.99
    assert jump_frames(root, 30.0).tolist() == [0]


def test_far_first_frame_dropped_by_default_kept_on_request(body, clips, caplog):
    _, ordinary, rested = clips
    reference = import_bvh(ordinary, body)
    with caplog.at_level(logging.WARNING, logger="loosefit.motion"):
        dropped = load_motion(rested, body)
    notes = _jump_records(caplog)
    assert len(notes) == 1 and "\n" not in notes[0]
    assert str(rested) in notes[0] and "frame 0" in notes[0] and "dropped" in notes[0]
    assert "--keep-first-frame" in notes[0] and "1.58 m" in notes[0]
    # The frame is dropped before retargeting: the rest are the ordinary file's frames exactly.
    assert dropped.num_frames == reference.num_frames
    assert np.allclose(dropped.rotations, reference.rotations, atol=1e-5)
    assert np.allclose(dropped.translation, reference.translation, atol=1e-5)

    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="loosefit.motion"):
        kept = load_motion(rested, body, keep_first_frame=True)
    assert kept.num_frames == reference.num_frames + 1
    assert np.linalg.norm(kept.translation[1] - kept.translation[0]) == pytest.approx(np.linalg.norm(AWAY), abs=0.05)
    (warning,) = _jump_records(caplog)  # kept: the jump it makes is said, not dropped
    assert "between frames 0 and 1" in warning and "keeps it" not in warning


def test_amass_far_first_frame(body, tmp_path, caplog):
    motion = smooth_motion(body, 30.0, seconds=0.5)
    export_amass(tmp_path / "plain.npz", motion, body)
    export_amass(tmp_path / "rested.npz", _prepended(motion, body), body)
    with caplog.at_level(logging.WARNING, logger="loosefit.motion"):
        plain = load_motion(tmp_path / "plain.npz", body)
        assert not _jump_records(caplog)
        dropped = load_motion(tmp_path / "rested.npz", body)
    (note,) = _jump_records(caplog)
    assert str(tmp_path / "rested.npz") in note and "frame 0" in note
    assert dropped.num_frames == plain.num_frames
    assert np.abs(body.pose(dropped).joints - body.pose(plain).joints).max() < 1e-4
    assert load_motion(tmp_path / "rested.npz", body, keep_first_frame=True).num_frames == plain.num_frames + 1


def test_later_jump_is_warned_with_its_frames(body, tmp_path, caplog):
    motion = smooth_motion(body, 30.0)
    motion.translation[15:] += [1.0, 0.0, 0.0]  # two takes spliced between frames 14 and 15
    write_bvh(tmp_path / "spliced.bvh", to_bvh(body, motion, up="y", scale=100.0))
    with caplog.at_level(logging.WARNING, logger="loosefit.motion"):
        loaded = load_motion(tmp_path / "spliced.bvh", body)
    (warning,) = _jump_records(caplog)
    assert loaded.num_frames == motion.num_frames  # nothing dropped
    assert str(tmp_path / "spliced.bvh") in warning and "between frames 14 and 15 (0.47 s" in warning


def test_ordinary_file_untouched(body, clips, caplog):
    motion, ordinary, _ = clips
    with caplog.at_level(logging.WARNING, logger="loosefit.motion"):
        default = load_motion(ordinary, body)
        kept = load_motion(ordinary, body, keep_first_frame=True)
    assert not _jump_records(caplog)
    assert default.num_frames == kept.num_frames == motion.num_frames
    assert np.array_equal(default.rotations, kept.rotations) and np.array_equal(default.translation, kept.translation)


def test_plan_start_counts_the_files_frames(body, clips, tmp_path, caplog):
    """A plan reads every frame of a file: ``start: 1`` skips the rest frame as it did before the importer
    dropped such frames (the frames bench-real.yaml and demo.yaml simulate stay the same); ``start: 0`` keeps
    it, and the jump is warned about."""
    from loosefit.simulate import load_plan_motion
    from loosefit.sim.plan import load_plan

    _, _, rested = clips
    plan = {"garments": {"g": {"template": "skirt"}},
            "motions": {"skip": {"file": rested.name, "start": 1, "frames": 20},
                        "whole": {"file": rested.name}}}
    (tmp_path / "plan.yaml").write_text(yaml.safe_dump(plan))
    loaded = load_plan(tmp_path / "plan.yaml")
    every = read_motion(rested, body, keep_first_frame=True)
    with caplog.at_level(logging.WARNING, logger="loosefit.motion"):
        skip = load_plan_motion(loaded, "skip")
    assert not _jump_records(caplog)
    assert np.array_equal(skip.rotations, every.rotations[1:21]) and np.array_equal(skip.translation, every.translation[1:21])
    with caplog.at_level(logging.WARNING, logger="loosefit.motion"):
        whole = load_plan_motion(loaded, "whole")
    (warning,) = _jump_records(caplog)
    assert whole.num_frames == every.num_frames and "plan motion 'whole'" in warning
    assert "between frames 0 and 1" in warning


def test_every_verb_that_imports_motions_has_the_flag():
    from loosefit.cli import build_parser

    parser = build_parser()
    for argv in (["body", "--motion", "m.bvh", "--out", "b.npz"],
                 ["motion", "import", "m.bvh", "--out", "m.npz"],
                 ["animate", "run", "--motion", "m.bvh", "--out", "a.npz"],
                 ["simulate", "--garment", "g.obj", "--motion", "m.bvh", "--out", "s.npz"],
                 ["export-rig", "run", "--motion", "m.bvh", "--out", "r.glb"],
                 ["view", "run:m.bvh"]):
        assert parser.parse_args(argv + ["--keep-first-frame"]).keep_first_frame, argv
        assert not parser.parse_args(argv).keep_first_frame, argv
    from loosefit.cli_args import keep_first_frame_option

    class Help:
        def add_argument(self, *names, help="", **kw):
            self.text = help

    keep_first_frame_option(spy := Help())
    assert f"> {MAX_ROOT_SPEED:g} m/s" in spy.text  # the help states the importer's threshold


def test_plan_refuses_the_flag(tmp_path):
    from loosefit.cli import main

    (tmp_path / "plan.yaml").write_text("garments: {g: {template: skirt}}\nmotions: {w: {procedural: walk, seconds: 1}}\n")
    assert main(["simulate", str(tmp_path / "plan.yaml"), "--out", str(tmp_path / "d.zarr"), "--keep-first-frame"]) == 2
    assert not (tmp_path / "d.zarr").exists()


def test_cli_says_it_in_one_line(clips, tmp_path):
    """``loosefit motion import``: one stderr line names the file, the frame and the flag; the flag keeps it."""
    motion, _, rested = clips
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    base = [sys.executable, "-m", "loosefit.cli", "motion", "import", str(rested)]
    done = subprocess.run(base + ["--out", str(tmp_path / "d.npz")], capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stderr.splitlines() if "frame 0" in line]
    assert len(lines) == 1 and str(rested) in lines[0] and "--keep-first-frame" in lines[0], done.stderr
    assert Motion.load(tmp_path / "d.npz").num_frames == motion.num_frames
    kept = subprocess.run(base + ["--out", str(tmp_path / "k.npz"), "--keep-first-frame"], capture_output=True,
                          text=True, env=env)
    assert kept.returncode == 0, kept.stderr
    assert Motion.load(tmp_path / "k.npz").num_frames == motion.num_frames + 1
