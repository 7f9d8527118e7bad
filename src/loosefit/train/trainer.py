"""The training loop shared by every model: stages, optimisers, schedules, validation, logs,
checkpoints and exact resume.

A model (see :mod:`loosefit.train.protocol`) is trained stage by stage; each stage has its own
optimiser over that stage's parameters, its own epochs, learning rate and schedule. Each epoch
shuffles the training set with a generator seeded from ``(seed, stage index, epoch)``; every global
random generator is saved in each checkpoint. Resuming from ``checkpoints/last.pt`` therefore gives
the same weights, bit for bit, as a run that was never interrupted (on the same device and thread
count).

Several processes (DistributedDataParallel, :mod:`loosefit.train.distributed`): when the job has more
than one process, :func:`train` joins the process group, wraps the model in DDP, shards each epoch's
shuffle across the ranks (``batch_size`` is the global batch) and lets only rank 0 validate and write.

Seed the generators (:func:`loosefit.train.seeding.seed_everything` with ``config.seed``) before
constructing the model, so that its initial weights are reproducible too.
"""

from __future__ import annotations

import contextlib
import copy
import json
import logging
import math
import time
from collections import defaultdict
from pathlib import Path
from typing import Any, Optional

import torch
from torch.utils.data import DataLoader, Dataset
# not tqdm.auto: its asyncio class calls iter() on the DataLoader once more, drawing from the shuffle generator
from tqdm import tqdm

from loosefit.config import config_to_dict, save_config
from loosefit.train import distributed
from loosefit.errors import InputError, LoosefitError
from loosefit.paths import atomic_path
from loosefit.threads import torch_threads
from loosefit.train.metrics_log import MetricsLog
from loosefit.train.protocol import batch_size, collate_fn, model_stages, parameter_count, stage_parameters, to_device
from loosefit.train.run import RunDir, load_checkpoint, save_checkpoint
from loosefit.train.seeding import epoch_generator, rng_state, seed_everything, set_rng_state
from loosefit.train.settings import StageConfig, TrainConfig, TrainResult  # noqa: F401 - re-exported

log = logging.getLogger(__name__)

# Settings that change neither the weights nor the logged numbers: a resumed run may change them.
RESUME_MAY_CHANGE = ("progress", "tensorboard", "log_every", "num_workers", "device", "threads", "checkpoint_every")


class TrainingError(LoosefitError):
    """Training cannot go on (e.g. the loss became NaN); the last good checkpoint is kept."""


class StaleRunError(InputError):
    """A run cannot be resumed: it was trained on other data, with other settings or another network."""


def _device(name: str) -> torch.device:
    return distributed.resolve_device(name)


#: ``TrainConfig.optimizer`` -> (torch class, its settings). ``"rmsprop"`` is RMSProp (squared-gradient average
#: with smoothing 0.99, no momentum) whose average is corrected for its zero start, as Adam corrects its own:
#: that is torch's Adam without the first moment. torch's RMSprop (``"rmsprop-torch"``) divides the first
#: gradient by ``sqrt(0.01 g^2)``, a step of ``10 lr`` on every weight at once, still ``1.9 lr`` after 30 steps.
OPTIMIZERS = {
    "adam": (torch.optim.Adam, {}),
    "adamw": (torch.optim.AdamW, {}),
    "rmsprop": (torch.optim.Adam, {"betas": (0.0, 0.99), "eps": 1e-8}),
    "rmsprop-torch": (torch.optim.RMSprop, {"alpha": 0.99, "eps": 1e-8}),
}


def _optimizer(params: list[torch.nn.Parameter], config: TrainConfig, stage: StageConfig) -> torch.optim.Optimizer:
    kind, settings = OPTIMIZERS[config.optimizer]
    return kind(params, lr=stage.lr, weight_decay=stage.weight_decay, **settings)


def _scheduler(optimizer: torch.optim.Optimizer, config: TrainConfig, stage: StageConfig):
    if stage.schedule == "cosine":
        return torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=max(stage.epochs, 1), eta_min=config.min_lr)
    if stage.schedule == "step":
        return torch.optim.lr_scheduler.StepLR(optimizer, step_size=config.step_epochs, gamma=config.step_gamma)
    return None


class _Averager:
    """Per-key averages weighted by sample counts (keys may be missing from some batches)."""

    def __init__(self):
        self.sums: dict[str, float] = defaultdict(float)
        self.counts: dict[str, int] = defaultdict(int)

    def add(self, values: dict[str, float], n: int) -> None:
        for key, value in values.items():
            self.sums[key] += float(value) * n
            self.counts[key] += n

    def means(self) -> dict[str, float]:
        return {key: self.sums[key] / self.counts[key] for key in self.sums}


