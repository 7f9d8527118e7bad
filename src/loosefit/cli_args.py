"""Argument checks of the command line: argparse ``type=`` functions (a bad value is a usage error, exit 2,
without a traceback) and the check that an output can be written before any work starts."""

from __future__ import annotations

import argparse
from pathlib import Path

from loosefit.paths import check_writable


def int_at_least(least: int, most: int | None = None):
    """An argparse ``type=``: an integer in ``[least, most]``; anything else is a usage error (exit 2)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < least or (most is not None and value > most):
            bounds = f">= {least}" if most is None else f"in {least}..{most}"
            raise argparse.ArgumentTypeError(f"must be an integer {bounds}, got {value}")
        return value

    return parse


def _finite_float(text: str, zero_allowed: bool, rule: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (0 <= value if zero_allowed else 0 < value) or not value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be {rule}, got {text}")
    return value


def positive_float(text: str) -> float:
    """An argparse ``type=``: a finite number > 0 (frame rates, durations, lengths)."""
    return _finite_float(text, False, "a positive number")


def nonnegative_float(text: str) -> float:
    """An argparse ``type=``: a finite number >= 0 (a start time)."""
    return _finite_float(text, True, "a number >= 0")


def writable(path, folder: bool | None = None) -> None:
    """Refuse an output that cannot be written before any work starts (``folder``: default, a path
    without a suffix or ending in ``/``)."""
    if folder is None:
        folder = str(path).endswith(("/", "\\")) or Path(path).suffix == ""
    check_writable(path, folder=folder)
