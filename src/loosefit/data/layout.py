"""What a dataset store looks like on disk: format constants, names, attribute schemas, JSON helpers.

Shared by the store's reading, writing, verification and locking modules (:mod:`loosefit.data.store`
puts them together); nothing here opens a store.
"""

from __future__ import annotations

import datetime
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
from numcodecs import Blosc

from loosefit.errors import InputError

FORMAT = "loosefit-dataset"
FORMAT_VERSION = 1
COLLECTIONS = ("garments", "bodies", "motions", "sequences")
SPLITS = ("train", "val", "test")
STATUSES = ("ok", "failed")
FRAMES_PER_CHUNK = 32
#: Group of a sequence's reference runs: ``sequences/<name>/references/<k>`` (T, V, 3) float32, k = 1, 2, ...
REFERENCES = "references"
# Lossless: cloth positions keep their full float32 mantissa, so expect ratios near 1.2, not 10.
COMPRESSOR = Blosc(cname="zstd", clevel=3, shuffle=Blosc.BITSHUFFLE)

NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+=-]{0,127}$")
CORE_ARRAYS = {
    "garments": ("verts", "faces", "pinned"),
    "bodies": ("values",),
    "motions": ("rotations", "translation"),
}
RESERVED_ATTRS = ("name", "complete", "arrays", "checksums")
SINGULAR = {"garments": "garment", "bodies": "body", "motions": "motion", "sequences": "sequence"}

# Attributes every complete entry has, with their JSON types (what the readers index without a check).
_ENTRY_SCHEMA: dict[str, dict[str, type | tuple[type, ...]]] = {
    "garments": {"kind": str, "params": dict, "garment_name": str},
    "bodies": {"model": str},
    "motions": {"fps": (int, float), "rig": str, "joint_names": list, "motion_name": str},
    "sequences": {
        "garment": str, "body": str, "motion": str, "sim_params": dict, "stats": dict,
        "split": str, "status": str, "reason": str, "created": str, "arrays": list,
    },
}


def now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def read_json(path: Path) -> dict | None:
    """A JSON object from ``path``, or None when the file is missing or not a JSON object."""
    try:
        value = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return value if isinstance(value, dict) else None


def jsonable(value: Any, what: str, path: Path) -> Any:
    """``value`` with NumPy scalars and arrays turned into Python ones; tuples become lists."""
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise InputError(f"{what}: keys must be strings, got {k!r}", path)
            out[k] = jsonable(v, what, path)
        return out
    if isinstance(value, (list, tuple)):
        return [jsonable(v, what, path) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist(), what, path)
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise InputError(f"{what}: value {value!r} of type {type(value).__name__} cannot be stored as JSON", path)


def entry_arrays(collection: str, attrs: dict) -> tuple[str, ...]:
    """Names of an entry's own arrays (a sequence lists them; the other collections have fixed ones)."""
    return tuple(attrs.get("arrays", CORE_ARRAYS.get(collection, ())))


def attrs_problem(collection: str, path: Path) -> str | None:
    """What is wrong with the ``.zattrs`` of the entry directory ``path`` of ``collection``, or None.

    A complete entry's attributes are a JSON object with ``complete: true``, every attribute its
    readers use (of the right JSON type) and, for sequences, a valid split, status and array list.
    """
    file = path / ".zattrs"
    try:
        text = file.read_text()
    except FileNotFoundError:
        return "no .zattrs (no completion marker; corrupt or not written by loosefit)"
    except OSError as e:
        return f".zattrs cannot be read ({e.strerror or e})"
    try:
        attrs = json.loads(text)
    except ValueError:
        return ".zattrs is not valid JSON (corrupt)"
    if not isinstance(attrs, dict):
        return ".zattrs is not a JSON object (corrupt)"
    if attrs.get("complete") is not True:
        return "no completion marker in its .zattrs (corrupt or not written by loosefit)"
    for key, kind in _ENTRY_SCHEMA[collection].items():
        if not isinstance(attrs.get(key), kind) or isinstance(attrs.get(key), bool):
            return f".zattrs attribute {key!r} is missing or malformed (corrupt)"
    if collection == "sequences":
        if attrs["split"] not in SPLITS or attrs["status"] not in STATUSES:
            return f".zattrs has split {attrs['split']!r} and status {attrs['status']!r} (corrupt)"
        arrays = attrs["arrays"]
        if not arrays or arrays[0] != "verts" or not all(isinstance(a, str) and NAME_RE.match(a) for a in arrays):
            return ".zattrs attribute 'arrays' is malformed (corrupt)"
    checksums = attrs.get("checksums", {})
    if not isinstance(checksums, dict) or not all(isinstance(v, int) for v in checksums.values()):
        return ".zattrs attribute 'checksums' is malformed (corrupt)"
    return None
