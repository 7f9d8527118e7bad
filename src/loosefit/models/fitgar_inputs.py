"""FitGar's per-frame inputs for one garment-body pair (Li et al. 2023, Sec. 4.1-4.4).

A :class:`GarmentBodyPair` holds what does not change with the pose: the garment's rest mesh and
graph, the indicator (each garment vertex's anchor on the rest body, FitGar Eq. 5's
``I``: see the departure below), the body's skinning weights, rest positions and normals there, the body
shape ``beta`` and the fit attribute ``alpha``. :meth:`GarmentBodyPair.frames` turns a motion into the
inputs of every frame, all in the heading frame of that frame (:mod:`loosefit.models.motion_features`:
the body faces -Y, its root above the origin), ``T`` frames, ``V`` garment vertices, ``J`` joints:

- ``anchor (T, V, 3)``: ``I M_b``, the posed body point under each garment vertex (FitGar Eq. 5), metres;
- ``body_normal (T, V, 3)``: the posed body's area-weighted vertex normal there (interpolated, unit);
- ``body_rel (T, V, 3)``: the relative skinning feature of that body point (FitGar Sec. 4.3): its
  skinned position without the root's translation, metres;
- ``garment_rel (T, V, 3)``: the same for the garment's rest vertices, skinned with the weights of their
  body vertex (FitGar Sec. 4.4's ``p_i``);
- ``joints (T, J, 3)``: posed joint positions (for FitGar Sec. 4.4's vertex-to-joint distances ``x_i``);
- ``pose (T, 6 J)``: FitGar's ``theta``: the root's rotation without its heading, then every other
  joint's local rotation, each as 6D (first two matrix columns);
- ``rot (T, 3, 3)``, ``origin (T, 3)``: the heading frames, to put predictions back in the world.

Only the indicated body vertices and their one-ring (for the normals) are skinned, not the whole body:
the cost follows the garment.

Departure from the paper, named: the anchors are points of the body surface, not body vertices. FitGar
subdivides SMPL once (6,890 to 27,554 vertices) so that every garment vertex has a body vertex of its own
(Sec. 4.1, 4.3, 5.1). Here each garment vertex is anchored at a point of the rest body's surface: a triangle and
barycentric coordinates, with which the posed triangle's corners, their area-weighted normals (renormalised) and
skinning weights are interpolated, so the anchor stays on the posed surface. The point is the garment vertex's
projection along the body's interpolated normal field (:func:`~loosefit.geometry.features.normal_projection_points`),
with the few projections that fall within 1 mm of another one moved apart (``anchor="spread"``, the default;
:func:`~loosefit.geometry.features.spread_shared_points`); the projection alone (``anchor="normal"``); or the closest
point (``anchor="surface"``). Chosen by measurement (``benchmarks/experiments/capacity.py anchors``, seed-0
templates at 3 cm edges on the average Anny body; share of garment vertices whose anchor another one's is within 1 mm, largest group):

=========== ======== ============= ====================== ============= ============= ===================
kind        vertices closest Anny  closest vertex,        closest       projection    projection, shared
                     vertex        subdivided once        surface point along the     ones moved apart
                     (13,718)      (54,848; the paper's)                normals       (default)
=========== ======== ============= ====================== ============= ============= ===================
skirt       781      45 %, 6       10 %, 3                0.5 %, 2      0 %, 1        0 %, 1
dress       2,615    76 %, 28      56 %, 22               23 %, 19      0.6 %, 6      0 %, 1 (12 moved)
long shirt  1,807    25 %, 4       3.8 %, 3               0.4 %, 2      0 %, 1        0 %, 1
jumpsuit    2,453    58 %, 9       25 %, 9                5.6 %, 9      0.7 %, 3      0 %, 1 (13 moved)
=========== ======== ============= ====================== ============= ============= ===================

What the closest point leaves shared is low on the garment and far from the body (the dress's hem: 28 cm from the
body; the jumpsuit's trouser ends, 13 cm), two thirds of it at a body vertex itself: every point in the cone of
normals at a convex vertex has that vertex as its closest point. The projection along the normals gives each
direction a point of its own; what it leaves within 1 mm is where the normals converge under a long hem: the
dress's hem, 45 cm out, and the trouser ends project onto the toe tips, whose normals turn through 90 degrees in a
centimetre. Spreading moves those anchors (in each group all but the vertex nearest the body) by at most 6.5 mm,
in the layout of their garment vertices. ``anchor="normal"``, ``"vertex"`` (the closest body vertex, ``nearest``)
and ``"surface"`` are kept: runs record their anchor, and a run recorded before anchors were (its sizes name none)
was trained on body vertices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from loosefit.errors import InputError
from loosefit.geometry.features import (closest_body_points, coincident_groups, nearest_body_vertex,
                                        normal_projection_points, spread_shared_points)
from loosefit.geometry.lbs import forward_kinematics, linear_blend_skinning, skinning_transforms
from loosefit.geometry.normals import vertex_normals
from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.models.motion_features import motion_features
from loosefit.motion.heading import heading_frames, to_canonical
from loosefit.motion.motion import Motion

#: Columns of :func:`motion_features`' ``root`` block holding the root rotation without its heading (6D).
ROOT_TILT = slice(5, 11)


def graph_edges(faces: np.ndarray) -> np.ndarray:
    """``(2, E)`` int64 directed mesh edges, both directions of every undirected edge
    (:func:`loosefit.geometry.garment_batch.directed_edges`, the graph every garment batch builds)."""
    from loosefit.geometry.garment_batch import directed_edges

    return directed_edges(faces)


def pose_vector(motion: Motion) -> np.ndarray:
    """FitGar's pose attribute ``theta (T, 6 J)`` float32 (see the module docstring)."""
    feats = motion_features(motion)
    T = motion.num_frames
    return np.concatenate([feats["root"][:, ROOT_TILT], feats["joints"].reshape(T, -1)], 1).astype(np.float32)


