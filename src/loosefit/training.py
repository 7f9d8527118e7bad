"""``loosefit train``: data -> model -> trained run folder, for any method.

A per-garment method trains on the sequences of one garment; a multi-garment method (its class has
``multi_garment = True``) trains on every garment, body shape and motion of the store: a static one
(``static = True``: FitGar) on its frames (:class:`loosefit.models.fitgar_data.GarmentFrames`), taking
no garment; a dynamic one (SwinGar) on windows of its sequences
(:class:`loosefit.models.multi_garment.MultiWindowDataset`), on every garment or the named ones.

The run folder holds, besides the trainer's files (:mod:`loosefit.train.run`), ``model.json`` (method,
garment, sizes, dataset, the training and validation sequences and how the validation was chosen
(``validation``: :mod:`loosefit.train.validation`), the range of the training motions' root:
:mod:`loosefit.motion_range`) and ``method.yaml`` (the method's full config: model, train and data
sections), so that :mod:`loosefit.animate` rebuilds the model from the folder alone.

While it trains, the main process holds the run folder's write lock (``.lock``, :func:`run_lock`): a second
``train`` into the folder is refused naming the holder. A resume with settings other than the run's own is
refused before anything in the folder is written.

Validation never sees a test motion unless asked to: the store's ``val`` split, or training motions
carved out by name, or none (:func:`loosefit.train.validation.choose_validation`). It selects
``checkpoints/best.pt``, which animation uses by default.
"""

from __future__ import annotations

import contextlib
import json
import logging
from pathlib import Path
from typing import Iterator

from loosefit.config import (apply_overrides, config_from_dict, config_to_dict, load_config, load_yaml,
                             read_yaml_text, save_config)
from loosefit.data import lock
from loosefit.data.mirror import MIRRORED
from loosefit.data.store import DatasetStore
from loosefit.errors import InputError
from loosefit.models.dataset import GarmentSequences
from loosefit.models.motion_features import HISTORY_FRAMES, MotionHistory
from loosefit.models.registry import model_class, run_config_class
from loosefit.motion_range import META_KEY as MOTION_RANGE, store_motion_range
from loosefit.paths import atomic_path
from loosefit.train import distributed
from loosefit.train.protocol import model_stages
from loosefit.train.run import RunDir, save_checkpoint
from loosefit.train.seeding import rng_state, seed_everything
from loosefit.train.settings import TrainResult
from loosefit.train.validation import Validation, choose_validation, train_on_fraction
from loosefit.train.trainer import RESUME_MAY_CHANGE, StaleRunError, train  # noqa: F401 - StaleRunError re-exported

