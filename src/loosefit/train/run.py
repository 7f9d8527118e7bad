"""The layout of a training run folder, and checkpoint files (atomic writes, validated reads).

::

    RUN/
      config.yaml            the TrainConfig the run was started with
      metrics.csv            one row per epoch per stage
      run.json               summary written when training finishes
      checkpoints/last.pt    state after the last saved epoch (resume from here)
      checkpoints/best.pt    state at the best validation metric of the latest stage (only with validation)
      tensorboard/           TensorBoard event files

A checkpoint is a ``torch.save``d dict: ``model``, ``optimizer``, ``scheduler`` (state dicts; the
last two ``None`` at a stage's start or without a schedule), ``stages`` (names), ``stage_index`` and
``epoch`` (epochs completed in that stage, 1-based count), ``global_step`` (optimiser steps so far),
``best_metric`` (best monitored value of the stage, or ``None``), ``rng`` (generator states,
:func:`loosefit.train.seeding.rng_state`), ``config`` (the TrainConfig as a dict), ``history`` (the
metrics rows so far), ``elapsed_s`` (training seconds so far), ``complete`` (training finished), plus
``format`` and ``version`` tags.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from loosefit.errors import InputError
from loosefit.paths import atomic_path, remove_stale_temporaries

CHECKPOINT_FORMAT = "loosefit-checkpoint"
CHECKPOINT_VERSION = 1

# key -> accepted types of a checkpoint's top-level entries
_REQUIRED: dict[str, tuple[type, ...]] = {
    "format": (str,),
    "version": (int,),
    "model": (dict,),
    "optimizer": (dict, type(None)),
    "scheduler": (dict, type(None)),
    "stages": (list,),
    "stage_index": (int,),
    "epoch": (int,),
    "global_step": (int,),
    "best_metric": (float, type(None)),
    "rng": (dict,),
    "config": (dict,),
    "history": (list,),
    "elapsed_s": (float,),
    "complete": (bool,),
}


class RunDir:
    """Paths inside a run folder (nothing is created until :meth:`create`)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)

    @property
    def config(self) -> Path:
        return self.path / "config.yaml"

    @property
    def metrics_csv(self) -> Path:
        return self.path / "metrics.csv"

    @property
    def summary(self) -> Path:
        return self.path / "run.json"

    @property
    def checkpoints(self) -> Path:
        return self.path / "checkpoints"

    @property
    def last_checkpoint(self) -> Path:
        return self.checkpoints / "last.pt"

    @property
    def best_checkpoint(self) -> Path:
        return self.checkpoints / "best.pt"

    @property
    def tensorboard(self) -> Path:
        return self.path / "tensorboard"

    def create(self) -> "RunDir":
        """Create the folder and its checkpoint folder (at the start of a run and of a resume), and delete
        the temporary files of atomic writes that a killed run left in them (``.last.pt.k2j4x9_a.pt``)."""
        self.checkpoints.mkdir(parents=True, exist_ok=True)
        self.remove_stale_temporaries()
        return self

    def remove_stale_temporaries(self) -> list[Path]:
        """Delete leftover temporary files of :func:`~loosefit.paths.atomic_path` in the run folder and its
        checkpoint folder; call it only while no process of this run writes. Returns the paths removed."""
        return remove_stale_temporaries(self.path) + remove_stale_temporaries(self.checkpoints)

    def has_checkpoint(self) -> bool:
        return self.last_checkpoint.exists()

    def __repr__(self) -> str:
        return f"RunDir({str(self.path)!r})"


