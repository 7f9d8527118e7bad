"""The body-LBS baseline: the garment skinned to the body skeleton, the approach that fails on loose garments.

Each garment vertex takes the skinning weights of its nearest rest-pose body vertex (the weights the
simulator uses for pinned vertices, :func:`loosefit.sim.attach.garment_weights`) and follows the body's
joints by linear blend skinning. Both JointNet and VirtualBones papers show it for contrast: a skirt
skinned this way splits between the legs instead of swinging.

The model works in the canonical heading frame like the learned methods, from the same features. The
features hold every non-root joint's local rotation, the root's orientation without its heading (its
tilt) and the root height; in the heading frame the root joint lies at ``(0, 0, height)`` with
orientation ``tilt``. So forward kinematics from the features alone gives the canonical skeleton pose,
and the world result is the canonical one put back with the frame's heading rotation and origin.
It has no trainable parameters (``trainable = False``): the training pipeline skips it.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import torch

from loosefit.body import AnnyBody, AnnyShape
from loosefit.errors import InputError
from loosefit.models.base import GarmentModel
from loosefit.models.dataset import GarmentSequences
from loosefit.models.motion_features import skin_from_features
from loosefit.sim.attach import garment_weights


@functools.lru_cache(maxsize=8)
def _anny(values: tuple[float, ...], rig: str) -> AnnyBody:
    return AnnyBody(AnnyShape.from_array(np.asarray(values, np.float32)), rig=rig)


def training_body(data: GarmentSequences) -> AnnyBody:
    """The body that every sequence of ``data`` was simulated on (its shape and its motions' rig).

    Raises:
        InputError: the sequences use several bodies or rigs, or a body that is not an Anny body.
    """
    bodies = sorted({s.body_name for s in data.sequences})
    rigs = sorted({s.motion.rig for s in data.sequences})
    if len(bodies) != 1 or len(rigs) != 1:
        raise InputError(f"the sequences of garment {data.garment_name!r} use bodies {bodies} on rigs {rigs}; "
                         "a per-garment model needs one body and one rig", data.store.path)
    model = data.store.read_attrs(f"bodies/{bodies[0]}").get("model", "anny")
    if model != "anny":
        raise InputError(f"body {bodies[0]!r} is a {model!r} body; the per-garment models read Anny bodies", data.store.path)
    body = _anny(tuple(float(v) for v in data.store.body(bodies[0])), rigs[0])
    for s in data.sequences:
        body.check_motion(s.motion)
    return body


@dataclass(frozen=True)
class BodyLBSConfig:
    """body-LBS has no hyper-parameters: its weights come from the body (nearest rest vertex)."""


@dataclass(frozen=True)
class Config:
    """Everything ``configs/models/body-lbs.yaml`` holds: an empty model section (nothing to train)."""

    model: BodyLBSConfig = field(default_factory=BodyLBSConfig)


class BodyLBS(GarmentModel):
    """The garment skinned to the body skeleton (see the module doc). No trainable parameters.

    ``sizes`` adds ``parents`` (``J`` parent indices of the body rig, -1 for the root) to the base sizes.
    Buffers: ``rest_joints (J, 3)`` metres, ``weights (V, J)`` skinning weights of the garment vertices.
    """

    method: ClassVar[str] = "body-lbs"
    Config: ClassVar[type] = BodyLBSConfig
    #: The training pipeline skips this model: it has nothing to learn.
    trainable: ClassVar[bool] = False

    def __init__(self, sizes: dict, config: BodyLBSConfig | None = None):
        super().__init__(sizes, config or BodyLBSConfig())
        J, V = sizes["num_joints"], sizes["num_verts"]
        if len(sizes["parents"]) != J:
            raise InputError(f"sizes give {len(sizes['parents'])} joint parents for {J} joints")
        self.parents = np.asarray(sizes["parents"], np.int64)
        self.register_buffer("rest_joints", torch.zeros(J, 3))
        self.register_buffer("weights", torch.zeros(V, J))

    @classmethod
    def data_sizes(cls, data: GarmentSequences) -> dict:
        return {**super().data_sizes(data), "parents": [int(p) for p in training_body(data).parents]}

    def init_from_data(self, data: GarmentSequences) -> None:
        super().init_from_data(data)
        body = training_body(data)
        with torch.no_grad():
            self.rest_joints.copy_(torch.from_numpy(body.rest_joints()))
            self.weights.copy_(torch.from_numpy(garment_weights(data.garment.verts, body)))

    def stages(self) -> list[str]:
        return []

    def forward(self, root: torch.Tensor, joints: torch.Tensor, state: Any = None) -> dict:
        """Raw features ``root (B, T, 11)``, ``joints (B, T, J-1, 6)`` -> ``{"verts": (B, T, V, 3) canonical,
        "joint_transforms": (B, T, J, 4, 4) canonical world transforms of the joints, "state": None}``
        (there is no recurrent state: each frame depends on its own pose only)."""
        verts, world = skin_from_features(self.template, self.weights, self.rest_joints, self.parents, root, joints)
        return {"verts": verts, "joint_transforms": world, "state": None}
