"""A refused command changes nothing: ``train --resume`` with a changed setting, ``prepare --force`` with a bad
setting and a writer meeting a symlinked lock leave every file byte-identical (hashed before and after);
``--resume`` of a folder that holds no run is an error naming it; a run folder is locked while ``train``
writes it (a second ``train`` is refused naming the holder) and a stale lock is taken over."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from loosefit.cli import main
from tests.robustness.cases_hostile import LONG_TRAIN
from tests.robustness.cases_pipeline import GARMENT, TINY_TRAIN
from tests.robustness.live import default_sigint


def snapshot(folder: Path) -> dict[str, str]:
    """Every file and link under ``folder`` (hidden ones too): relative path -> content hash or link target."""
    out = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            path = Path(root, name)
            rel = str(path.relative_to(folder))
            if path.is_symlink():
                out[rel] = "link -> " + os.readlink(path)
            elif path.is_file():
                out[rel] = hashlib.sha256(path.read_bytes()).hexdigest()
            else:
                out[rel] = "dir"
    return out


def train_argv(store: Path, run: Path, *extra: str) -> list[str]:
    return ["train", "--method", "virtualbones", "--data", str(store), "--garment", GARMENT, "--out", str(run),
            *TINY_TRAIN, *extra]


@pytest.fixture(scope="module")
def finished_run(tiny_store, tmp_path_factory):
    """A tiny virtualbones run trained to the end (copied by each test that may change it)."""
    run = tmp_path_factory.mktemp("refusals") / "run"
    assert main(train_argv(tiny_store, run)) == 0
    return run


@pytest.mark.parametrize("change", [["--set", "model.lf_hidden=32"], ["--set", "train.stages.low.epochs=3"],
                                    ["--set", "data.window=10"]])
def test_resume_with_a_changed_setting_leaves_the_run_byte_identical(tiny_store, finished_run, tmp_path, capsys,
                                                                      change):
    run = Path(shutil.copytree(finished_run, tmp_path / "run"))
    before = snapshot(run)
    assert main(train_argv(tiny_store, run, "--resume", *change)) == 2
    err = capsys.readouterr().err
    key = change[1].split("=")[0]
    assert f"loosefit train: error: {run}: --resume with settings other than the run's own ({key}: " in err, err
    assert "nothing was changed" in err
    assert snapshot(run) == before


def test_resume_with_its_own_settings_still_runs(tiny_store, finished_run, tmp_path, capsys):
    run = Path(shutil.copytree(finished_run, tmp_path / "run"))
    # where and how it runs may change (progress, tensorboard, device, threads...)
    assert main(train_argv(tiny_store, run, "--resume", "--set", "train.threads=1", "--device", "cpu")) == 0
    assert not (run / ".lock").exists()


@pytest.mark.parametrize("exists", [False, True])
def test_resume_of_a_folder_without_a_run_is_an_error_naming_it(tiny_store, tmp_path, capsys, exists):
    run = tmp_path / "never"
    if exists:
        run.mkdir()
        (run / "notes.txt").write_text("mine")
    before = snapshot(run) if exists else None
    assert main(train_argv(tiny_store, run, "--resume")) == 2
    err = capsys.readouterr().err
    assert f"loosefit train: error: {run}: --resume: this folder holds no run to resume" in err, err
    assert (snapshot(run) == before) if exists else not run.exists()


@pytest.mark.parametrize("setting,named", [("influences=0", "influences=0 (must be at least 1)"),
                                           ("smoothing=bogus", "unknown smoothing preset 'bogus'"),
                                           ("descriptor_sigma=nan", "descriptor_sigma=nan")])
def test_prepare_with_a_bad_setting_leaves_the_store_byte_identical(tiny_store, tmp_path, capsys, setting, named):
    store = Path(shutil.copytree(tiny_store, tmp_path / "d.zarr"))
    before = snapshot(store)
    assert main(["prepare", str(store), "--force", "--set", setting]) == 2
    err = capsys.readouterr().err
    assert "loosefit prepare: error: " in err and named in err, err
    assert snapshot(store) == before
    assert main(["info", str(store)]) == 0  # still prepared: info reads it as before
    assert "writing" not in capsys.readouterr().out


def test_symlinked_store_lock_is_refused_never_followed(tiny_store, tmp_path, capsys):
    store = Path(shutil.copytree(tiny_store, tmp_path / "d.zarr"))
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    (store / ".lock").symlink_to(victim)
    before = snapshot(store)
    assert main(["info", str(store), "--repair"]) == 2
    err = capsys.readouterr().err
    assert f"{store}: cannot lock the dataset store for writing: its lock file .lock is a symbolic link" in err, err
    assert victim.read_text() == "precious\n"
    assert snapshot(store) == before  # the link itself is still there, untouched


def _wait(proc: subprocess.Popen, ready, timeout: float = 240.0) -> None:
    start = time.monotonic()
    while not ready():
        if proc.poll() is not None or time.monotonic() - start > timeout:
            proc.kill()
            pytest.fail(f"the first train never got to work:\n{proc.communicate()[1]}")
        time.sleep(0.1)


def test_second_train_into_a_run_folder_is_refused_naming_the_holder(tiny_store, tmp_path, capsys):
    run = tmp_path / "run"
    argv = ["train", "--method", "virtualbones", "--data", str(tiny_store), "--garment", GARMENT, "--out", str(run),
            *LONG_TRAIN]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    first = subprocess.Popen([sys.executable, "-m", "loosefit.cli", *argv], env=env, stdin=subprocess.DEVNULL,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint)
    try:
        _wait(first, (run / "checkpoints" / "last.pt").is_file)
        assert main([*argv, "--resume"]) == 2
        err = capsys.readouterr().err
        assert f"loosefit train: error: {run}: run folder is locked for writing by pid {first.pid}" in err, err
    finally:
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=120)
    assert first.returncode == 130
    assert not (run / ".lock").exists()  # let go when the holder stopped


def test_stale_run_lock_is_taken_over(tiny_store, finished_run, tmp_path, capsys, caplog):
    run = Path(shutil.copytree(finished_run, tmp_path / "run"))
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    pid = int(dead.stdout)
    from loosefit.data.staging import this_host

    (run / ".lock").write_text(json.dumps({"pid": pid, "host": this_host(), "since": "earlier"}))
    with caplog.at_level("WARNING", logger="loosefit.training"):
        assert main(train_argv(tiny_store, run, "--resume")) == 0
    assert f"took over the write lock of pid {pid}" in caplog.text
    assert not (run / ".lock").exists()
