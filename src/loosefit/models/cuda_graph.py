"""CUDA graphs for the streaming step of a model: capture once per input shape, replay every frame.

A streaming frame of SwinGar or FitGar launches hundreds of small kernels; on a GPU the frame is then bound by
the host that launches them, not by the device. A :class:`torch.cuda.CUDAGraph` records the kernels of one call
once and replays them with a single launch. What it needs from the step:

- static memory: the inputs are copied into buffers the graph reads (:attr:`CapturedStep.inputs`), and the
  outputs come back in buffers the graph writes, overwritten by the next replay (the callers clone what they
  keep);
- fixed shapes and no host synchronisation inside the step (no ``.item()``, ``.cpu()``, ``nonzero`` or boolean
  indexing): every step captured here is written that way (:mod:`loosefit.models.layers.gat_ln`,
  :mod:`loosefit.models.fitgar_stream`).

:class:`CapturedStep` follows PyTorch's recipe: a few warm-up calls on a side stream (which also let cuDNN and
cuBLAS pick their algorithms and allocate their workspaces), then the capture; a failed capture is tried once more
with cuDNN off (its RNN kernels are the likeliest to refuse). Any failure of both (an operation that cannot be
captured, a driver without graph support) leaves the step to be run eagerly: one warning line, and the caller
goes on without the graph (:func:`capture_or_none`).
"""

from __future__ import annotations

import warnings
from typing import Callable, Sequence

import torch

#: Eager calls on a side stream before the capture.
WARMUP_CALLS = 3


class CapturedStep:
    """``fn(*inputs)`` captured in a CUDA graph.

    Args:
        fn: the step; takes tensors (fixed shapes, on one CUDA device) and returns a tensor or a dict, list or
            tuple of them. It may write into its input tensors (a recurrent state updated in place).
        example: tensors of the shapes, dtypes and device of every later call; copied into the static inputs.

    ``step(*inputs)`` copies ``inputs`` into the static inputs (skipping a tensor that is the static input
    itself), replays the graph and returns the static outputs (overwritten by the next call).

    Raises whatever capturing raises; :func:`capture_or_none` turns that into a warning.
    """

    def __init__(self, fn: Callable, example: Sequence[torch.Tensor], warmup: int = WARMUP_CALLS):
        if not example or any(not isinstance(t, torch.Tensor) or t.device.type != "cuda" for t in example):
            raise ValueError("a CUDA graph step takes CUDA tensors")
        self.inputs = [t.detach().clone() for t in example]
        self.shapes = [(t.shape, t.dtype, t.device) for t in self.inputs]
        with torch.no_grad():
            side = torch.cuda.Stream(self.inputs[0].device)
            side.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(side):
                for _ in range(warmup):
                    fn(*self.inputs)
            torch.cuda.current_stream().wait_stream(side)
            self.graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(self.graph):
                self.outputs = fn(*self.inputs)
        # the warm-up calls and the capture may have written into the inputs: refilled on every call
        self.fresh = False

    def matches(self, inputs: Sequence[torch.Tensor]) -> bool:
        """Whether ``inputs`` have the captured shapes, dtypes and device."""
        return len(inputs) == len(self.shapes) and all(
            (t.shape, t.dtype, t.device) == s for t, s in zip(inputs, self.shapes))

    def __call__(self, *inputs: torch.Tensor):
        for static, given in zip(self.inputs, inputs):
            if given is not static:
                static.copy_(given)
        self.graph.replay()
        return self.outputs


def capture_or_none(fn: Callable, example: Sequence[torch.Tensor], what: str) -> CapturedStep | None:
    """:class:`CapturedStep` of ``fn``, or None (after one warning line naming ``what`` and the reason) when
    the capture fails: the caller then runs ``fn`` eagerly."""
    reason = ""
    cudnn = torch.backends.cudnn
    for use_cudnn in (True, False):  # cuDNN's RNN kernels may refuse capture; torch's own LSTM kernels do not
        try:
            if use_cudnn:
                return CapturedStep(fn, example)
            with cudnn.flags(enabled=False, benchmark=cudnn.benchmark, deterministic=cudnn.deterministic,
                             allow_tf32=cudnn.allow_tf32):
                return CapturedStep(fn, example)
        except Exception as exc:  # any failure of capture falls back to eager execution, never to a crash
            try:
                torch.cuda.synchronize()
            except Exception:
                pass
            reason = reason or (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    warnings.warn(f"{what}: CUDA graph capture failed ({reason}); running eagerly", RuntimeWarning, stacklevel=3)
    return None


def graphs_enabled(device: torch.device | str) -> bool:
    """Whether steps on ``device`` are captured: a CUDA device, with autograd off (graphs are for inference)."""
    return torch.device(device).type == "cuda" and not torch.is_grad_enabled()


def clone_outputs(value):
    """A copy of a captured step's outputs (tensors cloned, containers rebuilt) that the next replay leaves alone."""
    if isinstance(value, torch.Tensor):
        return value.clone()
    if isinstance(value, dict):
        return {k: clone_outputs(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(clone_outputs(v) for v in value)
    return value