def _config_differences(saved: dict, current: dict) -> list[str]:
    keys = sorted((set(saved) | set(current)) - set(RESUME_MAY_CHANGE))
    return [k for k in keys if saved.get(k) != current.get(k)]


def _clone_to_cpu(state: Any) -> Any:
    """A deep copy of a (nested) state with tensors on the CPU: an in-memory checkpoint."""
    if isinstance(state, torch.Tensor):
        return state.detach().to("cpu", copy=True)
    if isinstance(state, dict):
        return {k: _clone_to_cpu(v) for k, v in state.items()}
    if isinstance(state, (list, tuple)):
        return type(state)(_clone_to_cpu(v) for v in state)
    return copy.deepcopy(state)


class _NoLog:
    """The metrics log of a rank other than 0: writes nothing."""

    def add_row(self, row) -> None:
        pass

    def scalars(self, *args, **kwargs) -> None:
        pass

    def close(self) -> None:
        pass


class _LossModule(torch.nn.Module):
    """``model.training_loss`` as a ``forward``, so that DistributedDataParallel sees the step."""

    def __init__(self, model: torch.nn.Module):
        super().__init__()
        self.model = model

    def forward(self, batch, stage: str):
        return self.model.training_loss(batch, stage)


def _merge_averagers(parts: list[tuple[dict, dict]]) -> dict[str, float]:
    """Every rank's (sums, counts) merged into per-key means."""
    sums: dict[str, float] = defaultdict(float)
    counts: dict[str, int] = defaultdict(int)
    for part_sums, part_counts in parts:
        for key in part_sums:
            sums[key] += part_sums[key]
            counts[key] += part_counts[key]
    return {key: sums[key] / counts[key] for key in sums}


def _write_summary(run: RunDir, result: TrainResult) -> None:
    with atomic_path(run.summary) as tmp:
        tmp.write_text(json.dumps(result.summary(), indent=2) + "\n")


