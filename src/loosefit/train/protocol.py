"""The contract between a model and the trainer, and the defaults for its optional parts.

A trainable model is a ``torch.nn.Module`` with the two required methods of :class:`TrainableModel`
and any of these optional ones:

- ``stages() -> list[str]``: the training stages in order (e.g. ``["low", "high"]`` for
  VirtualBones, ``["stage1", "stage2"]`` for JointNet); default ``["all"]``.
- ``stage_parameters(stage) -> Iterable[nn.Parameter]``: the parameters optimised in ``stage`` (the
  others stay unchanged during it); default all of ``model.parameters()``.
- ``collate(samples: list) -> batch``: how the DataLoader batches dataset items; default
  ``torch.utils.data.default_collate``.
- ``batch_size(batch) -> int``: how many samples a batch holds, used to weight per-batch averages;
  default :func:`batch_size` below.
- ``loss_weight(batch) -> float``: the normaliser of the loss's mean (e.g. the number of counted
  frames of a masked mean); in distributed training each process's loss is weighted by its share
  of the global sum, so that the step equals one process's on the whole global batch. Without it
  every process weighs the same (exact for a mean over equally many samples per process).

Batches are whatever the collate function returns; the trainer moves every tensor in them (inside
dicts, lists, tuples, or objects with a ``.to(device)`` method) to the training device before calling
the model. The trainer calls ``model.train()`` before training steps and ``model.eval()`` with
``torch.no_grad()`` before validation.
"""

from __future__ import annotations

from typing import Any, Callable, Mapping, Protocol, runtime_checkable

import torch
from torch.utils.data import default_collate

DEFAULT_STAGE = "all"


@runtime_checkable
class TrainableModel(Protocol):
    """What :func:`loosefit.train.trainer.train` needs from a model (an ``nn.Module``)."""

    def training_loss(self, batch: Any, stage: str) -> tuple[torch.Tensor, dict[str, float]]:
        """The scalar loss to minimise on ``batch`` in ``stage`` (differentiable), and its named terms
        as floats for the logs (e.g. ``{"l2": 0.01, "collision": 0.002}``); the trainer logs the loss
        itself as ``"loss"``."""
        ...

    def validation_metrics(self, batch: Any, stage: str) -> dict[str, float]:
        """Metrics of ``batch`` averaged over its samples (e.g. ``{"rmse_mm": 12.3}``); the trainer
        averages them over the validation set weighted by batch size."""
        ...


def model_stages(model: Any) -> list[str]:
    """``model.stages()`` if defined, else ``["all"]``."""
    stages = list(model.stages()) if hasattr(model, "stages") else [DEFAULT_STAGE]
    if not stages or len(set(stages)) != len(stages) or not all(isinstance(s, str) and s for s in stages):
        raise ValueError(f"model.stages() must return distinct non-empty names, got {stages}")
    return stages


def stage_parameters(model: Any, stage: str) -> list[torch.nn.Parameter]:
    """The trainable parameters of ``stage`` (``model.stage_parameters`` or all), duplicates removed."""
    params = model.stage_parameters(stage) if hasattr(model, "stage_parameters") else model.parameters()
    unique: dict[int, torch.nn.Parameter] = {}
    for p in params:
        if p.requires_grad:
            unique.setdefault(id(p), p)
    return list(unique.values())


def collate_fn(model: Any) -> Callable[[list], Any]:
    """``model.collate`` if defined, else torch's default collate."""
    return model.collate if hasattr(model, "collate") else default_collate


def batch_size(model: Any, batch: Any) -> int:
    """Samples in ``batch``: ``model.batch_size(batch)`` if defined; else the first dimension of a
    tensor, of a mapping's first tensor value, or of a sequence's first element when that is a tensor;
    else the length of a sequence."""
    if hasattr(model, "batch_size"):
        return int(model.batch_size(batch))
    if isinstance(batch, torch.Tensor):
        return int(batch.shape[0])
    if isinstance(batch, Mapping):
        for value in batch.values():
            if isinstance(value, torch.Tensor) and value.ndim > 0:
                return int(value.shape[0])
    if isinstance(batch, (list, tuple)) and batch:
        first = batch[0]
        return int(first.shape[0]) if isinstance(first, torch.Tensor) and first.ndim > 0 else len(batch)
    raise TypeError(f"cannot tell the size of a {type(batch).__name__} batch: define model.batch_size(batch)")


def to_device(batch: Any, device: torch.device) -> Any:
    """``batch`` with every tensor moved to ``device`` (mappings, returned as dicts, lists and tuples
    walked; objects with a ``.to`` method moved as a whole)."""
    if isinstance(batch, torch.Tensor):
        return batch.to(device, non_blocking=True)
    if isinstance(batch, Mapping):
        return {k: to_device(v, device) for k, v in batch.items()}
    if isinstance(batch, tuple) and hasattr(batch, "_fields"):  # named tuple
        return type(batch)(*(to_device(v, device) for v in batch))
    if isinstance(batch, (list, tuple)):
        return type(batch)(to_device(v, device) for v in batch)
    if callable(getattr(batch, "to", None)):
        return batch.to(device)
    return batch


def parameter_count(model: torch.nn.Module) -> int:
    """Number of scalar parameters of ``model`` (``parameters()`` lists a shared tensor once)."""
    return sum(p.numel() for p in model.parameters())