log = logging.getLogger(__name__)

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
    val_split: str | None = "val",
    sim_params: dict | None = None,
    val_motions: list[str] | str | None = None,
    val_fraction: float | None = None,
    train_fraction: float | None = None,
) -> TrainResult | None:
    """Train ``method`` on the training sequences of ``garment`` in dataset ``data`` (every garment for a
    multi-garment method, which takes ``garment=None``), validating as :mod:`loosefit.train.validation`
    chooses: the store's ``val`` split, training motions carved out, or nothing.

    Args:
        garment: the store garment of a per-garment method; for a multi-garment method (SwinGar) a
            comma-separated list of store garments, or None for every garment with training sequences.
        config: the method's YAML config (``configs/models/<method>.yaml``); None: the built-in defaults
            (on ``resume``: the run folder's own ``method.yaml``).
        overrides: ``"section.key=value"`` strings, e.g. ``"train.epochs=5"``, ``"model.hidden=64"``.
        val_split: ``"val"`` (the store's validation sequences; none: no validation), ``"test"`` (only
            when asked for: the best checkpoint is then chosen by the test motions, and a warning says
            so) or ``"none"``/None.
        val_motions: training motions (store names, a list or a comma-separated string) that validate
            instead of training; or ``val_fraction``: that share of the training motions, chosen by name
            (:func:`loosefit.train.validation.carve_motions`). Never a test motion. Not for SwinGar.
        sim_params: train only on sequences simulated with these parameters (pivot networks).
        train_fraction: train on that share of the training motions of each kind, in (0, 1] (a learning
            curve; :func:`loosefit.train.validation.train_on_fraction`); per-garment methods only.

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
    if resume and run.has_checkpoint() and saved.exists():  # before anything in the run folder is written
        _check_same_settings(saved, cfg)
    with run_lock(run):
        return _train_model(method, cls, cfg, data, garment, run, resume, val_split, sim_params, val_motions,
                            val_fraction, train_fraction)


@contextlib.contextmanager
def run_lock(run: RunDir) -> Iterator[None]:
    """Hold the write lock of the run folder (``.lock``, as a dataset store's: :mod:`loosefit.data.lock`) while
    training writes it: a second ``train`` into it is refused naming the holder; the lock of a process that
    is gone is taken over. The main process of a distributed job holds it. A folder made here for the
    lock alone is removed again when nothing was written into it."""
    if not distributed.is_main():
        yield
        return
    created = not run.path.exists()
    run.path.mkdir(parents=True, exist_ok=True)
    try:
        key, stale = lock.acquire(run.path, what="run folder")
    except BaseException:
        if created:
            _remove_if_empty(run.path)
        raise
    if stale:
        log.warning("%s: %s", run.path, stale)
    try:
        yield
    finally:
        lock.release(key)
        if created:
            _remove_if_empty(run.path)


def _remove_if_empty(path: Path) -> None:
    try:
        path.rmdir()
    except OSError:  # not empty (what was written stays), or gone
        pass


#: Settings whose default changed after runs were made without them: a run whose ``method.yaml`` lacks one was
#: trained with the value here, not today's default (the frame was the heading frame before ``model.frame``;
#: no pose noise before ``model.pose_noise``, no pins before ``model.pin_radius``): :func:`load_run_config` reads
#: it so.
FORMER_DEFAULTS = {"model.frame": "heading", "model.pose_noise": 0.0, "model.pin_radius": None}


def load_run_config(cls: type, path: Path):
    """A run's ``method.yaml`` as config ``cls``: the settings the run was trained with. A setting the file lacks
    is today's default, except those of :data:`FORMER_DEFAULTS`, which take the value they had then."""
    values = load_yaml(read_yaml_text(path, "config"), path)
    cfg = config_from_dict(cls, values, path)
    written, known = _flat(values or {}), _flat(config_to_dict(cfg))
    return apply_overrides(cfg, [f"{k}={json.dumps(v)}" for k, v in FORMER_DEFAULTS.items()
                                 if k in known and k not in written])


def _flat(value, key: str = "") -> dict:
    """A nested dict as ``{"section.key": value}``."""
    if isinstance(value, dict) and value:
        return {k: v for name, item in value.items()
                for k, v in _flat(item, f"{key}.{name}" if key else str(name)).items()}
    return {key: value}


def _settings(cfg) -> dict:
    """A run config as ``{"section.key": value}`` without the keys a resume may change."""
    flat = _flat(config_to_dict(cfg))
    return {k: v for k, v in flat.items() if not (k.startswith("train.") and k.split(".", 1)[1] in RESUME_MAY_CHANGE)}


def _check_same_settings(saved: Path, cfg) -> None:
    """Refuse to resume the run whose ``method.yaml`` is ``saved`` with other settings than its own (except the
    keys :data:`~loosefit.train.trainer.RESUME_MAY_CHANGE`): its checkpoint would not fit, or train on
    differently. Reads only."""
    before, now = _settings(load_run_config(type(cfg), saved)), _settings(cfg)
    changed = sorted(k for k in set(before) | set(now) if before.get(k, "(none)") != now.get(k, "(none)"))
    if changed:
        shown = "; ".join(f"{k}: {before.get(k, '(none)')!r} in the run, {now.get(k, '(none)')!r} now" for k in changed[:5])
        more = f"; and {len(changed) - 5} more" if len(changed) > 5 else ""
        raise InputError(f"--resume with settings other than the run's own ({shown}{more}): a run resumes with "
                         f"the settings in {saved.name}; drop the --set / --config that change them, or train into "
                         "a new folder; nothing was changed", saved.parent)


def _train_model(method, cls, cfg, data, garment, run: RunDir, resume: bool, val_split, sim_params, val_motions,
                 val_fraction, train_fraction) -> TrainResult | None:
    """:func:`train_model` once its settings are checked, with the run folder locked."""
    if isinstance(val_motions, str):
        val_motions = [m.strip() for m in val_motions.split(",") if m.strip()]
    carve = {"val_split": val_split, "val_motions": val_motions, "val_fraction": val_fraction}
    if train_fraction is not None and (getattr(cls, "static", False) or getattr(cls, "multi_garment", False)):
        raise InputError(f"{method} trains on every garment of the store: a training fraction is for the "
                         "per-garment methods")
    if getattr(cls, "static", False):
        if garment is not None:
            raise InputError(f"{method} trains on every garment of the store: give no garment (got {garment!r})")
        return _train_garment_frames(method, cls, cfg, data, run, resume, carve, sim_params)
    if getattr(cls, "multi_garment", False):
        return _train_garment_windows(cls, method, data, garment, run, cfg, resume, carve)
    if garment is None:
        raise InputError(f"{method} is trained per garment: name one (loosefit info lists them)", Path(data))
    trained = hasattr(cfg, "train")
    if trained:
        seed_everything(cfg.train.seed)
    store = DatasetStore.open(data, mode="r")
    if garment not in store.garment_names():
        raise InputError(f"no garment {garment!r} in the store (has {store.garment_names()})", store.path)
    # a method without trainable weights (body-lbs) has no checkpoint to select: no validation
    validation = choose_validation(store, _uses(store, garment, sim_params), what=f"garment {garment!r}",
                                   **(carve if trained else {"val_split": "none"}))
    if train_fraction is not None:
        validation = train_on_fraction(store, validation, train_fraction)
    history = _motion_history(cfg.model)  # the model reads as many root features as its data has
    frame = getattr(cfg.model, "frame", "heading")  # where the model predicts the garment
    train_data = GarmentSequences(store, garment, "train", sim_params=sim_params, bones=cls.needs_rig,
                                  names=validation.train, history=history, frame=frame,
                                  mirror=getattr(getattr(cfg, "data", None), "mirror", False))
    val_data = None
    if validation.val:
        val_data = GarmentSequences(store, garment, None, sim_params=sim_params, bones=False, body=False,
                                    names=validation.val, history=history, frame=frame)
    model = cls.from_data(train_data, cfg.model)
    meta = {"method": method, "garment": garment, "data": str(Path(data).resolve()), "sizes": model.sizes(),
            "sim_params": sim_params,  # train_sequences: the stored ones (their mirrors, if any, train too)
            "train_sequences": [s.name for s in train_data.sequences if not s.name.endswith(MIRRORED)],
            "val_sequences": [s.name for s in val_data.sequences] if val_data else [],
            "validation": validation.to_json(), "rig": train_data.rig_settings}
    _write_run(run, meta, cfg, resume, motion_range=trained)  # body-lbs follows any motion
    if not trained:
        _save_weights(model, run, ["fixed"])
        return None
    return train(model, cfg.data.dataset(train_data), cfg.data.dataset(val_data) if val_data else None,
                 cfg.train, run.path, resume=resume)


def _motion_history(model_config) -> MotionHistory | None:
    """The motion history a per-garment model reads (None: none). A method without the settings (body-LBS)
    takes the default history (it reads what it is given)."""
    if not getattr(model_config, "root_history", True):
        return None
    return MotionHistory(tuple(getattr(model_config, "history_frames", HISTORY_FRAMES)),
                         getattr(model_config, "history_vertical", False))


def _uses(store: DatasetStore, garment: str | None, sim_params: dict | None):
    """Which sequence names of ``store`` a run may use: those of ``garment`` (None: any) simulated with
    ``sim_params`` (None: any)."""

    def keep(name: str) -> bool:
        seq = store.sequence(name)
        return (garment is None or seq.garment == garment) and (sim_params is None or seq.sim_params == sim_params)

    return keep


def _train_garment_frames(method, cls, cfg, data, run: RunDir, resume: bool, carve: dict, sim_params) -> TrainResult:
    """:func:`train_model` for a static method (FitGar): the frames of every garment of the store at once."""
    from loosefit.models.fitgar_data import GarmentFrames

    seed_everything(cfg.train.seed)
    frames = {"frame_stride": cfg.data.frame_stride, "frame_offset": cfg.data.frame_offset}
    store = DatasetStore.open(data, mode="r")
    validation = choose_validation(store, _uses(store, None, sim_params), **carve)
    train_data = GarmentFrames(data, "train", sim_params=sim_params, names=validation.train, **frames)
    val_data = None
    if validation.val:
        val_data = GarmentFrames(data, None, sim_params=sim_params, names=validation.val, **frames)
    model = cls.from_data(train_data, cfg.model)
    _write_run(run, _garment_frames_meta(method, data, model, train_data, val_data, validation, sim_params), cfg,
               resume)
    return train(model, train_data, val_data, cfg.train, run.path, resume=resume)


def _garment_frames_meta(method, data, model, train_data, val_data, validation, sim_params) -> dict:
    """The ``model.json`` record of a static method's run."""
    return {"method": method, "garment": None, "data": str(Path(data).resolve()), "sizes": model.sizes(),
            "sim_params": sim_params, "train_sequences": train_data.sequence_names,
            "val_sequences": val_data.sequence_names if val_data else [], "validation": validation.to_json(),
            "rig": {}}


def save_trained_frames_run(out: str | Path, method: str, model, cfg, train_data, data: str | Path) -> RunDir:
    """A run folder for a static model (FitGar) trained outside :func:`train_model` (a benchmark's own loop),
    so that it animates, renders and scores as any run: ``model.json`` (no validation), ``method.yaml`` and
    a complete last checkpoint of the model's weights (its stages, step 0: the loop's own history is not kept).
    """
    run = RunDir(out)
    validation = Validation("none", train_data.sequence_names, note="trained outside loosefit train")
    _write_run(run, _garment_frames_meta(method, data, model, train_data, None, validation, None), cfg, False)
    _save_weights(model, run, list(model_stages(model)))
    return run


def _train_garment_windows(cls, method: str, data, garment: str | None, run: RunDir, cfg, resume: bool,
                           carve: dict) -> TrainResult:
    """:func:`train_model` for a dynamic multi-garment method (SwinGar): every (or each named) garment of the training split;
    validation on every garment of the validation split (held-out garments, shapes and motions; no carving)."""
    from loosefit.models.multi_garment import MultiGarmentData, MultiWindowDataset

    if carve["val_motions"] is not None or carve["val_fraction"] is not None:
        raise InputError(f"{method} validates on a split of the store (held-out garments too): give the plan a "
                         "'val' split instead of carving validation motions", Path(data))
    seed_everything(cfg.train.seed)
    names = None if garment is None else [g.strip() for g in garment.split(",") if g.strip()]
    settings = cfg.model.graph_settings()  # the garment graphs the model reads (its global descriptor)
    train_data = MultiGarmentData(data, "train", names, **settings)
    validation = choose_validation(DatasetStore.open(data, mode="r"), lambda name: True, carve["val_split"])
    val_data = None
    if validation.val:
        val_data = MultiGarmentData(data, validation.source, None, body=False, **settings)
    model = cls.from_data(train_data, cfg.model)
    meta = {"method": method, "garments": [g.name for g in train_data.graphs], "data": str(Path(data).resolve()),
            "sizes": model.sizes(),
            "train_sequences": [s.name for d in train_data.sequences for s in d.sequences],
            "val_sequences": [s.name for d in val_data.sequences for s in d.sequences] if val_data else [],
            "validation": validation.to_json()}
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


#: What a run's training data is: resuming on data that differs in any of these would silently mix two datasets.
SAME_DATA_KEYS = ("garment", "garments", "sim_params", "train_sequences", "val_sequences", "sizes", "rig")


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
                            "simulated or prepared again, or the run predates a change of the model's inputs); "
                            "train into a new folder or delete this run", path.parent)


def _save_weights(model, run: RunDir, stages: list[str]) -> None:
    """A complete checkpoint of ``model``'s weights alone: a method without trainable parameters (the body-LBS
    baseline, stages ``["fixed"]``) still gets a loadable one, and so does a model trained elsewhere."""
    if not distributed.is_main():
        return
    state = {"model": model.state_dict(), "optimizer": None, "scheduler": None, "stages": stages, "stage_index": 0,
             "epoch": 0, "global_step": 0, "best_metric": None, "rng": rng_state(),
             "config": {}, "history": [], "elapsed_s": 0.0, "complete": True}
    save_checkpoint(run.last_checkpoint, state)
