"""The body SDF network of SwinGar Sec. III-D, ``S(x | code)``, its inputs along a motion, and its file.

- :class:`BodySDFNet`: eight fully connected layers of 512 (three on the point, three on the body code (shape
  and pose), two fusing both), a residual link in each branch from its first layer's output to its last,
  Softplus(beta=100), geometric initialisation (Atzmon and Lipman 2020: the initial field is close to a
  sphere's, the code branch starting silent). With ``bone_frames`` (ours) the point branch also reads the
  point in every posed bone's frame (:func:`bone_local_points`, :func:`bone_frame_code`).
- :func:`body_code`, :func:`motion_sdf_inputs`: the code and canonical frame of each frame of a motion.
- :func:`save_body_sdf`, :func:`load_body_sdf`: one file with the weights and sizes.

Sign convention: loosefit's (:mod:`loosefit.geometry.signed_distance`): negative inside the body.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np
import torch
from torch import nn

from loosefit.errors import InputError

if TYPE_CHECKING:
    from loosefit.models.collision.fast_eval import BoundBodySDF

#: Softplus sharpness of the SDF network (SwinGar Sec. IV).
SOFTPLUS_BETA = 100.0

#: An SDF as a function: points ``(N, 3)`` -> signed distances ``(N,)`` (differentiable in the points).
SDFFunction = Callable[[torch.Tensor], torch.Tensor]

@dataclass(frozen=True)
class BodySDFConfig:
    """Sizes of :class:`BodySDFNet` (SwinGar Sec. IV), the radius of its initial sphere and whether the point
    branch also reads the point in every bone's frame (``bone_frames``; both ours, off in the paper)."""

    hidden: int = 512
    point_layers: int = 3
    code_layers: int = 3
    fusion_layers: int = 2
    init_radius: float = 0.5
    bone_frames: bool = False

    def __post_init__(self):
        if min(self.hidden, self.point_layers, self.code_layers) < 1 or self.fusion_layers < 1:
            raise InputError("BodySDFNet needs hidden >= 1, at least one layer per branch and one fusion layer")
        if not self.init_radius > 0:
            raise InputError(f"init_radius must be positive, got {self.init_radius}")


