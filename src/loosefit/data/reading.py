"""Reading a dataset store: entries, sequences, later stages' arrays and attributes, the summary.

:class:`StoreReader` is the reading half of :class:`loosefit.data.store.DatasetStore`. Every read
method raises :class:`~loosefit.errors.InputError` naming the file (the entry's ``.zattrs``, the
array's ``.zarray`` or chunk file inside the store) when what it reads is corrupt: garbage
attributes, a missing, truncated or changed chunk, or an array with an object or pickle codec
(never decoded). Listings (:meth:`StoreReader.sequence_names` & co) refuse a corrupt entry rather
than leave it out silently; ``loosefit info DATA.zarr --repair`` drops such entries.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zarr

from loosefit.data import staging
from loosefit.data.chunks import array_problem, open_checked
from loosefit.data.layout import (
    COLLECTIONS, NAME_RE, REFERENCES, SINGULAR, SPLITS, STATUSES, attrs_problem, entry_arrays, read_json,
)
from loosefit.data.lock import current_holder
from loosefit.data.run_spread import floor_m, stack_runs
from loosefit.errors import InputError
from loosefit.motion.motion import Motion


def _garment_class():
    # Imported on use: the garment package imports geometry code the store does not need.
    from loosefit.garment import Garment

    return Garment


@dataclass
class Sequence:
    """A simulated garment sequence in a store. Arrays stay on disk: slicing one (``seq.verts[10:42]``)
    reads only the chunks it touches; ``seq.verts[:]`` reads all frames. A damaged chunk raises
    :class:`~loosefit.errors.InputError` naming its file when it is read.

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


def array_checksums(checksums: dict, array: str) -> dict[str, int]:
    """The checksums of one array's files out of an entry's ``{"verts/0.0.0": crc}`` map."""
    prefix = f"{array}/"
    return {k[len(prefix):]: v for k, v in checksums.items() if k.startswith(prefix)}


