"""Reference runs of a plan's test sequences: simulated after their base runs and before the training
sequences, stored with them, resumable."""

import shutil

import numpy as np
import pytest
import yaml

from loosefit.data.store import DatasetStore
from loosefit.errors import InputError
import loosefit.simulate as runner
from loosefit.sim.params import SimParams
from loosefit.sim.plan import load_plan
from loosefit.simulate import CRASHED, perturb_start, run_plan
from loosefit.sim.sequence import simulate_sequence
from tests.sim.conftest import jump, ring_skirt, walk

FRAMES = 12
TEST = "skirt+average+jump+quick"


def write_plan(root, references):
    plan = {
        "name": "refs",
        "garments": {"skirt": {"file": "skirt.obj"}},
        "motions": {m: {"file": f"{m}.npz"} for m in ("walk", "jump")},
        "sim_params": {"quick": {"preroll": 0.2}},
        "split": {"test": {"motions": ["jump"]}},
    }
    if references is not None:
        plan["references"] = references
    path = root / f"refs-{len(list(root.glob('refs-*.yaml')))}.yaml"
    path.write_text(yaml.safe_dump(plan))
    return path


@pytest.fixture(scope="module")
def root(tmp_path_factory, body):
    root = tmp_path_factory.mktemp("refs")
    ring_skirt(body, n_around=24, n_down=8, length=0.3).save(root / "skirt.obj")
    for make in (walk, jump):
        make(body, FRAMES).save(root / f"{make.__name__}.npz")
    return root


@pytest.fixture(scope="module")
def done(root):
    """The plan with two reference runs, run in one go."""
    out = root / "done.zarr"
    summary = run_plan(write_plan(root, {"count": 2, "noise": 1.0e-5}), out, progress=False)
    return summary, out


def is_reference(payload):
    return payload["params"]["adaptive_quality"] is False


def test_test_sequences_get_their_runs_after_the_base(done, root, body):
    summary, out = done
    assert (summary["ok"], summary["references"]["jobs"], summary["references"]["ok"]) == (2, 2, 2)
    assert "2 of 2 reference runs ok" in runner.summary_line(summary, out)
    store = DatasetStore.open(out)
    assert store.reference_runs("skirt+average+walk+quick") == {}  # a training sequence gets none
    runs = store.reference_runs(TEST)
    base = store.sequence(TEST)
    assert [(k, r["status"], r["noise_seed"], r["noise_m"], r["quality"]) for k, r in runs.items()] == [
        (1, "ok", 1, 1e-5, base.stats["quality"]), (2, "ok", 2, 1e-5, base.stats["quality"])]
    refs = store.references(TEST)
    assert refs.shape == (2, FRAMES, 24 * 8, 3)
    assert not np.array_equal(refs[0], refs[1]) and not np.array_equal(refs[0], base.verts[:])
    # run 1 is the base's job started from the garment moved by seed-1 noise, at the base's steps
    garment = store.garment("skirt+average")
    params = SimParams(preroll=0.2, quality=base.stats["quality"], adaptive_quality=False)
    again = simulate_sequence(perturb_start(garment, 1, 1e-5), body, store.motion("jump"), params)
    np.testing.assert_array_equal(again.verts, refs[0])
    moved = np.linalg.norm(perturb_start(garment, 1, 1e-5).verts - garment.verts, axis=1)
    assert 5e-6 < np.sqrt(np.mean(moved**2) / 3) < 2e-5  # 10 micrometres per axis


