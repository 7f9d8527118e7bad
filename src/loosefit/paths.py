"""Project-controlled directories (caches), atomic file and folder writes and checks that an output can be written."""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Iterator

from loosefit.errors import InputError


def cache_dir() -> Path:
    """Root of loosefit's caches: ``$LOOSEFIT_CACHE`` or ``~/.cache/loosefit``."""
    root = Path(os.environ.get("LOOSEFIT_CACHE", Path.home() / ".cache" / "loosefit"))
    root.mkdir(parents=True, exist_ok=True)
    return root


def anny_cache_dir() -> Path:
    """Where Anny's model cache (~790 MB, built once in 40-70 s) lives: ``$ANNY_CACHE_DIR`` if set,
    else ``<cache_dir>/anny``."""
    path = Path(os.environ.get("ANNY_CACHE_DIR", cache_dir() / "anny"))
    path.mkdir(parents=True, exist_ok=True)
    return path


def _reason(err: OSError) -> str:
    return err.strerror or str(err)


def _existing_ancestor(path: Path) -> Path:
    """``path`` itself or its nearest ancestor that exists (as anything: a folder, a file...)."""
    path = Path(os.path.abspath(path))
    while not os.path.lexists(path) and path != path.parent:
        path = path.parent
    return path


def check_writable(path: str | Path, folder: bool = False) -> None:
    """Raise :class:`InputError` naming ``path`` when it cannot be written, before any work is done.

    ``path`` is an output file (``folder=False``) or an output folder (``folder=True``) that may not
    exist yet (its missing parents are created when it is written). The check creates and removes a
    temporary file in the nearest existing folder, so it sees what the OS would refuse (a read-only
    file system, /proc, permissions) and also a parent that is a file. Nothing is left behind.
    """
    path = Path(path)
    if path.exists():
        if folder and not path.is_dir():
            raise InputError("cannot write here: it is a file, a folder is needed", path)
        if not folder and path.is_dir():
            raise InputError("cannot write here: it is a folder, a file is needed", path)
    probe_in = _existing_ancestor(path if folder else path.parent)
    if not probe_in.is_dir():
        raise InputError(f"cannot write here: {probe_in} is a file, not a folder", path)
    try:
        fd, probe = tempfile.mkstemp(prefix=".loosefit-write-check.", dir=probe_in)
    except OSError as e:
        raise InputError(f"cannot write here: {_reason(e)} ({probe_in})", path) from None
    os.close(fd)
    os.unlink(probe)


