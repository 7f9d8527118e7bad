"""Atomic writes and output checks: an unwritable place is an InputError naming it (never a traceback),
checked before any work; stale temporaries of killed writes are found by name only."""

import os
import tempfile
from pathlib import Path

import pytest

from loosefit.errors import InputError
from loosefit.paths import atomic_path, check_writable, remove_stale_temporaries


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
