"""The training range of root motion: closed-form motions give their numbers, a run records the range of
its training motions, and animating a motion outside it warns while a training motion does not."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from loosefit.cli import main
from loosefit.data import DatasetStore
from loosefit.motion import Motion
from loosefit.motion_range import (HEIGHT_TOLERANCE_M, META_KEY, SPEED_TOLERANCE, TURN_TOLERANCE, MotionExtent, MotionRange,
                                   range_warnings, root_speeds, root_turn_rates, turn_bouts)
from loosefit.training import MODEL_META, train_model

FPS = 30.0
SMALL_JOINTNET = ["model.gru_hidden=16", "model.features=16", "model.bone_mlp=[32]", "model.psd_mlp=[16]",
                  "model.psd_shapes=4", "train.stages.stage1.epochs=1", "train.stages.stage2.epochs=1",
                  "train.progress=false", "train.tensorboard=false", "data.window=20", "data.stride=10",
                  "data.burn_in=4"]


def closed_form(T=61, height=0.9, speed=1.3, direction=0.7, turn=2.5, tilt=0.3, fps=FPS, name="closed") -> Motion:
    """The root at constant ``height`` (m), moving at ``speed`` (m/s) along the horizontal direction at angle
    ``direction``, turning about Z at ``turn`` rad/s while pitched by ``tilt`` about its own X axis."""
    t = np.arange(T) / fps
    trans = np.stack([speed * t * np.cos(direction), speed * t * np.sin(direction), np.full(T, height)], 1)
    root = Rotation.from_euler("ZX", np.stack([turn * t, np.full(T, tilt)], 1)).as_rotvec()  # Rz(turn t) Rx(tilt)
    rotations = np.zeros((T, 3, 3))
    rotations[:, 0] = root
    rotations[:, 1:] = 0.2  # other joints play no part
    return Motion(rotations, trans, fps=fps, joint_names=["root", "a", "b"], name=name)


def test_closed_form_motions_give_their_numbers():
    m = closed_form()
    r = MotionRange.of([m])
    assert r.height_min == r.height_max == float(np.float32(0.9))
    assert r.speed_max == pytest.approx(1.3, rel=1e-5)
    assert r.turn_rate_max == pytest.approx(2.5, rel=1e-5)
    np.testing.assert_allclose(root_speeds(m), 1.3, rtol=1e-5)
    np.testing.assert_allclose(root_turn_rates(m), 2.5, rtol=1e-5)  # the heading passes +-pi: wrapped
    # turning the other way, faster than half a turn a second, at 60 fps; standing still
    np.testing.assert_allclose(root_turn_rates(closed_form(turn=-7.0, fps=60.0)), 7.0, rtol=1e-5)
    still = MotionRange.of([closed_form(speed=0.0, turn=0.0, height=1.1)])
    assert (still.speed_max, still.turn_rate_max) == (0.0, 0.0)
    # several motions: the union of their ranges
    both = MotionRange.of([m, closed_form(height=0.7, speed=0.4, turn=4.0, T=2)])
    assert (both.height_min, both.height_max) == (float(np.float32(0.7)), float(np.float32(0.9)))
    assert both.speed_max == pytest.approx(1.3, rel=1e-5) and both.turn_rate_max == pytest.approx(4.0, rel=1e-5)
    assert MotionRange.of([closed_form(T=1)]).speed_max == 0.0  # one frame: no speed or turn


def test_warnings_name_the_motion_the_quantity_its_value_and_the_range():
    training = closed_form()
    meta = {META_KEY: MotionRange.of([training]).to_json()}
    assert range_warnings(meta, training) == []
    lifted = Motion(training.rotations, training.translation + [0, 0, 1.0], FPS, joint_names=training.joint_names)
    (line,) = range_warnings(meta, lifted, "lifted.npz")
    assert line.startswith("motion lifted.npz: root height 1.900 to 1.900 m, outside the training range 0.900 to 0.900 m")
    # just inside and just outside each tolerance
    h, v, w = HEIGHT_TOLERANCE_M, SPEED_TOLERANCE, TURN_TOLERANCE
    assert range_warnings(meta, closed_form(height=0.9 + h - 1e-3)) == []
    assert "root height 0.849 to 0.849 m" in range_warnings(meta, closed_form(height=0.9 - h - 1e-3))[0]
    fast = 1.3 * (1 + v[0]) + v[1]
    assert range_warnings(meta, closed_form(speed=fast - 1e-3)) == []
    (line,) = range_warnings(meta, closed_form(speed=fast + 0.015, name="dash"))
    assert fast == pytest.approx(1.725) and line.startswith("motion 'dash': root horizontal speed up to 1.74 m/s, above the training "
                           "maximum 1.30 m/s")
    spin = 2.5 * (1 + w[0]) + w[1]
    assert range_warnings(meta, closed_form(turn=-(spin - 1e-3))) == []
    height, turn = range_warnings(meta, closed_form(turn=-(spin + 0.015), height=2.0))  # one line per quantity
    assert height.startswith("motion 'closed': root height 2.000 to 2.000 m")
    assert spin == pytest.approx(3.375) and turn.startswith("motion 'closed': root turn rate up to 3.39 rad/s, above the training "
                           "maximum 2.50 rad/s")
    # a run trained before ranges were recorded, or a damaged record: nothing to compare with
    assert range_warnings({}, lifted) == [] and range_warnings({META_KEY: None}, lifted) == []
    assert range_warnings({META_KEY: {"height_min": "x"}}, lifted) == []


def test_other_takes_of_trained_motions_pass(body):
    from loosefit.motion.procedural import generate

    meta = {META_KEY: MotionRange.of([generate("walk", 2.0, 0, body), generate("spin", 2.0, 1, body)]).to_json()}
    for kind, seed in (("walk", 0), ("spin", 1), ("walk", 1), ("walk", 2), ("sway", 2)):
        assert range_warnings(meta, generate(kind, 2.0, seed, body)) == [], (kind, seed)
    assert [line.split(": ")[1].split(" up to")[0] for line in range_warnings(meta, generate("run", 2.0, 0, body))] \
        == ["root horizontal speed"]


@pytest.fixture(scope="module")
def run(tiny_store, tmp_path_factory):
    run = tmp_path_factory.mktemp("range") / "jn"
    train_model("jointnet", tiny_store, "skirt+average", run, overrides=SMALL_JOINTNET)
    return run


def test_a_run_records_the_range_of_its_training_motions(run, tiny_store, tmp_path):
    meta = json.loads((run / MODEL_META).read_text())
    store = DatasetStore.open(tiny_store)
    seqs = [store.sequence(n) for n in meta["train_sequences"]]
    assert sorted(s.motion for s in seqs) == ["spin", "walk"]
    expected = MotionRange.of([store.motion(s.motion).slice(0, s.num_frames) for s in seqs])
    assert MotionRange.from_meta(meta) == expected
    assert 0.5 < expected.height_min < expected.height_max < 1.2 and expected.turn_rate_max > 2.0
    # the body-LBS baseline follows any motion: no range
    train_model("body-lbs", tiny_store, "skirt+average", tmp_path / "lbs")
    assert META_KEY not in json.loads((tmp_path / "lbs" / MODEL_META).read_text())


def lifted(motion: Motion, metres: float = 1.0) -> Motion:
    return Motion(motion.rotations, motion.translation + [0, 0, metres], motion.fps, motion.rig, motion.joint_names,
                  motion.name)


def test_animate_warns_for_a_lifted_motion_only(run, tiny_store, tmp_path, capsys):
    store = DatasetStore.open(tiny_store)
    walk = store.motion("walk")
    walk.save(tmp_path / "walk.npz")
    lifted(walk).save(tmp_path / "lifted.npz")
    args = ["animate", str(run), "--motion", str(tmp_path / "walk.npz"), "--motion", str(tmp_path / "lifted.npz"),
            "--out", str(tmp_path / "out")]
    assert main(args) == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"loosefit animate: warning: motion {tmp_path / 'lifted.npz'}: root height ")
    low, high = (float(x) for x in err[0].split("root height ")[1].split(" m,")[0].split(" to "))
    assert (low, high) == pytest.approx((walk.translation[:, 2].min() + 1, walk.translation[:, 2].max() + 1), abs=6e-4)
    assert "outside the training range" in err[0] and "the garment may not follow the body" in err[0]
    assert (tmp_path / "out" / "lifted.npz").is_file()
    # a run trained before the range was recorded: animated as before, nothing said
    meta = json.loads((run / MODEL_META).read_text())
    old = tmp_path / "old"
    old.mkdir()
    for f in run.iterdir():
        (old / f.name).symlink_to(f)
    (old / MODEL_META).unlink()
    (old / MODEL_META).write_text(json.dumps({k: v for k, v in meta.items() if k != META_KEY}))
    assert main(["animate", str(old), "--motion", str(tmp_path / "lifted.npz"), "--out", str(tmp_path / "o.npz")]) == 0
    assert capsys.readouterr().err == ""


def test_view_warns_for_a_lifted_motion_only(run, tiny_store, tmp_path, capsys, body):
    from loosefit.viz.viewer import view

    walk = DatasetStore.open(tiny_store).motion("walk")
    walk.save(tmp_path / "walk.npz")
    lifted(walk).save(tmp_path / "lifted.npz")
    view([f"{run}:{tmp_path / 'walk.npz'}"], export=tmp_path / "v1", body=body, collisions=False)
    assert capsys.readouterr().err == ""
    view([f"{run}:{tmp_path / 'lifted.npz'}"], export=tmp_path / "v2", body=body, collisions=False)
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"loosefit view: warning: motion {tmp_path / 'lifted.npz'}: root height ")
    assert (tmp_path / "v2" / "index.html").is_file()


def test_report_warns_for_a_sequence_outside_the_range(run, tiny_store, tmp_path, capsys):
    from loosefit.report import build_report

    # the store with two short test sequences: the start of a training one, and the same lifted by a metre
    data = tmp_path / "short.zarr"
    shutil.copytree(tiny_store, data)
    store = DatasetStore.open(data, mode="a")
    seq = store.sequence(next(n for n in store.sequence_names(split="train") if store.sequence(n).motion == "walk"))
    walk, verts = store.motion("walk").slice(0, 4), np.asarray(seq.verts[:4])
    for name, motion, lift in (("walk-start", walk, 0.0), ("walk-lifted", lifted(walk), 1.0)):
        store.add_motion(name, motion)
        store.write_sequence(name, verts + np.float32([0, 0, lift]), seq.garment, seq.body, name, seq.sim_params,
                             {}, "test")
    build_report(data, [run], tmp_path / "r", sequences=["walk-start", "walk-lifted"], results_dir=None,
                 images=False)
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("loosefit report: warning: jointnet: motion of sequence walk-lifted: root height ")
    doc = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert doc["methods"][0]["warnings"] == [line.removeprefix("loosefit report: warning: jointnet: ")]
    for page in ("report.md", "index.html"):
        text = (tmp_path / "r" / page).read_text()
        assert "motion of sequence walk-lifted: root height" in text and "sequence walk-start" not in text


def yawing(yaw: np.ndarray, heights: np.ndarray | None = None, fps=FPS) -> Motion:
    """A motion whose root heading follows ``yaw (T,)`` radians about Z, standing at ``heights (T,)`` (0.9 m)."""
    T = len(yaw)
    trans = np.zeros((T, 3))
    trans[:, 2] = 0.9 if heights is None else heights
    rotations = np.zeros((T, 3, 3))
    rotations[:, 0] = Rotation.from_euler("z", yaw[:, None]).as_rotvec()
    return Motion(rotations, trans, fps=fps, joint_names=["root", "a", "b"], name="yawing")


def test_turn_bouts_and_extent_of_a_closed_form_spin():
    # still 10 frames, a full turn ccw at 2 pi rad/s (30 frames), still 15, half a turn cw at 4 rad/s, still 10,
    # and a slow drift (1 rad/s, under the bout rate) that never counts
    rate = np.concatenate([np.zeros(10), np.full(30, 2 * np.pi), np.zeros(15), np.full(int(round(np.pi / 4 * FPS)), -4.0),
                           np.zeros(10), np.full(20, 1.0)]) / FPS
    yaw = np.concatenate([[0.0], np.cumsum(rate)])
    bouts = turn_bouts(yawing(yaw))
    assert len(bouts) == 2
    assert bouts[0].turn == pytest.approx(2 * np.pi, rel=1e-5) and bouts[0].peak_rate == pytest.approx(2 * np.pi, rel=1e-5)
    assert (bouts[0].start, bouts[0].stop) == (10, 41)
    assert bouts[1].turn == pytest.approx(-4.0 * round(np.pi / 4 * FPS) / FPS, rel=1e-5)
    assert bouts[1].peak_rate == pytest.approx(4.0, rel=1e-5)
    heights = 0.9 + 0.3 * np.sin(np.linspace(0, np.pi, len(yaw)))  # a 30 cm rise
    e = MotionExtent.of(yawing(yaw, heights))
    assert (e.max_turn_ccw, e.max_turn_cw) == (pytest.approx(2 * np.pi, rel=1e-5), pytest.approx(-bouts[1].turn, rel=1e-5))
    assert e.reversals == 1 and e.rise == pytest.approx(0.3, abs=1e-4)
    # a motion covers its own extent; one turning only ccw covers neither the reversal nor the cw half turn; a third
    # of the turn does not cover a full one
    assert e.covers(e)
    ccw_only = MotionExtent.of(yawing(np.concatenate([[0.0], np.cumsum(rate * (rate > 0))]), heights))
    assert ccw_only.reversals == 0 and ccw_only.max_turn_cw == 0.0
    assert not ccw_only.covers(e) and e.covers(ccw_only)
    third = MotionExtent.of(yawing(yaw / 3, heights))
    assert not third.covers(e)