class _Trainer:
    """One call of :func:`train`: the state that lives across epochs and stages."""

    def __init__(self, model, train_set, val_set, config: TrainConfig, run: RunDir, device: torch.device):
        self.model = model
        self.train_set = train_set
        self.val_set = val_set
        self.config = config
        self.run = run
        self.device = device
        self.stages = model_stages(model)
        self.collate = collate_fn(model)
        self.global_step = 0
        self.history: list[dict[str, Any]] = []
        self.elapsed_before = 0.0  # seconds spent by earlier (interrupted) parts of this run
        self.started = time.perf_counter()
        self.best: Optional[float] = None
        self.best_written = False
        self.last_train: dict[str, float] = {}
        self.last_val: dict[str, float] = {}
        self.pending: Optional[dict[str, Any]] = None  # last completed epoch, not yet on disk
        self.log: Optional[MetricsLog] = None
        self.main = distributed.is_main()
        self.distributed = distributed.is_distributed()
        self.step_fn = model.training_loss

    def wrap(self) -> None:
        """In a distributed job, train through DistributedDataParallel (after the model is on its device):
        it broadcasts rank 0's weights and averages the gradients of every step."""
        if distributed.is_distributed():
            from torch.nn.parallel import DistributedDataParallel

            # stages train part of the parameters: the others take no gradient in that stage
            ids = [self.device.index] if self.device.type == "cuda" else None
            self.step_fn = DistributedDataParallel(_LossModule(self.model), device_ids=ids, find_unused_parameters=True)

    # -- checkpoints -------------------------------------------------------------------------
    def _state(self, stage_index, epoch, optimizer, scheduler, complete) -> dict[str, Any]:
        return {
            "model": self.model.state_dict(),
            "optimizer": None if optimizer is None else optimizer.state_dict(),
            "scheduler": None if scheduler is None else scheduler.state_dict(),
            "stages": list(self.stages),
            "stage_index": stage_index,
            "epoch": epoch,
            "global_step": self.global_step,
            "best_metric": self.best,
            "rng": rng_state(),
            "config": config_to_dict(self.config),
            "history": [dict(r) for r in self.history],
            "elapsed_s": self.elapsed(),
            "complete": complete,
        }

    def elapsed(self) -> float:
        return self.elapsed_before + time.perf_counter() - self.started

    def restore(self, state: dict[str, Any], path: Path) -> tuple[int, int, Optional[dict], Optional[dict]]:
        """Load a checkpoint; returns where to continue: (stage index, epochs done in it, optimiser and
        scheduler states to load, ``None`` at a stage's start)."""
        if state["stages"] != self.stages:
            raise InputError(f"checkpoint was trained with stages {state['stages']}, the model has {self.stages}", path)
        differences = _config_differences(state["config"], config_to_dict(self.config))
        if differences:
            raise StaleRunError(
                f"the training config differs from the checkpoint's in {differences}; resume with the run's "
                f"config.yaml or start a new run folder",
                path,
            )
        try:
            self.model.load_state_dict(state["model"])
        except RuntimeError as e:
            raise StaleRunError(f"checkpoint does not fit this model: {e}", path) from None
        self.global_step = state["global_step"]
        self.history = [dict(r) for r in state["history"]]
        self.elapsed_before = state["elapsed_s"]
        stage_index, epoch = state["stage_index"], state["epoch"]
        self._recall_last_metrics()
        self.best = state["best_metric"]
        self.best_written = self.best is not None and self.run.best_checkpoint.exists()
        if epoch >= self.config.stage(self.stages[stage_index]).epochs:
            return stage_index + 1, 0, None, None
        return stage_index, epoch, state["optimizer"], state["scheduler"]

    def _recall_last_metrics(self) -> None:
        """The last epoch's training averages and the last validation, from the history."""
        if self.history:
            self.last_train = {k[6:]: v for k, v in self.history[-1].items() if k.startswith("train_")}
        validated = [r for r in self.history if any(k.startswith("val_") for k in r)]
        if validated:
            self.last_val = {k[4:]: v for k, v in validated[-1].items() if k.startswith("val_")}

    # -- epochs ------------------------------------------------------------------------------
    def _loader(self, dataset: Dataset, size: int, shuffle: bool, generator: torch.Generator) -> DataLoader:
        if hasattr(dataset, "batch_sampler"):  # a dataset that orders its own batches (stateful windows)
            if distributed.is_distributed():
                raise InputError(f"{type(dataset).__name__} orders its batches itself (the GRU state carried from window to "
                                 "window): train in one process, or on several with --set data.carry_state=false")
            return DataLoader(dataset, batch_sampler=dataset.batch_sampler(size, generator, shuffle),
                              collate_fn=self.collate, num_workers=self.config.num_workers,
                              pin_memory=self.device.type == "cuda")
        sampler = None
        if shuffle and distributed.is_distributed():
            # this rank's share of the single-process shuffle, drawn from the same generator
            sampler, shuffle = distributed.ShardedSampler(dataset, generator), False
            size = distributed.local_batch_size(size)
        return DataLoader(
            dataset,
            batch_size=size,
            shuffle=shuffle,
            sampler=sampler,
            generator=generator,
            collate_fn=self.collate,
            num_workers=self.config.num_workers,
            pin_memory=self.device.type == "cuda",
        )

    def train_epoch(self, stage_index, epoch, params, optimizer, settings: StageConfig) -> dict[str, float]:
        stage = self.stages[stage_index]
        loader = self._loader(
            self.train_set, settings.batch_size, True, epoch_generator(self.config.seed, stage_index, epoch)
        )
        averager = _Averager()
        self.model.train()
        bar = tqdm(
            loader, desc=f"{stage} {epoch}/{settings.epochs}", disable=not (self.config.progress and self.main),
            dynamic_ncols=True,
        )
        for batch in bar:
            batch = to_device(batch, self.device)
            n = batch_size(self.model, batch)
            # zero every gradient, not only this stage's, so frozen parameters hold none
            self.model.zero_grad(set_to_none=True)
            loss, terms = self.step_fn(batch, stage)
            scale = 1.0
            if self.distributed and hasattr(self.model, "loss_weight"):
                scale = distributed.weight_share(self.model.loss_weight(batch), self.device)
            if not distributed.all_finite(loss):
                raise TrainingError(
                    f"stage {stage!r} epoch {epoch} step {self.global_step + 1}: the loss is {loss.item()}; "
                    "lower the learning rate or set grad_clip"
                )
            (loss * scale if scale != 1.0 else loss).backward()
            if settings.grad_clip is not None:
                torch.nn.utils.clip_grad_norm_(params, settings.grad_clip)
            optimizer.step()
            self.global_step += 1
            values = {"loss": loss.item(), **{k: float(v) for k, v in terms.items()}}
            averager.add(values, n)
            bar.set_postfix(loss=f"{averager.means()['loss']:.4g}", refresh=False)
            if self.global_step % self.config.log_every == 0:
                self.log.scalars(values, self.global_step, prefix=f"{stage}/step/")
                self.log.scalars({"lr": optimizer.param_groups[0]["lr"]}, self.global_step, prefix=f"{stage}/")
        bar.close()
        if distributed.is_distributed():  # the epoch's averages over every rank's samples
            return _merge_averagers(distributed.gather((dict(averager.sums), dict(averager.counts))))
        return averager.means()

    @torch.no_grad()
    def validate(self, stage: str, settings: StageConfig) -> dict[str, float]:
        loader = self._loader(self.val_set, settings.batch_size, False, torch.Generator().manual_seed(0))
        averager = _Averager()
        self.model.eval()
        for batch in tqdm(loader, desc=f"{stage} validation", disable=not self.config.progress, leave=False):
            batch = to_device(batch, self.device)
            averager.add(self.model.validation_metrics(batch, stage), batch_size(self.model, batch))
        return averager.means()

    def _monitored(self, train_metrics: dict, val_metrics: dict) -> Optional[float]:
        if self.val_set is None:
            return train_metrics["loss"]
        if not val_metrics:
            return None
        if self.config.monitor not in val_metrics:
            raise InputError(
                f"monitor metric {self.config.monitor!r} is not among the validation metrics "
                f"{sorted(val_metrics)}; set 'monitor' to one of them"
            )
        return val_metrics[self.config.monitor]

    def _improved(self, value: Optional[float]) -> bool:
        if value is None or not math.isfinite(value):
            return False
        if self.best is None:
            return True
        return value < self.best if self.config.monitor_mode == "min" else value > self.best

    # -- stages ------------------------------------------------------------------------------
    def run_stages(self, start_stage: int, start_epoch: int, optimizer_state, scheduler_state) -> None:
        for stage_index in range(start_stage, len(self.stages)):
            stage = self.stages[stage_index]
            settings = self.config.stage(stage)
            params = stage_parameters(self.model, stage)
            if not params:
                raise ValueError(f"model.stage_parameters({stage!r}) gave no trainable parameters")
            optimizer = _optimizer(params, self.config, settings)
            scheduler = _scheduler(optimizer, self.config, settings)
            first_epoch = 1
            if stage_index == start_stage and optimizer_state is not None:
                optimizer.load_state_dict(optimizer_state)
                if scheduler is not None:
                    scheduler.load_state_dict(scheduler_state)
                first_epoch = start_epoch + 1
            else:
                self.best, self.best_written = None, False  # best.pt is chosen within each stage
            for epoch in range(first_epoch, settings.epochs + 1):
                self.run_epoch(stage_index, epoch, params, optimizer, scheduler, settings)

    def run_epoch(self, stage_index, epoch, params, optimizer, scheduler, settings: StageConfig) -> None:
        stage = self.stages[stage_index]
        start = time.perf_counter()
        lr = optimizer.param_groups[0]["lr"]
        train_metrics = self.train_epoch(stage_index, epoch, params, optimizer, settings)
        last_epoch = epoch == settings.epochs
        val_metrics = {}
        if self.val_set is not None and self.main and (epoch % self.config.validate_every == 0 or last_epoch):
            val_metrics = self.validate(stage, settings)
        monitored = self._monitored(train_metrics, val_metrics)
        if scheduler is not None:
            scheduler.step()

        row = {"stage": stage, "epoch": epoch, "step": self.global_step, "lr": lr}
        row["seconds"] = time.perf_counter() - start
        row.update({f"train_{k}": v for k, v in train_metrics.items()})
        row.update({f"val_{k}": v for k, v in val_metrics.items()})
        self.history.append(row)
        self.log.add_row(row)
        self.log.scalars({f"train/{k}": v for k, v in train_metrics.items()}, self.global_step, prefix=f"{stage}/")
        self.log.scalars({f"val/{k}": v for k, v in val_metrics.items()}, self.global_step, prefix=f"{stage}/")
        self.last_train = train_metrics
        if val_metrics:
            self.last_val = val_metrics
        if self.config.progress and self.main:
            shown = [f"{k} {v:.4g}" for k, v in train_metrics.items()]
            shown += [f"val {k} {v:.4g}" for k, v in val_metrics.items()]
            tqdm.write(f"{stage} epoch {epoch}/{settings.epochs}: {', '.join(shown)}")

        improved = self._improved(monitored)
        if improved:
            self.best = monitored
        complete = last_epoch and all(self.config.stage(s).epochs == 0 for s in self.stages[stage_index + 1 :])
        if not self.main:
            return
        state = self._state(stage_index, epoch, optimizer, scheduler, complete)
        if improved and self.val_set is not None:  # best.pt is chosen by validation, never by the training loss
            save_checkpoint(self.run.best_checkpoint, state)
            self.best_written = True
        if epoch % self.config.checkpoint_every == 0 or last_epoch:
            save_checkpoint(self.run.last_checkpoint, state)
            self.pending = None
        else:
            self.pending = _clone_to_cpu(state)

    def result(self) -> TrainResult:
        return TrainResult(
            run_dir=self.run.path,
            stages=list(self.stages),
            global_step=self.global_step,
            train_metrics=dict(self.last_train),
            val_metrics=dict(self.last_val),
            monitor="loss" if self.val_set is None else self.config.monitor,
            best_metric=self.best,
            best_checkpoint=self.run.best_checkpoint if self.best_written else None,
            wall_s=self.elapsed(),
            parameter_count=parameter_count(self.model),
            history=[dict(r) for r in self.history],
        )


