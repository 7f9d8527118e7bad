"""Named arrays in ``.npz`` files: atomic writes, and reads whose errors name the file.

Every ``.npz`` loosefit reads goes through :func:`load_npz`: it never unpickles (an object array in a
file is refused, since unpickling can run code), and any damage to the file (truncated, a flipped
byte, not a zip archive) is an :class:`~loosefit.errors.InputError` naming the file. The sizes the arrays
declare are checked before any is inflated: a file whose arrays would take more than :data:`MAX_NPZ_BYTES`
(a zip bomb: a few MB that inflate to GBs) is refused naming the array and the limit.
"""

from __future__ import annotations

import contextlib
import math
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from loosefit.errors import InputError
from loosefit.paths import atomic_path


#: The most bytes the arrays read from one ``.npz`` may take once inflated (a 10,000-frame mesh sequence of the
#: 13,718-vertex body is 1.6 GB).
MAX_NPZ_BYTES = 4 * 1024**3


def save_npz(path: str | Path, arrays: dict[str, np.ndarray], compressed: bool = False) -> None:
    """Write ``arrays`` to ``path`` atomically (a crash never leaves a partial file)."""
    with atomic_path(path, suffix=".npz") as tmp:
        (np.savez_compressed if compressed else np.savez)(tmp, **arrays)


def load_npz(path: str | Path, what: str, names: Iterable[str] | None = None) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` file: all of them, or those of ``names`` that it holds.

    No pickles: an object array among those read is refused. A missing, unreadable or damaged file
    (truncated, a flipped byte, a bad zip or zlib stream, a bad ``.npy`` header) or a plain ``.npy``
    raises ``InputError("cannot read <what>: ...", path)``.
    """
    path = Path(path)
    with _reading(path, what) as current:
        with _open(path, what) as z:
            wanted = z.files if names is None else [k for k in names if k in z.files]
            _check_declared_sizes(z, wanted, path, what, current)
            arrays = {}
            for current[0] in wanted:
                arrays[current[0]] = z[current[0]]
            return arrays


def _check_declared_sizes(z: np.lib.npyio.NpzFile, names: list[str], path: Path, what: str, current: list) -> None:
    """Refuse, from the ``.npy`` headers alone (nothing inflated but them), arrays that would take more than
    :data:`MAX_NPZ_BYTES` together."""
    members = set(z.zip.namelist())
    total = 0
    for current[0] in names:
        member = current[0] + ".npy" if current[0] + ".npy" in members else current[0]
        with z.zip.open(member) as f:
            version = np.lib.format.read_magic(f)
            shape, _, dtype = np.lib.format._read_array_header(f, version)
        size = math.prod(shape) * dtype.itemsize
        total += size
        if total > MAX_NPZ_BYTES:
            raise InputError(f"cannot read {what}: array {current[0]!r} declares shape {tuple(shape)} of {dtype} "
                             f"({size / 1e9:.3g} GB); the arrays read from one .npz may take at most "
                             f"{MAX_NPZ_BYTES / 1e9:.3g} GB (loosefit.io.npz.MAX_NPZ_BYTES): nothing was inflated", path)
    current[0] = None


def npz_names(path: str | Path, what: str) -> list[str]:
    """The names of the arrays in an ``.npz`` file (none is read); errors as :func:`load_npz`."""
    path = Path(path)
    with _reading(path, what), _open(path, what) as z:
        return list(z.files)


def _open(path: Path, what: str) -> np.lib.npyio.NpzFile:
    z = np.load(path, allow_pickle=False)
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise InputError(f"cannot read {what}: not an .npz archive (a single .npy array)", path)
    return z


@contextlib.contextmanager
def _reading(path: Path, what: str) -> Iterator[list]:
    """Turn every failure of reading ``path`` into an InputError; yields a one-item list where the
    reader keeps the name of the array it is reading (for the message)."""
    current: list = [None]
    try:
        yield current
    except InputError:
        raise
    except ValueError as e:
        if "allow_pickle" in str(e) and current[0] is None:  # numpy takes any other file for a pickle
            raise InputError(f"cannot read {what}: not an .npz archive (nor an .npy array; loosefit never "
                             "unpickles a file, since that can run code)", path) from None
        if "allow_pickle" in str(e):
            raise InputError(f"cannot read {what}: array {current[0]!r} holds pickled Python objects, which loosefit "
                             "never loads (unpickling can run code); store plain numeric arrays", path) from None
        raise InputError(f"cannot read {what}: {e}", path) from None
    except OSError as e:
        raise InputError(f"cannot read {what}: {e.strerror or e}", path) from None
    except Exception as e:  # noqa: BLE001 - zipfile, zlib, numpy's header parser... raise many types on damaged files
        raise InputError(f"cannot read {what}: the file is damaged or not an .npz ({type(e).__name__}: {e})",
                         path) from None
