"""PyTorch access to a dataset store: windows of consecutive frames for recurrent models."""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

import numpy as np
import torch
import zarr
from torch.utils.data import Dataset

from loosefit.data.store import DatasetStore
from loosefit.errors import InputError

MOTION_FIELDS = ("rotations", "translation")


class FrameWindows(Dataset):
    """Windows of ``window`` consecutive frames from dataset sequences, starting every ``stride`` frames.

    Sequence frame ``i`` is frame ``i`` of the sequence's motion, so a window's garment vertices and
    motion frames cover the same instants. Item ``k`` is a dict:

    - ``"verts"``: ``(window, V, 3)`` float32 garment vertices, metres;
    - ``"rotations"``: ``(window, J, 3)`` float32 axis-angle joint rotations of the same frames;
    - ``"translation"``: ``(window, 3)`` float32 root positions, metres;
    - any extra per-frame array of the sequences named in ``fields``: ``(window, ...)``;
    - ``"name"``, ``"garment"``, ``"body"``: names of the sequence and of its garment and body entries;
    - ``"start"``: index of the window's first frame.

    Only the requested fields are read, and only the Zarr chunks a window touches; arrays are opened
    once per DataLoader worker (nothing is opened in the constructor's process until an item is read
    there). Sequences shorter than ``window`` contribute nothing. Windows from different garments have
    different ``V``: batch them with :func:`collate_windows`, which says so clearly.

    Args:
        store: a :class:`DatasetStore` or its path.
        names: sequence names, e.g. ``store.sequence_names(split="train")``; each must have status ``"ok"``.
        window: frames per window (>= 1). stride: frames between window starts (>= 1).
        fields: what to read, among ``"verts"``, ``"rotations"``, ``"translation"`` and extra array names.
    """

    def __init__(
        self,
        store: DatasetStore | str | Path,
        names: Iterable[str],
        window: int,
        stride: int = 1,
        fields: Iterable[str] = ("verts", "rotations", "translation"),
    ):
        if not isinstance(store, DatasetStore):
            store = DatasetStore.open(store, mode="r")
        self.names = list(names)
        self.window = int(window)
        self.stride = int(stride)
        self.fields = tuple(fields)
        if self.window < 1 or self.stride < 1:
            raise InputError(f"window and stride must be >= 1, got window={window}, stride={stride}", store.path)
        if not self.names:
            raise InputError("no sequences given for frame windows", store.path)
        if not self.fields:
            raise InputError("no fields requested for frame windows", store.path)
        self.garments: list[str] = []
        self.bodies: list[str] = []
        self._paths: list[dict[str, Path]] = []  # per sequence: field -> Zarr array directory
        starts = []
        for index, name in enumerate(self.names):
            seq = store.sequence(name)
            if seq.status != "ok":
                raise InputError(
                    f"sequence {name!r} has status {seq.status!r} ({seq.reason}); only 'ok' ones make windows", seq.path
                )
            motion_dir = store.path / "motions" / seq.motion
            paths = {}
            for field in self.fields:
                if field in MOTION_FIELDS:
                    paths[field] = motion_dir / field
                elif field == "verts":
                    paths[field] = seq.path / "verts"
                elif field in seq.extra and seq.extra[field].ndim >= 1 and seq.extra[field].shape[0] == seq.num_frames:
                    paths[field] = seq.path / field
                else:
                    raise InputError(
                        f"sequence {name!r} has no per-frame array {field!r} "
                        f"(it has verts and {sorted(seq.extra) or 'no extras'})",
                        seq.path,
                    )
            if any(f in MOTION_FIELDS for f in self.fields) and store.motion_num_frames(seq.motion) < seq.num_frames:
                raise InputError(f"sequence {name!r} has more frames than its motion {seq.motion!r}", seq.path)
            self.garments.append(seq.garment)
            self.bodies.append(seq.body)
            self._paths.append(paths)
            first = np.arange(0, seq.num_frames - self.window + 1, self.stride, dtype=np.int64)
            starts.append(np.stack([np.full_like(first, index), first], axis=1))
        self._index = np.concatenate(starts)
        if len(self._index) == 0:
            raise InputError(f"no sequence has {self.window} frames: no windows", store.path)
        self._open: dict[tuple[int, str], zarr.Array] = {}

    def __len__(self) -> int:
        return len(self._index)

    def __getstate__(self) -> dict:
        # Each worker opens its own arrays.
        state = self.__dict__.copy()
        state["_open"] = {}
        return state

    def _array(self, index: int, field: str) -> zarr.Array:
        key = (index, field)
        if key not in self._open:
            self._open[key] = zarr.open_array(str(self._paths[index][field]), mode="r")
        return self._open[key]

    def __getitem__(self, k: int) -> dict:
        if not -len(self) <= k < len(self):
            raise IndexError(f"window {k} out of range for {len(self)} windows")
        index, start = (int(v) for v in self._index[k])
        stop = start + self.window
        item = {"name": self.names[index], "garment": self.garments[index], "body": self.bodies[index], "start": start}
        for field in self.fields:
            try:
                values = self._array(index, field)[start:stop]
            except (RuntimeError, ValueError, OSError, KeyError) as e:
                raise InputError(
                    f"sequence {self.names[index]!r}: cannot read frames {start}-{stop - 1} of {field!r}: {e}",
                    self._paths[index][field],
                ) from None
            item[field] = torch.from_numpy(np.ascontiguousarray(values))
        return item


def collate_windows(batch: list[dict]) -> dict:
    """Stack :class:`FrameWindows` items into a batch: tensors get a leading batch axis, ``"start"``
    becomes an int64 tensor, names stay lists. Use it as a DataLoader's ``collate_fn``.

    Raises:
        InputError: the items' arrays differ in shape (windows of garments with different vertex counts).
    """
    out = {key: [b[key] for b in batch] for key in ("name", "garment", "body")}
    out["start"] = torch.tensor([b["start"] for b in batch], dtype=torch.int64)
    for field in batch[0]:
        if field in out:
            continue
        shapes = {tuple(b[field].shape) for b in batch}
        if len(shapes) > 1:
            raise InputError(
                f"cannot batch {field!r} of shapes {sorted(shapes)} (garments {sorted(set(out['garment']))}): "
                "batch windows of one garment together, or use batch_size=1"
            )
        out[field] = torch.stack([b[field] for b in batch])
    return out
