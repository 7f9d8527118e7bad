"""Checkpoint files: round trip, validation of damaged or foreign files, run folder layout."""

from __future__ import annotations

import subprocess
import sys

import pytest
import torch

from loosefit.errors import InputError
from loosefit.train.run import RunDir, load_checkpoint, load_weights, save_checkpoint
from loosefit.train.seeding import rng_state
from tests.train.conftest import SineGRU, make_model


def _state(model, **changes):
    state = {
        "model": model.state_dict(), "optimizer": None, "scheduler": None, "stages": ["encoder", "head"],
        "stage_index": 1, "epoch": 2, "global_step": 7, "best_metric": 1.5, "rng": rng_state(),
        "config": {"lr": 0.001}, "history": [{"stage": "encoder", "epoch": 1, "train_loss": 0.5}],
        "elapsed_s": 3.0, "complete": False,
    }
    state.update(changes)
    return state


def test_round_trip_and_load_weights(tmp_path):
    model = make_model(0)
    path = save_checkpoint(tmp_path / "c" / "last.pt", _state(model))
    loaded = load_checkpoint(path)
    assert loaded["history"] == [{"stage": "encoder", "epoch": 1, "train_loss": 0.5}]
    assert (loaded["stage_index"], loaded["epoch"], loaded["global_step"], loaded["best_metric"]) == (1, 2, 7, 1.5)
    other = make_model(1)
    assert not torch.equal(other.head.weight, model.head.weight)
    load_weights(other, path)
    for key, value in model.state_dict().items():
        assert torch.equal(other.state_dict()[key], value)
    with pytest.raises(InputError, match="does not fit this model"):
        load_weights(SineGRU(hidden=3), path)


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"epoch": "2"}, "entry 'epoch' has type str"),
        ({"complete": 1}, "entry 'complete' has type int"),
        ({"stage_index": 2}, "position is invalid"),
        ({"global_step": -1}, "position is invalid"),
        ({"version": 99}, "checkpoint version 99"),
    ],
)
def test_invalid_entries(tmp_path, changes, message):
    path = tmp_path / "bad.pt"
    torch.save({"format": "loosefit-checkpoint", "version": 1, **_state(make_model()), **changes}, path)
    with pytest.raises(InputError, match=message) as info:
        load_checkpoint(path)
    assert info.value.path == path


def test_damaged_files(tmp_path):
    path = save_checkpoint(tmp_path / "last.pt", _state(make_model()))
    whole = path.read_bytes()
    for damaged in (whole[: len(whole) // 3], b"not a zip at all", b""):
        path.write_bytes(damaged)
        with pytest.raises(InputError, match="corrupt or truncated") as info:
            load_checkpoint(path)
        assert str(path) in str(info.value)
    with pytest.raises(InputError, match="checkpoint not found"):
        load_checkpoint(tmp_path / "missing.pt")
    state = _state(make_model())
    del state["rng"]
    with pytest.raises(ValueError, match="lacks"):
        save_checkpoint(tmp_path / "x.pt", state)


def test_run_dir_layout(tmp_path):
    run = RunDir(tmp_path / "r")
    assert not run.has_checkpoint() and not run.path.exists()
    run.create()
    assert run.checkpoints.is_dir()
    assert run.last_checkpoint == tmp_path / "r" / "checkpoints" / "last.pt"
    assert run.best_checkpoint.name == "best.pt" and run.config.name == "config.yaml"
    assert run.metrics_csv.name == "metrics.csv" and run.summary.name == "run.json"
    save_checkpoint(run.last_checkpoint, _state(make_model()))
    assert run.has_checkpoint()


def _killed_while_writing(target):
    """A process killed inside ``atomic_path(target)``: its temporary file stays beside ``target``."""
    code = ("import os, sys; from loosefit.paths import atomic_path; "
            "tmp = atomic_path(sys.argv[1]).__enter__(); tmp.write_bytes(b'half'); os._exit(9)")
    subprocess.run([sys.executable, "-c", code, str(target)], check=False)


def test_resume_removes_temporaries_of_killed_writes(data, tmp_path):
    from loosefit.train import train
    from tests.train.conftest import quick_config

    train_set, val_set = data
    model = make_model()
    model.crash_at_call = 8
    with pytest.raises(KeyboardInterrupt):
        train(model, train_set, val_set, quick_config(), tmp_path / "run")
    run = RunDir(tmp_path / "run")
    _killed_while_writing(run.last_checkpoint)
    _killed_while_writing(run.path / "model.json")
    litter = [p.name for p in [*run.path.glob(".model.json.*"), *run.checkpoints.glob(".last.pt.*")]]
    assert len(litter) == 2 and litter[0].endswith(".json") and litter[1].endswith(".pt")  # what a killed run leaves
    (run.path / "notes.txt").write_text("mine")
    train(make_model(), train_set, val_set, quick_config(), run.path, resume=True)
    assert not list(run.path.glob(".model.json.*")) and not list(run.checkpoints.glob(".*"))
    assert (run.path / "notes.txt").read_text() == "mine" and load_checkpoint(run.last_checkpoint)["complete"]
