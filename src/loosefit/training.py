"""``loosefit train``: data -> model -> trained run folder, for any method.

A per-garment method trains on the sequences of one garment; a multi-garment method (its class has
``multi_garment = True``) trains on every garment, body shape and motion of the store: a static one
(``static = True``: FitGar) on its frames (:class:`loosefit.models.fitgar_data.GarmentFrames`), taking
no garment; a dynamic one (SwinGar) on windows of its sequences
(:class:`loosefit.models.multi_garment.MultiWindowDataset`), on every garment or the named ones.

The run folder holds, besides the trainer's files (:mod:`loosefit.train.run`), ``model.json`` (method,
garment, sizes, dataset, the range of the training motions' root: :mod:`loosefit.motion_range`) and
``method.yaml`` (the method's full config: model, train and data sections), so that
:mod:`loosefit.animate` rebuilds the model from the folder alone.
"""

from __future__ import annotations

import json
from pathlib import Path

from loosefit.config import load_config, save_config
from loosefit.errors import InputError
from loosefit.models.dataset import GarmentSequences
from loosefit.models.registry import model_class, run_config_class
from loosefit.motion_range import META_KEY as MOTION_RANGE, store_motion_range
from loosefit.paths import atomic_path
from loosefit.train import distributed
from loosefit.train.run import RunDir, save_checkpoint
from loosefit.train.seeding import rng_state, seed_everything
from loosefit.train.settings import TrainResult
from loosefit.train.trainer import train

MODEL_META = "model.json"
METHOD_CONFIG = "method.yaml"


def train_model(
    method: str,
    data: str | Path,
    garment: str | None,
    out: str | Path,
    config: str | Path | None = None,
    overrides: tuple[str, ...] | list[str] = (),
    resume: bool = False,
    val_split: str | None = "test",
    sim_params: dict | None = None,
) -> TrainResult | None:
    """Train ``method`` on the training sequences of ``garment`` in dataset ``data`` (every garment for a
    multi-garment method, which takes ``garment=None``); validate on ``val_split``.

    Args:
        garment: the store garment of a per-garment method; for a multi-garment method (SwinGar) a
            comma-separated list of store garments, or None for every garment with training sequences.
        config: the method's YAML config (``configs/models/<method>.yaml``); None: the built-in defaults
            (on ``resume``: the run folder's own ``method.yaml``).
        overrides: ``"section.key=value"`` strings, e.g. ``"train.epochs=5"``, ``"model.hidden=64"``.
        sim_params: train only on sequences simulated with these parameters (pivot networks).

    Returns:
        The trainer's result, or None for a method without trainable parameters (its run folder then holds
        a checkpoint of its fixed weights).
    """
    cls = model_class(method)
    run = RunDir(out)
    saved = run.path / METHOD_CONFIG
    if config is None and resume and saved.exists():
        config = saved
    cfg = load_config(run_config_class(method), config, overrides)
    if getattr(cls, "static", False):
        if garment is not None:
            raise InputError(f"{method} trains on every garment of the store: give no garment (got {garment!r})")
        return _train_garment_frames(method, cls, cfg, data, run, resume, val_split, sim_params)
    if getattr(cls, "multi_garment", False):
        return _train_garment_windows(cls, method, data, garment, run, cfg, resume, val_split)
    if garment is None:
        raise InputError(f"{method} is trained per garment: name one (loosefit info lists them)", Path(data))
    trained = hasattr(cfg, "train")
    if trained:
        seed_everything(cfg.train.seed)
    train_data = GarmentSequences(data, garment, "train", sim_params=sim_params, bones=cls.needs_rig)
    val_data = None
    if val_split is not None:
        try:
            val_data = GarmentSequences(data, garment, val_split, sim_params=sim_params, bones=False, body=False)
        except InputError:
            val_data = None  # no held-out sequences of this garment: train without validation
    model = cls.from_data(train_data, cfg.model)
    meta = {"method": method, "garment": garment, "data": str(Path(data).resolve()), "sizes": model.sizes(),
            "sim_params": sim_params, "train_sequences": [s.name for s in train_data.sequences],
            "val_sequences": [s.name for s in val_data.sequences] if val_data else [],
            "rig": train_data.rig_settings}
    _write_run(run, meta, cfg, resume, motion_range=trained)  # body-lbs follows any motion
    if not trained:
        _save_fixed(model, run)
        return None
    return train(model, cfg.data.dataset(train_data), cfg.data.dataset(val_data) if val_data else None,
                 cfg.train, run.path, resume=resume)