def save_checkpoint(path: str | Path, state: dict[str, Any]) -> Path:
    """Write a checkpoint dict (entries in the module docstring) atomically: a crash while writing
    leaves the previous file intact."""
    path = Path(path)
    state = {"format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, **state}
    missing = sorted(set(_REQUIRED) - set(state))
    if missing:
        raise ValueError(f"checkpoint state lacks {missing}")
    with atomic_path(path) as tmp:
        torch.save(state, tmp)
    return path


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read and validate a checkpoint written by :func:`save_checkpoint`; tensors land on the CPU.

    Loading uses ``weights_only=True`` (no arbitrary code from the file).

    Raises:
        InputError: missing, truncated or corrupt file, another format or version, or entries of
            the wrong type; the message names the file.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("checkpoint not found", path)
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # torch raises many types for damaged zip/pickle data
        raise InputError(f"checkpoint is corrupt or truncated ({type(e).__name__}: {e})", path) from None
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise InputError(f"not a loosefit checkpoint (no format tag {CHECKPOINT_FORMAT!r})", path)
    if state.get("version") != CHECKPOINT_VERSION:
        raise InputError(f"checkpoint version {state.get('version')!r}; this loosefit reads {CHECKPOINT_VERSION}", path)
    for key, types in _REQUIRED.items():
        if key not in state:
            raise InputError(f"checkpoint lacks the entry {key!r}", path)
        if not isinstance(state[key], types) or (bool not in types and isinstance(state[key], bool)):
            raise InputError(f"checkpoint entry {key!r} has type {type(state[key]).__name__}", path)
    if not 0 <= state["stage_index"] < len(state["stages"]) or state["epoch"] < 0 or state["global_step"] < 0:
        raise InputError(
            f"checkpoint position is invalid (stage {state['stage_index']} of {len(state['stages'])}, "
            f"epoch {state['epoch']}, step {state['global_step']})",
            path,
        )
    if "int8_scales" in state:
        state["model"] = dequantize_int8(state["model"], state.pop("int8_scales"), path)
    _check_finite(state["model"], path)
    return state


def quantize_int8(weights: dict[str, torch.Tensor], names: list[str]) -> tuple[dict[str, torch.Tensor],
                                                                             dict[str, torch.Tensor]]:
    """The floating-point tensors ``names`` of ``weights`` as int8 with one float32 scale per row (symmetric:
    ``w ~ q * scale``, ``|w - q scale| <= scale / 2``, the scale ``max |row| / 127``); the others unchanged. A row
    is the trailing dimensions that first hold at least 64 elements (a weight matrix's input dimension; JointNet's
    pose-space basis: one shape of one joint, every vertex and axis), so that the scales stay small beside the int8
    values. Returns ``(weights, scales)``, ``scales`` keyed by the quantized names, each of the tensor's shape with
    the row's dimensions 1. A shipped garment's storage (a quarter of float32); :func:`load_checkpoint` turns them
    back into float32."""
    out, scales = dict(weights), {}
    for name in names:
        value, row = weights[name].float(), [weights[name].dim() - 1]
        while value.shape[row[0]:].numel() < 64 and row[0] > 1:
            row.insert(0, row[0] - 1)
        scale = value.abs().amax(dim=row, keepdim=True).clamp_min(1e-30) / 127.0
        out[name], scales[name] = torch.round(value / scale).to(torch.int8), scale
    return out, scales


def dequantize_int8(weights: dict, scales: dict, path: Path) -> dict:
    """The float32 weights of a checkpoint stored by :func:`quantize_int8`; a scale without its int8 tensor, or
    of another shape, is refused naming the file."""
    if not isinstance(scales, dict):
        raise InputError(f"checkpoint entry 'int8_scales' has type {type(scales).__name__}", path)
    out = dict(weights)
    for name, scale in scales.items():
        q = weights.get(name)
        if (not isinstance(q, torch.Tensor) or q.dtype != torch.int8 or not isinstance(scale, torch.Tensor)
                or scale.dim() != q.dim() or any(s not in (1, n) for s, n in zip(scale.shape, q.shape))):
            raise InputError(f"checkpoint's int8 tensor {name!r} does not match its scale", path)
        out[name] = q.float() * scale.float()
    return out


def _check_finite(weights: dict, path: Path) -> None:
    """Refuse model weights or statistics (buffers) holding NaN or infinite values, naming the first tensor."""
    for name, value in weights.items():
        if isinstance(value, torch.Tensor) and value.is_floating_point() and not bool(torch.isfinite(value).all()):
            bad = int((~torch.isfinite(value)).sum())
            raise InputError(f"checkpoint tensor {name!r} {tuple(value.shape)} holds {bad} NaN or infinite value(s); "
                             "a model from it would be wrong everywhere: use another checkpoint or train again", path)


def load_weights(model: torch.nn.Module, path: str | Path) -> dict[str, Any]:
    """Load a checkpoint's model weights into ``model`` (for animation or evaluation); returns the
    checkpoint. A checkpoint of another architecture or size is an :class:`InputError` naming it."""
    state = load_checkpoint(path)
    try:
        model.load_state_dict(state["model"])
    except RuntimeError as e:
        raise InputError(f"checkpoint does not fit this model: {e}", path) from None
    return state
