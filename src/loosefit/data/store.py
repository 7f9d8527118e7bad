"""The on-disk dataset: garments, bodies, motions and simulated sequences in one Zarr 2 directory.

Layout (every group is a Zarr group; arrays are Blosc-zstd compressed)::

    DATA.zarr/                     attrs: format="loosefit-dataset", format_version, created, loosefit_version
      garments/<name>/             verts (V,3) float32, faces (F,3) int64, pinned (V,) bool;
                                   attrs kind, params, garment_name
      bodies/<name>/               values (S,) float32 (the body shape); attrs model
      motions/<name>/              rotations (T,J,3) float32, translation (T,3) float32;
                                   attrs fps, rig, joint_names, motion_name
      sequences/<name>/            verts (T,V,3) float32 in chunks of 32 frames, optional extra arrays;
                                   attrs garment, body, motion, sim_params, stats, split, status, reason
      .staging/                    writes in progress (see :mod:`loosefit.data.staging`)

Every entry (a garment, body, motion or sequence) and every array written with :meth:`DatasetStore.write_array`
is built under ``.staging/`` and renamed into place once flushed, with ``complete: true`` in its
attributes, so a killed writer never leaves an entry that reads as complete. Frame ``i`` of a
sequence is frame ``i`` of its motion. Names are 1-128 characters from ``[A-Za-z0-9_.+=-]``, not
starting with ``.``, ``_``, ``+``, ``=`` or ``-``.
"""

from __future__ import annotations

import contextlib
import datetime
import json
import logging
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import zarr
from numcodecs import Blosc

from loosefit import __version__
from loosefit.data import staging
from loosefit.errors import InputError
from loosefit.motion.motion import Motion
from loosefit.paths import atomic_path

log = logging.getLogger(__name__)

FORMAT = "loosefit-dataset"
FORMAT_VERSION = 1
COLLECTIONS = ("garments", "bodies", "motions", "sequences")
SPLITS = ("train", "val", "test")
STATUSES = ("ok", "failed")
FRAMES_PER_CHUNK = 32
# Lossless: cloth positions keep their full float32 mantissa, so expect ratios near 1.2, not 10.
COMPRESSOR = Blosc(cname="zstd", clevel=3, shuffle=Blosc.BITSHUFFLE)

_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+=-]{0,127}$")
_CHUNK_KEY_RE = re.compile(r"^\d+(\.\d+)*$")
_CORE_ARRAYS = {
    "garments": ("verts", "faces", "pinned"),
    "bodies": ("values",),
    "motions": ("rotations", "translation"),
}
_RESERVED_ATTRS = ("name", "complete", "arrays")
_SINGULAR = {"garments": "garment", "bodies": "body", "motions": "motion", "sequences": "sequence"}


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def _read_json(path: Path) -> dict | None:
    """A JSON object from ``path``, or None when the file is missing or not a JSON object."""
    try:
        value = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return value if isinstance(value, dict) else None


def _jsonable(value: Any, what: str, path: Path) -> Any:
    """``value`` with NumPy scalars and arrays turned into Python ones; tuples become lists."""
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise InputError(f"{what}: keys must be strings, got {k!r}", path)
            out[k] = _jsonable(v, what, path)
        return out
    if isinstance(value, (list, tuple)):
        return [_jsonable(v, what, path) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist(), what, path)
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise InputError(f"{what}: value {value!r} of type {type(value).__name__} cannot be stored as JSON", path)


def _array_problem(path: Path) -> str | None:
    """What is wrong with the Zarr array directory ``path`` (metadata or chunk files), or None."""
    meta = _read_json(path / ".zarray")
    if meta is None:
        return f"array {path.name!r} is missing or has no readable .zarray"
    try:
        expected = math.prod(math.ceil(s / c) for s, c in zip(meta["shape"], meta["chunks"]))
    except (KeyError, TypeError, ZeroDivisionError):
        return f"array {path.name!r} has malformed .zarray metadata"
    present = sum(1 for name in os.listdir(path) if _CHUNK_KEY_RE.match(name))
    if present != expected:
        return f"array {path.name!r} has {present} of its {expected} chunk files"
    return None


def _array_shape(path: Path) -> tuple[int, ...]:
    meta = _read_json(path / ".zarray")
    return tuple(meta["shape"]) if meta and "shape" in meta else ()


