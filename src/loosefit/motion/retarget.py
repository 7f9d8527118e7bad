"""Retargeting a foreign skeleton's motion onto a body rig by matching bone directions.

The source is any skeleton animated in world space (BVH forward kinematics, SMPL-H from AMASS, a
loosefit body); the target is a rig in loosefit's convention (world-aligned joint frames at rest,
``W_j = W_parent @ R_j``). A :class:`~loosefit.motion.joint_map.JointMap` pairs target joints with source joints by name.

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
measured from the feet, and the target's feet then meet the floor where the source's do (see
:func:`retarget`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from loosefit.errors import InputError
from loosefit.geometry.lbs import forward_kinematics, topological_order
from loosefit.geometry.rotations import (
    axis_angle_to_matrix,
    matrix_to_quaternion,
    nearest_rotation,
    quaternion_to_axis_angle,
    rotation_angle,
    rotation_between,
)
from loosefit.geometry.vectors import unit
from loosefit.motion.joint_map import ResolvedMap
from loosefit.motion.motion import Motion
from loosefit.motion.resample import resample_quaternions
from loosefit.motion.rig import Roles, TargetRig

# Weighted-frame calibration: frames whose bone is within about this angle of the rest direction count.
_CALIBRATION_SIGMA = np.radians(15.0)
# A bone shorter than this fraction of the leg length has no usable direction.
_SHORT_BONE = 1e-3
#: How far (metres) a retargeted motion's lowest foot joint at contact may be from its standing height.
FEET_TOLERANCE = 0.12


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



def _twist_fit(W: np.ndarray, axis: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Rotate ``W (F, 3, 3)`` about unit ``axis (F, 3)`` so that directions ``v (F, m, 3)`` best meet
    ``u (F, m, 3)`` seen along the axis (closed form least squares)."""
    a = axis[:, None]
    vp = v - (v * a).sum(-1, keepdims=True) * a
    up = u - (u * a).sum(-1, keepdims=True) * a
    angle = np.arctan2((np.cross(vp, up) * a).sum((-1, -2)), (vp * up).sum((-1, -2)))
    return axis_angle_to_matrix(axis * angle[..., None]).numpy() @ W


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
        d = unit(self.target.rest[kids] - self.target.rest[j])
        u = unit(positions[:, self.src[kids]] - positions[:, self.src[j], None])
        return d, u

    def _match(self, j: int, cand: np.ndarray, d: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Turn ``cand (F, 3, 3)`` so the main bone points exactly along the source's and the
        others best fit about it."""
        k = self.primary[j]
        W = rotation_between(cand @ d[k], u[:, k]).numpy() @ cand
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
                R = rotation_between(predicted[:, k], u[:, k]).numpy()
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


def source_root_path(positions: np.ndarray, probe: np.ndarray, target: TargetRig, resolved: ResolvedMap,
                     path: Path | None = None) -> np.ndarray:
    """The source's root joint path ``(T, 3)`` in the target's metres: ``positions (T, Js, 3)`` of the source
    root (the joint paired with the target's root) scaled by the leg-length ratio, as :func:`retarget` scales
    it; ``probe (Js, 3)``: the pose the source's legs are measured in (its rest pose, as :func:`retarget`
    measures them). Any axes: only distances matter to the caller. ``path``: the source file, named in errors."""
    source_of = np.full(len(target.joint_names), -1)
    for j, s in resolved.source_of.items():
        source_of[j] = s

    def src_index(name: str) -> int:
        return int(source_of[target.joint_names.index(name)])

    leg_source = _leg_length(probe, src_index, target.roles)
    if not leg_source > 0:
        raise InputError("source legs have zero length", path)
    scale = _leg_length(target.rest, target.joint_names.index, target.roles) / leg_source
    return positions[:, src_index(target.roles.root)] * scale


def standing(positions: np.ndarray, src_of_name, roles: Roles, max_angle: float = 45.0) -> bool:
    """Whether a Z-up pose ``positions (J, 3)`` stands: both legs hang within ``max_angle`` degrees
    of straight down and the spine rises within ``max_angle`` of straight up."""
    cos = np.cos(np.radians(max_angle))
    for hip, _, ankle in roles.legs:
        if unit(positions[src_of_name(hip)] - positions[src_of_name(ankle)])[2] < cos:
            return False
    top = [n for n in roles.spine if src_of_name(n) >= 0][-1]
    return unit(positions[src_of_name(top)] - positions[src_of_name(roles.root)])[2] >= cos


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
    the target's lowest foot joint at rest (loosefit bodies stand with their soles on ``z = 0``). Either
    way the root is then raised or lowered so that the target's posed feet touch the floor as the
    source's do (:func:`_match_contact`).

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
    rest = ref_pos[0] if calibration == "rest" else None
    return local, _match_contact(local, _root_positions(solver, source, rest), solver, source, rest)


def check_feet_on_floor(local: np.ndarray, root: np.ndarray, target: TargetRig, path: Path | None = None,
                        tolerance: float = FEET_TOLERANCE) -> float:
    """Check that a retargeted motion stands on the floor; return its foot height error, metres.

    The lowest foot joint (:attr:`Roles.feet`) of each frame, at contact (5th percentile over the
    frames, so jumps and steps do not count), must be within ``tolerance`` of its height when the rig
    stands in its rest pose on the floor.

    Args:
        local: ``(T, J, 3, 3)`` local rotations of ``target``'s joints.
        root: ``(T, 3)`` root joint positions, metres.

    Raises:
        InputError: naming ``path``, with how far the feet are above or below the floor.
    """
    up = np.asarray(target.roles.up, np.float64)
    feet = [target.joint_names.index(n) for n in target.roles.feet]
    with torch.no_grad():
        world = forward_kinematics(torch.from_numpy(local), torch.from_numpy(np.asarray(root, np.float64)),
                                   torch.from_numpy(target.rest), target.parents)
    error = contact_height(world[:, feet, :3, 3].numpy() @ up) - float((target.rest[feet] @ up).min())
    if abs(error) > tolerance:
        where = "above" if error > 0 else "below"
        raise InputError(f"the imported body's feet are {abs(error):.2f} m {where} the floor where they touch it "
                         f"(more than {tolerance:g} m): the file's root translation does not fit its skeleton", path)
    return error


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
    W_ref = solver.calibrate(ref_pos, rotation_between(up_t, np.array([0.0, 0.0, 1.0])).numpy())
    mapped = np.flatnonzero(solver.src >= 0)
    parents = target.parents
    swing = np.stack([
        rotation_angle(np.swapaxes(W_ref[:, parents[j]], -1, -2) @ W_ref[:, j]).numpy()
        if parents[j] >= 0 else np.zeros(len(ref_pos))
        for j in mapped
    ], 1)  # (F, n mapped)
    C, root_local = {}, np.zeros((0, 3))
    for col, j in enumerate(mapped):
        theta = swing.mean(1) if parents[j] < 0 else swing[:, col]
        w = np.exp(-(theta**2 - theta.min() ** 2) / _CALIBRATION_SIGMA**2)
        C[j] = nearest_rotation(np.einsum("f,fba,fbc->ac", w, ref_rot[:, solver.src[j]], W_ref[:, j])).numpy()
        if parents[j] < 0 and j in solver.pairs:
            _, u = solver.directions(ref_pos, j)
            root_local = unit(np.einsum("f,fba,fnb->na", w, ref_rot[:, solver.src[j]], u))
    return C, root_local


def _root_positions(solver: _Solver, source: SourceAnimation, rest: np.ndarray | None) -> np.ndarray:
    """World positions ``(T, 3)`` of the target root: horizontal motion scaled by the leg-length
    ratio; height from the feet as :func:`retarget` describes (``rest``: the source's rest pose
    ``(Js, 3)``, ``None`` for floor contact)."""
    target, roles = solver.target, solver.roles
    up_t = np.asarray(roles.up, np.float64)
    scale = solver.leg_target / solver.leg_source
    feet_t = _mapped_feet(solver)
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
        contact = contact_height(source.positions[:, feet_s, 2])
        root[:, 2] = float(np.min(target.rest[feet_t] @ up_t)) + scale * (height - contact)
    return root


def _mapped_feet(solver: _Solver) -> list[int]:
    """The target's foot joints (:attr:`Roles.feet`) that have a source joint."""
    names = solver.target.joint_names
    return [names.index(n) for n in solver.roles.feet if solver.src_index(n) >= 0]


def contact_height(feet: np.ndarray) -> float:
    """The height of floor contact from foot joint heights ``(T, F)``: the 5th percentile over the frames
    of the lowest foot joint, so that steps and jumps do not count."""
    return float(np.percentile(feet.min(1), 5))


def _match_contact(local: np.ndarray, root: np.ndarray, solver: _Solver, source: SourceAnimation,
                   rest: np.ndarray | None) -> np.ndarray:
    """``root (T, 3)`` raised or lowered so that the target's feet meet the floor as the source's do.

    The root height from :func:`_root_positions` scales the source's root height with the legs, but the
    target's bones take the source's directions: a source foot that slopes more steeply from ankle to toes
    tilts the target's foot as much, and legs of other proportions bend differently, so the target's feet
    end up a few centimetres above or below where the source's are (2.4 cm under the floor for an ankle
    3 cm higher above the toes). The shift makes the target's contact height (:func:`contact_height` of
    its posed foot joints) what it would be if its root stood above its lowest foot joint as the source's
    does: with rest calibration (the source's rest pose ``rest (Js, 3)``), the target's rest height above
    its feet plus the source's excess over its own rest height, scaled; with floor-contact calibration
    (``rest`` None), the target's rest foot height. A source of the target's own skeleton is unchanged.
    """
    target, roles = solver.target, solver.roles
    up = np.asarray(roles.up, np.float64)
    feet_t = _mapped_feet(solver)
    with torch.no_grad():  # posed joints in the Z-up world
        world = forward_kinematics(torch.from_numpy(local), torch.from_numpy(root), torch.from_numpy(target.rest),
                                   target.parents)[:, feet_t, :3, 3].numpy()
    if rest is None:
        wanted = float(np.min(target.rest[feet_t] @ up))
    else:
        feet_s, root_s = solver.src[feet_t], solver.src_index(roles.root)
        root_t = target.rest[target.joint_names.index(roles.root)]
        above_t = float(np.max((root_t - target.rest[feet_t]) @ up))
        above_s = float(np.max(rest[root_s, 2] - rest[feet_s, 2]))
        over_s = source.positions[:, root_s, 2] - source.positions[:, feet_s, 2].min(1)
        scale = solver.leg_target / solver.leg_source
        wanted = contact_height((root[:, 2] - above_t - scale * (over_s - above_s))[:, None])
    root = root.copy()
    root[:, 2] -= contact_height(world[..., 2]) - wanted  # world heights are Z up, the rig's rest ``up``
    return root


def to_motion(local: np.ndarray, root: np.ndarray, fps: float, target: TargetRig, name: str, out_fps: float) -> Motion:
    """A :class:`Motion` from retargeted local rotations ``(T, J, 3, 3)`` and root positions ``(T, 3)``
    at ``fps``, resampled to ``out_fps``."""
    q = matrix_to_quaternion(torch.from_numpy(local)).numpy()
    if abs(fps - out_fps) >= 1e-9 * out_fps:
        q, root = resample_quaternions(q, root, fps, out_fps)
    rotations = quaternion_to_axis_angle(torch.from_numpy(q)).numpy()
    return Motion(rotations, root, out_fps, target.name, target.joint_names, name)
