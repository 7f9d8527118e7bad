"""Body landmarks the garment templates are fitted to, measured on the rest-pose body."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

from loosefit.body.base import BodyModel
from loosefit.errors import InputError
from loosefit.geometry.signed_distance import BodySDF, PosedBodySDF

#: Joint names per rig family: Anny ``cmu_mb`` first, SMPL / SMPL-X second.
JOINT_NAMES = {
    "shoulder": (("LeftArm", "RightArm"), ("left_shoulder", "right_shoulder")),
    "elbow": (("LeftForeArm", "RightForeArm"), ("left_elbow", "right_elbow")),
    "wrist": (("LeftHand", "RightHand"), ("left_wrist", "right_wrist")),
    "hip": (("LeftUpLeg", "RightUpLeg"), ("left_hip", "right_hip")),
    "knee": (("LeftLeg", "RightLeg"), ("left_knee", "right_knee")),
    "neck": (("Neck", "Neck"), ("neck", "neck")),
}


def _descendants(parents: np.ndarray, root: int) -> list[int]:
    out = [root]
    for j in range(len(parents)):
        k = j
        while k >= 0 and k != root:
            k = parents[k]
        if k == root and j != root:
            out.append(j)
    return out


@dataclass
class BodyLandmarks:
    """Measurements of a rest-pose body (Z up, front -Y, left +X, metres).

    Attributes:
        verts: ``(V, 3)`` float64 rest vertices; ``faces (F, 3)`` int64.
        sdf: signed distance to the body.
        arm_weight: ``(V, 2)`` skinning weight of the left / right arm chains (shoulder joint and below).
        joints: name -> ``(2, 3)`` left / right joint positions (``neck`` twice).
        waist_z: height of the narrowest torso section between hips and chest.
        crotch_z: lowest body point between the legs.
        armpit_z: lowest point where torso and arm meet.
        center_y: front-back centre of the torso at the waist.
    """

    verts: np.ndarray
    faces: np.ndarray
    sdf: BodySDF
    arm_weight: np.ndarray
    joints: dict
    waist_z: float
    crotch_z: float
    armpit_z: float
    center_y: float

    @property
    def torso_mask(self) -> np.ndarray:
        """``(V,)`` vertices on the torso, legs and head (not on the arms)."""
        return self.arm_weight.sum(1) < 0.3

    def along_arm(self, points: np.ndarray, side: int) -> np.ndarray:
        """``(N,)`` position of ``points (N, 3)`` along the arm as a fraction of shoulder-to-wrist:
        0 at the shoulder joint, 1 at the wrist (projection on the upper arm, then on the forearm)."""
        s, e, w = self.joints["shoulder"][side], self.joints["elbow"][side], self.joints["wrist"][side]
        upper, fore = np.linalg.norm(e - s), np.linalg.norm(w - e)
        t_upper = (points - s) @ ((e - s) / upper)
        t_fore = upper + (points - e) @ ((w - e) / fore)
        return np.maximum(t_upper, t_fore) / (upper + fore)


def measure_body(body: BodyModel, shape=None, like: BodySDF | None = None) -> BodyLandmarks:
    """Measure ``body`` (rest pose of ``shape``) for garment fitting. ``like``: the signed distance of the same
    body in another shape, whose edge map the new one reuses (:class:`~loosefit.geometry.signed_distance.
    PosedBodySDF`: the same distances, in a third less time; the body-shape search measures dozens)."""
    verts = np.asarray(body.rest_verts(shape), dtype=np.float64)
    faces = np.asarray(body.faces, dtype=np.int64)
    rest_joints = np.asarray(body.rest_joints(shape), dtype=np.float64)
    names = list(body.joint_names)
    joints = {}
    ids = {}
    for key, families in JOINT_NAMES.items():
        for pair in families:
            if all(n in names for n in pair):
                ids[key] = [names.index(n) for n in pair]
                joints[key] = rest_joints[ids[key]]
                break
        else:
            raise InputError(f"body {body.name!r} rig {body.rig!r} has no joints named {families[0]} or {families[1]}")
    weights = body.skinning_weights()
    parents = np.asarray(body.parents)
    arm_weight = np.stack([weights[:, _descendants(parents, j)].sum(1) for j in ids["shoulder"]], 1).astype(np.float64)
    torso = arm_weight.sum(1) < 0.3

    hip_z = float(joints["hip"][:, 2].mean())
    shoulder_z = float(joints["shoulder"][:, 2].mean())
    knee_z = float(joints["knee"][:, 2].mean())
    zs = np.linspace(hip_z + 0.25 * (shoulder_z - hip_z), hip_z + 0.7 * (shoulder_z - hip_z), 24)
    perimeters = []
    for z in zs:
        pts = verts[torso & (np.abs(verts[:, 2] - z) < 0.01), :2]
        perimeters.append(ConvexHull(pts).area if len(pts) >= 3 else np.inf)
    waist_z = float(zs[int(np.argmin(perimeters))])

    mid = torso & (np.abs(verts[:, 0]) < 0.015) & (verts[:, 2] > knee_z) & (verts[:, 2] < hip_z + 0.1)
    crotch_z = float(verts[mid, 2].min()) if mid.any() else hip_z - 0.08
    seam = (arm_weight.max(1) > 0.35) & (arm_weight.max(1) < 0.65)
    armpit_z = float(verts[seam, 2].min()) if seam.any() else shoulder_z - 0.1
    ring = verts[torso & (np.abs(verts[:, 2] - waist_z) < 0.01)]
    center_y = float(0.5 * (ring[:, 1].min() + ring[:, 1].max()))
    return BodyLandmarks(
        verts=verts,
        faces=faces,
        sdf=BodySDF(verts, faces) if like is None else PosedBodySDF(verts, like),
        arm_weight=arm_weight,
        joints=joints,
        waist_z=waist_z,
        crotch_z=crotch_z,
        armpit_z=armpit_z,
        center_y=center_y,
    )
