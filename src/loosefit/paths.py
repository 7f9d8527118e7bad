"""Project-controlled directories (caches) and atomic file writes."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterator


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


@contextlib.contextmanager
def atomic_path(target: str | Path, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; on success it is renamed onto ``target``.

    An exception (or a killed process) leaves ``target`` as it was: whatever was written
    before is never lost. ``suffix`` defaults to the target's own suffix so that writers that
    pick a format from the extension keep working.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(
        prefix=f".{target.name}.", suffix=target.suffix if suffix is None else suffix, dir=target.parent
    )
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        if tmp_path.exists():  # mkstemp creates files 0600: give them the usual permissions
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp_path, 0o666 & ~umask)
        os.replace(tmp_path, target)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()