def _train_garment_frames(method, cls, cfg, data, run: RunDir, resume: bool, val_split, sim_params) -> TrainResult:
    """:func:`train_model` for a static method (FitGar): the frames of every garment of the store at once."""
    from loosefit.models.fitgar_data import GarmentFrames

    seed_everything(cfg.train.seed)
    frames = {"frame_stride": cfg.data.frame_stride, "frame_offset": cfg.data.frame_offset}
    train_data = GarmentFrames(data, "train", sim_params=sim_params, **frames)
    val_data = None
    if val_split is not None:
        try:
            val_data = GarmentFrames(data, val_split, sim_params=sim_params, **frames)
        except InputError:
            val_data = None  # no held-out sequences: train without validation
    model = cls.from_data(train_data, cfg.model)
    meta = {"method": method, "garment": None, "data": str(Path(data).resolve()), "sizes": model.sizes(),
            "sim_params": sim_params, "train_sequences": train_data.sequence_names,
            "val_sequences": val_data.sequence_names if val_data else [], "rig": {}}
    _write_run(run, meta, cfg, resume)
    return train(model, train_data, val_data, cfg.train, run.path, resume=resume)


def _train_garment_windows(cls, method: str, data, garment: str | None, run: RunDir, cfg, resume: bool,
                           val_split: str | None) -> TrainResult:
    """:func:`train_model` for a dynamic multi-garment method (SwinGar): every (or each named) garment of the training split;
    validation on every garment of ``val_split`` (held-out garments, shapes and motions)."""
    from loosefit.models.multi_garment import MultiGarmentData, MultiWindowDataset

    seed_everything(cfg.train.seed)
    names = None if garment is None else [g.strip() for g in garment.split(",") if g.strip()]
    settings = cfg.model.graph_settings()  # the garment graphs the model reads (its global descriptor)
    train_data = MultiGarmentData(data, "train", names, **settings)
    val_data = None
    if val_split is not None:
        try:
            val_data = MultiGarmentData(data, val_split, None, body=False, **settings)
        except InputError:
            val_data = None  # no held-out sequences: train without validation
    model = cls.from_data(train_data, cfg.model)
    meta = {"method": method, "garments": [g.name for g in train_data.graphs], "data": str(Path(data).resolve()),
            "sizes": model.sizes(),
            "train_sequences": [s.name for d in train_data.sequences for s in d.sequences],
            "val_sequences": [s.name for d in val_data.sequences for s in d.sequences] if val_data else []}
    _write_run(run, meta, cfg, resume)
    history = cfg.model.motion_frames - 1 + cfg.model.corrective_frames - 1
    windows = [None if d is None else MultiWindowDataset(d, cfg.data.window, cfg.data.stride, history)
               for d in (train_data, val_data)]
    return train(model, windows[0], windows[1], cfg.train, run.path, resume=resume)


def _write_run(run: RunDir, meta: dict, cfg, resume: bool, motion_range: bool = True) -> None:
    """Write the run folder's ``model.json`` and ``method.yaml``; on resume, first check that the data is the same.
    ``motion_range``: record the range of the training motions' root, which animation compares motions with."""
    if resume and run.has_checkpoint() and (run.path / MODEL_META).exists():
        _check_same_data(run.path / MODEL_META, meta)
    if not distributed.is_main():  # several training processes: rank 0 writes the run folder
        return
    if motion_range:
        found = store_motion_range(meta["data"], meta["train_sequences"])
        meta = {**meta, MOTION_RANGE: None if found is None else found.to_json()}
    run.path.mkdir(parents=True, exist_ok=True)
    with atomic_path(run.path / MODEL_META) as tmp:
        tmp.write_text(json.dumps(meta, indent=2))
    save_config(run.path / METHOD_CONFIG, cfg)


class StaleRunError(InputError):
    """A run cannot be resumed: it was trained on other data."""


#: What a run's training data is: resuming on data that differs in any of these would silently mix two datasets.
SAME_DATA_KEYS = ("garment", "garments", "sim_params", "train_sequences", "sizes", "rig")


def _check_same_data(path: Path, meta: dict) -> None:
    """Refuse to resume the run whose ``model.json`` is ``path`` on training data other than ``meta``'s
    (another garment or sequences, or a store prepared again with other rig settings)."""
    try:
        before = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read the run's data record: {e}", path) from None
    changed = [k for k in SAME_DATA_KEYS if k in before and before[k] != meta.get(k)]
    if changed:
        raise StaleRunError(f"the run was trained on other data ({', '.join(changed)} differ: the store was "
                            "simulated or prepared again); train into a new folder or delete this run", path.parent)


def _save_fixed(model, run: RunDir) -> None:
    """A method without trainable parameters (the body-LBS baseline) still gets a loadable checkpoint."""
    if not distributed.is_main():
        return
    state = {"model": model.state_dict(), "optimizer": None, "scheduler": None, "stages": ["fixed"], "stage_index": 0,
             "epoch": 0, "global_step": 0, "best_metric": None, "rng": rng_state(),
             "config": {}, "history": [], "elapsed_s": 0.0, "complete": True}
    save_checkpoint(run.last_checkpoint, state)
