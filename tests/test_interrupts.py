"""held_signals: a Ctrl-C or SIGTERM that arrives while Blender runs its own scripts waits for the call to return,
then acts as it would have (never swallowed, never lost); the handlers are put back."""

import os
import signal
import threading
import time

import pytest

from loosefit.interrupts import held_signals


@pytest.fixture(autouse=True)
def python_sigint_handler():
    """Each test starts from Python's own Ctrl-C handler, as a ``loosefit`` process does: in one long test process
    an earlier test (a simulator run) can leave another in place. Whatever was there is put back."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def test_sigint_is_raised_after_the_block_not_inside_it():
    before = signal.getsignal(signal.SIGINT)
    reached_end = False
    with pytest.raises(KeyboardInterrupt):
        with held_signals():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)  # Python runs handlers between bytecodes: an unheld one would have raised by now
            reached_end = True
    assert reached_end
    assert signal.getsignal(signal.SIGINT) is before


def test_sigterm_goes_to_the_handler_held_back_once():
    seen = []
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: seen.append(signum))
    try:
        with held_signals():
            os.kill(os.getpid(), signal.SIGTERM)
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.05)
            assert seen == []
        assert seen == [signal.SIGTERM]
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_nothing_arrives_nothing_happens_and_an_error_passes_through():
    handlers = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    with held_signals():
        pass
    with pytest.raises(ValueError):
        with held_signals():
            raise ValueError("the block's own error")
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == handlers


def test_outside_the_main_thread_nothing_is_held():
    handlers = []
    thread = threading.Thread(target=lambda: handlers.append(_in_block()))
    thread.start()
    thread.join()
    assert handlers == [signal.getsignal(signal.SIGINT)]


def _in_block():
    with held_signals():
        return signal.getsignal(signal.SIGINT)


def test_ctrl_c_during_blenders_reset_is_never_swallowed():
    """Blender's read_factory_settings runs its add-ons' scripts and drops a KeyboardInterrupt raised in them
    (most of the time, unheld); held, every Ctrl-C surfaces right after the call."""
    bpy = pytest.importorskip("bpy")
    start = time.perf_counter()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    reset = time.perf_counter() - start
    for k in range(6):
        timer = threading.Timer(reset * (k + 0.5) / 6, os.kill, (os.getpid(), signal.SIGINT))
        timer.start()
        with pytest.raises(KeyboardInterrupt):
            with held_signals():
                bpy.ops.wm.read_factory_settings(use_empty=True)
                timer.join()  # the signal has been sent by now, whatever the machine's load
        timer.cancel()
