import importlib
import logging

import numpy as np
import pytest
import yaml

from loosefit.data.store import DatasetStore
from loosefit.io.mesh_sequence import MeshSequence
import loosefit.simulate as runner
from loosefit.simulate import CRASHED, RAY_AUTH_NOTICE_LOGGER, run_plan, simulate_file
from tests.sim.conftest import jump, ring_skirt, spin, walk

FRAMES = 12


@pytest.fixture(scope="module")
def plan_path(tmp_path_factory, body):
    """A plan of three tiny sequences: a 24 x 8 ring skirt on three 12-frame motions, 0.2 s pre-roll."""
    root = tmp_path_factory.mktemp("plan")
    ring_skirt(body, n_around=24, n_down=8, length=0.3).save(root / "skirt.obj")
    for make in (walk, spin, jump):
        make(body, FRAMES).save(root / f"{make.__name__}.npz")
    plan = {
        "name": "tiny",
        "garments": {"skirt": {"file": "skirt.obj"}},
        "motions": {m: {"file": f"{m}.npz"} for m in ("walk", "spin", "jump")},
        "sim_params": {"quick": {"preroll": 0.2}},
        "split": {"test": {"motions": ["jump"]}},
    }
    path = root / "tiny.yaml"
    path.write_text(yaml.safe_dump(plan))
    return path


@pytest.fixture(scope="module")
def reference(plan_path, tmp_path_factory):
    """The plan run in one go, in this process."""
    out = tmp_path_factory.mktemp("ref") / "ref.zarr"
    summary = run_plan(plan_path, out, progress=False)
    assert (summary["jobs"], summary["ok"], summary["skipped"]) == (3, 3, 0)
    return DatasetStore.open(out)


def test_plan_run_fills_the_store(reference):
    assert reference.sequence_names() == ["skirt+average+jump+quick", "skirt+average+spin+quick", "skirt+average+walk+quick"]
    assert reference.sequence_names(split="test") == ["skirt+average+jump+quick"]
    seq = reference.sequence("skirt+average+walk+quick")
    assert seq.verts.shape == (FRAMES, 24 * 8, 3) and (seq.garment, seq.body, seq.motion) == ("skirt+average", "average", "walk")
    assert seq.sim_params["preroll"] == 0.2 and seq.stats["ms_per_frame"] > 0 and seq.stats["penetration"] < 0.01
    assert reference.garment("skirt+average").pinned.sum() == 24
    np.testing.assert_allclose(reference.body("average"), 0.5)


def test_interrupted_run_resumes_with_identical_results(plan_path, reference, tmp_path, monkeypatch):
    out = tmp_path / "data.zarr"
    real = runner.simulate_job
    calls = []

    def interrupt_second(payload):
        calls.append(payload["motion"].name)
        if len(calls) == 2:
            raise KeyboardInterrupt  # killed mid-run: the sequence in flight is never written
        return real(payload)

    monkeypatch.setattr(runner, "simulate_job", interrupt_second)
    with pytest.raises(KeyboardInterrupt):
        run_plan(plan_path, out, progress=False)
    monkeypatch.undo()
    store = DatasetStore.open(out)
    (first,) = store.sequence_names()
    created = store.sequence(first).created
    summary = run_plan(plan_path, out, progress=False)
    assert (summary["skipped"], summary["ok"]) == (1, 2)
    store = DatasetStore.open(out)
    assert store.sequence(first).created == created  # kept, not redone
    for name in reference.sequence_names():
        np.testing.assert_array_equal(store.sequence(name).verts[:], reference.sequence(name).verts[:])
    assert run_plan(plan_path, out, progress=False)["skipped"] == 3


def test_a_crash_does_not_stop_the_others_and_is_retried(plan_path, tmp_path, monkeypatch):
    out = tmp_path / "data.zarr"
    real = runner.simulate_sequence

    def crash_on_spin(garment, body, motion, params, **kw):
        if motion.name == "spin":
            raise RuntimeError("Blender fell over")
        return real(garment, body, motion, params, **kw)

    monkeypatch.setattr(runner, "simulate_sequence", crash_on_spin)
    summary = run_plan(plan_path, out, progress=False)
    assert (summary["ok"], summary["crashed"]) == (2, 1)
    line = runner.summary_line(summary, out)
    assert line.startswith(f"{summary['plan']}: 2 of 3 sequences simulated ok, 0 failed the quality gate and 1 crashed")
    assert "skirt+average+spin+quick: " + CRASHED in line
    seq = DatasetStore.open(out).sequence("skirt+average+spin+quick")
    assert seq.status == "failed" and seq.reason.startswith(CRASHED) and "Blender fell over" in seq.reason
    monkeypatch.undo()
    summary = run_plan(plan_path, out, progress=False)
    assert (summary["skipped"], summary["ok"]) == (2, 1)
    assert runner.summary_line(summary, out) == f"{summary['plan']}: 1 of 1 sequences simulated ok (2 of 3 were done before)"
    assert DatasetStore.open(out).sequence("skirt+average+spin+quick").status == "ok"


