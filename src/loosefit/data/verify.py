"""Verifying and repairing a dataset store.

:meth:`StoreChecks.problems` lists everything that is not as a finished writer leaves it: writes in
progress or interrupted, entries with missing or garbage attributes, arrays with bad metadata
(an object dtype or a pickle codec included), missing chunk files and, when verifying (the
default), every chunk whose bytes differ from the checksum recorded at commit or, for arrays
written without checksums, that does not decode. That is what ``loosefit info`` reports.

:meth:`StoreChecks.repair` (``loosefit info DATA.zarr --repair``) drops what is damaged, and only
that, leaving every other file bit-identical: a damaged sequence; a damaged garment, body or motion
together with the sequences made from it (``loosefit simulate PLAN --out DATA.zarr`` adds and
simulates them again); a damaged array of a later stage together with its stage's group
(``garments/<name>/rig``, ``prepare/fit_attribute``..., which ``loosefit prepare`` writes again).
"""

from __future__ import annotations

import os
from pathlib import Path

from loosefit.data import staging
from loosefit.data.chunks import array_problem
from loosefit.data.layout import COLLECTIONS, SINGULAR, attrs_problem, entry_arrays, read_json
from loosefit.data.reading import array_checksums


def _stage_unit(rel: str) -> str:
    """The group a later stage writes as one unit around the array ``rel`` (its stage's group:
    ``garments/g/rig`` for ``garments/g/rig/frames/s/rotations``), or the array itself."""
    parts = rel.split("/")
    depth = 3 if parts[0] in COLLECTIONS else 2
    return "/".join(parts[:depth]) if len(parts) > depth else rel


class StoreChecks:
    """Integrity checks and repair of a dataset store (``self._root``: its directory)."""

    _root: Path

    def _entry_problem(self, collection: str, name: str, verify: bool) -> str | None:
        path = self._entry_dir(collection, name)
        problem = attrs_problem(collection, path)
        if problem:
            return problem
        attrs = read_json(path / ".zattrs")
        for array in entry_arrays(collection, attrs):
            found = array_problem(path / array, array_checksums(attrs.get("checksums", {}), array), deep=verify)
            if found:
                return f"{found[0].relative_to(path)}: {found[1]}"
        return None

    def _stage_arrays(self) -> list[Path]:
        """Array directories other than the entries' own arrays (those of later stages)."""
        own = {
            (collection, name, array)
            for collection in COLLECTIONS
            for name, attrs in self._entries(collection).items()
            for array in entry_arrays(collection, attrs)
        }
        found = []
        for dirpath, dirnames, filenames in os.walk(self._root):
            rel = Path(dirpath).relative_to(self._root).parts
            if rel[:1] == (staging.STAGING,):
                dirnames.clear()
                continue
            if ".zarray" in filenames:
                dirnames.clear()
                if not (len(rel) == 3 and rel in own):
                    found.append(Path(dirpath))
            dirnames.sort()
        return found

    def problems(self, verify: bool = True) -> dict[str, str]:
        """Everything that is not as a finished writer leaves it, by path relative to the store
        (an entry ``sequences/s`` or a later stage's array): writes in progress or interrupted,
        entries without completion marker or with garbage attributes, bad array metadata, missing
        chunk files and, with ``verify``, chunks that differ from their checksums or do not decode
        (every chunk file is read: about the time of reading the store from disk)."""
        found = self._leftover_problems()
        for collection in COLLECTIONS:
            for entry in sorted(os.scandir(self._root / collection), key=lambda e: e.name):
                if entry.is_dir():
                    problem = self._entry_problem(collection, entry.name, verify)
                    if problem:
                        found[f"{collection}/{entry.name}"] = problem
        for path in self._stage_arrays():
            rel = "/".join(path.relative_to(self._root).parts)
            if any(rel.startswith(f"{key}/") for key in found):
                continue  # inside an entry already reported
            checksums = (read_json(path / ".zattrs") or {}).get("checksums")
            problem = array_problem(path, checksums if isinstance(checksums, dict) else {}, deep=verify)
            if problem:
                found[rel] = f"{problem[0].relative_to(path)}: {problem[1]}"
        return found

    def verify_sequence(self, name: str) -> str | None:
        """What is wrong with the stored sequence ``name`` (missing, interrupted, or any of its files
        damaged: every chunk is read), or None when it reads back as written."""
        if not isinstance(name, str) or not self._entry_dir("sequences", name).is_dir():
            return f"no sequence named {name!r}"
        return self._entry_problem("sequences", name, verify=True)

    def repair(self) -> dict[str, str]:
        """Drop every damaged entry and later-stage group (see the module docstring); returns what
        was dropped, by path relative to the store, with the reason. Needs mode ``"a"``."""
        self._check_writable()
        found = self.problems(verify=True)
        dropped: dict[str, str] = {}
        bad_inputs = set()
        for rel, problem in found.items():
            parts = rel.split("/")
            if parts[0] == staging.STAGING:
                continue  # a write still running (writers on other machines cannot be checked)
            if parts[0] in COLLECTIONS and len(parts) == 2:
                dropped[rel] = problem
                if parts[0] != "sequences":
                    bad_inputs.add((SINGULAR[parts[0]], parts[1]))
            else:
                dropped.setdefault(_stage_unit(rel), f"{rel}: {problem}")
        for name, attrs in self._entries("sequences").items():
            for key in ("garment", "body", "motion"):
                if (key, attrs[key]) in bad_inputs:
                    dropped.setdefault(f"sequences/{name}", f"made from the damaged {key} {attrs[key]!r}")
        for rel in dropped:
            if (self._root / rel).exists():
                staging.remove(self._root, rel)
        return dropped
