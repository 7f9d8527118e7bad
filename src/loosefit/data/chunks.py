"""Reading a store's Zarr arrays safely: metadata checks, chunk checksums, errors that name the file.

Every array a store reads is checked before Zarr touches it: its ``.zarray`` must be plain
(a numeric or string dtype, no object dtype; only the numeric codecs of :data:`SAFE_CODECS`), so a
Pickle, MsgPack or JSON codec is refused and no pickle is ever decoded. Chunks are read through
:class:`CheckedArray`, which turns a missing chunk file, a chunk whose CRC-32 differs from the one
recorded when it was written, or a chunk that does not decode (a truncated or damaged Blosc
frame) into an :class:`~loosefit.errors.InputError` naming the chunk file. Checksums are the CRC-32
of each file's bytes, computed when the write is committed (:func:`file_checksums`); arrays written
before checksums existed are verified by decoding every chunk instead.
"""

from __future__ import annotations

import itertools
import math
import os
import zlib
from pathlib import Path

import numcodecs
import numpy as np
import zarr
from zarr.storage import DirectoryStore

from loosefit.errors import InputError
from loosefit.data.layout import read_json

#: Codec ids a store may use: compressors and numeric filters whose decoding runs no user code.
SAFE_CODECS = frozenset({
    "blosc", "zstd", "lz4", "zlib", "gzip", "bz2", "lzma",
    "delta", "fixedscaleoffset", "quantize", "packbits", "astype", "shuffle", "bitround",
})
_SAFE_DTYPE_KINDS = "biufcSUmM"
# Zarr 2 metadata files inside an array directory; everything else there is a chunk.
_META_FILES = (".zarray", ".zattrs")
REPAIR_HINT = "`loosefit info DATA.zarr --repair` drops it"


def crc32_file(path: str | Path) -> int:
    with open(path, "rb") as f:
        return zlib.crc32(f.read())


def file_checksums(directory: Path, arrays: tuple[str, ...] | None = None) -> dict[str, int]:
    """CRC-32 of every file of the Zarr arrays in ``directory`` (``{"verts/0.0.0": crc, ...}``):
    of the named sub-directories ``arrays``, or of ``directory`` itself as one array when None
    (keys are then file names). Array ``.zattrs`` files are not covered (they may hold the sums)."""
    out = {}
    for array in arrays if arrays is not None else ("",):
        folder = directory / array if array else directory
        for name in sorted(os.listdir(folder)):
            if name != ".zattrs" and (folder / name).is_file():
                out[f"{array}/{name}" if array else name] = crc32_file(folder / name)
    return out


def _codec_problem(spec, role: str) -> str | None:
    if spec is None:
        return None
    codec_id = spec.get("id") if isinstance(spec, dict) else None
    if codec_id not in SAFE_CODECS:
        return (f"its {role} {codec_id!r} is not one a loosefit store uses (allowed: numeric codecs); "
                "it is not decoded (a pickle or object codec could run code)")
    try:
        numcodecs.get_codec(dict(spec))
    except Exception as e:  # any bad configuration of an allowed codec
        return f"its {role} {codec_id!r} has a bad configuration ({e})"
    return None


def meta_problem(meta: dict | None) -> str | None:
    """What is wrong with the ``.zarray`` metadata ``meta`` (None: missing or not JSON), or None."""
    if meta is None:
        return "no readable .zarray (missing or not JSON)"
    try:
        shape, chunks = [int(s) for s in meta["shape"]], [int(c) for c in meta["chunks"]]
        if len(shape) != len(chunks) or min(chunks, default=1) < 1 or min(shape, default=0) < 0:
            raise ValueError
        dtype = meta["dtype"]
        if meta.get("zarr_format") != 2 or meta.get("order", "C") not in ("C", "F"):
            raise ValueError
    except (KeyError, TypeError, ValueError):
        return ".zarray metadata is malformed (shape, chunks, dtype, order or zarr_format)"
    if meta.get("dimension_separator", ".") != ".":
        return f".zarray uses dimension separator {meta['dimension_separator']!r}; loosefit stores use '.'"
    if not isinstance(dtype, str):
        return f"its dtype {dtype!r} is structured; loosefit stores numeric arrays only"
    try:
        kind = np.dtype(dtype).kind
    except TypeError:
        return f"its dtype {dtype!r} is not a NumPy dtype"
    if kind not in _SAFE_DTYPE_KINDS:
        return f"its dtype {dtype!r} is an object dtype; loosefit stores numeric arrays only and never decodes objects"
    filters = meta.get("filters") or []
    if not isinstance(filters, list):
        return ".zarray filters are malformed"
    for problem in [_codec_problem(meta.get("compressor"), "compressor")] + [_codec_problem(f, "filter") for f in filters]:
        if problem:
            return problem
    return None