class StoreReader:
    """Read methods of a dataset store (``self._root``: its directory)."""

    _root: Path

    def repair_hint(self) -> str:
        return f"`loosefit info {self._root} --repair` drops it"

    # ---------------------------------------------------------------- internals

    def _check_name(self, name: str, what: str) -> None:
        if not isinstance(name, str) or not NAME_RE.match(name):
            raise InputError(
                f"bad {what} name {name!r}: use 1-128 characters from [A-Za-z0-9_.+=-], "
                "starting with a letter or digit",
                self._root,
            )

    def _entry_dir(self, collection: str, name: str) -> Path:
        return self._root / collection / name

    def _entry_attrs(self, collection: str, name: str) -> dict | None:
        """Attributes of a complete, well-formed entry, or None when there is no such entry."""
        path = self._entry_dir(collection, name)
        if attrs_problem(collection, path) is not None:
            return None
        return read_json(path / ".zattrs")

    def _entry_dirs(self, collection: str) -> list[str]:
        return sorted(e.name for e in os.scandir(self._root / collection) if e.is_dir() and NAME_RE.match(e.name))

    def _entries(self, collection: str, strict: bool = False) -> dict[str, dict]:
        """Attributes of the complete entries of a collection, by name, sorted. ``strict``: an entry
        directory with corrupt attributes raises :class:`InputError` naming its ``.zattrs``; otherwise
        it is left out."""
        found = {}
        for name in self._entry_dirs(collection):
            path = self._entry_dir(collection, name)
            problem = attrs_problem(collection, path)
            if problem is None:
                found[name] = read_json(path / ".zattrs")
            elif strict:
                raise InputError(f"corrupt {SINGULAR[collection]} {name!r}: {problem}; {self.repair_hint()}",
                                 path / ".zattrs")
        return found

    def _require_entry(self, collection: str, name: str) -> dict:
        """Attributes of a complete entry whose arrays are all present; :class:`InputError` naming
        the damaged file otherwise."""
        what = SINGULAR[collection]
        self._check_name(name, what)
        path = self._entry_dir(collection, name)
        if not path.is_dir():
            known = list(self._entries(collection))
            shown = f"{known[:10]}{'...' if len(known) > 10 else ''}" if known else "none"
            raise InputError(f"no {what} named {name!r} in the store (it has {shown})", self._root)
        problem = attrs_problem(collection, path)
        if problem:
            raise InputError(f"corrupt {what} {name!r}: {problem}; {self.repair_hint()}", path / ".zattrs")
        attrs = read_json(path / ".zattrs")
        for array in entry_arrays(collection, attrs):
            found = array_problem(path / array)
            if found:
                raise InputError(f"corrupt {what} {name!r}: array {array!r}: {found[1]}; {self.repair_hint()}",
                                 found[0])
        return attrs

    def _entry_array(self, collection: str, name: str, array: str, attrs: dict) -> zarr.Array:
        """An entry's own array for reading, its chunks checked against the checksums of the entry."""
        return open_checked(self._entry_dir(collection, name) / array,
                            array_checksums(attrs.get("checksums", {}), array), self.repair_hint())

    def _open_array(self, path: Path) -> zarr.Array:
        """An array written by :meth:`write_array` (its checksums are in its own ``.zattrs``)."""
        checksums = (read_json(path / ".zattrs") or {}).get("checksums")
        return open_checked(path, checksums if isinstance(checksums, dict) else {}, self.repair_hint())

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
                    f"group path {group_path!r}: no {SINGULAR[parts[0]]} named {parts[1]!r} in the store", self._root
                )
        return self._root.joinpath(*parts)

    # ---------------------------------------------------------------- garments, bodies, motions

    def garment(self, name: str):
        """The stored garment as a :class:`loosefit.garment.Garment`."""
        attrs = self._require_entry("garments", name)
        arrays = {key: self._entry_array("garments", name, key, attrs)[...] for key in ("verts", "faces", "pinned")}
        return _garment_class()(**arrays, kind=attrs["kind"], params=attrs["params"], name=attrs["garment_name"])

    def garment_num_verts(self, name: str) -> int:
        """Vertex count of a stored garment (read from metadata only)."""
        attrs = self._require_entry("garments", name)
        return self._entry_array("garments", name, "verts", attrs).shape[0]

    def garment_names(self) -> list[str]:
        return list(self._entries("garments", strict=True))

    def body(self, name: str) -> np.ndarray:
        """The stored shape values ``(S,)`` float32; the model is ``read_attrs(f"bodies/{name}")["model"]``."""
        attrs = self._require_entry("bodies", name)
        return self._entry_array("bodies", name, "values", attrs)[...]

    def body_names(self) -> list[str]:
        return list(self._entries("bodies", strict=True))

    def motion(self, name: str) -> Motion:
        attrs = self._require_entry("motions", name)
        return Motion(
            rotations=self._entry_array("motions", name, "rotations", attrs)[...],
            translation=self._entry_array("motions", name, "translation", attrs)[...],
            fps=attrs["fps"],
            rig=attrs["rig"],
            joint_names=attrs["joint_names"],
            name=attrs["motion_name"],
        )

    def motion_num_frames(self, name: str) -> int:
        """Frame count of a stored motion (read from metadata only)."""
        attrs = self._require_entry("motions", name)
        return self._entry_array("motions", name, "rotations", attrs).shape[0]

    def motion_names(self) -> list[str]:
        return list(self._entries("motions", strict=True))

    # ---------------------------------------------------------------- sequences

    def has_sequence(self, name: str) -> bool:
        """Whether a completely written sequence of that name exists (an interrupted write does not
        count). Reads its attributes only: see :meth:`verify_sequence` for its data."""
        return isinstance(name, str) and bool(NAME_RE.match(name)) and self._entry_attrs("sequences", name) is not None

    def sequence(self, name: str) -> Sequence:
        """A stored sequence, arrays lazily readable.

        Raises:
            InputError: no such sequence, or it is corrupt (attributes, array metadata or chunk files;
                a chunk damaged inside raises when it is read), naming the damaged file.
        """
        attrs = self._require_entry("sequences", name)
        arrays = {key: self._entry_array("sequences", name, key, attrs) for key in attrs["arrays"]}
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
            path=self._entry_dir("sequences", name),
        )

    def sequence_names(self, split: str | None = None, status: str | None = "ok") -> list[str]:
        """Sorted names of the complete sequences with that split and status (None: any).

        Raises:
            InputError: a sequence's attributes are corrupt (naming its ``.zattrs``): it is not
                skipped silently; ``loosefit info DATA.zarr --repair`` drops it.
        """
        if split is not None and split not in SPLITS:
            raise InputError(f"split must be one of {SPLITS} or None, got {split!r}", self._root)
        if status is not None and status not in STATUSES:
            raise InputError(f"status must be one of {STATUSES} or None, got {status!r}", self._root)
        return [
            name
            for name, attrs in self._entries("sequences", strict=True).items()
            if (split is None or attrs["split"] == split) and (status is None or attrs["status"] == status)
        ]

    # ---------------------------------------------------------------- reference runs

    def reference_runs(self, name: str) -> dict[int, dict]:
        """The reference runs stored with sequence ``name``, by index (sorted): each run's attributes (``status``,
        ``reason``, ``created``, ``frames`` and what the writer kept: noise, seed, hash, stats). {} for none
        (also for every store written before reference runs existed).

        Raises:
            InputError: no such sequence, or a run's attributes are corrupt (naming the file).
        """
        self._require_entry("sequences", name)
        folder = self._entry_dir("sequences", name) / REFERENCES
        if not folder.is_dir():
            return {}
        runs = {}
        for entry in os.scandir(folder):
            if not (entry.is_dir() and entry.name.isdigit() and (Path(entry.path) / ".zarray").is_file()):
                continue
            attrs = read_json(Path(entry.path) / ".zattrs")
            meta = read_json(Path(entry.path) / ".zarray")
            if attrs is None or attrs.get("status") not in STATUSES or not isinstance(attrs.get("checksums"), dict) \
                    or meta is None or not isinstance(meta.get("shape"), list):
                raise InputError(f"corrupt reference run {entry.name} of sequence {name!r}: attributes or metadata "
                                 f"unreadable; {self.repair_hint()}", Path(entry.path) / ".zattrs")
            runs[int(entry.name)] = {**{k: v for k, v in attrs.items() if k != "checksums"},
                                     "frames": int(meta["shape"][0])}
        return dict(sorted(runs.items()))

    def reference(self, name: str, index: int) -> np.ndarray:
        """Reference run ``index`` of sequence ``name``: ``(T, V, 3)`` float32 metres (fewer frames for a failed
        run), its chunks checked against their checksums."""
        if index not in self.reference_runs(name):
            raise InputError(f"sequence {name!r} has no reference run {index!r}", self._entry_dir("sequences", name))
        return self._open_array(self._entry_dir("sequences", name) / REFERENCES / str(int(index)))[...]

    def references(self, name: str) -> np.ndarray:
        """The ``"ok"`` reference runs of sequence ``name`` in index order: ``(K, T, V, 3)`` float32 metres,
        ``K = 0`` when it has none. With the base run (the sequence) they give the mean run and the floor of
        :mod:`loosefit.metrics.reference`."""
        T, V = self.sequence(name).verts.shape[:2]
        runs = [self.reference(name, k) for k, r in self.reference_runs(name).items() if r["status"] == "ok"]
        return np.stack(runs) if runs else np.zeros((0, T, V, 3), np.float32)

    # ---------------------------------------------------------------- later stages

    def read_array(self, group_path: str, name: str) -> np.ndarray:
        """The array ``<group_path>/<name>`` written by :meth:`write_array` (or an entry's own array)."""
        self._check_name(name, "array")
        path = self._group_path(group_path) / name
        if not path.exists():
            raise InputError(f"no array {name!r} in group {group_path!r}", path.parent)
        rel = path.relative_to(self._root).parts
        if len(rel) == 3 and rel[0] in COLLECTIONS:  # an entry's own array: its checksums are the entry's
            attrs = self._require_entry(rel[0], rel[1])
            if name in entry_arrays(rel[0], attrs):
                return self._entry_array(rel[0], rel[1], name, attrs)[...]
        return self._open_array(path)[...]

    def read_attrs(self, group_path: str) -> dict:
        """The attributes of ``group_path`` ({} for a group without any)."""
        group = self._group_path(group_path)
        if not group.is_dir():
            raise InputError(f"no group {group_path!r} in the store", self._root)
        if (group / ".zattrs").exists() and read_json(group / ".zattrs") is None:
            raise InputError("corrupt attributes: not a JSON object", group / ".zattrs")
        return read_json(group / ".zattrs") or {}

    # ---------------------------------------------------------------- summary

    def info(self, verify: bool = True) -> dict:
        """A summary of the store (the manifest), JSON-compatible: ``garments`` {name: kind, verts, faces,
        pinned}, ``bodies`` {name: model, shape}, ``motions`` {name: frames, joints, fps, rig},
        ``sequences`` {count, frames, by_split: {split: {status: count, "frames": frames of ok ones}}},
        ``references`` {sequence: ok, failed, floor_mm} for the sound sequences with reference runs (the floor of
        the base and its ok runs, :mod:`loosefit.data.run_spread`; None when no run is ok or one is damaged),
        ``problems`` (see :meth:`problems`; ``verify``: every chunk read), ``writer`` (the process
        holding the write lock, or None), ``size_bytes`` on disk, and the root attributes.
        Corrupt entries are left out of the counts and listed in ``problems``."""
        problems = self.problems(verify=verify)
        sound = {c: {n: a for n, a in self._entries(c).items() if f"{c}/{n}" not in problems} for c in COLLECTIONS}

        def shape(collection: str, name: str, array: str) -> tuple[int, ...]:
            return tuple(read_json(self._entry_dir(collection, name) / array / ".zarray")["shape"])

        def values(collection: str, name: str, array: str, attrs: dict) -> np.ndarray | None:
            try:  # damage inside a chunk is only seen when verifying
                return self._entry_array(collection, name, array, attrs)[...]
            except InputError:
                return None

        garments = {}
        for name, attrs in sound["garments"].items():
            pinned = values("garments", name, "pinned", attrs)
            garments[name] = {"kind": attrs["kind"], "verts": shape("garments", name, "verts")[0],
                              "faces": shape("garments", name, "faces")[0],
                              "pinned": None if pinned is None else int(pinned.sum())}
        bodies = {}
        for name, attrs in sound["bodies"].items():
            body = values("bodies", name, "values", attrs)
            bodies[name] = {"model": attrs["model"], "shape": None if body is None else body.tolist()}
        motions = {}
        for name, attrs in sound["motions"].items():
            frames, joints = shape("motions", name, "rotations")[:2]
            motions[name] = {"frames": frames, "joints": joints, "fps": attrs["fps"], "rig": attrs["rig"]}
        by_split: dict[str, dict[str, int]] = {}
        count = frames = 0
        for name, attrs in sound["sequences"].items():
            n = shape("sequences", name, "verts")[0]
            split = by_split.setdefault(attrs["split"], {"ok": 0, "failed": 0, "frames": 0})
            split[attrs["status"]] += 1
            count += 1
            if attrs["status"] == "ok":
                split["frames"] += n
                frames += n
        references = {}
        for name, attrs in sound["sequences"].items():
            if attrs["status"] == "ok" and (self._entry_dir("sequences", name) / REFERENCES).is_dir():
                references[name] = self._reference_summary(name)
        size = sum(os.path.getsize(os.path.join(d, f)) for d, _, files in os.walk(self._root) for f in files)
        writer = current_holder(self._root)
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
            "references": {name: r for name, r in references.items() if r["ok"] or r["failed"] or r.get("damaged")},
            "problems": problems,
            "writer": None if writer is None else writer.describe(),
            "size_bytes": size,
        }

    def _reference_summary(self, name: str) -> dict:
        """``ok`` and ``failed`` reference runs of sequence ``name`` and the floor in mm (None when unreadable)."""
        try:
            runs = self.reference_runs(name)
            ok = sum(r["status"] == "ok" for r in runs.values())
            floor = 1000.0 * floor_m(stack_runs(self.sequence(name).verts[:], self.references(name))) if ok else None
        except InputError:  # damage is listed among the problems
            return {"ok": 0, "failed": 0, "floor_mm": None, "damaged": True}
        return {"ok": ok, "failed": len(runs) - ok, "floor_mm": floor}

    def _leftover_problems(self) -> dict[str, str]:
        return {str(lo.path.relative_to(self._root)): lo.describe() for lo in staging.leftovers(self._root)}