#: Where a garment vertex is anchored on the body (FitGar Eq. 5's ``I M_b``; see the module docstring):
#: ``"spread"``, its projection along the body's normals with coinciding projections moved apart; ``"normal"``,
#: that projection alone; ``"surface"``, its closest point on the body surface; ``"vertex"``, its closest body
#: vertex (many-to-one on Anny), the behaviour of runs that record no anchor.
ANCHOR_MODES = ("surface", "vertex", "normal", "spread")
DEFAULT_ANCHOR = "spread"
#: Anchors closer than this (metres) in the rest pose count as shared (:func:`shared_anchor_fraction`).
SHARED_ANCHOR_DISTANCE = 1e-3


def check_anchor_mode(anchor: str) -> str:
    """``anchor`` if it is one of :data:`ANCHOR_MODES`, else :class:`InputError`."""
    if anchor not in ANCHOR_MODES:
        raise InputError(f"the anchor must be one of {ANCHOR_MODES}, got {anchor!r}")
    return anchor


@dataclass
class GarmentBodyPair:
    """A garment in the rest pose of a body shape (see the module docstring).

    Attributes:
        garment_verts: ``(V, 3)`` float32 rest garment, metres. faces: ``(F, 3)`` int64. edges: ``(2, E)`` int64.
        nearest: ``(V,)`` int64: the closest rest body vertex of each garment vertex (``"vertex"`` anchors), or
            the corner of its anchor's triangle with the largest barycentric coordinate (the others).
        ring_rest: ``(U, 3)`` float32 rest positions of the body vertices in the faces around the anchors'
            corners; ring_weights: ``(U, J)`` float32 their skinning weights; ring_faces: ``(K, 3)`` int64 those
            faces in that numbering; ring_tri: ``(V, 3)`` int64 where each anchor's three corners are (one
            vertex three times for ``"vertex"`` anchors); bary: ``(V, 3)`` float64 the anchor's barycentric
            coordinates on them (``1, 0, 0`` for ``"vertex"`` anchors).
        weights: ``(V, J)`` float32 skinning weights at the anchors (interpolated; borrowed by the garment).
        rest_joints: ``(J, 3)`` float32. parents: ``(J,)`` int64.
        shape: ``(S,)`` float32 body shape ``beta``. alpha: ``(F,)`` float32 fit attribute.
        anchor: ``"spread"``, ``"normal"``, ``"surface"`` or ``"vertex"`` (:data:`ANCHOR_MODES`).
    """

    garment_verts: np.ndarray
    faces: np.ndarray
    edges: np.ndarray
    nearest: np.ndarray
    ring_rest: np.ndarray
    ring_weights: np.ndarray
    ring_faces: np.ndarray
    ring_tri: np.ndarray
    bary: np.ndarray
    weights: np.ndarray
    rest_joints: np.ndarray
    parents: np.ndarray
    shape: np.ndarray
    alpha: np.ndarray
    anchor: str = DEFAULT_ANCHOR

    @classmethod
    def build(cls, garment_verts: np.ndarray, faces: np.ndarray, body, shape, alpha: np.ndarray,
              anchor: str = DEFAULT_ANCHOR) -> "GarmentBodyPair":
        """The pair of a garment ``(V, 3)`` fitted to ``body`` (a :class:`~loosefit.body.base.BodyModel`) of
        ``shape`` (the body's shape values, e.g. Anny's six), with fit attribute ``alpha (F,)``, anchored
        by ``anchor`` (:data:`ANCHOR_MODES`)."""
        check_anchor_mode(anchor)
        garment_verts = np.asarray(garment_verts, np.float32)
        faces = np.asarray(faces, np.int64)
        shape = np.asarray(shape, np.float32).reshape(-1)
        alpha = np.asarray(alpha, np.float32).reshape(-1)
        if not (np.isfinite(alpha).all() and np.isfinite(shape).all()):
            raise InputError("the fit attribute and the body shape must be finite")
        rest = body.rest_verts(shape)
        body_faces = np.asarray(body.faces, np.int64)
        if anchor == "vertex":
            nearest = nearest_body_vertex(garment_verts, rest)
            corners = np.repeat(nearest[:, None], 3, 1)
            bary = np.tile([1.0, 0.0, 0.0], (len(nearest), 1))
        else:
            project = closest_body_points if anchor == "surface" else normal_projection_points
            face, bary = project(garment_verts, rest, body_faces)
            if anchor == "spread":
                face, bary = spread_shared_points(garment_verts, rest, body_faces, face, bary,
                                                  min_distance=SHARED_ANCHOR_DISTANCE)
            corners = body_faces[face]
            nearest = corners[np.arange(len(corners)), bary.argmax(1)]
        around = body_faces[np.isin(body_faces, corners).any(1)]
        ring, local = np.unique(around, return_inverse=True)
        weights = body.skinning_weights()
        anchored = np.einsum("vk,vkj->vj", bary, weights[corners])
        return cls(garment_verts, faces, graph_edges(faces), nearest, rest[ring].astype(np.float32),
                   weights[ring].astype(np.float32), local.reshape(-1, 3).astype(np.int64),
                   np.searchsorted(ring, corners).astype(np.int64), bary.astype(np.float64),
                   anchored.astype(np.float32), body.rest_joints(shape).astype(np.float32),
                   np.asarray(body.parents, np.int64), shape, alpha, anchor)

    @property
    def num_verts(self) -> int:
        return len(self.garment_verts)

    def rest_anchors(self) -> np.ndarray:
        """``(V, 3)`` float64 the anchors on the rest body, metres."""
        return np.einsum("vk,vkc->vc", self.bary, self.ring_rest[self.ring_tri].astype(np.float64))

    def frames(self, motion: Motion) -> dict[str, np.ndarray]:
        """The per-frame inputs of ``motion`` (keys and shapes in the module docstring), float32."""
        return self.inputs(pose_motion(self.rest_joints, self.parents, motion))

    def inputs(self, posed: "PosedSkeleton") -> dict[str, np.ndarray]:
        """The per-frame inputs of a posed skeleton of this body shape (:func:`pose_motion`)."""
        if posed.transforms.shape[1] != len(self.rest_joints):
            raise InputError(f"the pose has {posed.transforms.shape[1]} joints, the body has {len(self.rest_joints)}")
        A = torch.from_numpy(posed.transforms)
        ring = linear_blend_skinning(torch.from_numpy(self.ring_rest).double(),
                                     torch.from_numpy(self.ring_weights).double(), A).numpy()
        # the anchor on the posed body's surface, and its normal interpolated from the corners' normals
        body = np.einsum("vk,tvkc->tvc", self.bary, ring[:, self.ring_tri])
        corner_normals = vertex_normals(ring, self.ring_faces).astype(np.float64)[:, self.ring_tri]
        normal = np.einsum("vk,tvkc->tvc", self.bary, corner_normals)
        normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
        garment = linear_blend_skinning(torch.from_numpy(self.garment_verts).double(),
                                        torch.from_numpy(self.weights).double(), A).numpy()
        rot, origin = posed.rot, posed.origin
        # Relative skinning features: the root's translation removed. Skinning is affine in it, so that is
        # the posed point minus the root's displacement; in the heading frame only its height remains.
        lift = np.zeros((len(rot), 1, 3))
        lift[:, 0, 2] = posed.root_height - float(self.rest_joints[0, 2])
        anchor = to_canonical(body, rot, origin)
        return {
            "anchor": anchor,
            "body_normal": (normal @ rot).astype(np.float32),
            "body_rel": (anchor - lift).astype(np.float32),
            "garment_rel": (to_canonical(garment, rot, origin) - lift).astype(np.float32),
            "joints": posed.joints,
            "pose": posed.pose,
            "rot": rot,
            "origin": origin,
        }


