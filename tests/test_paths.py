"""Atomic writes and output checks: an unwritable place is an InputError naming it (never a traceback),
checked before any work; stale temporaries of killed writes are found by name only; an output over a run
folder's own files or into a dataset store is refused unless forced."""

import os
import tempfile
from pathlib import Path

import pytest

from loosefit.errors import InputError
from loosefit.paths import RUN_NAMES, atomic_path, check_writable, guard_output, is_run_folder, remove_stale_temporaries


@pytest.fixture
def a_file(tmp_path):
    path = tmp_path / "plain.txt"
    path.write_text("keep me")
    return path


def _unwritable(tmp_path, a_file):
    """Places nobody can write, even root (the tests run as root: permissions do not stop it)."""
    return {
        "parent is a file": a_file / "out.npz",
        "grandparent is a file": a_file / "sub" / "out.npz",
        "/proc": Path("/proc/loosefit-test/out.npz"),
        "/proc itself": Path("/proc/out.npz"),
    }


@pytest.mark.parametrize("case", ["parent is a file", "grandparent is a file", "/proc", "/proc itself"])
def test_atomic_path_names_target_and_reason(tmp_path, a_file, case):
    target = _unwritable(tmp_path, a_file)[case]
    with pytest.raises(InputError) as err:
        with atomic_path(target) as tmp:
            tmp.write_text("never")
    assert str(err.value).startswith(f"{target}: cannot write: ") and len(err.value.problem) > len("cannot write: ")
    assert a_file.read_text() == "keep me"


@pytest.mark.parametrize("folder", [False, True])
@pytest.mark.parametrize("case", ["parent is a file", "grandparent is a file", "/proc", "/proc itself"])
def test_check_writable_refuses_before_work(tmp_path, a_file, case, folder):
    target = _unwritable(tmp_path, a_file)[case]
    with pytest.raises(InputError, match="cannot write here: ") as err:
        check_writable(target, folder=folder)
    assert str(err.value).startswith(str(target))


def test_check_writable_accepts_and_leaves_nothing(tmp_path, a_file):
    before = sorted(os.listdir(tmp_path))
    check_writable(tmp_path / "new" / "deeper" / "out.npz")  # missing folders are fine: they are created later
    check_writable(tmp_path / "run", folder=True)
    check_writable(a_file)  # an existing file is replaced atomically
    assert sorted(os.listdir(tmp_path)) == before
    with pytest.raises(InputError, match="it is a file, a folder is needed"):
        check_writable(a_file, folder=True)
    with pytest.raises(InputError, match="it is a folder, a file is needed"):
        check_writable(tmp_path)


def test_replacing_a_folder_is_an_input_error_and_keeps_it(tmp_path):
    (tmp_path / "out.npz").mkdir()
    (tmp_path / "out.npz" / "inside").write_text("data")
    with pytest.raises(InputError, match="out.npz: cannot write: "):
        with atomic_path(tmp_path / "out.npz") as tmp:
            tmp.write_text("new")
    assert (tmp_path / "out.npz" / "inside").read_text() == "data"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.npz"]  # the temporary file is gone


def test_remove_stale_temporaries_by_name(tmp_path):
    stale = []
    for name in ("last.pt", "model.json", "metrics.csv"):  # what atomic_path names its temporary files
        fd, path = tempfile.mkstemp(prefix=f".{name}.", suffix=Path(name).suffix, dir=tmp_path)
        os.close(fd)
        stale.append(Path(path))
    keep = ["last.pt", ".hidden", ".notes.txt", ".last.pt.abcd1234.json", ".a.pt.abc.pt", "x.pt.abcd1234.pt"]
    for name in keep:
        (tmp_path / name).write_text("keep")
    (tmp_path / ".dir.pt.abcd1234.pt").mkdir()
    assert sorted(remove_stale_temporaries(tmp_path)) == sorted(stale)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(keep + [".dir.pt.abcd1234.pt"])
    assert remove_stale_temporaries(tmp_path / "absent") == []