def _dim(path: Path, axis: int) -> int | None:
    """Length of one axis of the array at ``path`` from its metadata; None when unreadable."""
    shape = _array_shape(path)
    return shape[axis] if len(shape) > axis else None


def _garment_class():
    # Imported on use: the garment package imports geometry code the store does not need.
    from loosefit.garment import Garment

    return Garment


@dataclass
class Sequence:
    """A simulated garment sequence in a store. Arrays stay on disk: slicing one (``seq.verts[10:42]``)
    reads only the chunks it touches; ``seq.verts[:]`` reads all frames.

    Attributes:
        name: the sequence's name in the store.
        verts: ``(T, V, 3)`` float32 Zarr array of garment vertices, metres; frame ``i`` is frame ``i``
            of the motion ``motion``.
        extra: further arrays stored with the sequence, by name (Zarr arrays).
        garment, body, motion: names of the store's garment, body and motion entries it was made from.
        sim_params: simulation parameters (JSON values). stats: simulation statistics (JSON values).
        split: ``"train"``, ``"val"`` or ``"test"``. status: ``"ok"`` or ``"failed"``; reason: why it failed.
        created: ISO 8601 time of the write. path: the sequence's directory.
    """

    name: str
    verts: zarr.Array
    extra: dict[str, zarr.Array]
    garment: str
    body: str
    motion: str
    sim_params: dict
    stats: dict
    split: str
    status: str
    reason: str
    created: str
    path: Path

    @property
    def num_frames(self) -> int:
        return self.verts.shape[0]

    @property
    def num_verts(self) -> int:
        return self.verts.shape[1]


