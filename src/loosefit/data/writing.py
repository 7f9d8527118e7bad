"""Writing a dataset store: entries, sequences and later stages' arrays, each committed atomically.

:class:`StoreWriter` is the writing half of :class:`loosefit.data.store.DatasetStore`. Every entry
(a garment, body, motion or sequence) and every array written with :meth:`StoreWriter.write_array`
is built under ``.staging/`` (:mod:`loosefit.data.staging`), its files' CRC-32 checksums are
recorded in its attributes (written last, with ``complete: true``), and it is renamed into place,
so a killed writer never leaves an entry that reads as complete and later damage to any of its
files is detected (:mod:`loosefit.data.chunks`). Writing needs the store open in mode ``"a"``,
which holds its write lock (:mod:`loosefit.data.lock`).
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path
from typing import Collection, Iterator

import numpy as np
import zarr

from loosefit.data import staging
from loosefit.data.chunks import array_problem, file_checksums
from loosefit.data.reading import array_checksums
from loosefit.data.layout import (
    COLLECTIONS, COMPRESSOR, CORE_ARRAYS, FRAMES_PER_CHUNK, REFERENCES, RESERVED_ATTRS, SPLITS, STATUSES, jsonable,
    now, read_json,
)
from loosefit.errors import InputError
from loosefit.motion.motion import Motion
from loosefit.paths import atomic_path


class StoreWriter:
    """Write methods of a dataset store (``self._root``: its directory; ``self.mode``: ``"r"`` or ``"a"``)."""

    _root: Path
    mode: str

    def _check_writable(self) -> None:
        if self.mode != "a":
            raise InputError("dataset store is open read-only; open it with mode='a' to write", self._root)

    @contextlib.contextmanager
    def _staged_group(self, target: str, attrs: dict, name: str) -> Iterator[zarr.Group]:
        """A new Zarr group under ``.staging/``; on success its attributes (with the checksums of its
        arrays and the completion marker) are written last and it is renamed onto ``target``; on
        failure it is deleted."""
        self._check_writable()
        staged = staging.new_staging_dir(self._root, target)
        try:
            group = zarr.open_group(str(staged), mode="w-")
            yield group
            arrays = tuple(attrs.get("arrays", CORE_ARRAYS.get(target.split("/")[0], ())))
            group.attrs.put({**attrs, "name": name, "checksums": file_checksums(staged, arrays), "complete": True})
        except BaseException:
            staging.discard(staged)
            raise
        staging.commit(self._root, staged, target)

    def _same_entry(self, collection: str, name: str, arrays: dict[str, np.ndarray], attrs: dict) -> bool:
        """Whether the store already holds exactly this entry, undamaged (then re-adding it keeps
        what later stages stored under it)."""
        old = self._entry_attrs(collection, name)
        if old is None or any(old.get(k) != v for k, v in attrs.items()):
            return False
        path = self._entry_dir(collection, name)
        for key, value in arrays.items():
            if array_problem(path / key, array_checksums(old.get("checksums", {}), key), deep=True):
                return False
            stored = self._entry_array(collection, name, key, old)
            if stored.shape != value.shape or stored.dtype != value.dtype or not np.array_equal(stored[...], value):
                return False
        return True

    def _add_entry(self, collection: str, name: str, arrays: dict[str, np.ndarray], attrs: dict,
                   user_key: str | None = None, rewritten: Collection[str] | None = None) -> None:
        if self._same_entry(collection, name, arrays, attrs):
            return
        if rewritten is not None and self._entry_attrs(collection, name) is not None:
            stale = sorted(set(self._sequences_using(user_key, name)) - set(rewritten))
            if stale:
                raise InputError(
                    f"{user_key} {name!r} differs from the one stored, which sequences {stale[:5]}"
                    f"{'...' if len(stale) > 5 else ''} were simulated with; give it another name, or write into "
                    f"another store", self._root)
        with self._staged_group(f"{collection}/{name}", attrs, name) as group:
            for key, value in arrays.items():
                group.create_dataset(key, data=value, compressor=COMPRESSOR)

    def _refuse_resizing_used(self, collection: str, key: str, name: str, array: str, length: int, unit: str) -> None:
        """Refuse replacing entry ``name`` by one of another ``length`` (vertices, frames) while sequences use it."""
        if self._entry_attrs(collection, name) is None or self._stored_length(collection, name, array) == length:
            return
        users = self._sequences_using(key, name)
        if users:
            raise InputError(f"{key} {name!r} is used by sequences {users[:5]}{'...' if len(users) > 5 else ''}; "
                             f"replacing it with {length} {unit} would make them inconsistent", self._root)

    def _sequences_using(self, key: str, name: str) -> list[str]:
        return [s for s, attrs in self._entries("sequences").items() if attrs.get(key) == name]

    def _stored_length(self, collection: str, name: str, array: str) -> int | None:
        meta = read_json(self._entry_dir(collection, name) / array / ".zarray")
        try:
            return int(meta["shape"][0])
        except (TypeError, KeyError, IndexError, ValueError):
            return None

    # ---------------------------------------------------------------- garments, bodies, motions

    def add_garment(self, name: str, garment, rewritten: Collection[str] | None = None) -> None:
        """Store a garment (any object with ``verts (V,3)``, ``faces (F,3)``, ``pinned (V,)``, ``kind``,
        ``params`` (JSON values), ``name``), atomically.

        Adding an identical garment again does nothing (arrays stored under it by later stages stay);
        a different (or damaged) one is replaced, dropping those arrays. Replacing a garment that
        sequences use by one with another vertex count is refused. With ``rewritten`` (the sequences the
        caller is about to write again, e.g. a plan run's jobs), replacing it with different content is
        refused while any other sequence uses it: those would keep vertices simulated on the old one.
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
        self._refuse_resizing_used("garments", "garment", name, "verts", verts.shape[0], "vertices")
        attrs = {
            "kind": str(garment.kind),
            "params": jsonable(dict(garment.params), f"garment {name!r} params", self._root),
            "garment_name": str(garment.name),
        }
        self._add_entry("garments", name, {"verts": verts, "faces": faces, "pinned": pinned}, attrs,
                        user_key="garment", rewritten=rewritten)

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

    def add_motion(self, name: str, motion: Motion, rewritten: Collection[str] | None = None) -> None:
        """Store a motion, atomically; same replacement rules as :meth:`add_garment` (a motion that
        sequences use keeps its frame count; with ``rewritten``, only those sequences may use a motion
        whose content changes)."""
        self._check_writable()
        self._check_name(name, "motion")
        self._refuse_resizing_used("motions", "motion", name, "rotations", motion.num_frames, "frames")
        attrs = {
            "fps": float(motion.fps),
            "rig": str(motion.rig),
            "joint_names": [str(j) for j in motion.joint_names],
            "motion_name": str(motion.name),
        }
        self._add_entry("motions", name, {"rotations": motion.rotations, "translation": motion.translation}, attrs,
                        user_key="motion", rewritten=rewritten)

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
            "sim_params": jsonable(dict(sim_params), f"sequence {name!r} sim_params", where),
            "stats": jsonable(dict(stats), f"sequence {name!r} stats", where),
            "split": split,
            "status": status,
            "reason": str(reason),
            "created": now(),
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

    def write_reference(self, name: str, index: int, verts, status: str = "ok", reason: str = "",
                        info: dict | None = None) -> None:
        """Store reference run ``index`` (>= 1) of sequence ``name`` atomically, replacing one of that index:
        the array ``sequences/<name>/references/<index>`` with the run's metadata in its attributes.

        Args:
            verts: ``(T, V, 3)`` metres, stored as float32 in chunks of 32 frames; an ``"ok"`` run has the
                sequence's ``T`` frames and finite values, a ``"failed"`` one (with a ``reason``) at most ``T``.
            info: JSON values kept with the run (its noise, seed, hash, simulation stats...).

        Replacing the sequence (:meth:`write_sequence`) drops its reference runs: they belong to that base run.
        """
        self._check_writable()
        seq = self._require_entry("sequences", name)
        where = self._entry_dir("sequences", name)
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or index < 1:
            raise InputError(f"sequence {name!r}: a reference run's index must be an integer >= 1, got {index!r}", where)
        if status not in STATUSES or (status == "failed" and not reason):
            raise InputError(f"sequence {name!r}: reference run {index}: status must be one of {STATUSES} "
                             f"(a failed one with a reason), got {status!r}", where)
        T, V = self._stored_length("sequences", name, "verts"), self.garment_num_verts(seq["garment"])
        value = np.asarray(verts, dtype=np.float32)
        if value.ndim != 3 or value.shape[1:] != (V, 3) or value.shape[0] > T or (status == "ok" and value.shape[0] != T):
            raise InputError(f"sequence {name!r}: reference run {index} must have shape ({T}, {V}, 3) like the "
                             f"sequence, got {value.shape}", where)
        if status == "ok" and not np.isfinite(value).all():
            raise InputError(f"sequence {name!r}: reference run {index} has NaN or infinite vertices; store it "
                             "with status='failed' and a reason", where)
        attrs = {**jsonable(dict(info or {}), f"sequence {name!r} reference run {index}", where),
                 "status": status, "reason": str(reason), "created": now()}
        group = where / REFERENCES
        self._ensure_groups(group)
        target = f"sequences/{name}/{REFERENCES}/{int(index)}"
        staged = staging.new_staging_dir(self._root, target)
        try:
            out = zarr.open_array(str(staged), mode="w-", shape=value.shape, chunks=(FRAMES_PER_CHUNK, V, 3),
                                  dtype=np.float32, fill_value=np.nan, compressor=COMPRESSOR, write_empty_chunks=True)
            out[...] = value
            out.attrs.put({**attrs, "checksums": file_checksums(staged)})
        except BaseException:
            staging.discard(staged)
            raise
        staging.commit(self._root, staged, target)

    def delete_reference(self, name: str, index: int) -> None:
        """Remove reference run ``index`` of sequence ``name`` (nothing when there is none)."""
        self._check_writable()
        self._require_entry("sequences", name)
        if (self._entry_dir("sequences", name) / REFERENCES / str(int(index))).exists():
            staging.remove(self._root, f"sequences/{name}/{REFERENCES}/{int(index)}")

    def delete_sequence(self, name: str) -> None:
        """Remove a sequence (complete, corrupt or without marker) at once."""
        self._check_writable()
        self._check_name(name, "sequence")
        if not self._entry_dir("sequences", name).exists():
            raise InputError(f"no sequence named {name!r} in the store", self._root)
        staging.remove(self._root, f"sequences/{name}")

    # ---------------------------------------------------------------- arrays and attributes of later stages

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
        """Store ``array`` as ``<group_path>/<name>``, atomically (replacing one of that name), with
        its files' checksums in its own attributes.

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
            if name in attrs.get("arrays", CORE_ARRAYS.get(rel[0], ())):
                raise InputError(f"{'/'.join(rel)}/{name} is the entry's own array; it cannot be replaced", self._root)
        value = np.asarray(array)
        if value.dtype.kind in "OV":  # object arrays need a pickle-like codec, which a store never decodes
            raise InputError(f"{'/'.join(rel)}/{name}: object and structured arrays cannot be stored, "
                             f"got dtype {value.dtype}", self._root)
        self._ensure_groups(group)
        target = "/".join((*rel, name))
        staged = staging.new_staging_dir(self._root, target)
        try:
            out = zarr.open_array(str(staged), mode="w-", shape=value.shape, dtype=value.dtype, compressor=COMPRESSOR)
            out[...] = value
            out.attrs.put({"checksums": file_checksums(staged)})
        except BaseException:
            staging.discard(staged)
            raise
        staging.commit(self._root, staged, target)

    def write_attrs(self, group_path: str, attrs: dict) -> None:
        """Merge ``attrs`` (JSON values) into the attributes of ``group_path`` (created if needed);
        the attribute file is replaced atomically. ``name``, ``complete``, ``arrays`` and ``checksums``
        are reserved."""
        self._check_writable()
        group = self._group_path(group_path)
        clash = sorted(set(attrs) & set(RESERVED_ATTRS))
        if clash:
            raise InputError(f"attributes {clash} are reserved by the store", self._root)
        self._ensure_groups(group)
        new = jsonable(dict(attrs), f"attributes of {group_path!r}", self._root)
        merged = {**(read_json(group / ".zattrs") or {}), **new}
        with atomic_path(group / ".zattrs") as tmp:
            tmp.write_text(json.dumps(merged, indent=2, sort_keys=True))