def test_resume_simulates_only_missing_runs_and_follows_the_plan(done, root, tmp_path, monkeypatch):
    _, out = done
    copy = tmp_path / "copy.zarr"
    shutil.copytree(out, copy)
    with DatasetStore.open(copy, mode="a") as store:
        store.delete_reference(TEST, 2)
        created = store.reference_runs(TEST)[1]["created"]
    calls = []
    real = runner.simulate_job
    monkeypatch.setattr(runner, "simulate_job", lambda payload: calls.append(is_reference(payload)) or real(payload))
    summary = run_plan(write_plan(root, {"count": 2, "noise": 1.0e-5}), copy, progress=False)
    assert calls == [True] and (summary["skipped"], summary["references"]["skipped"]) == (2, 1)
    store = DatasetStore.open(copy)
    assert store.reference_runs(TEST)[1]["created"] == created
    np.testing.assert_array_equal(store.references(TEST), DatasetStore.open(out).references(TEST))
    # fewer runs asked for: the extra one goes, nothing is simulated
    calls.clear()
    summary = run_plan(write_plan(root, {"count": 1}), copy, progress=False)
    assert calls == [] and list(DatasetStore.open(copy).reference_runs(TEST)) == [1]
    assert runner.summary_line(summary, copy).endswith("; reference runs: all 1 done before")
    # other noise: the run is simulated again; no references key: the runs stay, nothing is simulated
    summary = run_plan(write_plan(root, {"count": 1, "noise": 2.0e-5}), copy, progress=False)
    assert calls == [True] and DatasetStore.open(copy).reference_runs(TEST)[1]["noise_m"] == 2e-5
    summary = run_plan(write_plan(root, None), copy, progress=False)
    assert calls == [True] and summary["references"]["jobs"] == 0 and "reference" not in runner.summary_line(summary, copy)


def test_test_sequences_and_their_runs_come_before_the_training_sequences(root, tmp_path, monkeypatch):
    """The plan lists walk (training) before jump (test); a run stopped part way must have the held-out
    sequence with its floor, so the order is the test base, its runs, then the rest."""
    calls = []
    real = runner.simulate_job
    monkeypatch.setattr(runner, "simulate_job",
                        lambda payload: calls.append((payload["motion"].name, is_reference(payload))) or real(payload))
    run_plan(write_plan(root, {"count": 2, "noise": 1.0e-5}), tmp_path / "order.zarr", progress=False)
    assert calls == [("jump", False), ("jump", True), ("jump", True), ("walk", False)]


def test_splits_simulate_the_training_motions_first_and_the_held_out_one_later(done, root, tmp_path, monkeypatch):
    """The demo's order: the training split alone (no reference runs), then the test split with its runs; the
    store ends as one run of the whole plan leaves it, bit for bit."""
    calls = []
    real = runner.simulate_job
    monkeypatch.setattr(runner, "simulate_job",
                        lambda payload: calls.append((payload["motion"].name, is_reference(payload))) or real(payload))
    plan, out = write_plan(root, {"count": 2, "noise": 1.0e-5}), tmp_path / "splits.zarr"
    first = run_plan(plan, out, progress=False, splits=("train",))
    assert calls == [("walk", False)] and (first["jobs"], first["ok"]) == (1, 1) and "references" not in first
    assert not DatasetStore.open(out).has_sequence(TEST)
    second = run_plan(plan, out, progress=False, splits=("test",))
    assert calls[1:] == [("jump", False), ("jump", True), ("jump", True)]
    assert (second["jobs"], second["ok"], second["references"]["ok"]) == (1, 1, 2)
    whole = run_plan(plan, out, progress=False)
    assert (whole["skipped"], whole["references"]["skipped"]) == (2, 2) and len(calls) == 4
    store, reference = DatasetStore.open(out), DatasetStore.open(done[1])
    np.testing.assert_array_equal(store.sequence(TEST).verts[:], reference.sequence(TEST).verts[:])
    np.testing.assert_array_equal(store.references(TEST), reference.references(TEST))


