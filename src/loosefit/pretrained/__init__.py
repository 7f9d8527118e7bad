"""Pretrained garments shipped with the package: ``loosefit animate pretrained:skirt --motion clip.bvh`` animates
a user's motion with no simulation and no training.

Each garment is a run folder reduced to what animation reads (``model.json``, ``method.yaml`` and one checkpoint,
``checkpoints/best.pt``, without the optimiser's state) and a ``pretrained.json`` saying what it was trained on and
how it scored, in ``loosefit/pretrained/<garment>-<method>/``. A run is named ``pretrained:<garment>`` (VirtualBones)
or ``pretrained:<garment>/<method>`` (``pretrained:skirt/jointnet``); :func:`resolve_run` turns the name into the
folder wherever a run folder is read. :func:`ship` makes one from a trained run.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import torch

from loosefit.errors import InputError
from loosefit.paths import atomic_path

#: A run argument that names a shipped garment starts with this.
PREFIX = "pretrained:"
#: The folder of the shipped garments (package data).
ROOT = Path(__file__).resolve().parent
#: The method a name without one means.
DEFAULT_METHOD = "virtualbones"
#: What a shipped run folder holds.
FILES = ("model.json", "method.yaml", "checkpoints/best.pt", "pretrained.json")
#: Each shipped checkpoint stays below this (bytes): they travel inside the wheel.
MAX_BYTES = 20 * 1024 * 1024
#: Weight tensors with more elements than this are stored as float16 in a shipped checkpoint (loading casts them
#: back to the model's float32), which halves a VirtualBones or JointNet garment; smaller tensors, the input and
#: target statistics among them, stay float32, so that positions of a metre keep their sub-millimetre precision.
HALF_ABOVE = 4096
#: A garment whose float16 checkpoint would exceed :data:`MAX_BYTES` (JointNet's dense pose-space basis: 24 joints x
#: 32 shapes x every vertex) stores its largest tensors as int8 with a float32 scale per row
#: (:func:`loosefit.train.run.quantize_int8`), the largest first and no more of them than it takes to fit: on the
#: real-capture skirt the basis, the joint GRUs' recurrent weights and the joint output moved the test animations by
#: at most 0.1, 1.7 and 0.15 mm each, while the skinning weights and the bone MLP alone moved them by 17 mm.
#: ``pretrained.json`` records the storage and, from ``scripts/ship_pretrained.py``, how far it moved the animations.


def available() -> list[str]:
    """The shipped garments as ``<garment>/<method>`` names, sorted."""
    return sorted(p.name.replace("-", "/", 1) for p in ROOT.iterdir() if (p / "model.json").is_file())


def resolve_run(run: str | Path) -> Path:
    """The run folder of ``run``: a ``pretrained:<garment>[/<method>]`` name's shipped folder, or ``run`` itself.

    Raises:
        InputError: a pretrained name that is not shipped (the message lists the ones that are).
    """
    text = str(run)
    if not text.startswith(PREFIX):
        return Path(run)
    garment, _, method = text[len(PREFIX):].partition("/")
    folder = ROOT / f"{garment}-{method or DEFAULT_METHOD}"
    if not garment or "/" in method or not (folder / "model.json").is_file():
        shipped = ", ".join(PREFIX + name for name in available()) or "none"
        raise InputError(f"no pretrained garment {text!r}; shipped: {shipped}")
    return folder


def ship(run: str | Path, out: str | Path, info: dict) -> Path:
    """Reduce the trained run folder ``run`` into ``out`` (a new folder): its ``model.json`` and ``method.yaml``,
    its best checkpoint (the last one for a run without validation) with the model's weights only (the large ones
    as float16: :data:`HALF_ABOVE`; the largest as int8 where float16 would exceed :data:`MAX_BYTES`), and ``pretrained.json`` holding ``info`` (what it was trained on, its scores). Returns ``out``.

    Raises:
        InputError: ``run`` is not a finished run folder, or the checkpoint exceeds :data:`MAX_BYTES` even in int8.
    """
    from loosefit.train.run import RunDir, load_checkpoint, quantize_int8

    run, out = RunDir(run), Path(out)
    checkpoint = run.best_checkpoint if run.best_checkpoint.is_file() else run.last_checkpoint
    state = load_checkpoint(checkpoint)  # checks the file
    for name in ("model.json", "method.yaml"):
        if not (run.path / name).is_file():
            raise InputError(f"not a finished run folder (no {name})", run.path)
    state.update(optimizer=None, scheduler=None)  # animation reads the weights only
    weights = state["model"]
    if out.exists():
        shutil.rmtree(out)
    (out / "checkpoints").mkdir(parents=True)
    for name in ("model.json", "method.yaml"):
        shutil.copy2(run.path / name, out / name)
    path = out / "checkpoints" / "best.pt"
    half = {k: v.half() if v.is_floating_point() and v.numel() > HALF_ABOVE else v for k, v in weights.items()}
    largest = sorted((k for k, v in weights.items() if v.is_floating_point() and v.dim() >= 2 and v.numel() > HALF_ABOVE),
                     key=lambda k: -weights[k].numel())
    for count in range(len(largest) + 1):  # float16, then the largest tensors as int8, one more each time
        state["model"], scales = quantize_int8(half, largest[:count])
        with atomic_path(path) as tmp:
            torch.save({**state, "int8_scales": scales} if scales else state, tmp)
        size = path.stat().st_size
        if size <= MAX_BYTES:
            break
    else:
        shutil.rmtree(out)
        raise InputError(f"the checkpoint is {size / 2**20:.1f} MB even in int8, over the {MAX_BYTES / 2**20:.0f} MB "
                         "a shipped garment may take", checkpoint)
    (out / "pretrained.json").write_text(json.dumps({**info, "checkpoint": checkpoint.name, "checkpoint_bytes": size,
                                                     "int8": largest[:count]}, indent=1))
    return out