def chunk_keys(meta: dict) -> list[str]:
    """The chunk file names of a (valid) array: ``"0.1.0"``...; a 0-d array has the one chunk ``"0"``."""
    grid = [range(math.ceil(s / c)) for s, c in zip(meta["shape"], meta["chunks"])]
    if not grid:
        return ["0"]
    return [".".join(map(str, idx)) for idx in itertools.product(*grid)]


def array_problem(path: Path, checksums: dict[str, int] | None = None, deep: bool = False) -> tuple[Path, str] | None:
    """The first problem of the Zarr array directory ``path`` as ``(file, problem)``, or None.

    Checks the metadata and that every chunk file is there; with ``deep`` also reads every file:
    those with a checksum in ``checksums`` (keys as in the array directory: ``"0.0.0"``) are compared
    with it, the others are decoded (a truncated or damaged chunk does not decode).
    """
    if not path.is_dir():
        return path, "array is missing"
    meta = read_json(path / ".zarray")
    problem = meta_problem(meta)
    if problem:
        return path / ".zarray", problem
    keys = chunk_keys(meta)
    present = set(os.listdir(path))
    missing = [k for k in keys if k not in present]
    if missing:
        return path / missing[0], f"chunk file is missing ({len(keys) - len(missing)} of the array's {len(keys)} are there)"
    if not deep:
        return None
    checksums = checksums or {}
    for key in (".zarray", *keys):
        if key in checksums and crc32_file(path / key) != checksums[key]:
            return path / key, "checksum mismatch: the file changed after it was written (corrupt)"
    unchecked = [k for k in keys if k not in checksums]
    if unchecked:
        array = open_checked(path, checksums, hint="")
        for key in unchecked:
            try:
                array.decode_chunk_file(key)
            except InputError as e:
                return path / key, e.problem
    return None


class VerifyingStore(DirectoryStore):
    """A read-only Zarr directory store of one array that compares each file it reads with its
    checksum and refuses missing chunks (instead of filling them with the fill value)."""

    def __init__(self, path: Path, checksums: dict[str, int], hint: str = REPAIR_HINT):
        super().__init__(str(path))
        self.checksums = checksums
        self.hint = f"; {hint}" if hint else ""  # what to do about a damaged file, appended to errors

    def _fromfile(self, fn):
        data = super()._fromfile(fn)
        key = os.path.relpath(fn, self.path).replace(os.sep, "/")
        expected = self.checksums.get(key)
        if expected is not None and zlib.crc32(data) != expected:
            raise InputError("checksum mismatch: the file changed after it was written (corrupt)" + self.hint, fn)
        return data

    def getitems(self, keys, *, contexts):
        out = {}
        for key in keys:
            try:
                out[key] = self[key]
            except KeyError:
                raise InputError("chunk file is missing (corrupt)" + self.hint, Path(self.path) / key) from None
        return out

    def __setitem__(self, key, value):
        raise InputError("a store array opened for reading cannot be written", Path(self.path) / key)


class CheckedArray(zarr.Array):
    """A read-only :class:`zarr.Array` whose chunk reads raise :class:`InputError` naming the chunk
    file (missing, checksum mismatch, or not decodable) instead of a codec's exception."""

    def _chunk_getitems(self, lchunk_coords, lchunk_selection, out, lout_selection, drop_axes=None, fields=None):
        try:
            return super()._chunk_getitems(lchunk_coords, lchunk_selection, out, lout_selection, drop_axes, fields)
        except InputError:
            raise
        except Exception as e:  # a codec's error on a damaged chunk: find which chunk it was
            for coords in lchunk_coords:
                self.decode_chunk_file(self._chunk_key(coords))
            raise InputError(f"chunk cannot be decoded ({type(e).__name__}: {e}) (corrupt)" + self.chunk_store.hint,
                             Path(self.chunk_store.path)) from e

    def decode_chunk_file(self, key: str) -> None:
        """Read and decode chunk ``key`` (a file name), raising :class:`InputError` naming it when it
        is missing, differs from its checksum, or does not decode to a whole chunk."""
        data = self.chunk_store.getitems([key], contexts={})[key]
        try:
            chunk = self._decode_chunk(data)
        except Exception as e:
            raise InputError(f"chunk cannot be decoded ({type(e).__name__}: {e}) (corrupt)" + self.chunk_store.hint,
                             Path(self.chunk_store.path) / key) from e
        if chunk.size != math.prod(self.chunks):
            raise InputError(f"chunk decodes to {chunk.size} values, expected {math.prod(self.chunks)} (corrupt)"
                             + self.chunk_store.hint, Path(self.chunk_store.path) / key)


def open_checked(path: Path, checksums: dict[str, int] | None = None, hint: str = REPAIR_HINT) -> CheckedArray:
    """The array at ``path`` for reading through :class:`CheckedArray`; its metadata and chunk files
    are checked first (:func:`array_problem`, not deep). ``hint``: what to do about damage, for errors."""
    problem = array_problem(path)
    if problem:
        raise InputError(f"{problem[1]}; {hint}" if hint else problem[1], problem[0])
    return CheckedArray(VerifyingStore(path, dict(checksums or {}), hint), read_only=True)
