"""Ctrl-C (SIGINT) and SIGTERM in the long verbs, through the CLI in a subprocess: one line saying what was
kept and the command that resumes, exit status 130 / 143, no traceback; the resume command works. A plan on
Ray workers leaves none of its processes running; one sequence leaves no half-written file."""

from __future__ import annotations

import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.robustness.cases_hostile import LONG_TRAIN, SLOW_PLAN
from tests.robustness.cases_pipeline import GARMENT
from tests.robustness.live import alive, default_sigint, descendants, module_loaded


def _start(argv: list[str], cwd: Path) -> subprocess.Popen:
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "loosefit.cli", *argv], cwd=cwd, env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint)


def _interrupt(proc: subprocess.Popen, ready, sig: int, timeout: float = 240.0) -> tuple[int, str, str]:
    """Send ``sig`` once ``ready()`` holds (the command is working); its exit status, stdout and stderr."""
    start = time.monotonic()
    while not ready():
        if proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"the command ended (status {proc.returncode}) before it was interrupted:\n{out}\n{err}")
        if time.monotonic() - start > timeout:
            proc.kill()
            pytest.fail("the command never got to work")
        time.sleep(0.1)
    proc.send_signal(sig)
    try:
        out, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"the command did not stop on the signal:\n{err}")
    return proc.returncode, out, err


def _stored_ok(store: Path) -> int:
    """Sequences of ``store`` stored with status ok (read from their attributes, as a reader does)."""
    count = 0
    for attrs in store.glob("sequences/*/.zattrs"):
        try:
            count += json.loads(attrs.read_text()).get("status") == "ok"
        except (OSError, ValueError):
            pass
    return count


def _one_line(err: str, verb: str) -> str:
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.startswith(f"loosefit {verb}: interrupted")]
    assert len(lines) == 1, err
    return lines[0]


@pytest.mark.parametrize("sig,status,name", [(signal.SIGINT, 130, "SIGINT"), (signal.SIGTERM, 143, "SIGTERM")])
def test_train_interrupted_keeps_last_epoch_and_resumes(tiny_store, tmp_path, sig, status, name):
    run = tmp_path / "run"
    argv = ["train", "--method", "virtualbones", "--data", str(tiny_store), "--garment", GARMENT, "--out", str(run),
            *LONG_TRAIN]
    last = run / "checkpoints" / "last.pt"
    rc, _, err = _interrupt(_start(argv, tmp_path), last.is_file, sig)
    assert rc == status, err
    line = _one_line(err, "train")
    assert f"({name})" in line and str(last) in line and line.rstrip().endswith("--resume"), line
    assert last.is_file()
    resume = shlex.split(line.split("resume: ", 1)[1])
    assert resume == ["loosefit", *argv, "--resume"], line


def test_simulate_interrupted_keeps_finished_sequences(tmp_path):
    plan, store = tmp_path / "slow.yaml", tmp_path / "d.zarr"
    plan.write_text(SLOW_PLAN)
    argv = ["simulate", str(plan), "--out", str(store)]
    # the short walk is stored first; the signal lands during the 20 s spin
    rc, _, err = _interrupt(_start(argv, tmp_path), lambda: _stored_ok(store) == 1, signal.SIGINT)
    line = _one_line(err, "simulate")
    assert rc == 130, err
    assert "1 finished sequence(s) are kept in" in line and str(store) in line, line
    assert line.endswith(f"loosefit simulate {plan} --out {store}"), line
    assert not (store / ".lock").exists()  # the store's write lock was let go


