"""The write lock of a dataset store (and of a training run folder), and the litter of interrupted store creations.

One process writes a store at a time: it holds ``<store>/.lock``, a file with its pid, host and
start time, locked with ``flock`` while the store is open for writing. The kernel drops the flock
when the holder exits however it ends, so a lock file whose holder is gone (a stale lock, pid dead)
is simply taken over by the next writer; a second writer while the holder runs is refused with an
:class:`~loosefit.errors.InputError` naming the store and the holder's pid and host. Within one
process the lock is re-entrant (several store objects may write one store). Readers take no lock.
The holder deletes the file when it lets go. A lock file that is a symbolic link is refused, never
followed (``O_NOFOLLOW``): a writer would otherwise write and delete whatever it points to. Training
locks its run folder the same way (``what="run folder"``).

A store is created beside its final place as ``.<name>.creating-<pid>@<host>`` and renamed into
place; a process killed during creation leaves that directory, which :func:`clean_creating_litter`
removes once its pid is dead.
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import shutil
import stat
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from loosefit.data.layout import now
from loosefit.data.staging import this_host
from loosefit.errors import InputError

LOCK_FILE = ".lock"
_CREATING_RE = re.compile(r"^\.(?P<name>.+)\.creating-(?P<pid>\d+)(?:@(?P<host>[A-Za-z0-9.-]+))?$")


def process_alive(pid: int, host: str) -> bool:
    """Whether process ``pid`` on ``host`` may still run (one on another machine cannot be checked: yes)."""
    if host != this_host():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


@dataclass(frozen=True)
class Holder:
    """Who holds (or last held) a store's lock, from the lock file."""

    pid: int
    host: str
    since: str

    def describe(self) -> str:
        return f"pid {self.pid} on {self.host} (since {self.since or '?'})"


def _parse(text: str) -> Holder | None:
    try:
        value = json.loads(text)
        return Holder(int(value["pid"]), str(value["host"]), str(value.get("since", "")))
    except (ValueError, TypeError, KeyError):
        return None


#: Opening a lock file never follows a symbolic link, nor waits on a FIFO.
_NOFOLLOW = os.O_NOFOLLOW | os.O_NONBLOCK


def read_holder(root: Path) -> Holder | None:
    """The pid, host and time written in the lock file of the store at ``root`` (None: none readable)."""
    try:
        fd = os.open(root / LOCK_FILE, os.O_RDONLY | _NOFOLLOW)
    except OSError:
        return None
    try:
        return _parse(os.read(fd, 4096).decode(errors="replace"))
    except OSError:
        return None
    finally:
        os.close(fd)


def current_holder(root: Path) -> Holder | None:
    """The process holding the store's write lock now, or None when no process holds it (a stale
    lock file of a dead writer counts as free). Takes no lock."""
    try:
        fd = os.open(root / LOCK_FILE, os.O_RDONLY | _NOFOLLOW)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return read_holder(root) or Holder(0, "?", "")
    except OSError:
        return None
    finally:
        os.close(fd)  # also drops the shared lock just taken
    return None


@dataclass
class _Held:
    fd: int
    path: Path
    count: int


_held: dict[str, _Held] = {}
_guard = threading.Lock()


def _forget_in_child() -> None:
    # A forked child shares the parent's flock; it must neither release nor delete the parent's lock.
    for held in _held.values():
        os.close(held.fd)
    _held.clear()


os.register_at_fork(after_in_child=_forget_in_child)


def _busy(root: Path, what: str) -> InputError:
    holder = None
    for _ in range(20):  # the holder writes its pid just after taking the lock
        holder = read_holder(root)
        if holder is not None:
            break
        time.sleep(0.05)
    if holder is None:
        who = "another process"
    elif process_alive(holder.pid, holder.host):
        who = holder.describe()
    else:
        who = f"{holder.describe()}, which has exited while a process it started still holds the lock"
    return InputError(
        f"{what} is locked for writing by {who}; one process writes a {what} at a time: "
        "wait for it to finish (or stop it) and run again",
        root,
    )


