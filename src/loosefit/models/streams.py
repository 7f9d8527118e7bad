"""Stateful truncated back-propagation through time: the recurrent state carried across the consecutive
windows of each training sequence, as inference carries it over a whole motion.

:class:`WindowDataset` trains every window from a zero state (after a burn-in), so a recurrent model
never sees more than one window of history: a spin bout of 2.5 s (75 frames) that winds a skirt up
lasts longer than the 64-frame windows. Here instead:

- :class:`StreamWindows` cuts each sequence into consecutive windows of ``window`` frames (frame 0, ``window``,
  ``2 window``...; no overlap, no burn-in; the last, shorter window is padded with its last frame and its
  padded frames carry no loss);
- its :meth:`StreamWindows.batch_sampler` deals the sequences (shuffled each epoch) to ``batch_size``
  lanes and steps every lane one window per batch, so that the windows of a sequence are trained in order;
- the model keeps the final recurrent state of each window in a :class:`StateCarry` (detached: the
  gradient stops at the window boundary) and starts the sequence's next window from it; a window at
  frame 0 starts from the zero state, as inference does.

Carrying the state over the consecutive windows of a sequence gives exactly the whole-sequence forward pass
(up to float round-off; tests/models/test_streams.py), so validation over these windows measures what
animation does.

Item and batch keys as :class:`loosefit.models.dataset.WindowDataset`'s, plus ``frames`` (real frames of the
window, the rest padding), ``last`` (whether it ends its sequence) and ``name`` (the sequence's store name).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch.utils.data import Dataset

from loosefit.errors import InputError
from loosefit.models.config import WindowConfig
from loosefit.models.dataset import GarmentSequences, WindowDataset, window_arrays
from loosefit.train.losses import frame_mask

@dataclass(frozen=True)
class MemoryWindowConfig(WindowConfig):
    """:class:`WindowConfig` plus how the recurrent state starts each window.

    Attributes:
        carry_state: ``False``: every window starts from the zero state and its first ``burn_in`` frames
            only warm it up (:class:`WindowDataset`, windows every ``stride`` frames). ``True``: stateful
            truncated back-propagation through time (:class:`StreamWindows`): consecutive windows of
            ``window`` frames, each starting from the state the previous window of its sequence ended in,
            so the memory reaches back to the sequence's start; ``stride`` and ``burn_in`` are not used.
        mirror: train on the left-right mirror of every training sequence too (``GarmentSequences``' ``mirror``;
            the store prepared with the setting ``mirror``). Never validation or test sequences.
    """

    carry_state: bool = False
    mirror: bool = False

    def __post_init__(self):
        if not self.carry_state:
            super().__post_init__()
        elif self.window < 1:
            raise InputError(f"window must be >= 1, got {self.window}")

    def dataset(self, data: GarmentSequences) -> Dataset:
        """The training (or validation) windows of ``data`` with these settings."""
        if self.carry_state:
            return StreamWindows(data, self.window)
        return WindowDataset(data, self.window, self.stride, self.burn_in)


class StreamWindows(Dataset):
    """Consecutive windows of ``window`` frames of every sequence, for stateful training (module doc).

    Items are padded to ``min(window, longest sequence)`` frames, so every item has the same length.
    """

    def __init__(self, data: GarmentSequences, window: int):
        if window < 1:
            raise InputError(f"window must be >= 1, got {window}")
        self.data, self.window = data, window
        self.length = min(window, max(s.num_frames for s in data.sequences))
        #: (sequence index, start frame) of every window, sequence by sequence, in time order
        self.index = [(i, a) for i, s in enumerate(data.sequences) for a in range(0, s.num_frames, window)]
        self.windows_of: list[list[int]] = [[] for _ in data.sequences]
        for k, (i, _) in enumerate(self.index):
            self.windows_of[i].append(k)

    def __len__(self) -> int:
        return len(self.index)

    def __getitem__(self, k: int) -> dict:
        i, a = self.index[k]
        s = self.data.sequences[i]
        b = min(a + self.window, s.num_frames)
        pad = self.length - (b - a)
        # the padding repeats the last frame: finite inputs, no loss (see window_mask)
        return {"sequence": i, "start": a, "burn_in": 0, "frames": b - a, "last": b == s.num_frames, "name": s.name,
                **window_arrays(s, a, b, pad)}

    def batch_sampler(self, batch_size: int, generator: torch.Generator | None, shuffle: bool) -> list[list[int]]:
        """Batches of item indices: the sequences (in an order drawn from ``generator`` when ``shuffle``)
        dealt to ``min(batch_size, sequences)`` lanes, each to the lane with the fewest frames so far; each
        batch holds the next window of every lane that has one left, so every sequence's windows come in
        order, one per batch."""
        order = list(range(len(self.windows_of)))
        if shuffle:
            order = torch.randperm(len(order), generator=generator).tolist()
        lanes: list[list[int]] = [[] for _ in range(min(batch_size, len(order)))]
        frames = [0] * len(lanes)
        for i in order:
            lane = int(np.argmin(frames))
            lanes[lane] += self.windows_of[i]
            frames[lane] += self.data.sequences[i].num_frames
        steps = max(len(lane) for lane in lanes)
        return [[lane[t] for lane in lanes if t < len(lane)] for t in range(steps)]


def window_mask(batch: dict) -> torch.Tensor:
    """``(B, T)`` frames that count in losses and metrics: not in the burn-in and, for a padded window
    (key ``frames``), among its real frames."""
    T = batch["verts"].shape[1]
    mask = frame_mask(batch["burn_in"], T)
    if "frames" in batch:
        t = torch.arange(T, device=mask.device)
        mask = mask * (t[None] < batch["frames"][:, None]).to(mask.dtype)
    return mask


def _rows(state: Any, dim: int, index: int) -> Any:
    if state is None:
        return None
    if isinstance(state, (tuple, list)):
        return tuple(_rows(s, dim, index) for s in state)
    return state.select(dim, index).detach()


def _stack(rows: list[Any], dim: int) -> Any:
    first = rows[0]
    if isinstance(first, tuple):
        return tuple(_stack([r[k] for r in rows], dim) for k in range(len(first)))
    if any(r is None for r in rows):
        return None
    return torch.stack(rows, dim)


def _zeros_like(state: Any) -> Any:
    if state is None:
        return None
    if isinstance(state, tuple):
        return tuple(_zeros_like(s) for s in state)
    return torch.zeros_like(state)


class StateCarry:
    """The recurrent states at the ends of training windows, waiting for the next window of their sequence.

    ``state_dim``: the batch dimension of the model's state tensors (1 for ``torch.nn.GRU``'s ``(layers, N, H)``,
    0 for JointNet's ``(N, J_s, H)``); a state may be a (nested) tuple of tensors and ``None``.
    """

    def __init__(self, state_dim: int):
        self.state_dim = state_dim
        self.saved: dict[tuple[str, int], Any] = {}

    def initial(self, batch: dict) -> Any:
        """The state the windows of ``batch`` start from: ``None`` (zeros) when every window starts at frame 0
        or the batch is not of :class:`StreamWindows`; otherwise the saved state of each window's sequence at
        its start frame (zeros for a window at frame 0).

        Raises:
            RuntimeError: a window does not follow the last one saved for its sequence (batches out of order).
        """
        if "frames" not in batch or not bool((batch["start"] > 0).any()):
            return None
        rows, template = [], None
        for name, start in zip(batch["name"], batch["start"].tolist()):
            if start == 0:
                rows.append(None)
                continue
            key = (name, start)
            if key not in self.saved:
                raise RuntimeError(f"no carried state for {name!r} at frame {start}: the windows of a sequence "
                                   "must come in order (StreamWindows.batch_sampler)")
            rows.append(self.saved.pop(key))
            template = rows[-1]
        rows = [_zeros_like(template) if r is None else r for r in rows]
        device = batch["root"].device
        return _to(_stack(rows, self.state_dim), device)

    def keep(self, batch: dict, state: Any) -> None:
        """Save the final ``state`` of each window of ``batch`` that its sequence continues (not the last)."""
        if "frames" not in batch:
            return
        for n, (name, start, frames, last) in enumerate(zip(batch["name"], batch["start"].tolist(),
                                                            batch["frames"].tolist(), batch["last"].tolist())):
            if not last:
                self.saved[(name, start + frames)] = _rows(state, self.state_dim, n)

    def clear(self) -> None:
        self.saved.clear()


def _to(state: Any, device: torch.device) -> Any:
    if state is None:
        return None
    if isinstance(state, tuple):
        return tuple(_to(s, device) for s in state)
    return state.to(device)