@pytest.fixture
def run_and_store(tmp_path):
    """A run folder (method.yaml, metrics.csv, checkpoints/last.pt) and a store (a Zarr group with a group inside)."""
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    for name in ("method.yaml", "metrics.csv", "checkpoints/last.pt"):
        (run / name).write_text(name)
    store = tmp_path / "d.zarr"
    (store / "sequences" / "s1").mkdir(parents=True)
    for group in (store, store / "sequences", store / "sequences" / "s1"):
        (group / ".zgroup").write_text('{"zarr_format": 2}')
    return run, store


def _refusal(path, **kw) -> str:
    with pytest.raises(InputError) as e:
        guard_output(path, **kw)
    return str(e.value)


@pytest.mark.parametrize("rel,said", [
    ("run/metrics.csv", "the training log of the training run folder {tmp}/run"),
    ("run/method.yaml", "the method config of the training run folder {tmp}/run"),
    ("run/checkpoints/last.pt", "inside the checkpoints folder of the training run folder {tmp}/run"),
    ("run/checkpoints/best.pt", "inside the checkpoints folder"),  # not there yet: training writes it later
    ("run/run.json", "the training summary"),  # the same
    ("run", "a training run folder"),
    ("d.zarr", "a dataset store"),
    ("d.zarr/x.gif", "inside the dataset store {tmp}/d.zarr"),
    ("d.zarr/sequences/s1/new/anim.npz", "inside the dataset store {tmp}/d.zarr"),  # the root is named
])
def test_outputs_over_run_or_store_files_are_refused_naming_them(tmp_path, run_and_store, rel, said):
    message = _refusal(tmp_path / rel)
    assert message.startswith(f"{tmp_path / rel}: this is {said.format(tmp=tmp_path)}"), message
    assert message.endswith("choose another output, or give --force to overwrite it"), message
    guard_output(tmp_path / rel, force=True)  # --force writes anyway


def test_ordinary_outputs_pass(tmp_path, run_and_store):
    run, _ = run_and_store
    (run / "anim.npz").write_text("an earlier animation of the user's")
    for path in (tmp_path / "new.npz", run / "anim.npz", run / "new" / "frames", tmp_path / "folder"):
        guard_output(path)
    guard_output(run, names=("metrics.json", "report.md"))  # a folder output checks only the names it writes
    assert "metrics.csv" in _refusal(run, names=("metrics.json", "metrics.csv"))


def test_links_are_followed_for_the_check(tmp_path, run_and_store):
    run, store = run_and_store
    (tmp_path / "log.csv").symlink_to(run / "metrics.csv")
    (tmp_path / "into-store").symlink_to(store / "sequences")
    assert f"(a link to {run / 'metrics.csv'})" in _refusal(tmp_path / "log.csv")
    assert "inside the dataset store" in _refusal(tmp_path / "into-store" / "a.npz")


def test_without_a_force_option_the_message_asks_only_for_another_output(run_and_store):
    run, store = run_and_store
    assert _refusal(run / "metrics.csv", force=None).endswith(": choose another output")
    guard_output(run, None, stores_only=True)  # train's own output is a run folder
    assert "dataset store" in _refusal(store / "runs" / "vb", force=None, stores_only=True)


def test_run_folder_recognised_by_its_records_not_by_a_stray_name(tmp_path):
    assert not is_run_folder(tmp_path)
    (tmp_path / "model.json").write_text("{}")  # a common name: alone it is no run
    (tmp_path / "checkpoints").mkdir()
    assert is_run_folder(tmp_path)  # beside a checkpoints folder it is
    other = tmp_path / "other"
    (other / "checkpoints").mkdir(parents=True)
    assert not is_run_folder(other)
    (other / "checkpoints" / "last.pt").write_bytes(b"")
    assert is_run_folder(other)


def test_run_names_agree_with_the_run_layout():
    from loosefit.data.lock import LOCK_FILE
    from loosefit.models.collision.training import SDF_FILE, SDF_META
    from loosefit.pretrained import FILES as PRETRAINED
    from loosefit.train.run import RunDir
    from loosefit.training import METHOD_CONFIG, MODEL_META

    run = RunDir("r")
    names = {run.config.name, run.metrics_csv.name, run.summary.name, run.checkpoints.name, run.tensorboard.name,
             METHOD_CONFIG, MODEL_META, SDF_FILE, SDF_META, LOCK_FILE, *(f.split("/")[0] for f in PRETRAINED)}
    assert names == set(RUN_NAMES)
