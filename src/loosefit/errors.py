"""Errors raised on bad input. Each names the offending file (when there is one) and the problem."""

from __future__ import annotations

from pathlib import Path


class LoosefitError(Exception):
    """Base class of every error loosefit raises on purpose."""


class InputError(LoosefitError, ValueError):
    """A user-supplied file or value is malformed; the message names the file and the problem."""

    def __init__(self, problem: str, path: str | Path | None = None):
        self.path = None if path is None else Path(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}" if self.path is not None else problem)
