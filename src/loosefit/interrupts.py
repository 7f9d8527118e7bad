"""Ctrl-C and SIGTERM held back while a library runs Python code of its own that an exception must not cut.

Blender (``bpy``) runs its own scripts inside operators (``read_factory_settings`` registers every bundled
add-on) and catches what they raise: a ``KeyboardInterrupt`` raised there is printed and dropped (the run goes
on as if nothing had been asked), or leaves half-registered add-ons behind, or marks the interpreter so that
it later dies of SIGINT after the command line has said it stopped (measured: 26 of 40 interrupts landing in
``read_factory_settings`` were dropped). :func:`held_signals` makes a signal that arrives during such a call
wait until the call returns, then acts as it would have (the handler installed before, e.g. the command
line's, runs), so that the interrupt is raised in loosefit's own code, between two frames.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from typing import Iterator

#: The signals that stop a verb (the command line's handlers raise ``KeyboardInterrupt`` for both).
STOPPING = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def held_signals() -> Iterator[None]:
    """Run the block with SIGINT and SIGTERM only noted; when it ends (returns or raises), restore the previous
    handlers and deliver what arrived to them, once each (SIGINT first). Outside the main thread, or for a
    signal whose handler was not set from Python, nothing is held."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived: list[int] = []
    previous = {}
    for sig in STOPPING:
        handler = signal.getsignal(sig)
        if handler is not None:  # None: a handler Python cannot put back
            previous[sig] = signal.signal(sig, lambda signum, frame: arrived.append(signum))
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        for sig in [s for s in STOPPING if s in arrived]:
            _deliver(sig, previous.get(sig))


def _deliver(sig: int, handler) -> None:
    """Act on ``sig`` as ``handler`` (the one held back) would have."""
    if callable(handler):
        handler(sig, None)  # e.g. Python's default_int_handler: raises KeyboardInterrupt here
    elif handler == signal.SIG_DFL:
        signal.raise_signal(sig)  # the default action, now that the handler is back in place