class BodySDFNet(nn.Module):
    """``S(x | code)``: points ``(..., N, 3)`` metres and codes ``(..., C)`` -> signed distances ``(..., N)``, metres.

    The code is the body's shape and pose as a vector (e.g. shape values and the pose features of
    :class:`~loosefit.models.swingar.SwinGar`); points are in the frame the body was posed in without its
    translation (SwinGar Sec. IV).

    With ``num_bones = B > 0`` (ours, ``config.bone_frames``) the code ends with the ``B`` posed bone frames,
    12 values each (:func:`bone_frame_code`: rotation ``R_b`` row-major, then origin ``t_b``, in the points'
    frame), and the point branch reads ``[x, R_1^T (x - t_1), ..., R_B^T (x - t_B)]``: where the point is
    relative to every bone. A body part keeps its shape in its bone's frame whatever the pose, so the field a
    narrow network must learn is far simpler than in the body's frame, where the paper's network has to undo
    the articulation from the concatenated code alone. The features are linear in ``x``: bound to a body
    (:class:`BoundBodySDF`) they fold into the first layer, and evaluation costs what it costs without them.
    """

    def __init__(self, code_size: int, config: BodySDFConfig = BodySDFConfig(), num_bones: int = 0):
        super().__init__()
        if code_size < 0:
            raise InputError(f"code size must be >= 0, got {code_size}")
        if num_bones < 0 or 12 * num_bones > code_size or (num_bones > 0) != config.bone_frames:
            raise InputError(f"a body SDF network with bone_frames={config.bone_frames} cannot have {num_bones} "
                             f"bones in a code of {code_size} values (12 a bone, at its end)")
        H = config.hidden
        self.code_size, self.config, self.num_bones = code_size, config, num_bones
        self.point = nn.ModuleList(nn.Linear(3 + 3 * num_bones if i == 0 else H, H)
                                   for i in range(config.point_layers))
        self.code = nn.ModuleList(nn.Linear(max(code_size, 1) if i == 0 else H, H) for i in range(config.code_layers))
        sizes = [2 * H] + [H] * (config.fusion_layers - 1) + [1]
        self.fusion = nn.ModuleList(nn.Linear(a, b) for a, b in zip(sizes[:-1], sizes[1:]))
        self.act = nn.Softplus(beta=SOFTPLUS_BETA)
        self.geometric_init()

    def geometric_init(self) -> None:
        """Atzmon and Lipman's initialisation on the point path (an initial field near ``|x| - r``); the first
        fusion layer's weights on the code branch start at zero, so the body code only enters through training."""
        with torch.no_grad():
            for layer in [*self.point, *self.fusion[:-1]]:
                nn.init.normal_(layer.weight, 0.0, math.sqrt(2.0) / math.sqrt(layer.out_features))
                nn.init.zeros_(layer.bias)
            for layer in self.code:
                nn.init.kaiming_uniform_(layer.weight, a=math.sqrt(5))
                nn.init.zeros_(layer.bias)
            self.fusion[0].weight[:, self.config.hidden:] = 0.0  # the code's half of the first fusion layer
            self.point[0].weight[:, 3:] = 0.0  # the bone frames' columns: they too enter through training
            last = self.fusion[-1]
            nn.init.normal_(last.weight, math.sqrt(math.pi) / math.sqrt(last.in_features), 1e-4)
            nn.init.constant_(last.bias, -self.config.init_radius)

    def _branch(self, layers: nn.ModuleList, x: torch.Tensor) -> torch.Tensor:
        first = h = self.act(layers[0](x))
        for layer in layers[1:]:
            h = self.act(layer(h))
        return h + first if len(layers) > 1 else h

    def bind(self, code: torch.Tensor | None = None) -> "BoundBodySDF":
        """The field of one body (code ``(C,)``) as an :data:`SDFFunction` ``(N, 3) -> (N,)``, its code branch
        evaluated once (see :class:`~loosefit.models.collision.fast_eval.BoundBodySDF`)."""
        from loosefit.models.collision.fast_eval import BoundBodySDF

        return BoundBodySDF(self, code)

    def forward(self, points: torch.Tensor, code: torch.Tensor | None = None) -> torch.Tensor:
        if points.shape[-1] != 3:
            raise InputError(f"SDF points must be (..., N, 3), got {tuple(points.shape)}")
        if code is None:
            code = points.new_zeros(points.shape[:-2] + (self.code_size,))
        if code.shape[-1] != self.code_size:
            raise InputError(f"SDF code must have {self.code_size} values, got {code.shape[-1]}")
        if self.num_bones:
            points = torch.cat([points, bone_local_points(points, code, self.num_bones)], -1)
        if self.code_size == 0:
            code = points.new_zeros(code.shape[:-1] + (1,))
        p = self._branch(self.point, points)
        c = self._branch(self.code, code)[..., None, :].expand(p.shape)
        h = torch.cat([p, c], -1)
        for layer in self.fusion[:-1]:
            h = self.act(layer(h))
        return self.fusion[-1](h)[..., 0]


