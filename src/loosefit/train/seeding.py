"""Random number generators for reproducible training: seeding, per-epoch shuffling, saved states.

Every generator the trainer or a model may draw from (torch CPU and CUDA, numpy's global one, Python's
``random``) is seeded at the start of a run and its state is stored in each checkpoint, so a resumed
run draws the same numbers as an uninterrupted one. The shuffling order of an epoch depends only on
``(seed, stage index, epoch)``.
"""

from __future__ import annotations

import random
from typing import Any

import numpy as np
import torch


def seed_everything(seed: int) -> None:
    """Seed torch (CPU and every CUDA device), numpy's global generator and Python's ``random``."""
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)  # also seeds every CUDA device


def derived_seed(*keys: int) -> int:
    """A 63-bit seed mixed from integers (e.g. run seed, stage index, epoch): different keys give
    unrelated streams."""
    return int(np.random.SeedSequence([int(k) % 2**63 for k in keys]).generate_state(2, np.uint64)[0] >> np.uint64(1))


def epoch_generator(seed: int, stage_index: int, epoch: int) -> torch.Generator:
    """The CPU generator that shuffles epoch ``epoch`` (1-based) of stage ``stage_index``."""
    return torch.Generator().manual_seed(derived_seed(seed, stage_index, epoch))


def rng_state() -> dict[str, Any]:
    """The state of every global generator, as tensors and plain Python values (safe to
    ``torch.load`` with ``weights_only=True``)."""
    name, keys, pos, has_gauss, cached = np.random.get_state()
    state: dict[str, Any] = {
        "torch": torch.get_rng_state(),
        "numpy": {
            "name": str(name),
            "keys": torch.from_numpy(keys.astype(np.int64)),
            "pos": int(pos),
            "has_gauss": int(has_gauss),
            "cached_gaussian": float(cached),
        },
        "python": random.getstate(),
    }
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: dict[str, Any]) -> None:
    """Restore the generators saved by :func:`rng_state` (CUDA ones only when both sides have CUDA)."""
    torch.set_rng_state(state["torch"])
    np_state = state["numpy"]
    np.random.set_state(
        (
            np_state["name"],
            np_state["keys"].numpy().astype(np.uint32),
            np_state["pos"],
            np_state["has_gauss"],
            np_state["cached_gaussian"],
        )
    )
    python = state["python"]
    random.setstate((python[0], tuple(python[1]), python[2]))
    if "cuda" in state and torch.cuda.is_available() and len(state["cuda"]) == torch.cuda.device_count():
        torch.cuda.set_rng_state_all(state["cuda"])
