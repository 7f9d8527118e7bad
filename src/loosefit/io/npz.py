"""Named arrays in ``.npz`` files: atomic writes, and reads whose errors name the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.paths import atomic_path


def save_npz(path: str | Path, arrays: dict[str, np.ndarray], compressed: bool = False) -> None:
    """Write ``arrays`` to ``path`` atomically (a crash never leaves a partial file)."""
    with atomic_path(path, suffix=".npz") as tmp:
        (np.savez_compressed if compressed else np.savez)(tmp, **arrays)


def load_npz(path: str | Path, what: str) -> dict[str, np.ndarray]:
    """All arrays of an ``.npz`` file (no pickles); an unreadable file raises
    ``InputError("cannot read <what>: ...", path)``."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read {what}: {e}", Path(path)) from None