def train(
    model: torch.nn.Module,
    train_set: Dataset,
    val_set: Optional[Dataset],
    config: TrainConfig,
    out_dir: str | Path,
    resume: bool = False,
) -> TrainResult:
    """Train ``model`` stage by stage; write logs and checkpoints into run folder ``out_dir``.

    Args:
        model: an ``nn.Module`` following :class:`loosefit.train.protocol.TrainableModel`; it is moved
            to the training device and left there, holding the final weights.
        train_set: training samples (any map-style Dataset the model's ``collate`` can batch). A dataset
            with a ``batch_sampler(batch_size, generator, shuffle)`` method orders its own batches (the
            stateful windows of :class:`loosefit.models.streams.StreamWindows`; one process only).
        val_set: validation samples (held-out motions), or ``None``.
        config: the :class:`TrainConfig`.
        out_dir: the run folder (layout in :mod:`loosefit.train.run`).
        resume: continue from ``out_dir/checkpoints/last.pt`` (with the same config, except the keys
            in :data:`RESUME_MAY_CHANGE`); when the folder has no checkpoint yet, training starts
            from the beginning. A run that had finished is not trained further.

    Returns:
        A :class:`TrainResult`; its summary is also written to ``out_dir/run.json``.

    Raises:
        InputError: ``out_dir`` already holds a run and ``resume`` is false; the checkpoint is
            corrupt, truncated, of another model or config; empty datasets; CUDA asked without CUDA;
            stage overrides naming no stage of the model; a monitor metric the model does not report.
        TrainingError: the loss became NaN or infinite.
        KeyboardInterrupt: re-raised after ``last.pt`` holds the last completed epoch.
    """
    run = RunDir(out_dir)
    stages = model_stages(model)
    unknown = sorted(set(config.stages) - set(stages))
    if unknown:
        raise InputError(f"config.stages names {unknown}, which are not stages of this model ({stages})")
    if len(train_set) == 0:
        raise InputError("the training set is empty")
    if val_set is not None and len(val_set) == 0:
        raise InputError("the validation set is empty (pass None for no validation)")
    state = None
    if run.has_checkpoint():
        if not resume:
            raise InputError("this folder already holds a training run; resume it or choose another folder", run.path)
        state = load_checkpoint(run.last_checkpoint)
    elif resume:
        log.info("%s has no checkpoint yet: training from the start", run.path)
    device = _device(config.device)

    threads = contextlib.ExitStack()  # closed in the finally below
    threads.enter_context(torch_threads(config.threads))
    trainer = _Trainer(model, train_set, val_set, config, run, device)
    model.to(device)
    joined = distributed.setup(device)  # several processes: join their group (gloo / nccl)
    finished = False
    try:
        trainer.wrap()
        if state is None:
            seed_everything(config.seed)
            position = (0, 0, None, None)
        else:
            position = trainer.restore(state, run.last_checkpoint)
        if trainer.main:
            run.create()
            save_config(run.config, config)
            # TensorBoard hides events the interrupted run wrote after its checkpoint's step
            purge = trainer.global_step + 1 if state is not None else None
            trainer.log = MetricsLog(
                run.metrics_csv, trainer.history, run.tensorboard if config.tensorboard else None, purge_step=purge
            )
        else:
            trainer.log = _NoLog()
        if state is not None:
            set_rng_state(state["rng"])
        try:
            trainer.run_stages(*position)
        except BaseException:
            # keep the last completed epoch (Ctrl-C, NaN, a crash in the model) before re-raising
            if trainer.pending is not None and trainer.main:
                save_checkpoint(run.last_checkpoint, trainer.pending)
                log.warning("training stopped: %s holds the last completed epoch", run.last_checkpoint)
            raise
        result = trainer.result()
        if trainer.main:
            _write_summary(run, result)
        finished = True
        return result
    finally:
        if trainer.log is not None:
            trainer.log.close()
        threads.close()
        if joined:
            distributed.teardown(wait=finished)
