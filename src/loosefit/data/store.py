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
        references/<k>             optional reference runs k = 1, 2... of the sequence (the same motion and
                                   settings, start noise with seed k): (T,V,3) float32; attrs status, reason,
                                   created, checksums and the run's info (:meth:`DatasetStore.write_reference`)
      .staging/                    writes in progress (see :mod:`loosefit.data.staging`)
      .lock                        pid, host and start of the process writing the store (:mod:`loosefit.data.lock`)

Every entry (a garment, body, motion or sequence) and every array written with :meth:`DatasetStore.write_array`
is built under ``.staging/`` and renamed into place once flushed, with the CRC-32 of each of its
files and ``complete: true`` in its attributes, so a killed writer never leaves an entry that reads
as complete and later damage is found. Frame ``i`` of a sequence is frame ``i`` of its motion.
Names are 1-128 characters from ``[A-Za-z0-9_.+=-]``, not starting with ``.``, ``_``, ``+``, ``=`` or ``-``.

The class is assembled from one module per concept: :mod:`~loosefit.data.reading` (read methods,
errors naming the damaged file), :mod:`~loosefit.data.writing` (atomic writes),
:mod:`~loosefit.data.verify` (problems, verification, repair), :mod:`~loosefit.data.lock` (one
writer at a time) and :mod:`~loosefit.data.chunks` (checked chunk reading).
"""

from __future__ import annotations

import logging
import os
import shutil
import weakref
from pathlib import Path

import zarr

from loosefit import __version__
from loosefit.data import lock, staging
from loosefit.data.layout import (
    COLLECTIONS, COMPRESSOR, FORMAT, FORMAT_VERSION, FRAMES_PER_CHUNK, SPLITS, STATUSES, now, read_json,
)
from loosefit.data.reading import Sequence, StoreReader
from loosefit.data.verify import StoreChecks
from loosefit.data.writing import StoreWriter
from loosefit.errors import InputError

__all__ = ["DatasetStore", "Sequence", "FORMAT_VERSION", "FRAMES_PER_CHUNK", "COMPRESSOR", "SPLITS", "STATUSES"]

log = logging.getLogger(__name__)


class DatasetStore(StoreReader, StoreWriter, StoreChecks):
    """A loosefit dataset on disk (Zarr 2 directory store); see the module docstring for the layout.

    Make one with :meth:`create` (or :meth:`open_or_create`), open one with :meth:`open`. Mode ``"r"``
    reads and takes no lock. Mode ``"a"`` also writes: it takes the store's write lock (a second
    process opening it in mode ``"a"`` is refused until :meth:`close`, the end of a ``with`` block,
    the object's collection or the holder's exit) and, on opening, cleans what writers that were
    killed left in ``.staging/`` and beside the store.
    """

    def __init__(self, root: Path, mode: str, attrs: dict):
        """Use :meth:`create` or :meth:`open`."""
        self._root = root
        self.mode = mode
        self.attrs = attrs
        self.recovered: list[str] = []
        self.created = False  # made by :meth:`create` (this object's process made the store)
        self._lock_key: str | None = None
        self._finalizer = None
        if mode == "a":
            self._lock_key, stale = lock.acquire(root)
            self._finalizer = weakref.finalize(self, lock.release, self._lock_key)
            self.recovered += [stale] if stale else []
            self.recovered += lock.clean_creating_litter(root)
            for leftover in staging.leftovers(root):
                if not leftover.writer_alive():
                    self.recovered.append(staging.recover(root, leftover))
            for line in self.recovered:
                log.info("%s: %s", root, line)
        for leftover in staging.leftovers(root):
            log.warning("%s: %s", root, leftover.describe())

    # ---------------------------------------------------------------- opening and closing

    @classmethod
    def create(cls, path: str | Path) -> "DatasetStore":
        """Create an empty store at ``path`` (which must not exist) and return it open in mode ``"a"``.

        Raises:
            InputError: the path exists (also when another process created it meanwhile).
        """
        path = Path(path)
        if path.exists():
            raise InputError("cannot create a dataset store: the path already exists", path)
        path.parent.mkdir(parents=True, exist_ok=True)
        cleaned = lock.clean_creating_litter(path)
        # Built beside its final place and renamed: an interrupted create leaves no half store, and
        # the store is locked from the moment it appears.
        tmp = lock.creating_path(path)
        fd = None
        try:
            root = zarr.open_group(str(tmp), mode="w-")
            for collection in COLLECTIONS:
                root.create_group(collection)
            root.attrs.put(
                {"format": FORMAT, "format_version": FORMAT_VERSION, "created": now(), "loosefit_version": __version__}
            )
            fd = lock.lock_new(tmp)
            staging.fsync_tree(tmp)
            try:
                os.rename(tmp, path)
            except OSError:  # another process created it first (a non-empty directory is not replaced)
                if path.exists():
                    raise InputError("cannot create a dataset store: the path already exists", path) from None
                raise
            lock.adopt(path, fd)
            fd = None
        finally:
            if fd is not None:
                os.close(fd)
            staging.discard(tmp)
        try:
            store = cls.open(path, mode="a")
            store.created = True
            store.recovered[:0] = cleaned
            return store
        except BaseException:
            lock.release(os.path.realpath(path))  # the hold adopted above
            raise

    @classmethod
    def open_or_create(cls, path: str | Path) -> "DatasetStore":
        """The store at ``path`` open in mode ``"a"``, created when missing (also when several
        processes try at once: one creates it, the others find it, locked)."""
        path = Path(path)
        if not path.exists():
            try:
                return cls.create(path)
            except InputError:
                if not path.exists():
                    raise
        return cls.open(path, mode="a")

    @classmethod
    def open(cls, path: str | Path, mode: str = "r") -> "DatasetStore":
        """Open the store at ``path``, checking that it is a loosefit dataset this version can read.

        Raises:
            InputError: not a directory, not a Zarr group, not a loosefit dataset, written by a newer
                format version, or missing one of its groups; in mode ``"a"``, another process holds
                the write lock (naming its pid and host).
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
        if read_json(path / ".zgroup") is None:
            raise InputError("not a Zarr dataset store: no readable .zgroup", path)
        attrs = read_json(path / ".zattrs") or {}
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
            if read_json(path / collection / ".zgroup") is None:
                raise InputError(f"corrupt dataset: group {collection!r} is missing", path)
        return cls(path, mode, attrs)

    def close(self) -> None:
        """Let go of the write lock (mode ``"a"``); the object then only reads. Idempotent."""
        if self._finalizer is not None:
            self._finalizer()
        self.mode = "r"

    def __enter__(self) -> "DatasetStore":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def remove_if_empty(self) -> bool:
        """Delete the whole store when no sequence is in it (used when the run that created it fails
        before simulating anything: its garments, bodies and motions are the run's inputs, added
        again by the next run). Needs mode ``"a"``; returns whether the store was deleted."""
        self._check_writable()
        if any(entry.is_dir() for entry in os.scandir(self._root / "sequences")):
            return False
        # Renamed to a creation leftover first: a kill during the deletion leaves litter that the
        # next run cleans, never a half store.
        aside = lock.creating_path(self._root)
        os.rename(self._root, aside)
        self.close()
        shutil.rmtree(aside, ignore_errors=True)
        return True

    @property
    def path(self) -> Path:
        return self._root

    def __repr__(self) -> str:
        return f"DatasetStore({str(self._root)!r}, mode={self.mode!r})"