@contextlib.contextmanager
def atomic_path(target: str | Path, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; on success it is renamed onto ``target``.

    An exception (or a killed process) leaves ``target`` as it was: whatever was written
    before is never lost. ``suffix`` defaults to the target's own suffix so that writers that
    pick a format from the extension keep working. A target that cannot be written (its folder
    cannot be created or is read-only, or it is an existing folder) raises :class:`InputError`
    naming ``target`` and the OS's reason.
    """
    target = Path(target)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(
            prefix=f".{target.name}.", suffix=target.suffix if suffix is None else suffix, dir=target.parent
        )
    except OSError as e:
        raise InputError(f"cannot write: {_reason(e)}", target) from None
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        if tmp_path.exists():  # mkstemp creates files 0600: give them the usual permissions
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp_path, 0o666 & ~umask)
        try:
            os.replace(tmp_path, target)
        except OSError as e:
            raise InputError(f"cannot write: {_reason(e)}", target) from None
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


#: The name :func:`atomic_path` gives its temporary file: ``.<target name>.<8 random characters><suffix>``.
_TEMPORARY = re.compile(r"^\.(?P<target>.+)\.[a-z0-9_]{8}(?P<suffix>\.[^.]*)?$")


def remove_stale_temporaries(folder: str | Path) -> list[Path]:
    """Delete the temporary files that :func:`atomic_path` left in ``folder`` (not its subfolders)
    when a process was killed while writing; returns the paths removed.

    Only names of the form ``.<name>.<8 characters><suffix of name>`` go (``.last.pt.k2j4x9_a.pt``);
    call it only when no other process writes into ``folder``.
    """
    folder = Path(folder)
    removed = []
    if not folder.is_dir():
        return removed
    for entry in folder.iterdir():
        match = _TEMPORARY.match(entry.name)
        if match is None or not entry.is_file() or entry.is_symlink():
            continue
        if (match["suffix"] or "") != Path(match["target"]).suffix:
            continue
        with contextlib.suppress(FileNotFoundError):
            entry.unlink()
            removed.append(entry)
    return removed


# ------------------------------------------------------------------------------------- outputs over others' files

#: What the names a training run folder reserves hold (``loosefit.train.run.RunDir``, ``loosefit.training``,
#: the body SDF's run, a shipped pretrained garment). Repeated here so that every verb checks its outputs
#: without importing torch; tests/test_paths.py checks that they agree.
RUN_NAMES = {
    "config.yaml": "the training config",
    "metrics.csv": "the training log",
    "run.json": "the training summary",
    "model.json": "the model record",
    "method.yaml": "the method config",
    "body_sdf.pt": "the body SDF network",
    "pretrained.json": "the pretrained record",
    ".lock": "the write lock",
    "checkpoints": "the checkpoints folder",
    "tensorboard": "the TensorBoard folder",
}
#: A Zarr group (every dataset store, and each group inside one) holds this file.
STORE_MARKER = ".zgroup"


def is_run_folder(path: str | Path) -> bool:
    """Whether ``path`` is a training run folder: it holds ``method.yaml``, or ``model.json`` with the body SDF
    network or a checkpoints folder, or checkpoint files (a run that has written nothing else yet)."""
    path = Path(path)
    checkpoints = path / "checkpoints"
    if (path / "method.yaml").is_file():
        return True
    if (path / "model.json").is_file() and ((path / "body_sdf.pt").is_file() or checkpoints.is_dir()):
        return True
    return checkpoints.is_dir() and any(checkpoints.glob("*.pt"))


def _owner(path: Path, stores_only: bool = False) -> str | None:
    """What writing ``path`` (absolute) would write over, in words: the dataset store it is in (any Zarr group:
    every file in a store is the store's), or the run folder it is or whose reserved name it is; else None."""
    ancestors = [p for p in (path, *path.parents) if p.is_dir()]
    stores = [p for p in ancestors if (p / STORE_MARKER).is_file()]
    if stores:
        root = stores[0]
        while root.parent != root and (root.parent / STORE_MARKER).is_file():  # a group inside the store
            root = root.parent
        what = "a dataset store" if path == root else f"inside the dataset store {root}"
        return what + " (only loosefit simulate and prepare write there)"
    for folder in [] if stores_only else ancestors:
        if is_run_folder(folder):
            if folder == path:
                return "a training run folder"
            parts = path.relative_to(folder).parts
            if parts[0] not in RUN_NAMES:  # anything else beside the run's files is the user's own (an animation...)
                return None
            return f"{'inside ' if len(parts) > 1 else ''}{RUN_NAMES[parts[0]]} of the training run folder {folder}"
    return None


def guard_output(path: str | Path, force: bool | None = False, names: tuple[str, ...] | list[str] | None = None,
                 stores_only: bool = False) -> None:
    """Refuse an output that would write over a training run folder's own files or into a dataset store,
    before any work is done.

    ``path`` is an output file or folder. It is refused when it is inside a dataset store (only ``simulate``
    and ``prepare`` write there) or is a name its run folder reserves (:data:`RUN_NAMES`: ``metrics.csv``,
    ``checkpoints/...``); an output folder also when it is a run folder itself, unless ``names`` lists the
    files the verb writes in it (then each of those is checked instead). The path as given and where its
    symbolic links lead are both checked. A new file, or a user's own earlier output beside a run's files, is
    written as before.

    Args:
        force: True: nothing is refused (the verb's ``--force``); None: the verb has no ``--force`` (the
            message asks for another output only).
        stores_only: check only that ``path`` is not in a dataset store (``train``, whose output is a run folder).

    Raises:
        InputError: naming the file or folder that would be overwritten and what it is.
    """
    if force:
        return
    path = Path(os.path.abspath(path))
    for target in [path] if names is None else [path / name for name in names]:
        for seen in dict.fromkeys((target, Path(os.path.realpath(target)))):
            what = _owner(seen, stores_only)
            if what is None:
                continue
            advice = "choose another output" + (", or give --force to overwrite it" if force is not None else "")
            link = "" if seen == target else f" (a link to {seen})"
            raise InputError(f"this is {what}{link}; an output here would write over it: {advice}", target)


@contextlib.contextmanager
def atomic_folder(target: str | Path) -> Iterator[Path]:
    """Yield an empty temporary folder beside ``target``; on success it replaces ``target``.

    On an exception the temporary folder is removed and ``target`` is left as it was.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    old = tmp.with_name(tmp.name + ".old")
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes folders 0700: give them the usual permissions
        if target.exists():
            os.replace(target, old)  # a folder cannot be renamed over a non-empty one: swap in two steps
        os.replace(tmp, target)
    except BaseException:
        if old.exists() and not target.exists():
            os.replace(old, target)
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    shutil.rmtree(old, ignore_errors=True)
