"""Simulation plans: a YAML file listing garments, body shapes, motions, parameter sets and the split,
expanded into sequence jobs with stable ids.

Plan format (paths are relative to the plan file)::

    name: demo
    shapes:                        # body shapes (Anny phenotype values; missing ones are average)
      average: {}
      tall: {height: 0.8}
    garments:                      # a template (loosefit.garment.make_garment) or a file
      skirt: {template: skirt, seed: 0, edge_length: 0.03, params: {length: 0.5}}
      mine: {file: garments/mine.obj, shape: average}   # a file fits one shape only
    motions:                       # procedural (loosefit.motion.procedural) or a file
      walk: {procedural: walk, seconds: 4, seed: 1}
      clip: {file: ../mocap/005_02.bvh, joint_map: cc, start: 1, frames: 300}   # counted at 30 fps from the file's frame 0
      extra: {file: ../mocap/007_01.bvh, joint_map: cc, optional: true}   # missing file: its sequences dropped
      slow: {procedural: walk, seconds: 6, seed: 1, slowdown: 4}   # 1.5 s of a walk over 6 s
      held: {procedural: walk, seconds: 6, seed: 1, hold: {every: 15, transition: 10, frames: 30, in_place: true}}
                                   # every 15th pose, reached in 10 frames then held for 30, on the spot
      rested: {procedural: walk, seconds: 6, seed: 1, hold: {every: 15, from_rest: true, order_seed: 2}}
                                   # each key reached from the rest pose, held there first; keys shuffled
    sim_params:                    # named SimParams sets (missing fields keep their defaults)
      default: {}
      stiff: {bending: 1.0e-4}
    gate: {max_penetration: 0.01}  # QualityGate limits (optional)
    sequences:                     # groups; each is the product of its lists (missing list: all)
      - {garments: [skirt], motions: [walk, clip]}
    split:                         # a sequence using any listed item goes there; the rest is train
      test: {motions: [clip]}
      val: {}
    references: {count: 4, noise: 1.0e-5}   # optional: perturbed reference runs of every test sequence

A job's id is ``<garment>+<shape>+<motion>+<sim_params>``; the garment entry in the dataset is
``<garment>+<shape>`` (templates are fitted to each shape). Motions are generated on, or
retargeted to, the average body and shared by all shapes.

``references`` asks for ``count`` extra runs of every *test* sequence (:class:`ReferencePlan`): run ``k``
(1..count) starts from the garment with every rest vertex moved by Gaussian noise of ``noise`` metres (noise
seed ``k``, :func:`loosefit.simulate.perturb_start`) and is otherwise the base run (its solver steps
included), over the whole motion. They are stored with the base sequence and give the floor of every
accuracy figure (:mod:`loosefit.metrics.reference`); they never change a sequence's job hash.

The file is read by :mod:`loosefit.config` (so ``1e-5`` is a number); each garment and motion entry is
checked as a typed spec (:class:`TemplateGarment`, :class:`FileGarment`, :class:`ProceduralMotion`,
:class:`FileMotion`, whose fields hold the defaults) and each parameter set is a :class:`SimParams`.
The plan keeps the entries as written: a job's hash is that of the file's text, not of the defaults.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional, Union

from loosefit.config import config_from_dict, load_yaml
from loosefit.errors import InputError
from loosefit.sim.params import SimParams
from loosefit.sim.quality import QualityGate

SEPARATOR = "+"
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.=-]{0,60}$")
_TOP_KEYS = {"name", "shapes", "garments", "motions", "sim_params", "gate", "sequences", "split", "references"}
_GROUP_KEYS = ("garments", "shapes", "motions", "sim_params")
_SPLITS = ("test", "val")


@dataclass(frozen=True)
class SequenceJob:
    """One sequence to simulate.

    Attributes:
        id: ``<garment>+<shape>+<motion>+<sim_params>``: the sequence's name in the dataset.
        garment, shape, motion, sim_params: names in the plan.
        split: ``"train"``, ``"val"`` or ``"test"``.
        hash: digest of everything that determines the result (specs and parameters); a stored
            sequence with another hash is simulated again.
    """

    id: str
    garment: str
    shape: str
    motion: str
    sim_params: str
    split: str
    hash: str

    @property
    def garment_entry(self) -> str:
        """Name of the (garment fitted to shape) entry in the dataset."""
        return f"{self.garment}{SEPARATOR}{self.shape}"


@dataclass(frozen=True)
class TemplateGarment:
    """A plan garment made from a template (:func:`loosefit.garment.make_garment`) on each shape.

    Attributes:
        template: the template's name.
        seed: its random seed; edge_length: target edge length, metres (None: ``make_garment``'s defaults).
        params: the template's own parameters (``length``, ``flare``...).
    """

    template: str
    seed: Optional[int] = None
    edge_length: Optional[float] = None
    params: dict[str, Any] = field(default_factory=dict)

    def make_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ``make_garment`` after the template and the body."""
        given = {k: getattr(self, k) for k in ("seed", "edge_length") if getattr(self, k) is not None}
        return {**given, **self.params}


@dataclass(frozen=True)
class FileGarment:
    """A plan garment read from a mesh file (relative to the plan), fitted to one ``shape`` (None: every shape)."""

    file: str
    shape: Optional[str] = None


@dataclass(frozen=True)
class Hold:
    """Key poses held until the cloth settles (:func:`loosefit.motion.hold.hold_poses`): every ``every``-th
    frame, reached in ``transition`` frames, then held for ``frames`` frames; ``in_place``: on the spot;
    ``from_rest``: each key reached from the rest pose, held as long first (twice the frames a key);
    ``order_seed``: the keys in a random order drawn with this seed."""

    every: int
    transition: int = 10
    frames: int = 30
    in_place: bool = False
    from_rest: bool = False
    order_seed: Optional[int] = None

    def __post_init__(self):
        for key in ("every", "transition", "frames"):
            if getattr(self, key) < 1:
                raise InputError(f"'hold.{key}' must be an integer >= 1, got {getattr(self, key)!r}")
        if self.order_seed is not None and self.order_seed < 0:
            raise InputError(f"'hold.order_seed' must be an integer >= 0, got {self.order_seed!r}")


@dataclass(frozen=True)
class ProceduralMotion:
    """A procedural plan motion (:func:`loosefit.motion.procedural.generate`) of ``seconds`` seconds, played
    ``slowdown`` times slower (:func:`loosefit.motion.resample.slow_down`; the result still lasts ``seconds``),
    then, with ``hold``, as held key poses (the result is longer: ``hold.transition + hold.frames`` frames a key)."""

    procedural: str
    seconds: Optional[float] = None
    seed: int = 0  # generate() takes it positionally: the default is the plan's
    slowdown: float = 1.0
    hold: Optional[Hold] = None

    def __post_init__(self):
        if self.seconds is None or not self.seconds > 0:
            raise InputError(f"'seconds' must be a positive number, got {self.seconds!r}")
        _check_slowdown(self.slowdown)


@dataclass(frozen=True)
class FileMotion:
    """A plan motion read from a file (relative to the plan): ``frames`` frames (None: all) from ``start``,
    counted after the motion is played ``slowdown`` times slower; then, with ``hold``, as held key poses.
    ``start`` counts the frames of the whole file as imported at 30 fps, frame 0 included: a plan reads every
    frame (``keep_first_frame``), never the importer's choice, so a plan selects the same frames whatever the
    importer's default; ``start: 1`` skips a rest pose a converter put at frame 0 (the "Imported" CMU clips)
    and a jump left in the frames selected is warned about when the motion is made.
    ``optional``: when the file is not there, the motion and its sequences leave the plan
    (:attr:`Plan.missing_motions`) instead of stopping it: for data kept outside the project, such as the demo's
    motion capture."""

    file: str
    joint_map: Optional[str] = None
    start: int = 0
    frames: Optional[int] = None
    slowdown: float = 1.0
    hold: Optional[Hold] = None
    optional: bool = False

    def __post_init__(self):
        _check_slowdown(self.slowdown)
        for key, least in (("start", 0), ("frames", 1)):
            value = getattr(self, key)
            if value is not None and value < least:
                raise InputError(f"{key!r} must be an integer >= {least}, got {value!r}")


def _check_slowdown(value) -> None:
    if not value >= 1:  # the type is checked by loosefit.config
        raise InputError(f"'slowdown' must be a number >= 1 (1: as made), got {value!r}")


@dataclass(frozen=True)
class ReferencePlan:
    """Reference runs of every test sequence: ``count`` runs (0: none), start noise ``noise`` metres
    (standard deviation per axis of every rest vertex); see the module docstring."""

    count: int = 0
    noise: float = 1.0e-5

    def __post_init__(self):
        if isinstance(self.count, bool) or not isinstance(self.count, int) or self.count < 0:
            raise InputError(f"'count' must be an integer >= 0, got {self.count!r}")
        if isinstance(self.noise, bool) or not isinstance(self.noise, (int, float)) or not 0 < self.noise < 0.01:
            raise InputError(f"'noise' must be a number of metres in (0, 0.01), got {self.noise!r}")

    def run_hash(self, job: "SequenceJob", index: int) -> str:
        """Digest of what determines reference run ``index`` of ``job``: the base's hash, the noise and the seed."""
        content = {"job_hash": job.hash, "noise": float(self.noise), "seed": int(index)}
        return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()[:16]


GarmentSpec = Union[TemplateGarment, FileGarment]
MotionSpec = Union[ProceduralMotion, FileMotion]


@dataclass
class Plan:
    """A parsed simulation plan (see the module docstring for the file format); ``missing_motions``: the optional
    file motions left out because their files are not there."""

    name: str
    path: Path
    shapes: dict[str, dict[str, float]]
    garments: dict[str, dict[str, Any]]
    motions: dict[str, dict[str, Any]]
    sim_params: dict[str, SimParams]
    gate: QualityGate
    jobs: list[SequenceJob] = field(default_factory=list)
    references: ReferencePlan = field(default_factory=ReferencePlan)
    missing_motions: list[str] = field(default_factory=list)

    def reference_jobs(self) -> list[SequenceJob]:
        """The jobs that get reference runs (the test sequences; none when ``references.count`` is 0)."""
        return [job for job in self.jobs if job.split == "test"] if self.references.count else []

    def garment_spec(self, name: str) -> GarmentSpec:
        """Garment ``name``'s entry as a typed spec (its defaults filled in)."""
        spec = self.garments[name]
        return config_from_dict(TemplateGarment if "template" in spec else FileGarment, spec, self.path)

    def motion_spec(self, name: str) -> MotionSpec:
        """Motion ``name``'s entry as a typed spec (its defaults filled in)."""
        spec = self.motions[name]
        return config_from_dict(ProceduralMotion if "procedural" in spec else FileMotion, spec, self.path)

    def resolve(self, value: str) -> Path:
        """A path from the plan, relative to the plan's folder."""
        return _plan_file(self.path, value)


def _plan_file(plan_path: Path, value: str) -> Path:
    """``value``, a path written in the plan ``plan_path``, relative to the plan's folder."""
    path = Path(value).expanduser()
    return path if path.is_absolute() else plan_path.parent / path


def _mapping(value, what: str, path: Path) -> dict:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise InputError(f"{what} must be a mapping, got {type(value).__name__}", path)
    return value


def _named(section: dict, what: str, path: Path) -> dict:
    for name in section:
        if not isinstance(name, str) or not _NAME.match(name):
            raise InputError(f"{what} name {name!r} must be 1-61 characters from [A-Za-z0-9_.=-] (no '+')", path)
    return section


def _check_keys(spec: dict, allowed: set[str], what: str, path: Path) -> None:
    unknown = sorted(set(spec) - allowed)
    if unknown:
        raise InputError(f"{what}: unknown keys {unknown}; allowed: {sorted(allowed)}", path)


def _typed(cls: type, spec: dict, what: str, path: Path) -> dict:
    """``spec`` checked as a ``cls`` (unknown keys, types, ranges by :mod:`loosefit.config`); returned as
    written, defaults not filled in, so that job hashes stay those of the file's text."""
    _check_keys(spec, {f.name for f in dataclasses.fields(cls)}, what, path)
    try:
        config_from_dict(cls, spec, path)
    except InputError as e:
        raise InputError(f"{what}: {e.problem.removeprefix('config: ')}", path) from None
    return spec


def _garment_spec(name: str, spec, path: Path) -> dict:
    spec = _mapping(spec, f"garment {name!r}", path)
    if ("template" in spec) == ("file" in spec):
        raise InputError(f"garment {name!r} needs exactly one of 'template' or 'file'", path)
    return _typed(TemplateGarment if "template" in spec else FileGarment, spec, f"garment {name!r}", path)


def _motion_spec(name: str, spec, path: Path) -> dict:
    spec = _mapping(spec, f"motion {name!r}", path)
    if ("procedural" in spec) == ("file" in spec):
        raise InputError(f"motion {name!r} needs exactly one of 'procedural' or 'file'", path)
    return _typed(ProceduralMotion if "procedural" in spec else FileMotion, spec, f"motion {name!r}", path)


def _shape_spec(name: str, spec, path: Path) -> dict:
    from loosefit.body import AnnyShape

    spec = _mapping(spec, f"shape {name!r}", path)
    try:
        AnnyShape(**spec)
    except TypeError:
        raise InputError(f"shape {name!r}: unknown values {sorted(set(spec) - set(AnnyShape.names()))}", path) from None
    except InputError as e:
        raise InputError(f"shape {name!r}: {e.problem}", path) from None
    return spec


def _references(value, path: Path) -> ReferencePlan:
    spec = _mapping(value, "references", path)
    _check_keys(spec, {f.name for f in dataclasses.fields(ReferencePlan)}, "references", path)
    try:
        return config_from_dict(ReferencePlan, spec, path)
    except InputError as e:
        raise InputError(f"references: {e.problem.removeprefix('config: ')}", path) from None


def load_plan(path: str | Path) -> Plan:
    """Read and check a plan file; expand its sequence groups into :class:`SequenceJob` s.

    Raises:
        InputError: naming the plan file and the problem (unknown key, undefined name, bad value).
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise InputError(f"cannot read simulation plan: {e}", path) from None
    raw = load_yaml(text, path)  # loosefit.config's reader: "1e-5" is a number
    raw = _mapping(raw, "a simulation plan", path)
    _check_keys(raw, _TOP_KEYS, "plan", path)
    shapes = _named(_mapping(raw.get("shapes"), "shapes", path), "shape", path) or {"average": {}}
    shapes = {n: _shape_spec(n, s, path) for n, s in shapes.items()}
    garments = _named(_mapping(raw.get("garments"), "garments", path), "garment", path)
    garments = {n: _garment_spec(n, s, path) for n, s in garments.items()}
    motions = _named(_mapping(raw.get("motions"), "motions", path), "motion", path)
    motions = {n: _motion_spec(n, s, path) for n, s in motions.items()}
    missing = [n for n, s in motions.items() if s.get("optional") is True and not _plan_file(path, s["file"]).is_file()]
    motions = {n: s for n, s in motions.items() if n not in missing}
    params_raw = _named(_mapping(raw.get("sim_params"), "sim_params", path), "sim_params", path) or {"default": {}}
    sim_params = {n: SimParams.from_dict(_mapping(v, f"sim_params {n!r}", path), path) for n, v in params_raw.items()}
    if not garments or not motions:
        raise InputError("a plan needs at least one garment and one motion", path)
    for name, spec in garments.items():
        if "shape" in spec and spec["shape"] not in shapes:
            raise InputError(f"garment {name!r}: shape {spec['shape']!r} is not in shapes {list(shapes)}", path)
    plan = Plan(
        name=str(raw.get("name", path.stem)),
        path=path,
        shapes=shapes,
        garments=garments,
        motions=motions,
        sim_params=sim_params,
        gate=QualityGate.from_dict(_mapping(raw.get("gate"), "gate", path), path),
        references=_references(raw.get("references"), path),
        missing_motions=missing,
    )
    plan.jobs = _expand(plan, raw.get("sequences"), _mapping(raw.get("split"), "split", path))
    return plan


def _expand(plan: Plan, groups, split: dict) -> list[SequenceJob]:
    path = plan.path
    available = {
        "garments": plan.garments, "shapes": plan.shapes, "motions": plan.motions, "sim_params": plan.sim_params
    }
    if groups is None:
        groups = [{}]
    if not isinstance(groups, list):
        raise InputError("sequences must be a list of groups", path)
    _check_keys(split, set(_SPLITS), "split", path)
    held_out = {}
    for which, lists in split.items():
        lists = _mapping(lists, f"split {which!r}", path)
        _check_keys(lists, set(_GROUP_KEYS), f"split {which!r}", path)
        for key, names in lists.items():
            for name in names or []:
                if key == "motions" and name in plan.missing_motions:
                    continue
                if name not in available[key]:
                    raise InputError(f"split {which!r}: {key} {name!r} is not defined in the plan", path)
                held_out.setdefault((key, name), which)
    jobs: dict[str, SequenceJob] = {}
    for i, group in enumerate(groups):
        group = _mapping(group, f"sequences[{i}]", path)
        _check_keys(group, set(_GROUP_KEYS), f"sequences[{i}]", path)
        lists = []
        for key in _GROUP_KEYS:
            names = group.get(key, list(available[key]))
            if not isinstance(names, list) or not names:
                raise InputError(f"sequences[{i}].{key} must be a non-empty list of names", path)
            if key == "motions":
                names = [n for n in names if n not in plan.missing_motions]  # may leave the group empty
            for name in names:
                if name not in available[key]:
                    what = key if key == "sim_params" else key[:-1]
                    raise InputError(f"sequences[{i}]: {what} {name!r} is not defined in the plan", path)
            lists.append(names)
        for garment, shape, motion, params in itertools.product(*lists):
            fixed_shape = plan.garments[garment].get("shape")
            if fixed_shape is not None and fixed_shape != shape:
                continue  # a garment file fits its own shape only
            names = {"garments": garment, "shapes": shape, "motions": motion, "sim_params": params}
            splits = {held_out.get((key, name)) for key, name in names.items()}
            job_split = "test" if "test" in splits else "val" if "val" in splits else "train"
            job_id = SEPARATOR.join((garment, shape, motion, params))
            content = {
                "garment": plan.garments[garment],
                "shape": plan.shapes[shape],
                "motion": plan.motions[motion],
                "sim_params": plan.sim_params[params].to_dict(),
                "gate": vars(plan.gate),
            }
            if content["sim_params"]["backend"] == "blender":
                del content["sim_params"]["backend"]  # sequences stored before there were backends stay valid
            digest = hashlib.sha256(json.dumps(content, sort_keys=True, default=str).encode()).hexdigest()[:16]
            jobs[job_id] = SequenceJob(job_id, garment, shape, motion, params, job_split, digest)
    if not jobs:
        raise InputError("the plan's sequence groups select no sequence", path)
    return list(jobs.values())
