"""torch's CPU thread count, set for a block of work and restored after it.

With torch's default thread count, the scatter operations of graph layers run far slower than with one
thread on small CPU machines (see the design notes), so training, animation and the ensemble set the
count deliberately through this one context manager.
"""

from __future__ import annotations

import contextlib
from typing import Iterator

import torch


@contextlib.contextmanager
def torch_threads(count: int | None) -> Iterator[None]:
    """Run the block with ``count`` torch CPU threads (None or 0: leave the setting as it is), then
    restore the previous setting, also when the block raises."""
    before = torch.get_num_threads()
    if count:
        torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(before)
