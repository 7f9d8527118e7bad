"""Third-party libraries' own console output, kept off the command line unless ``loosefit -v`` asks for it.

NVIDIA Warp (imported by Anny for skinning, and by loosefit's Warp kernels) prints a banner when it starts
("Warp 1.x initialized: CUDA ... Kernel cache: ...") and a line per kernel module it loads ("Module ... load on
device 'cpu' took ..."), both at its INFO log level, and its native library writes "Warp CUDA warning: Could
not find or load the NVIDIA CUDA driver" on machines without one (every CPU machine, the normal case here).
:func:`quiet_third_party` raises Warp's log level to warnings and drops that one native line while Warp
starts, whether Warp is imported already or later (an import hook: importing Warp up front would cost the
verbs that never use it); Warp's other warnings and errors still show.
"""

from __future__ import annotations

import contextlib
import importlib.abc
import os
import sys
import tempfile
from collections.abc import Iterator

#: Warp's log level from which messages show (``warp.LOG_WARNING``).
WARP_QUIET_LEVEL = 30
#: The native line Warp prints at start on a machine without a CUDA driver, dropped when quiet.
NO_CUDA_DRIVER = "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver"


@contextlib.contextmanager
def quiet_third_party(quiet: bool = True) -> Iterator[None]:
    """While active (and ``quiet``), Warp starts without its banner and logs warnings and errors only.
    Afterwards Warp's log level is what it was and the import hook is gone."""
    if not quiet:
        yield
        return
    restore = []
    finder = None
    if "warp" in sys.modules:
        restore.append(_quiet_warp(sys.modules["warp"]))
    else:
        finder = _WarpFinder(lambda module: restore.append(_quiet_warp(module)))
        sys.meta_path.insert(0, finder)
    try:
        yield
    finally:
        if finder is not None and finder in sys.meta_path:
            sys.meta_path.remove(finder)
        for undo in restore:
            undo()


def _quiet_warp(warp):
    """Raise ``warp``'s log level to :data:`WARP_QUIET_LEVEL` and start it now, without the native no-driver
    line; returns the function that puts the log level back."""
    config = getattr(warp, "config", None)
    previous = getattr(config, "log_level", None)
    if previous is None:  # a Warp without log levels: leave it as it is
        return lambda: None
    config.log_level = max(previous, WARP_QUIET_LEVEL)
    try:
        with _native_stderr_without(NO_CUDA_DRIVER):
            warp.init()  # now, so that the native line is caught here, not whenever a kernel first runs
    except Exception:  # noqa: BLE001 - a Warp that cannot start fails where it is used, with its own error
        pass

    def undo():
        if config.log_level == max(previous, WARP_QUIET_LEVEL):  # unless someone set it since
            config.log_level = previous

    return undo


@contextlib.contextmanager
def _native_stderr_without(prefix: str) -> Iterator[None]:
    """Collect what is written to file descriptor 2 (native code's stderr too) and write it back after, less
    the lines that start with ``prefix``. Without a usable descriptor 2, nothing is collected."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):
        yield
        return
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            yield
        finally:
            with contextlib.suppress(Exception):
                sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            held.seek(0)
            kept = [line for line in held.read().decode("utf-8", "replace").splitlines(keepends=True)
                    if not line.startswith(prefix)]
            if kept:
                sys.stderr.write("".join(kept))
                sys.stderr.flush()


class _WarpFinder(importlib.abc.MetaPathFinder):
    """Finds the top-level ``warp`` package through the other finders and runs ``then(module)`` once it is
    imported; removes itself on first use."""

    def __init__(self, then):
        self.then = then

    def find_spec(self, name, path=None, target=None):
        if name != "warp" or path is not None:
            return None
        with contextlib.suppress(ValueError):
            sys.meta_path.remove(self)
        for finder in sys.meta_path:
            find = getattr(finder, "find_spec", None)
            spec = find(name, path, target) if find is not None else None
            if spec is not None:
                break
        else:
            return None
        if spec.loader is not None and hasattr(spec.loader, "exec_module"):
            spec.loader = _ThenLoader(spec.loader, self.then)
        return spec


class _ThenLoader(importlib.abc.Loader):
    """``loader`` that runs ``then(module)`` after executing the module; anything else is the loader's."""

    def __init__(self, loader, then):
        self.loader = loader
        self.then = then

    def create_module(self, spec):
        return self.loader.create_module(spec)

    def exec_module(self, module):
        self.loader.exec_module(module)
        self.then(module)

    def __getattr__(self, name):
        return getattr(self.loader, name)
