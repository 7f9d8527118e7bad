"""Atomic writes: a writer killed mid-write leaves a readable store without its partial sequence, and
an interrupted replacement is rolled back."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from loosefit.data import DatasetStore
from loosefit.data import lock, staging
from tests.data.conftest import random_verts

# Writes sequences slowly, each in its own thread of one process (one process writes a store at a
# time): one 32-frame block every 0.1 s, touching a flag file once half way. Arguments: the store,
# then name, flag file and seed for each sequence.
_SLOW_WRITER = textwrap.dedent(
    """
    import sys, threading, time, pathlib
    import numpy as np
    from loosefit.data import DatasetStore

    class SlowFrames:
        shape = (70, 25, 3)
        def __init__(self, flag, seed):
            self.flag = flag
            self.data = np.random.default_rng(seed).normal(0, 0.3, self.shape).astype(np.float32)
        def __getitem__(self, frames):
            if frames.start > 0:
                self.flag.touch()
                time.sleep(60)  # killed here, half of the chunks written
            return self.data[frames]

    store = DatasetStore.open(sys.argv[1], mode="a")
    jobs = [sys.argv[i:i + 3] for i in range(2, len(sys.argv), 3)]
    threads = [
        threading.Thread(target=store.write_sequence,
                         args=(name, SlowFrames(pathlib.Path(flag), int(seed)), "g", "b", "m70", {}, {}, "train"))
        for name, flag, seed in jobs
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    """
)


def _start_writer(store, *jobs):
    """A process writing ``jobs`` ((name, flag, seed)...) into ``store``."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    args = [str(x) for job in jobs for x in job]
    return subprocess.Popen([sys.executable, "-c", _SLOW_WRITER, str(store.path), *args], env=env)


def _wait_for(flags, procs, timeout=60.0):
    deadline = time.monotonic() + timeout
    while not all(f.exists() for f in flags):
        for p in procs:
            assert p.poll() is None, f"writer exited early with code {p.returncode}"
        assert time.monotonic() < deadline, "writers did not reach the middle of their write"
        time.sleep(0.05)


def test_killed_writers_leave_no_partial_sequence(store, tmp_path):
    kept = random_verts(70, 25, seed=7)
    store.write_sequence("kept", kept, "g", "b", "m70", {"a": 1}, {}, "train")
    store.write_sequence("replaced", random_verts(70, 25, seed=8), "g", "b", "m70", {}, {}, "test")
    old_replaced = store.sequence("replaced").verts[:]

    # Two writes at once: one of a new sequence, one rewriting an existing one; the writer is killed.
    store.close()  # the writer process needs the store's write lock
    flags = [tmp_path / "new.flag", tmp_path / "rewrite.flag"]
    procs = [_start_writer(store, ("new", flags[0], 1), ("replaced", flags[1], 2))]
    try:
        _wait_for(flags, procs)
    finally:
        for p in procs:
            p.send_signal(signal.SIGKILL)
            p.wait()

    # The killed writer's lock file stays, naming it, but nobody holds the lock any more (stale).
    assert lock.read_holder(store.path).pid == procs[0].pid and lock.current_holder(store.path) is None
    leftovers = staging.leftovers(store.path)
    assert sorted(l.target for l in leftovers) == ["sequences/new", "sequences/replaced"]
    assert all(l.kind == "tmp" and not l.writer_alive() for l in leftovers)
    # Each left half its chunks behind: the kill happened mid-write.
    assert all(len([f for f in os.listdir(l.path / "verts") if f[0].isdigit()]) == 1 for l in leftovers)

    reader = DatasetStore.open(store.path)
    assert not reader.has_sequence("new")
    assert reader.sequence_names(status=None) == ["kept", "replaced"]
    np.testing.assert_array_equal(reader.sequence("kept").verts[:], kept)
    np.testing.assert_array_equal(reader.sequence("replaced").verts[:], old_replaced)
    assert reader.sequence("kept").sim_params == {"a": 1}
    problems = reader.problems()
    assert len(problems) == 2 and all("unfinished write" in p and "writer gone" in p for p in problems.values())

    writer = DatasetStore.open(store.path, mode="a")  # cleans what dead writers left, takes over the lock
    assert len(writer.recovered) == 3 and staging.leftovers(store.path) == [] and writer.problems() == {}
    assert writer.recovered[0].startswith(f"took over the write lock of pid {procs[0].pid} on {staging.this_host()}")
    assert writer.recovered[0].endswith("which no longer holds it")
    again = random_verts(70, 25, seed=1)
    writer.write_sequence("new", again, "g", "b", "m70", {}, {}, "train")
    np.testing.assert_array_equal(DatasetStore.open(store.path).sequence("new").verts[:], again)
    assert writer.sequence_names() == ["kept", "new", "replaced"]


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_interrupted_replacement_is_rolled_back(store):
    """A writer killed between moving the old sequence aside and renaming the new one into place."""
    verts = random_verts(45, 25, seed=4)
    store.write_sequence("s", verts, "g", "b", "m45", {}, {}, "train")
    aside = store.path / staging.STAGING / f"old@sequences:s@{_dead_pid()}@{staging.this_host()}@0123abcd"
    os.rename(store.path / "sequences" / "s", aside)

    reader = DatasetStore.open(store.path)
    assert not reader.has_sequence("s")
    pid = aside.name.split("@")[2]
    assert list(reader.problems().values()) == [
        f"interrupted replacement of 'sequences/s' by pid {pid} on {staging.this_host()} (writer gone)"
    ]
    writer = DatasetStore.open(store.path, mode="a")
    assert writer.recovered == ["restored the previous 'sequences/s' (its replacement was interrupted)"]
    np.testing.assert_array_equal(writer.sequence("s").verts[:], verts)
    assert staging.leftovers(store.path) == []


def test_leftovers_of_running_writers_are_kept(store):
    """Opening in mode "a" must not delete the staging directory of a writer that is still running."""
    staged = staging.new_staging_dir(store.path, "sequences/busy")  # this process: alive
    writer = DatasetStore.open(store.path, mode="a")
    assert writer.recovered == [] and staged.is_dir()
    assert "writer still running" in writer.problems()[f"{staging.STAGING}/{staged.name}"]
    staging.discard(staged)


@pytest.mark.parametrize("replace", [False, True])
def test_commit_places_or_replaces_directory(tmp_path, replace):
    (tmp_path / "grp").mkdir()
    if replace:
        (tmp_path / "grp" / "x").mkdir()
        (tmp_path / "grp" / "x" / "old.txt").write_text("old")
    staged = staging.new_staging_dir(tmp_path, "grp/x")
    (staged / "new.txt").write_text("new")
    staging.commit(tmp_path, staged, "grp/x")
    assert os.listdir(tmp_path / "grp" / "x") == ["new.txt"]
    assert os.listdir(tmp_path / staging.STAGING) == []