def test_prepare_interrupted_names_store_and_resume(tiny_store, tmp_path):
    store = Path(shutil.copytree(tiny_store, tmp_path / "d.zarr"))
    # many SSDR iterations: prepare is still solving when the signal arrives
    argv = ["prepare", str(store), "--force", "--set", "iterations=100000", "--set", "transform_iterations=1000"]
    proc = _start(argv, tmp_path)
    began = time.monotonic()
    rc, _, err = _interrupt(proc, lambda: (store / ".lock").exists() and time.monotonic() - began > 1.0,
                            signal.SIGTERM)
    line = _one_line(err, "prepare")
    assert rc == 143, err
    assert str(store) in line and line.endswith(f"resume: loosefit prepare {store} --force --set iterations=100000 "
                                                "--set transform_iterations=1000"), line
    assert not (store / ".lock").exists()


@pytest.fixture(scope="module")
def one_sequence(tmp_path_factory):
    """A coarse skirt and a 20 s walk: a single-sequence simulation of a minute or more."""
    from loosefit.cli import main

    folder = tmp_path_factory.mktemp("one-sequence")
    garment, motion = folder / "g.obj", folder / "walk.npz"
    assert main(["garment", "make", "--kind", "skirt", "--seed", "0", "--edge-length", "0.06", "--param", "length=0.4",
                 "--param", "flare=20", "--out", str(garment)]) == 0
    assert main(["motion", "generate", "--kind", "walk", "--seconds", "20", "--out", str(motion)]) == 0
    return garment, motion


def _after(ready, seconds: float):
    """``ready`` once it has held for ``seconds`` (the command has gone on into its work)."""
    since = []

    def check() -> bool:
        if not since and ready():
            since.append(time.monotonic())
        return bool(since) and time.monotonic() - since[0] > seconds
    return check


@pytest.mark.parametrize("sig,status,name", [(signal.SIGINT, 130, "SIGINT"), (signal.SIGTERM, 143, "SIGTERM")])
def test_single_sequence_interrupted_writes_nothing_and_says_so(one_sequence, tmp_path, sig, status, name):
    garment, motion = one_sequence
    out = tmp_path / "seq.npz"
    argv = ["simulate", "--garment", str(garment), "--motion", str(motion), "--out", str(out)]
    proc = _start(argv, tmp_path)
    # Blender loaded, then long enough for the body and garment to be set up and the frames to run
    rc, _, err = _interrupt(proc, _after(lambda: module_loaded("/bpy/")(tmp_path, proc.pid), 15.0), sig)
    assert rc == status, err
    line = _one_line(err, "simulate")
    assert line == (f"loosefit simulate: interrupted ({name}): nothing was written to {out} (a sequence is written "
                    f"when its simulation ends); run again: {shlex.join(['loosefit', *argv])}"), line
    assert not out.exists() and not list(tmp_path.glob(".seq.npz.*"))  # no half-written file, no temporary


@pytest.mark.parametrize("sig,status,name", [(signal.SIGINT, 130, "SIGINT"), (signal.SIGTERM, 143, "SIGTERM")])
def test_ray_plan_interrupted_keeps_finished_sequences_and_stops_its_workers(tmp_path, sig, status, name):
    plan, store = tmp_path / "slow.yaml", tmp_path / "d.zarr"
    plan.write_text(SLOW_PLAN)
    argv = ["simulate", str(plan), "--out", str(store), "--workers", "2"]
    proc = _start(argv, tmp_path)
    started: set[int] = set()

    def ready() -> bool:  # the walk is stored while a worker simulates the 20 s spin
        if _stored_ok(store) < 1:
            return False
        started.update(descendants(proc.pid))
        return True

    rc, _, err = _interrupt(proc, ready, sig)
    assert rc == status, err
    line = _one_line(err, "simulate")
    assert line.startswith(f"loosefit simulate: interrupted ({name}): 1 finished sequence(s) are kept in {store}")
    assert line.endswith(shlex.join(["loosefit", *argv])), line
    assert not (store / ".lock").exists()
    assert len(started) >= 3, started  # Ray's own processes and its workers ran under the command ...
    deadline = time.monotonic() + 30
    while alive(started) and time.monotonic() < deadline:
        time.sleep(0.5)
    assert not alive(started)  # ... and none of them outlives it
