"""The simulator's pins kept at inference (loosefit's; not in the papers).

The simulation attaches a garment's pinned vertices (:attr:`loosefit.garment.Garment.pinned`: a skirt's waistband, a
dress's strap tops) to the body: each follows the body's skinning with the weights of its nearest rest body vertex
(:func:`loosefit.sim.attach.garment_weights`), exactly, in every frame. A network predicts them like any other vertex
and, on a person it was not trained on, misses: the shipped dress's networks put its strap tops 61-75 mm from the
shoulders on the validation subject, where skinning puts them within 1.3 mm (``benchmarks/experiments/LOG.md``, "The
simulator's pins kept").

:class:`Pins` puts them back where the simulation would and fades the network's garment into them:

    x_v = x_v^net + a_v (x_v^skin - x_v^net),    a_v = max(0, 1 - d_v / radius)

``x^skin`` the rest garment skinned to the body (body-LBS, in the model's frame from the motion features alone, as
:class:`~loosefit.models.body_lbs.BodyLBS`), ``d_v`` the distance from vertex ``v`` to the nearest pinned vertex
along the rest mesh's edges (metres; 0 at a pin). It is applied to what is animated (:class:`loosefit.animate.Animator`,
the one-frame graph, the ONNX step model), not in training: the losses and the bones are the method's own.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import torch
from scipy.sparse.csgraph import dijkstra
from torch import nn

from loosefit.errors import InputError
from loosefit.geometry.laplacian import edges
from loosefit.models.motion_features import skin_from_features

#: Metres along the garment from its pins over which the network's garment is faded into the skinned one. Chosen on
#: two validation sets (pooled RMSE, VirtualBones / JointNet, mm), the real-capture dress's validation subject (its
#: strap tops pinned): no pins 77.02 / 80.13; radius 0 (the pins alone) 76.84 / 79.88, 0.1 m 76.67 / 79.75, 0.2 m
#: 76.36 / 79.67, 0.3 m 75.96 / 79.67, 0.4 m 75.79 / 79.74; and the demo's validation motions (its skirt's waistband
#: pinned): no pins 53.71 / 54.49; 0 53.29 / 54.37, 0.1 m 53.18 / 54.37, 0.2 m 53.38 / 54.56, 0.3 m 54.16 / 55.33.
#: 0.1 m is better than none on all four; from 0.2 m on the skirt's hips take the body's skinning too. A run keeps
#: its own radius: the shipped dress's garments, whose pins are the strap tops, carry theirs from the dress's
#: validation subject alone (VirtualBones 0.4 m, JointNet 0.3 m; benchmarks/experiments/LOG.md).
PIN_RADIUS = 0.1


def check_pin_radius(radius: float | None) -> None:
    """Refuse a config's ``pin_radius`` that is neither None (no pins) nor a number of metres >= 0."""
    if radius is not None and not (isinstance(radius, (int, float)) and np.isfinite(radius) and radius >= 0):
        raise InputError(f"pin_radius must be >= 0 metres or null (no pins), got {radius!r}")


