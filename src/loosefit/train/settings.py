"""What a training run is told and what it returns: :class:`TrainConfig` (with per-stage
:class:`StageConfig` overrides), loaded from YAML by :func:`loosefit.config.load_config`, and
:class:`TrainResult`, written to ``run.json``."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Optional

from loosefit.errors import InputError


@dataclass(frozen=True)
class StageConfig:
    """Per-stage settings; ``None`` keeps the value of :class:`TrainConfig`."""

    epochs: Optional[int] = None
    lr: Optional[float] = None
    weight_decay: Optional[float] = None
    batch_size: Optional[int] = None
    schedule: Optional[Literal["cosine", "step", "none"]] = None
    grad_clip: Optional[float] = None


@dataclass(frozen=True)
class TrainConfig:
    """How to train a model (loaded with :func:`loosefit.config.load_config`).

    Attributes:
        seed: seeds every generator at the start, and each epoch's shuffling.
        epochs: epochs per stage (overridable per stage in ``stages``).
        batch_size: samples per batch (training and validation).
        optimizer: ``"adam"``, ``"adamw"`` (decoupled weight decay), ``"rmsprop"`` (smoothing 0.99, no
            momentum, its squared-gradient average corrected for its zero start; JointNet's optimiser) or
            ``"rmsprop-torch"`` (torch's RMSprop, uncorrected: its first steps are up to 10 times ``lr``;
            :data:`loosefit.train.trainer.OPTIMIZERS`).
        lr: initial learning rate of each stage's optimiser.
        weight_decay: L2 penalty (Adam, RMSProp) or decoupled decay (AdamW).
        schedule: learning-rate schedule over a stage's epochs, stepped once per epoch:
            ``"cosine"`` (from ``lr`` to ``min_lr``), ``"step"`` (times ``step_gamma`` every
            ``step_epochs``) or ``"none"``.
        min_lr: final learning rate of the cosine schedule.
        step_epochs, step_gamma: the step schedule.
        grad_clip: maximum total gradient norm of a stage's parameters, ``None`` for no clipping.
        threads: torch CPU threads during training (1 is fastest for scatter-heavy graph layers on
            small machines); the previous setting is restored afterwards.
        device: ``"cpu"``, ``"cuda"`` (an error without CUDA) or ``"auto"`` (CUDA when available).
        num_workers: DataLoader worker processes (0 loads in the training process).
        checkpoint_every: write ``checkpoints/last.pt`` every N epochs (and always at a stage's end).
        validate_every: validate every N epochs (and always at a stage's end).
        log_every: send the running training loss to TensorBoard every N optimiser steps.
        monitor: validation metric that selects ``checkpoints/best.pt``. Without a validation set the
            training loss ``"loss"`` is tracked as ``best_metric`` but no ``best.pt`` is written: the
            training loss selects no checkpoint.
        monitor_mode: ``"min"`` or ``"max"``: whether lower or higher ``monitor`` is better.
        progress: show tqdm progress bars.
        tensorboard: write TensorBoard event files.
        stages: per-stage overrides, e.g. ``{"low": StageConfig(epochs=20, lr=1e-3)}``; in YAML
            ``stages: {low: {epochs: 20, lr: 1.0e-3}}``.
    """

    seed: int = 0
    epochs: int = 10
    batch_size: int = 8
    optimizer: Literal["adam", "adamw", "rmsprop", "rmsprop-torch"] = "adam"
    lr: float = 1e-3
    weight_decay: float = 0.0
    schedule: Literal["cosine", "step", "none"] = "cosine"
    min_lr: float = 0.0
    step_epochs: int = 10
    step_gamma: float = 0.5
    grad_clip: Optional[float] = None
    threads: int = 1
    device: Literal["cpu", "cuda", "auto"] = "cpu"
    num_workers: int = 0
    checkpoint_every: int = 1
    validate_every: int = 1
    log_every: int = 10
    monitor: str = "rmse_mm"
    monitor_mode: Literal["min", "max"] = "min"
    progress: bool = True
    tensorboard: bool = True
    stages: dict[str, StageConfig] = field(default_factory=dict)

    def __post_init__(self):
        positive = ("batch_size", "step_epochs", "threads", "checkpoint_every", "validate_every", "log_every")
        for name in positive:
            if getattr(self, name) < 1:
                raise InputError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name in ("epochs", "num_workers"):
            if getattr(self, name) < 0:
                raise InputError(f"{name} must be >= 0, got {getattr(self, name)}")
        if not 0 < self.step_gamma <= 1:
            raise InputError(f"step_gamma must be in (0, 1], got {self.step_gamma}")
        if not 0 <= self.min_lr:
            raise InputError(f"min_lr must be >= 0, got {self.min_lr}")
        for stage in [""] + list(self.stages):
            s = self.stage(stage) if stage else self
            where = f"stages.{stage}." if stage else ""
            if s.epochs < 0 or s.batch_size < 1:
                raise InputError(f"{where}epochs must be >= 0 and {where}batch_size >= 1")
            if not (s.lr > 0 and math.isfinite(s.lr)) or not s.weight_decay >= 0:
                raise InputError(f"{where}lr must be > 0 and {where}weight_decay >= 0, got {s.lr}, {s.weight_decay}")
            if s.grad_clip is not None and not s.grad_clip > 0:
                raise InputError(f"{where}grad_clip must be > 0 (or null for none), got {s.grad_clip}")

    def stage(self, name: str) -> StageConfig:
        """The settings of stage ``name`` with every field resolved (no ``None`` left but ``grad_clip``)."""
        own = self.stages.get(name, StageConfig())
        return StageConfig(
            **{f.name: getattr(self, f.name) if getattr(own, f.name) is None else getattr(own, f.name)
               for f in dataclasses.fields(StageConfig)}
        )


@dataclass
class TrainResult:
    """What :func:`train` returns (and writes, less ``history``, to ``run.json``).

    Attributes:
        run_dir: the run folder.
        stages: stage names in training order.
        global_step: optimiser steps over all stages.
        train_metrics: training averages of the last epoch (``"loss"`` and the model's terms).
        val_metrics: validation averages of the last validated epoch (empty without validation).
        monitor: the metric that selected ``best_checkpoint``; best_metric: its best value in the last stage.
        best_checkpoint: ``checkpoints/best.pt``, or ``None`` if never written (always without validation).
        wall_s: training seconds, summed over interrupted and resumed parts.
        parameter_count: scalar parameters of the model.
        history: the ``metrics.csv`` rows, as dicts.
    """

    run_dir: Path
    stages: list[str]
    global_step: int
    train_metrics: dict[str, float]
    val_metrics: dict[str, float]
    monitor: str
    best_metric: Optional[float]
    best_checkpoint: Optional[Path]
    wall_s: float
    parameter_count: int
    history: list[dict[str, Any]]

    def summary(self) -> dict[str, Any]:
        """``run.json``'s content: everything but the history."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "history"}
        out["run_dir"] = str(self.run_dir)
        out["best_checkpoint"] = None if self.best_checkpoint is None else str(self.best_checkpoint)
        out["epochs"] = {s: sum(1 for r in self.history if r["stage"] == s) for s in self.stages}
        return out