def _bone_frames(code: torch.Tensor, num_bones: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The ``B = num_bones`` bone frames at the end of ``code (..., C)`` (:func:`bone_frame_code`): rotations
    ``(..., B, 3, 3)`` and origins ``(..., B, 3)``."""
    frames = code[..., code.shape[-1] - 12 * num_bones:].unflatten(-1, (num_bones, 12))
    return frames[..., :9].unflatten(-1, (3, 3)), frames[..., 9:]


def bone_local_points(points: torch.Tensor, code: torch.Tensor, num_bones: int) -> torch.Tensor:
    """``points (..., N, 3)`` in the ``B = num_bones`` bone frames at the end of ``code (..., C)``
    (:func:`bone_frame_code`) -> ``(..., N, 3 B)``: ``R_b^T (x - t_b)`` for every bone, in bone order."""
    rot, origin = _bone_frames(code, num_bones)
    # row vectors: R^T (x - t) is (x - t) @ R
    local = torch.einsum("...nbi,...bij->...nbj", points[..., :, None, :] - origin[..., None, :, :], rot)
    return local.flatten(-2)


def fold_bone_frames(weight: torch.Tensor, bias: torch.Tensor, code: torch.Tensor, num_bones: int):
    """The first point layer of a network with bone frames as one layer on ``x`` alone, per body code
    ``(..., C)``: ``W [x, R_b^T (x - t_b)] + b = (W_x + sum_b W_b R_b^T) x + (b - sum_b W_b R_b^T t_b)``.
    ``weight (H, 3 + 3 B)``, ``bias (H,)`` -> ``(..., H, 3)``, ``(..., H)``."""
    rot, origin = _bone_frames(code, num_bones)
    blocks = weight[:, 3:].reshape(len(weight), num_bones, 3)  # W_b (H, B, 3)
    folded = torch.einsum("hbj,...bij->...hbi", blocks, rot)  # W_b R_b^T
    return weight[:, :3] + folded.sum(-2), bias - torch.einsum("...hbi,...bi->...h", folded, origin)


def bone_frame_code(world: np.ndarray, rot: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Posed joint transforms ``world (T, J, 4, 4)`` (:func:`~loosefit.geometry.lbs.forward_kinematics`) in
    the canonical frame of each frame (``rot (T, 3, 3)``, ``origin (T, 3)``, points ``(p - origin) @ rot``) as
    ``(T, 12 J)`` float32 code values: per joint its rotation ``rot^T W_j`` row-major, then its position."""
    R = np.einsum("tki,tjkl->tjil", rot, world[..., :3, :3])  # rot^T W_j
    t = np.einsum("tjk,tki->tji", world[..., :3, 3] - origin[:, None], rot)
    return np.concatenate([R.reshape(*R.shape[:2], 9), t], -1).reshape(len(world), -1).astype(np.float32)


# ---------------------------------------------------------------------------------------------- on Anny bodies


def body_code(shape_values: np.ndarray, root: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """The code the body SDF network is conditioned on, per frame: ``(T, S + 7 + 6 (J-1))`` float32 from the
    body's shape values ``(S,)`` and the motion features ``root (T, 11)``, ``joints (T, J-1, 6)``
    (:mod:`loosefit.models.motion_features`): shape, root height, root tilt and joint rotations, everything
    that places the body in the canonical heading frame."""
    T = len(root)
    shape = np.broadcast_to(np.asarray(shape_values, np.float32), (T, len(shape_values)))
    return np.concatenate([shape, root[:, :1], root[:, 5:11], joints.reshape(T, -1)], 1).astype(np.float32)


def motion_sdf_inputs(body, motion, bone_frames: bool = False) -> tuple[torch.Tensor, np.ndarray, np.ndarray]:
    """What the body SDF network reads along ``motion`` on ``body`` (an Anny body): the codes ``(T, C)``
    (:func:`body_code`, then with ``bone_frames`` the :func:`bone_frame_code` of the posed skeleton) and each
    frame's canonical frame ``rot (T, 3, 3)``, ``origin (T, 3)``, for :class:`FramedSDF` (the network works in
    the canonical heading frame)."""
    from loosefit.models.motion_features import motion_features
    from loosefit.motion.heading import heading_frames

    feats = motion_features(motion)
    rot, origin = heading_frames(motion)
    code = body_code(body.shape.to_array(), feats["root"], feats["joints"])
    if bone_frames:
        code = np.concatenate([code, bone_frame_code(posed_joints(body, motion), rot, origin)], 1)
    return torch.from_numpy(code), rot, origin


def posed_joints(body, motion) -> np.ndarray:
    """``(T, J, 4, 4)`` world joint transforms of ``body`` along ``motion`` (forward kinematics only)."""
    from loosefit.geometry.lbs import forward_kinematics
    from loosefit.geometry.rotations import axis_angle_to_matrix

    with torch.no_grad():
        world = forward_kinematics(axis_angle_to_matrix(torch.from_numpy(motion.rotations)),
                                   torch.from_numpy(motion.translation), torch.from_numpy(body.rest_joints()),
                                   body.parents)
    return world.numpy()


def save_body_sdf(path, net: BodySDFNet) -> None:
    """Write the network and its sizes to one file (``torch.save`` of tensors and plain values)."""
    from loosefit.paths import atomic_path

    state = {"format": "loosefit-body-sdf", "code_size": net.code_size, "num_bones": net.num_bones,
             "config": dict(vars(net.config)), "model": net.state_dict()}
    with atomic_path(path) as tmp:
        torch.save(state, tmp)


def load_body_sdf(path) -> BodySDFNet:
    """Read a network written by :func:`save_body_sdf`; a bad file is an :class:`InputError` naming it."""
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
        if state.get("format") != "loosefit-body-sdf":
            raise ValueError("not a loosefit body SDF")
        net = BodySDFNet(int(state["code_size"]), BodySDFConfig(**state["config"]), int(state.get("num_bones", 0)))
        net.load_state_dict(state["model"])
    except Exception as e:  # missing, truncated or foreign files
        raise InputError(f"cannot read a body SDF network: {e}", path) from None
    return net.eval()

