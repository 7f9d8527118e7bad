"""The store's write lock (one writing process at a time, taken over when stale), races to create a
store, the litter of interrupted creations, and no empty store left by a failed first plan run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

from loosefit.cli import main
from loosefit.data import DatasetStore, lock, staging
from loosefit.errors import InputError
from tests.data.conftest import random_verts

# Opens (or creates) the store for writing, writes a sequence when the store has garment "g", says
# "ready" (or the error) and holds the store until its stdin closes; then exits normally.
_HOLDER = textwrap.dedent(
    """
    import sys
    import numpy as np
    from loosefit.data import DatasetStore
    from loosefit.errors import InputError

    try:
        store = DatasetStore.open_or_create(sys.argv[1])
    except InputError as e:
        print("refused:", e, flush=True)
        sys.exit(3)
    if "g" in store.garment_names():
        store.write_sequence("held", np.zeros((45, 25, 3), np.float32), "g", "b", "m45", {}, {}, "train")
    print("ready", flush=True)
    sys.stdin.read()
    """
)


def _holder(path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    return subprocess.Popen([sys.executable, "-c", _HOLDER, str(path)], env=env, text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE)


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_second_writer_is_refused_while_the_first_holds_the_lock(store, capsys):
    store.write_sequence("mine", random_verts(45, 25), "g", "b", "m45", {}, {}, "train")
    store.close()
    holder = _holder(store.path)
    try:
        assert holder.stdout.readline() == "ready\n"
        with pytest.raises(InputError, match=f"locked for writing by pid {holder.pid} on {staging.this_host()}") as err:
            DatasetStore.open(store.path, mode="a")
        assert err.value.path == store.path
        with pytest.raises(InputError, match=f"pid {holder.pid}"):
            DatasetStore.open_or_create(store.path)
        # The CLI says so in one line; readers need no lock.
        assert main(["info", str(store.path), "--repair"]) == 2
        assert f"loosefit info: error: {store.path}: dataset store is locked for writing by pid {holder.pid}" \
            in capsys.readouterr().err
        reader = DatasetStore.open(store.path)
        assert reader.sequence_names() == ["held", "mine"]
        assert reader.info()["writer"].startswith(f"pid {holder.pid} on {staging.this_host()}")
    finally:
        holder.stdin.close()
        assert holder.wait(timeout=60) == 0
    assert not (store.path / ".lock").exists()  # let go: no lock file left
    with DatasetStore.open(store.path, mode="a") as writer:
        writer.write_sequence("after", random_verts(45, 25), "g", "b", "m45", {}, {}, "train")
    assert DatasetStore.open(store.path).info()["writer"] is None


def test_lock_is_reentrant_within_a_process(store):
    second = DatasetStore.open(store.path, mode="a")
    assert lock.current_holder(store.path).pid == os.getpid()
    second.close()
    second.close()  # idempotent
    assert (store.path / ".lock").exists() and lock.current_holder(store.path).pid == os.getpid()
    with pytest.raises(InputError, match="read-only"):
        second.write_sequence("s", random_verts(45, 25), "g", "b", "m45", {}, {}, "train")
    store.write_sequence("s", random_verts(45, 25), "g", "b", "m45", {}, {}, "train")
    store.close()
    assert not (store.path / ".lock").exists() and lock.current_holder(store.path) is None


def test_stale_lock_of_a_dead_pid_is_taken_over(store):
    store.close()
    dead = _dead_pid()
    (store.path / ".lock").write_text(json.dumps({"pid": dead, "host": staging.this_host(), "since": "then"}))
    assert lock.current_holder(store.path) is None  # nobody holds it: stale
    writer = DatasetStore.open(store.path, mode="a")
    assert writer.recovered == [f"took over the write lock of pid {dead} on {staging.this_host()} (since then), "
                                "which no longer holds it"]
    assert json.loads((store.path / ".lock").read_text())["pid"] == os.getpid()


def test_racing_creators_one_wins_the_others_are_refused_cleanly(tmp_path):
    path = tmp_path / "new.zarr"
    procs = [_holder(path) for _ in range(3)]
    try:
        lines = [p.stdout.readline() for p in procs]
        winners = [p for p, line in zip(procs, lines) if line == "ready\n"]
        assert len(winners) == 1, lines
        for p, line in zip(procs, lines):
            if p is not winners[0]:
                assert p.wait(timeout=60) == 3
                assert line.startswith("refused: ") and f"locked for writing by pid {winners[0].pid}" in line, line
    finally:
        for p in procs:
            p.stdin.close()
            p.wait(timeout=60)
    assert DatasetStore.open(path).sequence_names() == []
    assert sorted(os.listdir(tmp_path)) == ["new.zarr"]  # no creation leftovers beside it


def test_litter_of_killed_creations_is_cleaned_once_its_pid_is_dead(tmp_path):
    path = tmp_path / "data.zarr"
    dead = _dead_pid()
    litter = [tmp_path / f".data.zarr.creating-{dead}@{staging.this_host()}", tmp_path / f".data.zarr.creating-{dead}"]
    running = tmp_path / f".data.zarr.creating-{os.getppid()}@{staging.this_host()}"  # a live process
    for d in (*litter, running):
        (d / "garments").mkdir(parents=True)
    store = DatasetStore.create(path)
    assert sorted(os.listdir(tmp_path)) == sorted(["data.zarr", running.name])
    store.close()
    for d in litter:
        (d / "bodies").mkdir(parents=True)
    writer = DatasetStore.open(path, mode="a")
    assert sorted(writer.recovered) == sorted(
        f"removed {d.name} (an interrupted creation of the store by pid {dead})" for d in litter
    )
    assert running.is_dir()


def test_remove_if_empty_keeps_a_store_with_sequences(store):
    store.write_sequence("s", random_verts(45, 25), "g", "b", "m45", {}, {}, "train")
    assert store.remove_if_empty() is False and store.path.is_dir()
    store.delete_sequence("s")
    assert store.remove_if_empty() is True
    assert not store.path.exists() and os.listdir(store.path.parent) == []


def test_failed_first_plan_run_leaves_no_store(tmp_path):
    """(Its time is the import of the simulator and the body model, shared with the other plan tests.)"""
    from loosefit.simulate import run_plan

    (tmp_path / "bad.obj").write_text("v 0 0 0\nthis is not an OBJ file\n")
    plan = tmp_path / "plan.yaml"
    plan.write_text("name: bad\ngarments:\n  g: {file: bad.obj}\nmotions:\n  walk: {procedural: walk, seconds: 0.2}\n")
    out = tmp_path / "out" / "data.zarr"
    with pytest.raises(InputError, match="not an OBJ statement") as err:
        run_plan(plan, out, progress=False)
    assert err.value.path == tmp_path / "bad.obj"
    assert not out.exists() and os.listdir(out.parent) == []  # no store, no creation leftovers

    DatasetStore.create(out).close()  # a store that exists before the run is kept
    with pytest.raises(InputError, match="not an OBJ statement"):
        run_plan(plan, out, progress=False)
    assert DatasetStore.open(out).body_names() == ["average"] and not (out / ".lock").exists()