def test_two_ray_workers(plan_path, reference, tmp_path):
    plan = yaml.safe_load(plan_path.read_text())
    plan["sequences"] = [{"motions": ["walk", "spin"]}]
    path = plan_path.parent / "two.yaml"
    path.write_text(yaml.safe_dump(plan))
    summary = run_plan(path, tmp_path / "ray.zarr", workers=2, progress=False)
    assert (summary["jobs"], summary["ok"]) == (2, 2)
    # Ray's notice about its own token authentication is held back: the logger we quieten is the one Ray writes with
    assert importlib.import_module(RAY_AUTH_NOTICE_LOGGER).logger.name == RAY_AUTH_NOTICE_LOGGER
    assert logging.getLogger(RAY_AUTH_NOTICE_LOGGER).getEffectiveLevel() == logging.ERROR
    store = DatasetStore.open(tmp_path / "ray.zarr")
    for name in store.sequence_names():
        np.testing.assert_array_equal(store.sequence(name).verts[:], reference.sequence(name).verts[:])


def test_simulate_file(plan_path, tmp_path):
    result = simulate_file(plan_path.parent / "skirt.obj", plan_path.parent / "walk.npz", tmp_path / "seq.npz")
    seq = MeshSequence.load(tmp_path / "seq.npz")
    assert result.status == "ok" and seq.verts.shape == (FRAMES, 24 * 8, 3)
    np.testing.assert_array_equal(seq.verts, result.verts)


def test_template_garment_and_procedural_motion(tmp_path):
    plan = {
        "garments": {"skirt": {"template": "skirt", "seed": 3, "edge_length": 0.06, "params": {"length": 0.4}}},
        "motions": {"sway": {"procedural": "sway", "seconds": 0.4, "seed": 1}},
        "shapes": {"tall": {"height": 0.9}},
        "sim_params": {"quick": {"preroll": 0.2}},
    }
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(plan))
    summary = run_plan(path, tmp_path / "d.zarr", progress=False)
    assert summary["ok"] == 1, summary
    store = DatasetStore.open(tmp_path / "d.zarr")
    garment = store.garment("skirt+tall")
    assert garment.kind == "skirt" and garment.params["length"] == 0.4 and garment.pinned.any()
    assert store.motion("sway").num_frames == 12 and store.body("tall")[4] == np.float32(0.9)
    seq = store.sequence("skirt+tall+sway+quick")
    assert seq.verts.shape == (12, len(garment.verts), 3) and seq.split == "train"


def test_slowed_plan_motions(plan_path, tmp_path):
    """``slowdown: 4`` plays a motion 4x slower: a procedural one keeps its ``seconds``, a file's frames are
    counted after the slow-down; every 4th frame is a frame of the motion as made."""
    from loosefit.body import AnnyShape
    from loosefit.motion.motion import Motion
    from loosefit.motion.procedural import generate
    from loosefit.sim.plan import load_plan

    plan = {
        "garments": {"skirt": {"template": "skirt"}},
        "motions": {"sway": {"procedural": "sway", "seconds": 2.0, "seed": 1, "slowdown": 4},
                    "walk": {"file": str(plan_path.parent / "walk.npz"), "slowdown": 2, "start": 2, "frames": 9}},
    }
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(plan))
    loaded = load_plan(path)
    sway = runner.load_plan_motion(loaded, "sway")
    assert sway.num_frames == 60 and sway.fps == 30
    made = generate("sway", 0.5 + 1 / 30, 1, runner.plan_body(tuple(AnnyShape().to_array().tolist())))
    np.testing.assert_allclose(sway.translation[::4], made.translation[:15], atol=1e-9)
    walk = runner.load_plan_motion(loaded, "walk")
    original = Motion.load(plan_path.parent / "walk.npz")
    assert walk.num_frames == 9
    np.testing.assert_allclose(walk.translation[::2], original.translation[1:6], atol=1e-9)


def test_held_plan_motions(plan_path, tmp_path):
    """``hold``: a file's motion, cut, then every 3rd frame held; the settled frames are those source frames."""
    from loosefit.motion.hold import settled_frames
    from loosefit.motion.motion import Motion
    from loosefit.sim.plan import load_plan

    plan = {"garments": {"skirt": {"template": "skirt"}},
            "motions": {"walk": {"file": str(plan_path.parent / "walk.npz"), "start": 2, "frames": 9,
                                 "hold": {"every": 3, "transition": 2, "frames": 4}}}}
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(plan))
    walk = runner.load_plan_motion(load_plan(path), "walk")
    original = Motion.load(plan_path.parent / "walk.npz")
    assert walk.num_frames == 3 * 6
    settled = settled_frames(walk.num_frames, 2, 4)
    np.testing.assert_allclose(walk.translation[settled], original.translation[2:11:3], atol=1e-6)



def test_simulate_file_drapes_a_garment_made_on_another_shape(plan_path, tmp_path):
    """A skirt made on a tall body, simulated on the average one (``simulate --garment --shape``): draped
    onto it first (stats say from which shape), then simulated through the gate like any other."""
    from loosefit.body import AnnyBody
    from loosefit.body.anny_body import AnnyShape
    from loosefit.garment import make_garment
    from loosefit.sim import SimParams

    make_garment("skirt", AnnyBody(AnnyShape(height=0.8)), seed=0, edge_length=0.06).save(tmp_path / "tall.obj")
    result = simulate_file(tmp_path / "tall.obj", plan_path.parent / "walk.npz", tmp_path / "seq.npz",
                           params=SimParams(preroll=0.2))
    fitted = result.stats["garment_fit"]
    assert result.status == "ok" and fitted["from_shape"]["height"] == 0.8 and fitted["to_shape"]["height"] == 0.5
    assert fitted["inside_after_percent"] <= 1.0
    assert MeshSequence.load(tmp_path / "seq.npz").verts.shape[0] == FRAMES