def _take(path: Path, root: Path, what: str = "dataset store") -> tuple[int, Holder | None]:
    """Lock the file ``path`` (created if missing, never followed if a symbolic link) for this process;
    returns its descriptor and the previous holder written in it."""
    for _ in range(50):
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | _NOFOLLOW, 0o644)
        except OSError as e:
            if path.is_symlink():
                raise InputError(f"cannot lock the {what} for writing: its lock file {path.name} is a symbolic link "
                                 "(a lock is never followed); delete the link and run again", root) from None
            raise InputError(f"cannot lock the {what} for writing: {e.strerror or e}", root) from None
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            raise InputError(f"cannot lock the {what} for writing: its lock file {path.name} is not a regular file; "
                             "delete it and run again", root)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise _busy(root, what) from None
        except OSError as e:
            os.close(fd)
            raise InputError(f"cannot lock the {what} for writing ({e.strerror or e}); "
                             "its file system does not support file locks", root) from None
        try:  # the previous holder may have deleted the file between our open and flock: retry
            same = os.lstat(path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if not same:
            os.close(fd)
            continue
        previous = _parse(os.pread(fd, 4096, 0).decode(errors="replace"))
        record = json.dumps({"pid": os.getpid(), "host": this_host(), "since": now()}).encode()
        os.ftruncate(fd, 0)
        os.pwrite(fd, record, 0)
        os.fsync(fd)
        return fd, previous
    raise InputError(f"cannot lock the {what} for writing: its lock file keeps changing", root)


def acquire(root: Path, what: str = "dataset store") -> tuple[str, str | None]:
    """Take the write lock of the store (or other folder: ``what`` it is, for messages) at ``root`` for this
    process (re-entrant).

    Returns:
        The key to pass to :func:`release`, and a sentence when a stale lock was taken over.
    Raises:
        InputError: another process holds the lock (the message names its pid and host).
    """
    key = os.path.realpath(root)
    with _guard:
        held = _held.get(key)
        if held is not None:
            held.count += 1
            return key, None
        fd, previous = _take(root / LOCK_FILE, root, what)
        _held[key] = _Held(fd, root / LOCK_FILE, 1)
    if previous is None or (previous.pid, previous.host) == (os.getpid(), this_host()):
        return key, None
    return key, f"took over the write lock of {previous.describe()}, which no longer holds it"


def lock_new(directory: Path) -> int:
    """Lock a store being created in ``directory`` (not yet visible); :func:`adopt` it once renamed."""
    fd, _ = _take(directory / LOCK_FILE, directory)
    return fd


def adopt(root: Path, fd: int) -> None:
    """Register the lock taken by :func:`lock_new` as this process's lock of the store at ``root``."""
    with _guard:
        _held[os.path.realpath(root)] = _Held(fd, root / LOCK_FILE, 0)


def release(key: str) -> None:
    """Let go of one hold on the lock (from :func:`acquire`); the last one deletes the lock file."""
    with _guard:
        held = _held.get(key)
        if held is None:
            return
        held.count -= 1
        if held.count > 0:
            return
        del _held[key]
        try:  # delete only our own lock file, then unlock by closing
            if os.lstat(held.path).st_ino == os.fstat(held.fd).st_ino:
                os.unlink(held.path)
        except OSError:
            pass
        os.close(held.fd)


def creating_path(path: Path) -> Path:
    """Where :meth:`DatasetStore.create` builds the store ``path`` before renaming it into place."""
    return path.with_name(f".{path.name}.creating-{os.getpid()}@{this_host()}")


def clean_creating_litter(path: Path) -> list[str]:
    """Delete what killed creators (or removers) of the store ``path`` left beside it, once their
    pid is dead; returns what was removed, in words."""
    removed = []
    prefix = f".{path.name}.creating-"
    try:
        entries = [e for e in os.scandir(path.parent) if e.name.startswith(prefix)]
    except OSError:
        return removed
    for entry in entries:
        m = _CREATING_RE.match(entry.name)
        if not m or m["name"] != path.name:
            continue
        pid, host = int(m["pid"]), m["host"] or this_host()  # names without a host predate hosts: local
        if not process_alive(pid, host):
            shutil.rmtree(entry.path, ignore_errors=True)
            removed.append(f"removed {entry.name} (an interrupted creation of the store by pid {pid})")
    return removed