def pin_blend(rest: np.ndarray, faces: np.ndarray, pinned: np.ndarray, radius: float) -> np.ndarray:
    """``a (V,)`` float32: 1 at the ``pinned (V,)`` vertices of the mesh ``rest (V, 3)``, ``faces (F, 3)``, falling
    linearly to 0 at ``radius`` metres from the nearest pin along the mesh's edges (0 everywhere without pins;
    the pins alone for a radius of 0)."""
    rest = np.asarray(rest, np.float64)
    pinned = np.asarray(pinned, bool)
    check_pin_radius(radius)
    if pinned.shape != (len(rest),):
        raise InputError(f"pinned must be ({len(rest)},), got {pinned.shape}")
    if not pinned.any():
        return np.zeros(len(rest), np.float32)
    if radius == 0:
        return pinned.astype(np.float32)
    e = edges(np.asarray(faces, np.int64))
    length = np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1)
    graph = sp.coo_matrix((np.r_[length, length], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                          shape=(len(rest), len(rest))).tocsr()
    distance = dijkstra(graph, indices=np.flatnonzero(pinned), min_only=True, limit=radius)
    return np.clip(1.0 - distance / radius, 0.0, 1.0).astype(np.float32)


def pin_sizes(garment, body, radius: float) -> dict:
    """What a model's sizes record of ``garment``'s pins over ``radius`` metres on ``body``'s rig: the radius, the rig's
    ``parents`` and ``vertices``, how many vertices the pins move (those with ``a > 0``: only they are skinned)."""
    blend = pin_blend(garment.verts, garment.faces, garment.pinned, radius)
    return {"radius": float(radius), "parents": [int(p) for p in body.parents], "vertices": int((blend > 0).sum())}


class Pins(nn.Module):
    """A garment's pins (module doc) for a model predicting in ``frame`` (:data:`~loosefit.motion.heading.FRAMES`),
    moving ``count`` of the garment's vertices (:func:`pin_sizes`).

    Buffers, for those vertices only: ``index (K,)`` (which), ``blend (K,)`` (``a``), ``weights (K, J)`` (their body
    skinning weights), ``template (K, 3)`` (their rest positions); ``rest_joints (J, 3)`` metres (the training
    body's). ``parents (J,)``: the body rig's.
    """

    def __init__(self, count: int, parents, frame: str):
        super().__init__()
        self.parents = np.asarray(parents, np.int64)
        self.frame = frame
        J = len(self.parents)
        self.register_buffer("index", torch.zeros(count, dtype=torch.long))
        self.register_buffer("blend", torch.zeros(count))
        self.register_buffer("weights", torch.zeros(count, J))
        self.register_buffer("rest_joints", torch.zeros(J, 3))
        self.register_buffer("template", torch.zeros(count, 3))

    def fill(self, template: np.ndarray, faces: np.ndarray, pinned: np.ndarray, body, radius: float) -> None:
        """Set the buffers from the rest garment ``template (V, 3)``, ``faces``, its ``pinned (V,)`` mask and the
        ``body`` it was simulated on."""
        from loosefit.sim.attach import garment_weights

        blend = pin_blend(template, faces, pinned, radius)
        index = np.flatnonzero(blend > 0)
        if len(index) != len(self.index):
            raise InputError(f"the pins move {len(index)} vertices of this garment, the model was sized for "
                             f"{len(self.index)}")
        template = np.asarray(template, np.float32)[index]
        with torch.no_grad():
            self.index.copy_(torch.from_numpy(index))
            self.blend.copy_(torch.from_numpy(blend[index]))
            self.weights.copy_(torch.from_numpy(garment_weights(template, body)))
            self.rest_joints.copy_(torch.from_numpy(np.asarray(body.rest_joints(), np.float32)))
            self.template.copy_(torch.from_numpy(template))

    def skinned(self, root: torch.Tensor, joints: torch.Tensor) -> torch.Tensor:
        """The pins' vertices of the rest garment skinned to the body in the model's frame
        (:func:`~loosefit.models.motion_features.skin_from_features`): raw features ``root (..., R)``,
        ``joints (..., J-1, 6)`` -> ``(..., K, 3)`` metres."""
        return skin_from_features(self.template, self.weights, self.rest_joints, self.parents, root, joints,
                                  self.frame)[0]

    def forward(self, verts: torch.Tensor, root: torch.Tensor, joints: torch.Tensor) -> torch.Tensor:
        """Canonical ``verts (..., V, 3)`` with the pinned ones skinned and the rest faded into them (module doc),
        from the same frames' raw features ``root (..., R)``, ``joints (..., J-1, 6)``."""
        near = verts[..., self.index, :]
        out = verts.clone()
        out[..., self.index, :] = near + self.blend[:, None] * (self.skinned(root, joints) - near)
        return out


def with_pins(model, garment, body, radius: float = PIN_RADIUS):
    """A copy of the per-garment ``model`` (a :class:`~loosefit.models.base.GarmentModel` trained without pins, or
    with others) keeping ``garment``'s pins (a :class:`~loosefit.garment.Garment`, the one it was trained on, simulated
    on ``body``) over ``radius`` metres: its sizes, config and buffers say so; every other weight is the model's."""
    import dataclasses

    check_pin_radius(radius)
    if len(garment.verts) != model.sizes()["num_verts"]:
        raise InputError(f"garment {garment.name!r} has {len(garment.verts)} vertices, the model "
                         f"{model.sizes()['num_verts']}")
    sizes = {**model.sizes(), "pins": pin_sizes(garment, body, radius)}
    out = type(model)(sizes, dataclasses.replace(model.config, pin_radius=float(radius)))
    state = {k: v for k, v in model.state_dict().items() if not k.startswith("pins.")}
    missing, unexpected = out.load_state_dict(state, strict=False)
    if unexpected or any(not k.startswith("pins.") for k in missing):
        raise InputError(f"{model.method}: the model's weights do not fit it with pins ({missing}, {unexpected})")
    out.pins.fill(garment.verts, garment.faces, garment.pinned, body, radius)
    return out.train(model.training)