class DatasetStore:
    """A loosefit dataset on disk (Zarr 2 directory store); see the module docstring for the layout.

    Make one with :meth:`create`, open one with :meth:`open`. Mode ``"r"`` reads; mode ``"a"`` also
    writes and, on opening, cleans what writers that were killed left in ``.staging/``. Several processes
    may write different entries at once (each entry is its own directory); one entry is written by one
    process at a time.
    """

    def __init__(self, root: Path, mode: str, attrs: dict):
        """Use :meth:`create` or :meth:`open`."""
        self._root = root
        self.mode = mode
        self.attrs = attrs
        self.recovered: list[str] = []
        if mode == "a":
            for leftover in staging.leftovers(root):
                if not leftover.writer_alive():
                    self.recovered.append(staging.recover(root, leftover))
                    log.info("%s: %s", root, self.recovered[-1])
        for leftover in staging.leftovers(root):
            log.warning("%s: %s", root, leftover.describe())

    # ---------------------------------------------------------------- opening

    @classmethod
    def create(cls, path: str | Path) -> "DatasetStore":
        """Create an empty store at ``path`` (which must not exist) and return it open in mode ``"a"``."""
        path = Path(path)
        if path.exists():
            raise InputError("cannot create a dataset store: the path already exists", path)
        path.parent.mkdir(parents=True, exist_ok=True)
        # Built beside its final place and renamed: an interrupted create leaves no half store.
        tmp = path.with_name(f".{path.name}.creating-{os.getpid()}")
        try:
            root = zarr.open_group(str(tmp), mode="w-")
            for collection in COLLECTIONS:
                root.create_group(collection)
            root.attrs.put(
                {"format": FORMAT, "format_version": FORMAT_VERSION, "created": _now(), "loosefit_version": __version__}
            )
            staging.fsync_tree(tmp)
            os.rename(tmp, path)
        finally:
            staging.discard(tmp)
        return cls.open(path, mode="a")

    @classmethod
    def open(cls, path: str | Path, mode: str = "r") -> "DatasetStore":
        """Open the store at ``path``, checking that it is a loosefit dataset this version can read.

        Raises:
            InputError: not a directory, not a Zarr group, not a loosefit dataset, written by a newer
                format version, or missing one of its groups.
        """
        path = Path(path)
        if mode not in ("r", "a"):
            raise InputError(f"dataset store mode must be 'r' or 'a', got {mode!r}", path)
        if not path.exists():
            raise InputError("no such dataset store", path)
        if not path.is_dir():
            raise InputError("not a Zarr dataset store (it is a file, not a directory)", path)
        if (path / ".zarray").exists():
            raise InputError("not a loosefit dataset: it is a single Zarr array, not a group", path)
        if _read_json(path / ".zgroup") is None:
            raise InputError("not a Zarr dataset store: no readable .zgroup", path)
        attrs = _read_json(path / ".zattrs") or {}
        if attrs.get("format") != FORMAT:
            raise InputError(
                f"not a loosefit dataset: root attribute 'format' is {attrs.get('format')!r}, expected {FORMAT!r}", path
            )
        version = attrs.get("format_version")
        if not isinstance(version, int) or isinstance(version, bool) or version < 1:
            raise InputError(f"corrupt dataset: format_version is {version!r}, expected a positive integer", path)
        if version > FORMAT_VERSION:
            raise InputError(
                f"dataset format version {version} was written by a newer loosefit; this loosefit "
                f"({__version__}) reads up to version {FORMAT_VERSION}: upgrade loosefit",
                path,
            )
        for collection in COLLECTIONS:
            if _read_json(path / collection / ".zgroup") is None:
                raise InputError(f"corrupt dataset: group {collection!r} is missing", path)
        return cls(path, mode, attrs)

    @property
    def path(self) -> Path:
        return self._root

    def __repr__(self) -> str:
        return f"DatasetStore({str(self._root)!r}, mode={self.mode!r})"

    # ---------------------------------------------------------------- internals

    def _check_writable(self) -> None:
        if self.mode != "a":
            raise InputError("dataset store is open read-only; open it with mode='a' to write", self._root)

    def _check_name(self, name: str, what: str) -> None:
        if not isinstance(name, str) or not _NAME_RE.match(name):
            raise InputError(
                f"bad {what} name {name!r}: use 1-128 characters from [A-Za-z0-9_.+=-], "
                "starting with a letter or digit",
                self._root,
            )

    def _entry_dir(self, collection: str, name: str) -> Path:
        return self._root / collection / name

    def _entry_attrs(self, collection: str, name: str) -> dict | None:
        """Attributes of a complete entry, or None when there is no complete entry of that name."""
        attrs = _read_json(self._entry_dir(collection, name) / ".zattrs")
        return attrs if attrs and attrs.get("complete") is True else None

    def _entries(self, collection: str) -> dict[str, dict]:
        """Attributes of the complete entries of a collection, by name, sorted."""
        found = {}
        for entry in sorted(os.scandir(self._root / collection), key=lambda e: e.name):
            if entry.is_dir() and _NAME_RE.match(entry.name):
                attrs = self._entry_attrs(collection, entry.name)
                if attrs is not None:
                    found[entry.name] = attrs
        return found

    def _require_entry(self, collection: str, name: str, hint: str = "") -> dict:
        """Attributes of a complete entry whose arrays are all present; clear errors otherwise
        (``hint`` is appended to corruption errors)."""
        what = _SINGULAR[collection]
        self._check_name(name, what)
        path = self._entry_dir(collection, name)
        if not path.is_dir():
            known = list(self._entries(collection))
            shown = f"{known[:10]}{'...' if len(known) > 10 else ''}" if known else "none"
            raise InputError(f"no {what} named {name!r} in the store (it has {shown})", self._root)
        attrs = self._entry_attrs(collection, name)
        problem = "no completion marker in its .zattrs" if attrs is None else None
        for array in () if attrs is None else attrs.get("arrays", _CORE_ARRAYS.get(collection, ())):
            problem = problem or _array_problem(path / array)
        if problem:
            raise InputError(f"corrupt {what} {name!r}: {problem}{hint}", path)
        return attrs

    def _open_array(self, path: Path) -> zarr.Array:
        return zarr.open_array(str(path), mode="r")

    @contextlib.contextmanager
    def _staged_group(self, target: str, attrs: dict, name: str) -> Iterator[zarr.Group]:
        """A new Zarr group under ``.staging/``; on success its attributes (with the completion
        marker) are written last and it is renamed onto ``target``; on failure it is deleted."""
        self._check_writable()
        staged = staging.new_staging_dir(self._root, target)
        try:
            group = zarr.open_group(str(staged), mode="w-")
            yield group
            group.attrs.put({**attrs, "name": name, "complete": True})
        except BaseException:
            staging.discard(staged)
            raise
        staging.commit(self._root, staged, target)

    def _same_entry(self, collection: str, name: str, arrays: dict[str, np.ndarray], attrs: dict) -> bool:
        """Whether the store already holds exactly this entry (then re-adding it keeps what later stages
        stored under it)."""
        old = self._entry_attrs(collection, name)
        if old is None or any(old.get(k) != v for k, v in attrs.items()):
            return False
        path = self._entry_dir(collection, name)
        for key, value in arrays.items():
            if _array_problem(path / key):
                return False
            stored = self._open_array(path / key)
            if stored.shape != value.shape or stored.dtype != value.dtype or not np.array_equal(stored[...], value):
                return False
        return True

    def _add_entry(self, collection: str, name: str, arrays: dict[str, np.ndarray], attrs: dict) -> None:
        if self._same_entry(collection, name, arrays, attrs):
            return
        with self._staged_group(f"{collection}/{name}", attrs, name) as group:
            for key, value in arrays.items():
                group.create_dataset(key, data=value, compressor=COMPRESSOR)

    def _sequences_using(self, key: str, name: str) -> list[str]:
        return [s for s, attrs in self._entries("sequences").items() if attrs.get(key) == name]

    # ---------------------------------------------------------------- garments, bodies, motions

    def add_garment(self, name: str, garment) -> None:
        """Store a garment (any object with ``verts (V,3)``, ``faces (F,3)``, ``pinned (V,)``, ``kind``,
        ``params`` (JSON values), ``name``), atomically.

        Adding an identical garment again does nothing (arrays stored under it by later stages stay);
        a different one replaces the group, dropping those arrays. Replacing a garment that sequences
        use by one with another vertex count is refused.
        """
        self._check_writable()
        self._check_name(name, "garment")
        verts = np.asarray(garment.verts, dtype=np.float32)
        faces = np.asarray(garment.faces, dtype=np.int64)
        pinned = np.asarray(garment.pinned, dtype=bool)
        if verts.ndim != 2 or verts.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
            raise InputError(
                f"garment {name!r}: verts must be (V, 3) and faces (F, 3), got {verts.shape} and {faces.shape}",
                self._root,
            )
        if pinned.shape != (verts.shape[0],):
            raise InputError(
                f"garment {name!r}: pinned must have shape ({verts.shape[0]},), got {pinned.shape}", self._root
            )
        if not np.isfinite(verts).all():
            raise InputError(f"garment {name!r}: vertices contain NaN or infinite values", self._root)
        if faces.size and (faces.min() < 0 or faces.max() >= verts.shape[0]):
            raise InputError(f"garment {name!r}: face indices outside [0, {verts.shape[0]})", self._root)
        old = self._entry_attrs("garments", name)
        if old is not None and _array_shape(self._entry_dir("garments", name) / "verts")[:1] != verts.shape[:1]:
            users = self._sequences_using("garment", name)
            if users:
                raise InputError(
                    f"garment {name!r} is used by sequences {users[:5]}{'...' if len(users) > 5 else ''}; "
                    f"replacing it with {verts.shape[0]} vertices would make them inconsistent",
                    self._root,
                )
        attrs = {
            "kind": str(garment.kind),
            "params": _jsonable(dict(garment.params), f"garment {name!r} params", self._root),
            "garment_name": str(garment.name),
        }
        self._add_entry("garments", name, {"verts": verts, "faces": faces, "pinned": pinned}, attrs)

    def garment(self, name: str):
        """The stored garment as a :class:`loosefit.garment.Garment`."""
        attrs = self._require_entry("garments", name)
        path = self._entry_dir("garments", name)
        return _garment_class()(
            verts=self._open_array(path / "verts")[...],
            faces=self._open_array(path / "faces")[...],
            pinned=self._open_array(path / "pinned")[...],
            kind=attrs["kind"],
            params=attrs["params"],
            name=attrs["garment_name"],
        )

    def garment_num_verts(self, name: str) -> int:
        """Vertex count of a stored garment (read from metadata only)."""
        self._require_entry("garments", name)
        return _array_shape(self._entry_dir("garments", name) / "verts")[0]

    def garment_names(self) -> list[str]:
        return list(self._entries("garments"))

    def add_body(self, name: str, shape: np.ndarray, model: str = "anny") -> None:
        """Store a body shape: ``shape (S,)`` values of the body ``model`` (Anny: the six phenotype
        values of :meth:`AnnyShape.to_array`; SMPL: betas), atomically; same replacement rules as
        :meth:`add_garment`."""
        self._check_writable()
        self._check_name(name, "body")
        values = np.asarray(shape, dtype=np.float32)
        if values.ndim != 1 or not np.isfinite(values).all():
            raise InputError(
                f"body {name!r}: shape must be a 1-D array of finite values, got shape {values.shape}", self._root
            )
        self._add_entry("bodies", name, {"values": values}, {"model": str(model)})

    def body(self, name: str) -> np.ndarray:
        """The stored shape values ``(S,)`` float32; the model is ``read_attrs(f"bodies/{name}")["model"]``."""
        self._require_entry("bodies", name)
        return self._open_array(self._entry_dir("bodies", name) / "values")[...]

    def body_names(self) -> list[str]:
        return list(self._entries("bodies"))

    def add_motion(self, name: str, motion: Motion) -> None:
        """Store a motion, atomically; same replacement rules as :meth:`add_garment` (a motion that
        sequences use keeps its frame count)."""
        self._check_writable()
        self._check_name(name, "motion")
        if self._entry_attrs("motions", name) is not None:
            frames = _array_shape(self._entry_dir("motions", name) / "rotations")[:1]
            users = self._sequences_using("motion", name)
            if frames != (motion.num_frames,) and users:
                raise InputError(
                    f"motion {name!r} is used by sequences {users[:5]}{'...' if len(users) > 5 else ''}; "
                    f"replacing it with {motion.num_frames} frames would make them inconsistent",
                    self._root,
                )
        attrs = {
            "fps": float(motion.fps),
            "rig": str(motion.rig),
            "joint_names": [str(j) for j in motion.joint_names],
            "motion_name": str(motion.name),
        }
        self._add_entry("motions", name, {"rotations": motion.rotations, "translation": motion.translation}, attrs)

    def motion(self, name: str) -> Motion:
        attrs = self._require_entry("motions", name)
        path = self._entry_dir("motions", name)
        return Motion(
            rotations=self._open_array(path / "rotations")[...],
            translation=self._open_array(path / "translation")[...],
            fps=attrs["fps"],
            rig=attrs["rig"],
            joint_names=attrs["joint_names"],
            name=attrs["motion_name"],
        )

    def motion_num_frames(self, name: str) -> int:
        """Frame count of a stored motion (read from metadata only)."""
        self._require_entry("motions", name)
        return _array_shape(self._entry_dir("motions", name) / "rotations")[0]

    def motion_names(self) -> list[str]:
        return list(self._entries("motions"))

    # ---------------------------------------------------------------- sequences

    def write_sequence(
        self,
        name: str,
        verts,
        garment: str,
        body: str,
        motion: str,
        sim_params: dict,
        stats: dict,
        split: str,
        status: str = "ok",
        reason: str = "",
        extra: dict[str, np.ndarray] | None = None,
    ) -> None:
        """Write a simulated sequence atomically, replacing one of the same name.

        Args:
            name: the sequence's name.
            verts: ``(T, V, 3)`` garment vertices, metres, stored as float32: a NumPy array or anything
                with ``.shape`` and frame slicing (a memmap, a Zarr array); read 32 frames at a time.
            garment, body, motion: names of entries already in the store (add them first). ``V`` must be
                the garment's vertex count; frame ``i`` is motion frame ``i``, so an ``"ok"`` sequence has
                exactly the motion's ``T`` frames (a failed one at most that many).
            sim_params, stats: JSON values (NumPy scalars and arrays are converted).
            split: ``"train"``, ``"val"`` or ``"test"``.
            status: ``"ok"``, or ``"failed"`` with a ``reason``; NaN or infinite vertices are refused
                unless the status is ``"failed"``.
            extra: further arrays stored with the sequence (e.g. per-frame ``(T, ...)`` arrays, which are
                chunked like ``verts``); names as for entries, not ``"verts"``.

        Raises:
            InputError: a missing garment/body/motion, a shape mismatch, NaN in an ``"ok"`` sequence,
                a bad name, split or status. Nothing is written then.
        """
        self._check_writable()
        self._check_name(name, "sequence")
        where = self._entry_dir("sequences", name)
        if split not in SPLITS:
            raise InputError(f"sequence {name!r}: split must be one of {SPLITS}, got {split!r}", where)
        if status not in STATUSES:
            raise InputError(f"sequence {name!r}: status must be one of {STATUSES}, got {status!r}", where)
        if status == "failed" and not reason:
            raise InputError(f"sequence {name!r}: a failed sequence needs a reason", where)
        for key, value in (("garment", garment), ("body", body), ("motion", motion)):
            if not isinstance(value, str):
                raise InputError(
                    f"sequence {name!r}: {key} must be the name of a stored {key}, got {type(value).__name__}", where
                )
        num_verts = self.garment_num_verts(garment)
        num_frames = self.motion_num_frames(motion)
        self._require_entry("bodies", body)
        shape = tuple(getattr(verts, "shape", ()))
        if len(shape) != 3 or shape[1:] != (num_verts, 3):
            raise InputError(
                f"sequence {name!r}: verts must have shape (T, {num_verts}, 3) for garment {garment!r}, got {shape}",
                where,
            )
        T = shape[0]
        if status == "ok" and T != num_frames:
            raise InputError(f"sequence {name!r}: {T} frames but motion {motion!r} has {num_frames}", where)
        if T > num_frames:
            raise InputError(f"sequence {name!r}: {T} frames, more than the {num_frames} of motion {motion!r}", where)
        extra = dict(extra or {})
        for key in extra:
            self._check_name(key, "array")
            if key == "verts":
                raise InputError(f"sequence {name!r}: extra array name 'verts' is taken by the vertices", where)
        attrs = {
            "garment": garment,
            "body": body,
            "motion": motion,
            "sim_params": _jsonable(dict(sim_params), f"sequence {name!r} sim_params", where),
            "stats": _jsonable(dict(stats), f"sequence {name!r} stats", where),
            "split": split,
            "status": status,
            "reason": str(reason),
            "created": _now(),
            "arrays": ["verts", *extra],
        }
        with self._staged_group(f"sequences/{name}", attrs, name) as group:
            # NaN fill: a chunk that somehow goes missing can never read as plausible zeros.
            out = group.create_dataset(
                "verts",
                shape=shape,
                chunks=(FRAMES_PER_CHUNK, num_verts, 3),
                dtype=np.float32,
                fill_value=np.nan,
                compressor=COMPRESSOR,
                write_empty_chunks=True,
            )
            for start in range(0, T, FRAMES_PER_CHUNK):
                stop = min(start + FRAMES_PER_CHUNK, T)
                block = np.asarray(verts[start:stop], dtype=np.float32)
                if status == "ok" and not np.isfinite(block).all():
                    raise InputError(
                        f"sequence {name!r}: frames {start}-{stop - 1} contain NaN or infinite vertices; "
                        "store it with status='failed' and a reason",
                        where,
                    )
                out[start:stop] = block
            for key, value in extra.items():
                value = np.asarray(value)
                per_frame = value.ndim >= 1 and value.shape[0] == T and T > 0
                chunks = (FRAMES_PER_CHUNK, *value.shape[1:]) if per_frame else True
                group.create_dataset(key, data=value, chunks=chunks, compressor=COMPRESSOR, write_empty_chunks=True)

    def has_sequence(self, name: str) -> bool:
        """Whether a completely written sequence of that name exists (an interrupted write does not count)."""
        return isinstance(name, str) and bool(_NAME_RE.match(name)) and self._entry_attrs("sequences", name) is not None

    def sequence(self, name: str) -> Sequence:
        """A stored sequence, arrays lazily readable.

        Raises:
            InputError: no such sequence, or it is corrupt (missing marker, array metadata or chunk files).
        """
        self._check_name(name, "sequence")
        attrs = self._require_entry(
            "sequences", name, hint="; rewrite it (write_sequence replaces it) or delete it (delete_sequence)"
        )
        path = self._entry_dir("sequences", name)
        arrays = {key: self._open_array(path / key) for key in attrs["arrays"]}
        return Sequence(
            name=name,
            verts=arrays.pop("verts"),
            extra=arrays,
            garment=attrs["garment"],
            body=attrs["body"],
            motion=attrs["motion"],
            sim_params=attrs["sim_params"],
            stats=attrs["stats"],
            split=attrs["split"],
            status=attrs["status"],
            reason=attrs["reason"],
            created=attrs["created"],
            path=path,
        )

    def sequence_names(self, split: str | None = None, status: str | None = "ok") -> list[str]:
        """Sorted names of the complete sequences with that split and status (None: any)."""
        if split is not None and split not in SPLITS:
            raise InputError(f"split must be one of {SPLITS} or None, got {split!r}", self._root)
        if status is not None and status not in STATUSES:
            raise InputError(f"status must be one of {STATUSES} or None, got {status!r}", self._root)
        return [
            name
            for name, attrs in self._entries("sequences").items()
            if (split is None or attrs.get("split") == split) and (status is None or attrs.get("status") == status)
        ]

    def delete_sequence(self, name: str) -> None:
        """Remove a sequence (complete, corrupt or without marker) at once."""
        self._check_writable()
        self._check_name(name, "sequence")
        if not self._entry_dir("sequences", name).exists():
            raise InputError(f"no sequence named {name!r} in the store", self._root)
        staging.remove(self._root, f"sequences/{name}")

    # ---------------------------------------------------------------- arrays and attributes of later stages

    def _group_path(self, group_path: str) -> Path:
        """Check a group path for :meth:`write_array` & co: segments are valid names; under a
        collection it names an existing complete entry (``garments/<name>/...``)."""
        parts = str(group_path).strip("/").split("/")
        for part in parts:
            self._check_name(part, "group")
        if parts[0] in COLLECTIONS:
            if len(parts) < 2:
                raise InputError(
                    f"group path {group_path!r} must name an entry, e.g. '{parts[0]}/<name>/...'", self._root
                )
            if self._entry_attrs(parts[0], parts[1]) is None:
                raise InputError(
                    f"group path {group_path!r}: no {_SINGULAR[parts[0]]} named {parts[1]!r} in the store", self._root
                )
        return self._root.joinpath(*parts)

    def _ensure_groups(self, path: Path) -> None:
        """Make ``path`` and its parents Zarr groups (a ``.zgroup`` file, itself written atomically)."""
        rel = path.relative_to(self._root)
        current = self._root
        for part in rel.parts:
            current = current / part
            if not (current / ".zgroup").exists():
                current.mkdir(exist_ok=True)
                with atomic_path(current / ".zgroup") as tmp:
                    tmp.write_text(json.dumps({"zarr_format": 2}))

    def write_array(self, group_path: str, name: str, array: np.ndarray) -> None:
        """Store ``array`` as ``<group_path>/<name>``, atomically (replacing one of that name).

        For later stages that keep data with an entry: ``write_array("garments/skirt/rig", "weights", w)``,
        or in groups of their own (``"normalisation/skirt"``). Replacing an entry (e.g. :meth:`add_garment`
        with a different garment) drops the arrays stored under it. An entry's own arrays (a garment's
        ``verts``...) cannot be overwritten this way.
        """
        self._check_writable()
        self._check_name(name, "array")
        group = self._group_path(group_path)
        rel = group.relative_to(self._root).parts
        if len(rel) == 2 and rel[0] in COLLECTIONS:
            attrs = self._entry_attrs(*rel)
            if name in attrs.get("arrays", _CORE_ARRAYS.get(rel[0], ())):
                raise InputError(f"{'/'.join(rel)}/{name} is the entry's own array; it cannot be replaced", self._root)
        value = np.asarray(array)
        self._ensure_groups(group)
        target = "/".join((*rel, name))
        staged = staging.new_staging_dir(self._root, target)
        try:
            out = zarr.open_array(str(staged), mode="w-", shape=value.shape, dtype=value.dtype, compressor=COMPRESSOR)
            out[...] = value
        except BaseException:
            staging.discard(staged)
            raise
        staging.commit(self._root, staged, target)

    def read_array(self, group_path: str, name: str) -> np.ndarray:
        """The array ``<group_path>/<name>`` written by :meth:`write_array` (or an entry's own array)."""
        self._check_name(name, "array")
        path = self._group_path(group_path) / name
        problem = _array_problem(path) if path.exists() else f"no array {name!r} in group {group_path!r}"
        if problem:
            raise InputError(problem, path.parent)
        return self._open_array(path)[...]

    def write_attrs(self, group_path: str, attrs: dict) -> None:
        """Merge ``attrs`` (JSON values) into the attributes of ``group_path`` (created if needed);
        the attribute file is replaced atomically. ``name``, ``complete`` and ``arrays`` are reserved."""
        self._check_writable()
        group = self._group_path(group_path)
        clash = sorted(set(attrs) & set(_RESERVED_ATTRS))
        if clash:
            raise InputError(f"attributes {clash} are reserved by the store", self._root)
        self._ensure_groups(group)
        new = _jsonable(dict(attrs), f"attributes of {group_path!r}", self._root)
        merged = {**(_read_json(group / ".zattrs") or {}), **new}
        with atomic_path(group / ".zattrs") as tmp:
            tmp.write_text(json.dumps(merged, indent=2, sort_keys=True))

    def read_attrs(self, group_path: str) -> dict:
        """The attributes of ``group_path`` ({} for a group without any)."""
        group = self._group_path(group_path)
        if not group.is_dir():
            raise InputError(f"no group {group_path!r} in the store", self._root)
        return _read_json(group / ".zattrs") or {}

    # ---------------------------------------------------------------- integrity and summary

    def problems(self) -> dict[str, str]:
        """Everything that is not as a finished writer leaves it, by path relative to the store:
        writes in progress or interrupted, entries without completion marker, missing array metadata
        or chunk files. Reads metadata and directory listings only."""
        found = {}
        for leftover in staging.leftovers(self._root):
            found[str(leftover.path.relative_to(self._root))] = leftover.describe()
        for collection in COLLECTIONS:
            for entry in sorted(os.scandir(self._root / collection), key=lambda e: e.name):
                if not entry.is_dir():
                    continue
                rel = f"{collection}/{entry.name}"
                attrs = self._entry_attrs(collection, entry.name)
                if attrs is None:
                    found[rel] = "no completion marker in its .zattrs (corrupt or not written by loosefit)"
                    continue
                for array in attrs.get("arrays", _CORE_ARRAYS.get(collection, ())):
                    problem = _array_problem(Path(entry.path) / array)
                    if problem:
                        found[rel] = problem
                        break
        return found

    def info(self) -> dict:
        """A summary of the store (the manifest), JSON-compatible: ``garments`` {name: kind, verts, faces,
        pinned}, ``bodies`` {name: model, shape}, ``motions`` {name: frames, joints, fps, rig},
        ``sequences`` {count, frames, by_split: {split: {status: count, "frames": frames of ok ones}}},
        ``problems`` (see :meth:`problems`), ``size_bytes`` on disk, and the root attributes."""
        garments = {}
        for name, attrs in self._entries("garments").items():
            path = self._entry_dir("garments", name)
            pinned = None if _array_problem(path / "pinned") else int(self._open_array(path / "pinned")[...].sum())
            garments[name] = {
                "kind": attrs.get("kind"),
                "verts": _dim(path / "verts", 0),
                "faces": _dim(path / "faces", 0),
                "pinned": pinned,
            }
        bodies = {}
        for name, attrs in self._entries("bodies").items():
            path = self._entry_dir("bodies", name) / "values"
            shape = None if _array_problem(path) else self._open_array(path)[...].tolist()
            bodies[name] = {"model": attrs.get("model"), "shape": shape}
        motions = {}
        for name, attrs in self._entries("motions").items():
            path = self._entry_dir("motions", name) / "rotations"
            motions[name] = {
                "frames": _dim(path, 0),
                "joints": _dim(path, 1),
                "fps": attrs.get("fps"),
                "rig": attrs.get("rig"),
            }
        by_split: dict[str, dict[str, int]] = {}
        count = frames = 0
        for name, attrs in self._entries("sequences").items():
            n = _dim(self._entry_dir("sequences", name) / "verts", 0) or 0
            split = by_split.setdefault(str(attrs.get("split")), {"ok": 0, "failed": 0, "frames": 0})
            status = "ok" if attrs.get("status") == "ok" else "failed"
            split[status] += 1
            count += 1
            if status == "ok":
                split["frames"] += n
                frames += n
        size = sum(os.path.getsize(os.path.join(d, f)) for d, _, files in os.walk(self._root) for f in files)
        return {
            "path": str(self._root),
            "format": self.attrs["format"],
            "format_version": self.attrs["format_version"],
            "created": self.attrs.get("created", ""),
            "loosefit_version": self.attrs.get("loosefit_version", ""),
            "garments": garments,
            "bodies": bodies,
            "motions": motions,
            "sequences": {"count": count, "frames": frames, "by_split": by_split},
            "problems": self.problems(),
            "size_bytes": size,
        }
