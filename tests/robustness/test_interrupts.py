"""Ctrl-C (SIGINT) and SIGTERM in the long verbs, through the CLI in a subprocess: one line saying what was
kept and the command that resumes, exit status 130 / 143, no traceback; the resume command works."""

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

from tests.robustness.cases_pipeline import GARMENT, TINY_TRAIN

#: Long enough that the signal always lands while the command works (a few hundred epochs of a tiny model).
LONG_TRAIN = [a if a != "train.stages.low.epochs=2" else "train.stages.low.epochs=500" for a in TINY_TRAIN]

SLOW_PLAN = """\
name: slow
garments:
  skirt: {template: skirt, seed: 0, edge_length: 0.06, params: {length: 0.4, flare: 20}}
motions:
  walk: {procedural: walk, seconds: 0.3, seed: 0}
  spin: {procedural: spin, seconds: 20.0, seed: 1}
sim_params:
  default: {preroll: 0.2}
"""


def _start(argv: list[str], cwd: Path) -> subprocess.Popen:
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "loosefit.cli", *argv], cwd=cwd, env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


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
    line = _one_line(err, "train")
    assert rc == status, err
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
