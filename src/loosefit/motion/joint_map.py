"""Joint maps: which joint of a foreign skeleton drives which joint of a body rig.

A map is a YAML file (format in :class:`JointMap`); the built-in ones are in
``loosefit/motion/joint_maps/`` (``cmu``, ``mixamo``, ``cc``, ``smplh``). :func:`resolve_joint_map`
applies a map to one source skeleton and checks that it fits.
"""

from __future__ import annotations

import fnmatch
import functools
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from loosefit.config import load_yaml, read_yaml_text
from loosefit.errors import InputError
from loosefit.motion.axes import parse_axis
from loosefit.motion.rig import TargetRig


#: The keys a joint map YAML may have.
MAP_KEYS = ("name", "target_rig", "joints", "ignore", "optional", "calibration", "up", "front")
#: What an error for a skeleton no map fits tells the user to do.
WRITE_A_MAP = ("write a starting map with `loosefit motion map FILE.bvh --out MAP.yaml`, check it, and pass it "
               "with --joint-map MAP.yaml")


@dataclass(frozen=True)
class JointMap:
    """Which source joint drives which target joint.

    YAML form (every key but ``joints`` optional)::

        name: my-skeleton
        target_rig: cmu_mb          # rig whose joint names are the keys of ``joints``
        joints:                     # target joint: source joint (or a list of alternatives)
          Hips: pelvis
          LeftUpLeg: [l_hip, LeftHip]
        ignore: [prop_*, "*_twist"] # source joints with no target (fnmatch patterns)
        optional: [LeftToeBase]     # target joints whose source may be absent from a file
        calibration: rest           # rest | motion (default: rest if the rest pose stands)
        up: y                       # source up axis (+x, -y, z ...), default: detected
        front: z                    # source front axis, default: detected

    Source names match with or without a namespace prefix (``mixamorig:Hips`` matches ``Hips``).
    Every source joint must be mapped or ignored, and every non-optional mapped source joint must be
    in the file; otherwise import fails with an error listing them.
    """

    name: str
    joints: dict[str, tuple[str, ...]]
    ignore: tuple[str, ...] = ()
    optional: tuple[str, ...] = ()
    target_rig: str = "cmu_mb"
    calibration: str | None = None
    up: str | None = None
    front: str | None = None
    path: Path | None = field(default=None, compare=False)

    @classmethod
    def from_dict(cls, data, path: Path | None = None) -> "JointMap":
        """Build and validate a map from its YAML content; errors name ``path``."""
        if not isinstance(data, dict):
            raise InputError("joint map must be a mapping with a 'joints' key", path)
        unknown = sorted(set(map(str, data)) - set(MAP_KEYS))
        if unknown:
            raise InputError(f"joint map has unknown keys {unknown}; the allowed keys are {', '.join(MAP_KEYS)}", path)
        joints = data.get("joints")
        if not isinstance(joints, dict) or not joints:
            raise InputError("joint map needs a non-empty 'joints' mapping (target joint: source joint)", path)
        parsed = {}
        for target, source in joints.items():
            alts = [source] if isinstance(source, str) else source
            if not (isinstance(alts, list) and alts and all(isinstance(a, str) and a for a in alts)):
                raise InputError(f"joint map entry {target!r} must name a source joint or a list of them", path)
            parsed[str(target)] = tuple(alts)
        lists = {}
        for key in ("ignore", "optional"):
            value = data.get(key) or []
            if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
                raise InputError(f"joint map {key!r} must be a list of names", path)
            lists[key] = tuple(value)
        calibration = data.get("calibration")
        if calibration not in (None, "rest", "motion"):
            raise InputError(f"joint map calibration must be 'rest' or 'motion', got {calibration!r}", path)
        for key in ("up", "front"):
            if data.get(key) is not None:
                parse_axis(data[key], path)
        return cls(
            name=str(data.get("name", path.stem if path else "custom")),
            joints=parsed,
            ignore=lists["ignore"],
            optional=lists["optional"],
            target_rig=str(data.get("target_rig", "cmu_mb")),
            calibration=calibration,
            up=data.get("up"),
            front=data.get("front"),
            path=path,
        )

    def inverted(self, name: str, target_rig: str) -> "JointMap":
        """The map read the other way (source joints become targets, first alternatives only);
        joints it leaves out are ignored."""
        return JointMap(name, {alts[0]: (t,) for t, alts in self.joints.items()}, ignore=("*",),
                        target_rig=target_rig, calibration="rest")


def load_joint_map(path: str | Path) -> JointMap:
    """Read a YAML joint map (format in :class:`JointMap`)."""
    path = Path(path)
    text = read_yaml_text(path, "joint map")
    try:
        data = load_yaml(text, path)  # safe, and a key given twice (a joint mapped twice) is an error
    except InputError as e:
        raise InputError(f"cannot read joint map: {e.problem}", path) from None
    return JointMap.from_dict(data, path)


@functools.lru_cache(maxsize=1)
def builtin_joint_maps() -> dict[str, JointMap]:
    """The maps shipped in ``loosefit/motion/joint_maps/``: ``cmu``, ``mixamo``, ``cc`` (Character
    Creator), ``smplh`` (AMASS)."""
    folder = resources.files("loosefit.motion") / "joint_maps"
    maps = {}
    for item in sorted(folder.iterdir(), key=lambda p: p.name):
        if item.name.endswith(".yaml"):
            with resources.as_file(item) as path:
                maps[path.stem] = load_joint_map(path)
    return maps