def shared_anchor_fraction(pair: GarmentBodyPair, distance: float = SHARED_ANCHOR_DISTANCE) -> dict:
    """How many garment vertices share their anchor: ``fraction``, the share of vertices whose rest anchor
    another vertex's is within ``distance`` metres of; ``largest``, the most vertices in one such group
    (connected through pairs within ``distance``); ``vertices``."""
    groups = coincident_groups(pair.rest_anchors(), distance)
    V = pair.num_verts
    return {"fraction": sum(len(g) for g in groups) / V, "largest": max((len(g) for g in groups), default=1),
            "vertices": int(V)}


@dataclass
class PosedSkeleton:
    """A motion on a body shape's skeleton, ``T`` frames: skinning ``transforms (T, J, 4, 4)`` float64
    (:func:`~loosefit.geometry.lbs.skinning_transforms`), canonical ``joints (T, J, 3)`` float32,
    ``pose (T, 6 J)`` float32 (FitGar's ``theta``), heading frames ``rot (T, 3, 3)``, ``origin (T, 3)``
    float64 and the root's ``root_height (T,)`` float64, metres."""

    transforms: np.ndarray
    joints: np.ndarray
    pose: np.ndarray
    rot: np.ndarray
    origin: np.ndarray
    root_height: np.ndarray

    def __getitem__(self, frames) -> "PosedSkeleton":
        """The frames ``frames`` (an index array or a slice), as a posed skeleton."""
        return PosedSkeleton(self.transforms[frames], self.joints[frames], self.pose[frames], self.rot[frames],
                             self.origin[frames], self.root_height[frames])


def pose_motion(rest_joints: np.ndarray, parents: np.ndarray, motion: Motion) -> PosedSkeleton:
    """The skeleton of rest joints ``(J, 3)`` (one body shape) along ``motion``."""
    J = len(rest_joints)
    if motion.num_joints != J:
        raise InputError(f"motion {motion.name!r} has {motion.num_joints} joints, the body has {J}")
    rest = torch.from_numpy(np.asarray(rest_joints)).double()
    world = forward_kinematics(axis_angle_to_matrix(torch.from_numpy(motion.rotations).double()),
                               torch.from_numpy(motion.translation).double(), rest, parents)
    rot, origin = heading_frames(motion)
    return PosedSkeleton(skinning_transforms(world, rest).numpy(), to_canonical(world[..., :3, 3].numpy(), rot, origin),
                         pose_vector(motion), rot, origin, motion.translation[:, 2].astype(np.float64))
