"""Atomic directory commits inside a dataset store.

Every write builds its directory under ``<store>/.staging/`` first, flushes it to disk and then
renames it into place, so no reader ever sees a half-written group. A staging directory's name
records what it is for and who writes it::

    tmp@<target>@<pid>@<host>@<token>   a directory being built for <target>
    old@<target>@<pid>@<host>@<token>   the previous <target>, moved aside just before the new one
                                        took its place

``<target>`` is the path relative to the store root with ``/`` written as ``:`` (store names never
contain ``@`` or ``:``). A writer killed at any moment leaves either the old version or the new one
at the target, never a mix, plus leftovers that :func:`recover` resolves once their writer is gone:
a ``tmp`` leftover is deleted; an ``old`` leftover is deleted when its target exists and renamed
back otherwise (the replacement never happened, so the previous version stays).
"""

from __future__ import annotations

import os
import re
import secrets
import shutil
import socket
from dataclasses import dataclass
from pathlib import Path

STAGING = ".staging"
_LEFTOVER_RE = re.compile(r"^(tmp|old)@([^@]+)@(\d+)@([^@]+)@([0-9a-f]{8})$")


def this_host() -> str:
    """This machine's name with only ``[A-Za-z0-9.-]`` (it is part of directory names)."""
    return re.sub(r"[^A-Za-z0-9.-]", "-", socket.gethostname()) or "localhost"


@dataclass(frozen=True)
class Leftover:
    """A staging directory found in a store: an unfinished or interrupted write."""

    path: Path
    kind: str  # "tmp" (being built) or "old" (a replaced target moved aside)
    target: str  # path of the target relative to the store root
    pid: int
    host: str

    def writer_alive(self) -> bool:
        """Whether the writing process may still be running. A writer on another machine (a store
        on a shared file system) cannot be checked and counts as alive."""
        if self.host != this_host():
            return True
        try:
            os.kill(self.pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:  # exists, owned by someone else
            return True
        return True

    def describe(self) -> str:
        what = "unfinished write" if self.kind == "tmp" else "interrupted replacement"
        state = "writer still running" if self.writer_alive() else "writer gone"
        return f"{what} of {self.target!r} by pid {self.pid} on {self.host} ({state})"


def new_staging_dir(root: Path, target: str) -> Path:
    """Create and return an empty staging directory for ``target`` (relative to ``root``)."""
    name = f"tmp@{target.replace('/', ':')}@{os.getpid()}@{this_host()}@{secrets.token_hex(4)}"
    path = root / STAGING / name
    path.mkdir(parents=True)
    return path


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_tree(path: Path) -> None:
    """Flush every file and directory under ``path`` to disk, so that after the commit's rename a
    power cut cannot leave a target whose files are empty."""
    for dirpath, _, filenames in os.walk(path):
        for name in filenames:
            fd = os.open(os.path.join(dirpath, name), os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        _fsync_dir(Path(dirpath))


def commit(root: Path, staged: Path, target: str) -> None:
    """Move the finished staging directory ``staged`` onto ``root / target``, replacing what is there.

    The parent of the target must exist. The only moment the target is absent is between two
    renames; a writer killed there leaves an ``old`` leftover that :func:`recover` puts back.
    """
    fsync_tree(staged)
    dest = root / target
    aside = staged.with_name("old" + staged.name[3:])
    replacing = dest.exists()
    if replacing:
        os.rename(dest, aside)
    os.rename(staged, dest)
    _fsync_dir(dest.parent)
    if replacing:
        shutil.rmtree(aside)


def remove(root: Path, target: str) -> None:
    """Delete ``root / target``: it disappears at once (a rename), its files are deleted after."""
    staged = new_staging_dir(root, target)
    os.rename(root / target, staged / "gone")
    shutil.rmtree(staged)


def discard(staged: Path) -> None:
    """Delete a staging directory whose write failed."""
    shutil.rmtree(staged, ignore_errors=True)


def leftovers(root: Path) -> list[Leftover]:
    """Staging directories present in the store at ``root`` (unknown names are ignored)."""
    staging = root / STAGING
    if not staging.is_dir():
        return []
    found = []
    for entry in sorted(os.scandir(staging), key=lambda e: e.name):
        m = _LEFTOVER_RE.match(entry.name)
        if m and entry.is_dir():
            kind, target, pid, host, _ = m.groups()
            found.append(Leftover(Path(entry.path), kind, target.replace(":", "/"), int(pid), host))
    return found


def recover(root: Path, leftover: Leftover) -> str:
    """Resolve the leftover of a writer that is gone; returns what was done, in words."""
    dest = root / leftover.target
    if leftover.kind == "old" and not dest.exists():
        try:
            os.rename(leftover.path, dest)
        except FileNotFoundError:  # another process recovered it first
            return f"{leftover.target!r} already restored"
        return f"restored the previous {leftover.target!r} (its replacement was interrupted)"
    shutil.rmtree(leftover.path, ignore_errors=True)
    return f"removed the {'unfinished' if leftover.kind == 'tmp' else 'replaced'} copy of {leftover.target!r}"
