"""Where a model runs: ``"cpu"``, ``"cuda"`` or ``"auto"`` (CUDA when available) as a torch device.

One rule for training, animation and the benchmarks: asking for CUDA on a machine without it is an
:class:`~loosefit.errors.InputError`, never a silent fall-back to the CPU.
"""

from __future__ import annotations

import torch

from loosefit.errors import InputError

DEVICES = ("cpu", "cuda", "auto")


def resolve_device(name: str, index: int = 0) -> torch.device:
    """The torch device for ``name`` (``cuda:index`` for CUDA, e.g. a process's local rank).

    Raises:
        InputError: an unknown name, CUDA asked for but unavailable, or no GPU ``index``.
    """
    if name not in DEVICES:
        raise InputError(f"device must be one of {list(DEVICES)}, got {name!r}")
    if name == "cuda" and not torch.cuda.is_available():
        raise InputError("device 'cuda' was asked for but CUDA is not available (use 'cpu' or 'auto')")
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cpu":
        return torch.device("cpu")
    if index >= torch.cuda.device_count():
        raise InputError(f"GPU {index} was asked for; this machine has {torch.cuda.device_count()}")
    return torch.device("cuda", index)
