"""Project-controlled directories (caches), atomic file writes and checks that an output can be written."""

from __future__ import annotations

import contextlib
import os
import re
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