def _short_name(name: str) -> str:
    """A joint name without namespace prefix: ``mixamorig:Hips`` -> ``Hips``."""
    return name.replace("|", ":").rsplit(":", 1)[-1]


@dataclass
class ResolvedMap:
    """A joint map applied to one source skeleton: ``source_of[target joint index] = source index``."""

    joint_map: JointMap
    source_of: dict[int, int]


def resolve_joint_map(
    source_names: list[str],
    source_parents: np.ndarray,
    target: TargetRig,
    joint_map: JointMap | str | Path | None = None,
    path: Path | None = None,
    skip: np.ndarray | None = None,
) -> ResolvedMap:
    """Pair target joints with source joints.

    Args:
        source_names: the source skeleton's joint names.
        source_parents: ``(J,)`` the source skeleton's parent indices.
        target: the rig to retarget onto.
        joint_map: a :class:`JointMap`, the name of a built-in map (``"cmu"``, ``"mixamo"``, ``"cc"``),
            a YAML file, or ``None`` to pick the built-in map that fits the names best.
        path: the source file, named in errors.
        skip: ``(J,)`` bool, source entries that need no mapping (BVH End Sites).

    Raises:
        InputError: listing source joints neither mapped nor ignored, mapped source joints missing
            from the file, target joints the rig lacks, joints that retargeting needs and the map
            leaves out, or pairs whose parent-child order differs between the skeletons.
    """
    skip = np.zeros(len(source_names), bool) if skip is None else skip
    hint = ""
    if joint_map is None:
        candidates = [m for m in builtin_joint_maps().values() if m.target_rig == target.name]
        if not candidates:
            raise InputError(f"no built-in joint map targets rig {target.name!r}; {WRITE_A_MAP}", path)
        joint_map = max(candidates, key=lambda m: _coverage(m, source_names))
        hint = f" (the closest built-in map; for another skeleton {WRITE_A_MAP})"
    elif isinstance(joint_map, str) and joint_map in builtin_joint_maps():
        joint_map = builtin_joint_maps()[joint_map]
    elif not isinstance(joint_map, JointMap):
        joint_map = load_joint_map(joint_map)
    if joint_map.target_rig != target.name:
        raise InputError(
            f"joint map {joint_map.name!r} targets rig {joint_map.target_rig!r}, the body uses {target.name!r}", path)
    where = _name_index(source_names)
    bad_targets = sorted(set(joint_map.joints) - set(target.joint_names))
    if bad_targets:
        raise InputError(
            f"joint map {joint_map.name!r} names joints that rig {target.name!r} lacks: {bad_targets}", joint_map.path)
    source_of, missing = {}, []
    for tname, alts in joint_map.joints.items():
        found = next((where[a] for a in alts if a in where), None)
        if found is None:
            if tname not in joint_map.optional:
                missing.append(f"{tname} <- {' | '.join(alts)}")
            continue
        source_of[target.joint_names.index(tname)] = found
    used = set(source_of.values())
    unknown = [
        n for i, n in enumerate(source_names)
        if i not in used and not skip[i]
        and not any(fnmatch.fnmatchcase(n, p) or fnmatch.fnmatchcase(_short_name(n), p) for p in joint_map.ignore)
    ]
    problems = []
    if missing:
        problems.append(f"missing source joints (target <- source): {missing}")
    if unknown:
        problems.append(f"unknown source joints, neither mapped nor ignored: {unknown}")
    if problems:
        raise InputError(f"joint map {joint_map.name!r}{hint} does not fit: " + "; ".join(problems), path)
    doubled = sorted({source_names[s] for s in source_of.values() if list(source_of.values()).count(s) > 1})
    if doubled:
        raise InputError(f"joint map {joint_map.name!r} drives several target joints from {doubled}", path)
    roles = target.roles
    needed = [roles.root, *roles.legs[0], *roles.legs[1]]
    lacking = [n for n in needed if target.joint_names.index(n) not in source_of]
    if not any(target.joint_names.index(n) in source_of for n in roles.spine):
        lacking.append(f"one of {list(roles.spine)}")
    if lacking:
        raise InputError(f"joint map {joint_map.name!r} leaves out joints retargeting needs: {lacking}", path)
    _check_hierarchy(source_of, target, source_names, np.asarray(source_parents), path)
    return ResolvedMap(joint_map, source_of)


def _coverage(joint_map: JointMap, source_names: list[str]) -> float:
    where = _name_index(source_names)
    required = [alts for t, alts in joint_map.joints.items() if t not in joint_map.optional]
    return sum(any(a in where for a in alts) for alts in required) / max(len(required), 1)


def _name_index(names: list[str]) -> dict[str, int]:
    """Source names and their short forms -> index (full names win over short ones)."""
    where = {}
    for i, n in enumerate(names):
        where.setdefault(_short_name(n), i)
    for i, n in enumerate(names):
        where[n] = i
    return where


def _check_hierarchy(source_of: dict[int, int], target: TargetRig, source_names, source_parents, path) -> None:
    """Every mapped target joint's nearest mapped ancestor must map to an ancestor of its source."""
    for j, s in source_of.items():
        a = target.parents[j]
        while a >= 0 and a not in source_of:
            a = target.parents[a]
        if a < 0:
            continue
        p = source_parents[s]
        while p >= 0 and p != source_of[a]:
            p = source_parents[p]
        if p < 0:
            raise InputError(
                f"joint map pairs {target.joint_names[j]!r} with {source_names[s]!r}, which is not below "
                f"{source_names[source_of[a]]!r} (paired with {target.joint_names[a]!r}) in the source skeleton", path)