def test_a_crashed_run_is_stored_failed_and_retried(done, root, tmp_path, monkeypatch):
    _, out = done
    copy = tmp_path / "copy.zarr"
    shutil.copytree(out, copy)
    with DatasetStore.open(copy, mode="a") as store:
        store.delete_reference(TEST, 1)
    real = runner.simulate_sequence

    def crash(garment, body, motion, params, **kw):
        raise RuntimeError("Blender fell over")

    monkeypatch.setattr(runner, "simulate_sequence", crash)
    plan = write_plan(root, {"count": 2, "noise": 1.0e-5})
    summary = run_plan(plan, copy, progress=False)
    assert (summary["references"]["crashed"], summary["references"]["skipped"]) == (1, 1)
    run = DatasetStore.open(copy).reference_runs(TEST)[1]
    assert run["status"] == "failed" and run["reason"].startswith(CRASHED) and run["frames"] == 0
    assert DatasetStore.open(copy).references(TEST).shape[0] == 1  # the failed run is not a reference
    monkeypatch.setattr(runner, "simulate_sequence", real)
    summary = run_plan(plan, copy, progress=False)
    assert summary["references"]["ok"] == 1
    np.testing.assert_array_equal(DatasetStore.open(copy).references(TEST), DatasetStore.open(out).references(TEST))
    assert load_plan(plan).references.count == 2


@pytest.mark.parametrize("value, message", [
    ({"count": -1}, "'count' must be an integer >= 0"),
    ({"count": 2.5}, "expected an integer"),
    ({"noise": 0}, r"'noise' must be a number of metres in \(0, 0.01\)"),
    ({"cnt": 2}, r"unknown keys \['cnt'\]"),
    (3, "references must be a mapping"),
])
def test_plan_key_is_checked(tmp_path, value, message):
    from loosefit.errors import InputError

    plan = {"garments": {"s": {"template": "skirt"}}, "motions": {"t": {"procedural": "spin", "seconds": 1}},
            "split": {"test": {"motions": ["t"]}}, "references": value}
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(plan))
    with pytest.raises(InputError, match=message) as err:
        load_plan(path)
    assert err.value.path == path


def test_plan_key_leaves_job_hashes_alone(tmp_path):
    plan = {"garments": {"s": {"template": "skirt"}}, "motions": {m: {"procedural": "spin", "seconds": 1}
                                                                  for m in ("t", "u")},
            "split": {"test": {"motions": ["t"]}}}
    (tmp_path / "a.yaml").write_text(yaml.safe_dump(plan))
    (tmp_path / "b.yaml").write_text(yaml.safe_dump({**plan, "references": {"count": 3, "noise": 2e-5}}))
    a, b = load_plan(tmp_path / "a.yaml"), load_plan(tmp_path / "b.yaml")
    assert [j.hash for j in a.jobs] == [j.hash for j in b.jobs]  # stored sequences stay valid
    assert (a.references.count, a.reference_jobs()) == (0, [])
    assert [j.motion for j in b.reference_jobs()] == ["t"] and b.references.noise == 2e-5
    # each run's hash follows the base's hash, the noise and its seed
    job = b.reference_jobs()[0]
    hashes = {b.references.run_hash(job, k) for k in (1, 2, 3)} | {a.references.run_hash(job, 1)}
    assert len(hashes) == 4


def test_garments_simulate_one_garment_of_a_plan_with_its_reference_runs(root, tmp_path):
    """``garments``: only that garment's sequences and reference runs; the other garment's come with a later run,
    and a garment the plan lacks is refused before anything is written."""
    plan = yaml.safe_load(write_plan(root, {"count": 1, "noise": 1.0e-5}).read_text())
    plan["garments"]["other"] = {"file": "skirt.obj"}
    path = root / "two-garments.yaml"
    path.write_text(yaml.safe_dump(plan))
    out = tmp_path / "garments.zarr"
    with pytest.raises(InputError, match="no garment 'coat' in the plan"):
        run_plan(path, out, progress=False, garments=("coat",))
    assert not out.exists()
    first = run_plan(path, out, progress=False, garments=("other",))
    store = DatasetStore.open(out)
    assert sorted(store.sequence_names()) == ["other+average+jump+quick", "other+average+walk+quick"]
    assert (first["jobs"], first["references"]["jobs"]) == (2, 1) and store.reference_runs("other+average+jump+quick")
    second = run_plan(path, out, progress=False)
    assert (second["skipped"], second["ok"], second["references"]["skipped"], second["references"]["ok"]) == (2, 2, 1, 1)
    assert DatasetStore.open(out).reference_runs(TEST)
