"""Neural collision handling (SwinGar Sec. III-D): a learned body signed distance field and the step that
moves garment vertices out of the body (SwinGar Eq. 10), with the exact and push-out references.

Sign convention: loosefit's (:mod:`loosefit.geometry.signed_distance`): negative inside the body, the
gradient pointing outwards. SwinGar Eq. 7 calls the inside positive, with which SwinGar Eq. 10 would
move a vertex further in; the displacement here is along the outward gradient, as intended there.

- :class:`BodySDFNet` ``S(x | code)``: eight fully connected layers of 512 (three on the point, three on the
  body code (shape and pose), two fusing both), a residual link in each branch from its first layer's
  output to its last, Softplus(beta=100), geometric initialisation (Atzmon and Lipman 2020: the
  initial field is close to a sphere's, the code branch starting silent). :func:`sdf_loss` is SwinGar
  Eqs. 8-9 (``mu_e = 0.15``); :func:`sdf_samples` draws training points on, near and inside a body.
- :func:`resolve_collisions` / :class:`CollisionResolver`: SwinGar Eq. 10 for any SDF (the network,
  :class:`ExactSDF` from libigl, or a closed-form one), and :func:`push_out` the fixed-distance baseline
  (TailorNet) the paper compares with.

Speed. Evaluating the network's value and autograd gradient at every vertex of a 10k-vertex garment took
300-450 ms a frame on this project's CPUs at the paper's size. Frame by frame (:func:`correct_frame`, for
streaming) these changes bring it to about 3 ms with a 32- or 64-wide network; over a whole motion
(:func:`correct_motion`, used by :func:`handle_motion_collisions` and ``loosefit animate --collision``) to
0.75-0.92 ms a frame (the median of five runs, per garment kind) with the 32-wide network of
``configs/models/collision-cpu.yaml`` at its calibrated 13 mm margin, in two worker threads (benchmarks/collision.py,
``collision-speed-32-30k*.json``). With the exact
field they change nothing (beyond float rounding); with the network, a vertex it wrongly calls inside but
that the cull proves outside is no longer moved:

- the posed collision proxy's :class:`~loosefit.geometry.ray_cull.AxisRayCuller` proves most vertices outside
  (an axis-aligned ray that meets no triangle facing back along it), filling only the bins of the garment's box,
  and only the others (0.9-3.5 % of a garment with 1.25 cm bins) reach the network;
- :class:`BoundBodySDF` runs the body-code branch once per frame and differentiates by hand; the gradient is
  taken only at the vertices found inside, the value of their other neighbours only where ``delta_i`` needs it;
- denormal floats are flushed while the network runs (:func:`flushed_denormals`): Softplus(beta=100) makes
  many, and the CPU computed with them several times slower;
- over a motion, :data:`FRAME_CHUNK` frames go through each step at once (the cull's kernels launched once,
  :class:`MotionBodySDF` with the frame folded into its first layer, :meth:`CollisionResolver.frames`), so
  Python's overhead is paid per chunk, and chunks run in two threads (the kernels, torch and NumPy release
  Python's lock).

What remains is the cull (about 0.6-0.9 ms of one core a frame with 1.25 cm bins, most of it rasterising the
proxy's 2,454 triangles) and the network on the candidates (most of it Softplus, which torch computes element by
element): narrower networks (``net.hidden``) are faster and less exact, the paper's width the slowest; the
benchmark reports both sides. A margin (``--collision-margin``) finds more vertices inside, and each costs a
gradient and its neighbours' values.
"""

from __future__ import annotations

import copy
import math
import queue
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch
from torch import nn

from loosefit.errors import InputError
from loosefit.geometry.laplacian import edges
from loosefit.geometry.ray_cull import AxisRayCuller
from loosefit.geometry.signed_distance import BodySDF
from loosefit.threads import torch_threads

#: Softplus sharpness of the SDF network (SwinGar Sec. IV).
SOFTPLUS_BETA = 100.0
#: Weight of the Eikonal term, ``mu_e`` of SwinGar Eq. 8.
EIKONAL_WEIGHT = 0.15

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
        evaluated once (see :class:`BoundBodySDF`)."""
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


class BoundBodySDF:
    """:class:`BodySDFNet` with its body code fixed, for inference: ``points (N, 3) -> (N,)`` metres, the same
    values as ``net(points[None], code[None])[0]``. The code branch and its share of the first fusion layer
    (``W_c c + b``) are computed once, so a point costs only the point branch and the fusion layers (per frame of
    a motion the code changes once, the points are evaluated several times: candidates, neighbours, gradients).
    :meth:`value_and_gradient` differentiates by hand (Softplus' derivative is ``sigmoid(beta z)``), without
    autograd's bookkeeping.

    Args:
        net: the network (its weights are shared, not copied; detached: nothing here trains it).
        code: ``(C,)`` the body's code (:func:`body_code`); None: zeros.
    """

    def __init__(self, net: BodySDFNet, code: torch.Tensor | None = None):
        H = net.config.hidden
        first = net.fusion[0]
        self.code_size, self.num_bones = net.code_size, net.num_bones
        self.point = [(m.weight.detach(), m.bias.detach()) for m in net.point]
        self.point_first = self.point[0]  # with bone frames, self.point[0] is this folded with the body's bones
        self.code = [(m.weight.detach(), m.bias.detach()) for m in net.code]
        self.fusion = [(first.weight.detach()[:, :H].contiguous(), first.bias.detach())]
        self.fusion += [(m.weight.detach(), m.bias.detach()) for m in net.fusion[1:]]
        self.code_weight = first.weight.detach()[:, H:].contiguous()
        self.beta = float(net.act.beta)
        self.threshold = float(net.act.threshold)
        self._set_code(code)

    def _set_code(self, code: torch.Tensor | None) -> None:
        w = self.fusion[0][0]
        with torch.no_grad():
            if code is None:
                code = w.new_zeros(self.code_size)
            code = torch.as_tensor(code, dtype=w.dtype, device=w.device)
            if code.shape != (self.code_size,):
                raise InputError(f"SDF code must be ({self.code_size},), got {tuple(code.shape)}")
            self.first_bias = self._code_bias(code)
            if self.num_bones:
                self.point = [fold_bone_frames(*self.point_first, code, self.num_bones), *self.point[1:]]

    def _code_bias(self, code: torch.Tensor) -> torch.Tensor:
        """The code branch and its share of the first fusion layer, ``W_c c + b``: codes ``(..., C)`` ->
        ``(..., H)``."""
        if self.code_size == 0:
            code = code.new_zeros(code.shape[:-1] + (1,))
        first = h = self._act(nn.functional.linear(code, *self.code[0]))
        for cw, cb in self.code[1:]:
            h = self._act(nn.functional.linear(h, cw, cb))
        c = h + first if len(self.code) > 1 else h
        return self.fusion[0][1] + c @ self.code_weight.T

    def offset(self, margin: float) -> "BoundBodySDF":
        """The field of the surface moved ``margin`` metres outwards, ``S(x) - margin`` (the last layer's bias
        lowered: no cost). The same weights otherwise; :meth:`with_code` keeps the offset."""
        other = copy.copy(self)
        w, b = self.fusion[-1]
        other.fusion = [*self.fusion[:-1], (w, b - margin)]
        return other

    def with_code(self, code: torch.Tensor | None) -> "BoundBodySDF":
        """The same network bound to another body code ``(C,)`` (the weights are shared; only the code branch
        runs): per frame of a motion."""
        other = copy.copy(self)
        other._set_code(code)
        return other

    def _act(self, z: torch.Tensor) -> torch.Tensor:
        return nn.functional.softplus(z, self.beta, self.threshold)

    def _first_layer(self, points: torch.Tensor, frame) -> torch.Tensor:
        """The first point layer's pre-activation ``(N, H)`` (``frame``: see :class:`MotionBodySDF`)."""
        return nn.functional.linear(points, *self.point[0])

    def _first_layer_gradient(self, g: torch.Tensor, frame) -> torch.Tensor:
        """``dS/dz (N, H)`` of the first point layer -> ``dS/dx (N, 3)``."""
        return g @ self.point[0][0]

    def _fusion_bias(self, frame) -> torch.Tensor:
        """The first fusion layer's bias with the code's share, ``(H,)`` (or per point, ``(N, H)``)."""
        return self.first_bias

    def _forward(self, points: torch.Tensor, keep: bool, frame=None):
        """Value ``(N,)`` and, with ``keep``, every pre-activation (point branch, then fusion)."""
        pre = []
        z = self._first_layer(points, frame)
        first = h = self._act(z)
        pre.append(z)
        for w, b in self.point[1:]:
            z = nn.functional.linear(h, w, b)
            h = self._act(z)
            pre.append(z)
        if len(self.point) > 1:
            h = h + first
        z = nn.functional.linear(h, self.fusion[0][0]) + self._fusion_bias(frame)
        for w, b in self.fusion[1:]:
            pre.append(z)
            z = nn.functional.linear(self._act(z), w, b)
        return z[..., 0], (pre if keep else None)

    def __call__(self, points: torch.Tensor, frame=None) -> torch.Tensor:
        return self._forward(points, False, frame)[0]

    def _slope(self, z: torch.Tensor) -> torch.Tensor:
        """Softplus' derivative ``sigmoid(beta z)`` (torch uses 1 above its threshold, ``beta z > 20``, where
        the sigmoid is within 2e-9 of 1)."""
        return torch.sigmoid(z * self.beta)

    def _backward(self, pre: list[torch.Tensor], frame=None) -> torch.Tensor:
        """``grad S (N, 3)`` from the pre-activations of :meth:`_forward` (rows of N points)."""
        n_point = len(self.point)
        g = self.fusion[-1][0].expand(len(pre[0]), -1)  # dS / d(input of the last fusion layer)
        for (w, _), z in zip(reversed(self.fusion[:-1]), reversed(pre[n_point:])):
            g = (g * self._slope(z)) @ w  # through the activation, then the layer before it
        residual = g  # the branch output p = h_k + h_1 passes its gradient to h_1 directly too
        for j in range(n_point - 1, 0, -1):
            g = (g * self._slope(pre[j])) @ self.point[j][0]
            if j == 1:
                g = g + residual
        return self._first_layer_gradient(g * self._slope(pre[0]), frame)

    def value_and_gradient(self, points: torch.Tensor, frame=None) -> tuple[torch.Tensor, torch.Tensor]:
        """``S (N,)`` and ``grad S (N, 3)`` at ``points (N, 3)``, no autograd (the chain rule written out)."""
        with torch.no_grad():
            value, pre = self._forward(points, True, frame)
            return value, self._backward(pre, frame)

    def value_and_gradient_fn(self, points: torch.Tensor, frame=None):
        """``S (N,)`` at ``points (N, 3)`` and a function ``rows (M,) -> grad S (M, 3)`` at ``points[rows]`` that
        reuses this pass's activations (the gradient of a few of many points without a second forward pass)."""
        with torch.no_grad():
            value, pre = self._forward(points, True, frame)

        def gradient(rows: torch.Tensor) -> torch.Tensor:
            with torch.no_grad():
                return self._backward([z.index_select(0, rows) for z in pre], None if frame is None else frame[rows])

        return value, gradient


class MotionBodySDF(BoundBodySDF):
    """:class:`BodySDFNet` bound to every frame of a motion and read in the world: for frame ``t``,
    ``S_t(p) = S((p - origin_t) @ rot_t | code_t)``, the field :func:`correct_frame` evaluates through
    :class:`FramedSDF` and :meth:`BodySDFNet.bind`, for the points of many frames in one pass (each point
    with its frame index). The code branch runs once for all frames, and the world-to-canonical map (and with
    bone frames, the bones) fold into a per-frame first layer ``A_t p + c_t``, ``A_t = W_1 rot_t^T``,
    ``c_t = b_1 - A_t origin_t``: a point costs what it costs in one frame, and Python's overhead is paid per
    call, not per frame (:func:`handle_motion_collisions`). Values equal the per-frame field's up to float
    rounding.

    Args:
        net: the network (weights shared, detached).
        codes: ``(T, C)`` body codes (:func:`motion_sdf_inputs`).
        rot, origin: ``(T, 3, 3)``, ``(T, 3)``: each frame's canonical frame, ``p_canonical = (p - origin) @ rot``.

    Points are world ``(N, 3)`` metres, ``frame`` ``(N,)`` int64 their frame indices, sorted (``__call__(points,
    frame)``, :meth:`value_and_gradient_fn`).
    """

    def __init__(self, net: BodySDFNet, codes, rot, origin):
        super().__init__(net, None)
        w = self.code_weight
        codes = torch.as_tensor(np.asarray(codes), dtype=w.dtype)
        rot = torch.as_tensor(np.asarray(rot), dtype=w.dtype)
        origin = torch.as_tensor(np.asarray(origin), dtype=w.dtype)
        T = len(codes)
        if codes.shape != (T, self.code_size) or rot.shape != (T, 3, 3) or origin.shape != (T, 3):
            raise InputError(f"MotionBodySDF needs codes (T, {self.code_size}), rot (T, 3, 3), origin (T, 3), got "
                             f"{tuple(codes.shape)}, {tuple(rot.shape)}, {tuple(origin.shape)}")
        with torch.no_grad():
            self.first_bias = self._code_bias(codes)  # (T, H)
            if self.num_bones:
                weight, bias = fold_bone_frames(*self.point_first, codes, self.num_bones)  # (T, H, 3), (T, H)
            else:
                weight, bias = self.point_first[0].expand(T, -1, -1), self.point_first[1].expand(T, -1)
            self.world_weight = weight @ rot.transpose(1, 2)  # A_t = W rot^T: (T, H, 3)
            self.world_bias = bias - torch.einsum("thi,ti->th", self.world_weight, origin)
        self.num_frames = T

    def with_code(self, code):
        raise InputError("a MotionBodySDF holds its frames' codes; bind the network again for other frames")

    def _by_frame(self, rows: torch.Tensor, frame: torch.Tensor, layer) -> torch.Tensor:
        """``layer(t, rows of frame t)`` for every frame, in order: one small matrix product a frame instead of a
        per-point copy of the weights. ``frame (N,)`` must be sorted (flat indices ``t V + i`` in increasing order
        are, as :class:`CollisionResolver` passes them)."""
        if frame is None:
            raise InputError("a MotionBodySDF needs each point's frame index")
        if len(frame) > 1 and not bool((frame[1:] >= frame[:-1]).all()):
            raise InputError("MotionBodySDF takes points sorted by frame")
        counts = torch.bincount(frame, minlength=self.num_frames).tolist()
        return torch.cat([layer(t, part) for t, part in enumerate(rows.split(counts))])

    def _frame_layer(self, t: int, points: torch.Tensor) -> torch.Tensor:
        return torch.addmm(self.world_bias[t], points, self.world_weight[t].T)

    def _frame_gradient(self, t: int, g: torch.Tensor) -> torch.Tensor:
        return g @ self.world_weight[t]

    def _first_layer(self, points: torch.Tensor, frame) -> torch.Tensor:
        return self._by_frame(points, frame, self._frame_layer)

    def _first_layer_gradient(self, g: torch.Tensor, frame) -> torch.Tensor:
        return self._by_frame(g, frame, self._frame_gradient)

    def _fusion_bias(self, frame) -> torch.Tensor:
        return self.first_bias[frame]


class FramedSDF:
    """A field defined in another frame, read in the world: ``S_world(p) = S((p - origin) @ rot)`` for world
    points ``(N, 3)``; its autograd gradient is the world one (``rot @ grad S``). Only the points evaluated are
    transformed (the culled ones never are).

    Args:
        sdf: the :data:`SDFFunction` in its own frame (e.g. :meth:`BodySDFNet.bind`, canonical).
        rot: ``(3, 3)``, origin: ``(3,)``: the frame, as :func:`~loosefit.models.motion_features.to_canonical`
            uses them.
    """

    def __init__(self, sdf: SDFFunction, rot, origin):
        self.sdf = sdf
        self.rot = torch.as_tensor(np.asarray(rot), dtype=torch.float32)
        self.origin = torch.as_tensor(np.asarray(origin), dtype=torch.float32)

    def __call__(self, points: torch.Tensor) -> torch.Tensor:
        local = (points.to(torch.float32) - self.origin) @ self.rot
        return self.sdf(local).to(points.dtype)

    def value_and_gradient(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``S (N,)`` and the world gradient ``(N, 3)`` (the field's own, rotated back)."""
        local = (points.to(torch.float32) - self.origin) @ self.rot
        value, g = sdf_and_gradient(self.sdf, local)
        return value.to(points.dtype), (g @ self.rot.T).to(points.dtype)

    def value_and_gradient_fn(self, points: torch.Tensor):
        """As :func:`value_and_gradient_fn`, in the world frame."""
        local = (points.to(torch.float32) - self.origin) @ self.rot
        value, gradient = value_and_gradient_fn(self.sdf, local)
        return value.to(points.dtype), lambda rows: (gradient(rows) @ self.rot.T).to(points.dtype)


def _denormals_flushed() -> bool:
    """Whether this thread's float arithmetic flushes denormal numbers to zero."""
    return float(torch.tensor([1e-39], dtype=torch.float32).mul(1.0)) == 0.0


@contextmanager
def flushed_denormals():
    """Flush denormal floats to zero on this thread for the block (then restore): the SDF network's
    Softplus(beta=100) makes many (``exp(beta z)`` of negative pre-activations), and computing with them
    made its evaluation several times slower on the CPU here (measured in benchmarks/collision.py); the values
    they stand for (below 1e-38) are negligible."""
    was = _denormals_flushed()
    if not was:
        torch.set_flush_denormal(True)
    try:
        yield
    finally:
        if not was:
            torch.set_flush_denormal(False)


def sdf_and_gradient(sdf: SDFFunction, points: torch.Tensor, create_graph: bool = False):
    """``S (N,)`` and ``grad S (N, 3)`` of an SDF at ``points (N, 3)``: by the field's own
    ``value_and_gradient`` when it has one (and no graph is wanted), else by autograd."""
    if not create_graph and hasattr(sdf, "value_and_gradient"):
        return sdf.value_and_gradient(points.detach())
    with torch.enable_grad():
        x = points.detach().requires_grad_(True)
        s = sdf(x)
        (g,) = torch.autograd.grad(s.sum(), x, create_graph=create_graph)
    return (s if create_graph else s.detach()), g


def value_and_gradient_fn(sdf: SDFFunction, points: torch.Tensor, *frame):
    """``S (N,)`` at ``points (N, 3)`` and a function ``rows (M,) -> grad S (M, 3)`` at ``points[rows]``: the
    field's own when it has one (:meth:`BoundBodySDF.value_and_gradient_fn`; a :class:`MotionBodySDF` also
    takes the points' frames), else a second evaluation of the rows with :func:`sdf_and_gradient`."""
    if hasattr(sdf, "value_and_gradient_fn"):
        return sdf.value_and_gradient_fn(points, *frame)
    with torch.no_grad():
        value = sdf(points)
    return value, lambda rows: sdf_and_gradient(sdf, points[rows])[1]


def sdf_loss(net: BodySDFNet, points: torch.Tensor, target: torch.Tensor, normals: torch.Tensor,
             code: torch.Tensor | None = None, eikonal: float = EIKONAL_WEIGHT) -> tuple[torch.Tensor, dict]:
    """SwinGar Eqs. 8-9 on ``points (N, 3)`` with true signed distances ``target (N,)`` and true gradients
    ``normals (N, 3)`` (unit): ``mean(|S - s| + |grad S - n|) + mu_e mean((|grad S| - 1)^2)``."""
    with torch.enable_grad():
        x = points.detach().requires_grad_(True)
        s = net(x, code)
        (g,) = torch.autograd.grad(s.sum(), x, create_graph=True)
    value = (s - target).abs().mean()
    normal = (g - normals).norm(dim=-1).mean()
    eik = ((g.norm(dim=-1) - 1) ** 2).mean()
    terms = {"value": float(value.detach()), "normal": float(normal.detach()), "eikonal": float(eik.detach())}
    return value + normal + eikonal * eik, terms


class ExactSDF:
    """The body's exact signed distance (libigl, :class:`BodySDF`) as an :data:`SDFFunction`: values from the
    mesh, gradients the unit direction from the closest surface point (outwards), so that
    :func:`resolve_collisions` can use it as the reference for the network.

    Args:
        mesh: a :class:`BodySDF` (the posed body, its tree built once).
    """

    def __init__(self, mesh: BodySDF):
        self.mesh = mesh

    def _query(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Signed distances ``(N,)`` and unit outward gradients ``(N, 3)``, as tensors like ``points``."""
        p = points.detach().cpu().double().numpy()
        dist, closest, face = self.mesh.closest(p)
        away = p - closest
        norm = np.linalg.norm(away, axis=1, keepdims=True)
        direction = np.where(norm > 1e-9, away / np.maximum(norm, 1e-12) * np.sign(dist)[:, None],
                             self.mesh.face_normals[face])  # on the surface: the face normal
        as_points = dict(dtype=points.dtype, device=points.device)
        return torch.as_tensor(dist, **as_points), torch.as_tensor(direction, **as_points)

    def __call__(self, points: torch.Tensor) -> torch.Tensor:
        value, direction = self._query(points)
        # the value with the exact gradient attached: d/dx (value + n . (x - x0)) = n
        return value + (direction * (points - points.detach())).sum(-1)

    def value_and_gradient_fn(self, points: torch.Tensor):
        """Values ``(N,)`` and ``rows -> gradients (M, 3)`` from one query (see :func:`value_and_gradient_fn`)."""
        value, direction = self._query(points)
        return value, lambda rows: direction[rows]


def vertex_neighbours(faces: np.ndarray, num_verts: int) -> tuple[np.ndarray, np.ndarray]:
    """Both directions of every mesh edge: ``src, dst (2E,)`` int64."""
    e = edges(np.asarray(faces, np.int64))
    return np.concatenate([e[:, 0], e[:, 1]]), np.concatenate([e[:, 1], e[:, 0]])


def _bool_mask(mask, shape: tuple) -> np.ndarray:
    """``mask`` (NumPy or torch) as a NumPy bool array of ``shape``, or a clear error."""
    mask = mask.cpu().numpy() if isinstance(mask, torch.Tensor) else np.asarray(mask)
    if mask.shape != shape or mask.dtype != bool:
        raise InputError(f"candidates must be a {shape} bool mask, got {mask.dtype} {mask.shape}")
    return mask


class CollisionResolver:
    """SwinGar Eq. 10 on one garment mesh: its neighbour lists are built once, then each call moves the
    vertices a field says are inside out of the body.

    For a vertex with ``S(x_i) < 0``: ``x_i + grad S / |grad S| * (|S(x_i)| + delta_i)``, where ``delta_i`` is the
    Gaussian-weighted average of ``|S|`` over its mesh neighbours that are not inside (weights
    ``exp(-d^2 / (2 sigma^2))`` of their distances, normalised to mean 1; 0 without such a neighbour).
    One step leaves a vertex inside only where the field's gradient is not a unit vector: on the medial
    axis of a non-smooth field, or where a learned field is not yet a distance.

    The field is evaluated where it is needed, not everywhere: its value at the ``candidates`` (every vertex by
    default), its value at the other neighbours of the vertices found inside (their ``|S|`` enters
    ``delta_i``), and its gradient at the inside vertices only. A vertex left out of ``candidates`` must be known
    to be outside (:class:`~loosefit.geometry.ray_cull.AxisRayCuller` proves it); it is never moved and counts as
    a free neighbour. With every vertex a candidate the result is that of evaluating the field everywhere.

    Args:
        faces: ``(F, 3)`` triangles (the neighbourhoods).
        num_verts: ``V``.
        sigma: Gaussian width, metres; None: the mean edge length of the first mesh given to :meth:`__call__`.
    """

    def __init__(self, faces: np.ndarray, num_verts: int, sigma: float | None = None):
        src, dst = vertex_neighbours(faces, num_verts)
        self.src, self.dst = src, dst
        order = np.argsort(src, kind="stable")
        self.neighbours = dst[order]  # CSR: the neighbours of i are neighbours[start[i]:start[i + 1]]
        self.start = np.concatenate([[0], np.cumsum(np.bincount(src, minlength=num_verts))])
        self.num_verts = num_verts
        self.sigma = sigma

    def mean_edge(self, verts: torch.Tensor) -> float:
        """Mean edge length of ``verts (V, 3)``, metres (1 for a mesh without edges)."""
        if len(self.src) == 0:
            return 1.0
        src, dst = (torch.from_numpy(a).to(verts.device) for a in (self.src, self.dst))
        return float((verts[src] - verts[dst]).norm(dim=-1).mean())  # each edge twice: the same mean

    def __call__(self, verts: torch.Tensor, sdf: SDFFunction, candidates=None):
        """Move the inside vertices of ``verts (V, 3)`` (metres, in the SDF's frame) out.

        Args:
            verts: ``(V, 3)`` garment vertices.
            sdf: an :data:`SDFFunction` (a :meth:`BodySDFNet.bind`, :class:`ExactSDF`, ...).
            candidates: ``(V,)`` bool (NumPy or torch), the vertices that may be inside; None: all.

        Returns:
            ``(V, 3)`` corrected vertices and the ``(V,)`` bool mask of the vertices that were inside.
        """
        V = self.num_verts
        if verts.ndim != 2 or verts.shape != (V, 3):
            raise InputError(f"resolve_collisions takes one garment ({V}, 3), got {tuple(verts.shape)}")
        cand = np.arange(V) if candidates is None else np.flatnonzero(_bool_mask(candidates, (V,)))
        moved, inside = self._resolve(verts, sdf, cand)
        return moved, torch.from_numpy(inside).to(verts.device)

    def frames(self, verts: torch.Tensor, sdf: "MotionBodySDF", candidates) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`__call__` on ``T`` frames of the garment at once: ``verts (T, V, 3)`` world metres, ``sdf`` the
        :class:`MotionBodySDF` of those frames, ``candidates (T, V)`` bool (NumPy or torch). Returns ``(T, V, 3)``
        and ``(T, V)`` bool, what :meth:`__call__` gives frame by frame (up to float rounding)."""
        V = self.num_verts
        if verts.ndim != 3 or verts.shape[1:] != (V, 3):
            raise InputError(f"resolving frames takes a garment (T, {V}, 3), got {tuple(verts.shape)}")
        T = len(verts)
        cand = np.flatnonzero(_bool_mask(candidates, (T, V)))
        if getattr(sdf, "num_frames", None) != T:
            raise InputError(f"resolving {T} frames needs a MotionBodySDF of {T} frames")
        moved, inside = self._resolve(verts.reshape(T * V, 3), sdf, cand, frames=True)
        return moved.reshape(T, V, 3), torch.from_numpy(inside.reshape(T, V)).to(verts.device)

    def _resolve(self, verts: torch.Tensor, sdf, cand: np.ndarray, frames: bool = False):
        """The moved copy of ``verts`` and the NumPy mask of the vertices found inside, evaluating ``sdf`` at the
        flat indices ``cand`` (and where ``delta_i`` needs it). The field runs in torch on the vertices' device;
        the bookkeeping of a few hundred vertices runs in NumPy (cheaper per call). With ``frames``, ``verts``
        is ``(T V, 3)``, flat index ``t V + i`` is vertex ``i`` of frame ``t``, and ``sdf`` (a
        :class:`MotionBodySDF`) takes each point's frame. The Gaussian width, if not set, is the mean edge of
        the first frame."""
        if self.sigma is None:
            self.sigma = self.mean_edge(verts[:self.num_verts])
        out = verts.detach().clone()
        inside = np.zeros(len(out), bool)
        with flushed_denormals():
            self._move_out(out, sdf, cand, inside, frames)
        return out, inside

    def _move_out(self, out: torch.Tensor, sdf, cand: np.ndarray, inside: np.ndarray, frames: bool) -> None:
        """:meth:`_resolve`'s work, in place on ``out``, filling ``inside``."""
        dev = out.device
        V = self.num_verts
        if len(cand) == 0:
            return

        def at(index: np.ndarray) -> tuple:  # the field's arguments for these flat indices
            rows = torch.from_numpy(index).to(dev)
            return (out[rows], rows // V) if frames else (out[rows],)

        x = out.cpu().numpy()
        s_cand, gradient = value_and_gradient_fn(sdf, *at(cand))
        s_cand = s_cand.detach().cpu().numpy().astype(np.float64)
        hit = s_cand < 0
        ins = cand[hit]
        inside[ins] = True
        if len(ins) == 0:
            return
        g = gradient(torch.from_numpy(np.flatnonzero(hit)).to(dev)).detach().cpu().numpy().astype(np.float64)
        value = np.full(len(x), np.nan)
        value[cand] = s_cand
        # the neighbours of the inside vertices, flat: neighbour nbr[k] belongs to inside vertex ins[rows[k]]
        vertex = ins % V
        count = self.start[vertex + 1] - self.start[vertex]
        total = np.cumsum(count)
        nbr = self.neighbours[np.repeat(self.start[vertex] - total + count, count) + np.arange(total[-1])]
        nbr = nbr + np.repeat(ins - vertex, count)  # the same frame's
        rows = np.repeat(np.arange(len(ins)), count)
        free = ~inside[nbr]
        need = np.zeros(len(x), bool)
        need[nbr[free]] = True
        need[cand] = False
        missing = np.flatnonzero(need)  # free neighbours not evaluated yet: their |S| enters delta
        if len(missing):
            with torch.no_grad():
                value[missing] = sdf(*at(missing)).cpu().numpy()
        x_in = x[ins].astype(np.float64)
        diff = x_in[rows] - x[nbr]
        d2 = np.einsum("ij,ij->i", diff, diff)
        w = np.exp(-d2 / (2 * self.sigma**2)) * free
        wsum = np.bincount(rows, w, len(ins))
        weighted = np.bincount(rows, w * np.abs(np.where(free, value[nbr], 0.0)), len(ins))
        delta = np.divide(weighted, wsum, out=np.zeros(len(ins)), where=wsum > 0)
        direction = g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
        moved = x_in + direction * (np.abs(s_cand[hit]) + delta)[:, None]
        out[torch.from_numpy(ins).to(dev)] = torch.from_numpy(moved).to(out)


def resolve_collisions(verts: torch.Tensor, faces: np.ndarray, sdf: SDFFunction, sigma: float | None = None,
                       candidates=None):
    """Move every vertex inside the body out of it (SwinGar Eq. 10): one call of a :class:`CollisionResolver`.

    Args:
        verts: ``(V, 3)`` garment vertices, metres, in the SDF's frame.
        faces: ``(F, 3)`` triangles (the neighbourhoods).
        sdf: an :data:`SDFFunction` (a :meth:`BodySDFNet.bind`, :class:`ExactSDF`, a closed-form one).
        sigma: Gaussian width, metres; None: the mean edge length.
        candidates: ``(V,)`` bool, the vertices that may be inside (the others are known outside); None: all.

    Returns:
        ``(V, 3)`` corrected vertices and the ``(V,)`` bool mask of the vertices that were inside.
    """
    if verts.ndim != 2 or verts.shape[1] != 3:
        raise InputError(f"resolve_collisions takes one garment (V, 3), got {tuple(verts.shape)}")
    return CollisionResolver(faces, len(verts), sigma)(verts, sdf, candidates)


def push_out(verts: np.ndarray, body: BodySDF, distance: float = 0.004) -> tuple[np.ndarray, np.ndarray]:
    """The baseline (TailorNet): each vertex inside the body moves to its closest surface point plus
    ``distance`` along the outward direction, whatever its neighbours do. Returns vertices and the mask."""
    v = np.asarray(verts, np.float64)
    dist, closest, face = body.closest(v)
    inside = dist < 0
    away = closest - v
    norm = np.linalg.norm(away, axis=1, keepdims=True)
    direction = np.where(norm > 1e-9, away / np.maximum(norm, 1e-12), body.face_normals[face])
    out = v.copy()
    out[inside] = closest[inside] + distance * direction[inside]
    return out.astype(np.float32), inside


def sdf_samples(body: BodySDF, surface: int, near: int, inside: int, near_sigma: float = 0.02,
                seed: int = 0) -> dict[str, np.ndarray]:
    """Training points for the SDF network around one posed body: ``surface`` points on it, ``near`` points
    within about ``near_sigma`` metres of it, and ``inside`` points uniformly inside it.

    Returns ``points (N, 3)``, ``sdf (N,)`` (negative inside) and ``normals (N, 3)`` (the unit gradient of the
    true field: outward from the closest point; the face normal on the surface), float32.
    """
    rng = np.random.default_rng(seed)
    v, f = body.verts, body.faces
    tri = v[f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    n_on = surface + near
    face = rng.choice(len(f), n_on, p=area / area.sum())
    a, b = rng.random((2, n_on))
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    on = tri[face, 0] + a[:, None] * (tri[face, 1] - tri[face, 0]) + b[:, None] * (tri[face, 2] - tri[face, 0])
    on[surface:] += rng.normal(0.0, near_sigma, (near, 3))
    lo, hi = v.min(0), v.max(0)
    found = np.zeros((0, 3))
    for _ in range(100):
        if len(found) >= inside:
            break
        cand = rng.uniform(lo, hi, (max(4 * inside, 64), 3))
        found = np.concatenate([found, cand[body.query(cand) < 0]])
    points = np.concatenate([on, found[:inside]])
    dist, closest, fid = body.closest(points)
    dist[:surface] = 0.0
    away = points - closest
    norm = np.linalg.norm(away, axis=1, keepdims=True)
    normals = np.where(norm > 1e-6, away / np.maximum(norm, 1e-12) * np.sign(dist)[:, None], body.face_normals[fid])
    normals[:surface] = body.face_normals[face[:surface]]
    return {"points": points.astype(np.float32), "sdf": dist.astype(np.float32), "normals": normals.astype(np.float32)}


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
    from loosefit.models.motion_features import heading_frames, motion_features

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


@dataclass(frozen=True)
class SDFTrainConfig:
    """How :func:`train_body_sdf` samples posed bodies and fits the network.

    Attributes:
        frames: posed frames drawn from each (shape, motion) pair.
        random_shapes: Anny shapes drawn at random (:func:`random_anny_shapes`) beside the store's bodies, so
            that the network learns bodies no sequence has (SwinGar trains it on many bodies and poses).
        random_motions: procedural motions (:func:`random_procedural_motions`, ``random_motion_seconds`` long)
            beside the store's training motions (ours): poses no training sequence has, for a network that meets
            the poses of unseen motions.
        calibration_motions: procedural motions of a validation set (:func:`calibrate_margin`: the training
            bodies and 4 random ones, in poses no training sample has) on which ``loosefit train`` measures the
            margin the network needs (``--collision-margin auto``); 0: none.
        surface, near, inside: sample points per posed frame (:func:`sdf_samples`).
        near_sigma: metres. steps, lr, batch_frames: Adam steps, learning rate, frames per step. seed.
    """

    frames: int = 8
    random_shapes: int = 0
    random_motions: int = 0
    random_motion_seconds: float = 4.0
    calibration_motions: int = 6
    surface: int = 2048
    near: int = 2048
    inside: int = 512
    near_sigma: float = 0.02
    steps: int = 2000
    lr: float = 5e-4
    batch_frames: int = 4
    seed: int = 0


def random_anny_shapes(count: int, seed: int) -> list:
    """``count`` Anny shapes with every phenotype value drawn uniformly from ``[0.05, 0.95]`` (seeded)."""
    from loosefit.body import AnnyShape

    if count < 0:
        raise InputError(f"random_shapes must be >= 0, got {count}")
    values = np.random.default_rng(seed).uniform(0.05, 0.95, (count, len(AnnyShape.names())))
    return [AnnyShape.from_array(v) for v in values]


def random_procedural_motions(count: int, seed: int, body, seconds: float = 4.0) -> list:
    """``count`` procedural motions of ``body`` (:func:`~loosefit.motion.procedural.generate`), every kind in
    turn from one picked by ``seed``, each with its own seed from ``1000 + seed`` on (far from the seeds of the
    dataset plans' motions)."""
    from loosefit.motion.procedural import KINDS, generate

    if count < 0:
        raise InputError(f"random_motions must be >= 0, got {count}")
    return [generate(KINDS[(seed + k) % len(KINDS)], seconds, 1000 + seed + k, body) for k in range(count)]


def body_sdf_samples(shapes, motions, config: SDFTrainConfig) -> dict[str, np.ndarray]:
    """Samples of many posed Anny bodies (the collision proxy), canonical: ``points (P, N, 3)``, ``sdf (P, N)``,
    ``normals (P, N, 3)``, ``code (P, C)`` and ``bones (P, 12 J)`` (:func:`bone_frame_code`) for ``P`` posed
    frames (``config.frames`` per shape and motion)."""
    from loosefit.body import AnnyBody
    from loosefit.models.motion_features import heading_frames, motion_features, to_canonical

    rng = np.random.default_rng(config.seed)
    out: dict[str, list] = {"points": [], "sdf": [], "normals": [], "code": [], "bones": []}
    for shape in shapes:
        proxy = AnnyBody(shape, resolution="low")
        for motion in motions:
            feats = motion_features(motion)
            rot, origin = heading_frames(motion)
            frames = np.sort(rng.choice(motion.num_frames, min(config.frames, motion.num_frames), replace=False))
            posed_body = proxy.pose(motion)
            posed = to_canonical(posed_body.verts[frames], rot[frames], origin[frames])
            code = body_code(shape.to_array(), feats["root"][frames], feats["joints"][frames])
            bones = bone_frame_code(posed_body.joint_transforms[frames], rot[frames], origin[frames])
            for k, verts in enumerate(posed):
                s = sdf_samples(BodySDF(verts, proxy.faces), config.surface, config.near, config.inside,
                                config.near_sigma, seed=int(rng.integers(2**31)))
                for key in ("points", "sdf", "normals"):
                    out[key].append(s[key])
                out["code"].append(code[k])
                out["bones"].append(bones[k])
    return {k: np.stack(v) for k, v in out.items()}


def samples_code(samples: dict[str, np.ndarray], bone_frames: bool) -> np.ndarray:
    """The network codes ``(P, C)`` of :func:`body_sdf_samples`: ``code``, then with ``bone_frames`` ``bones``."""
    return np.concatenate([samples["code"], samples["bones"]], 1) if bone_frames else samples["code"]


def train_body_sdf(samples: dict[str, np.ndarray], config: SDFTrainConfig = SDFTrainConfig(),
                   net_config: BodySDFConfig = BodySDFConfig(), progress: bool = False) -> tuple[BodySDFNet, list]:
    """Fit a :class:`BodySDFNet` to :func:`body_sdf_samples` with SwinGar Eqs. 8-9 (Adam). Returns the network
    and the loss per step."""
    torch.manual_seed(config.seed)
    pts, sdf, nrm = (torch.from_numpy(samples[k]) for k in ("points", "sdf", "normals"))
    code = torch.from_numpy(samples_code(samples, net_config.bone_frames))
    num_bones = samples["bones"].shape[1] // 12 if net_config.bone_frames else 0
    net = BodySDFNet(code.shape[1], net_config, num_bones)
    opt = torch.optim.Adam(net.parameters(), config.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, config.steps)
    gen = torch.Generator().manual_seed(config.seed)
    history = []
    with flushed_denormals():  # as at inference: Softplus(beta=100) makes denormals, slow on x86 (~10 % a step)
        for step in range(config.steps):
            pick = torch.randperm(len(pts), generator=gen)[:config.batch_frames]
            loss, terms = sdf_loss(net, pts[pick], sdf[pick], nrm[pick], code[pick])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            history.append(float(loss.detach()))
            if progress and step % 100 == 0:
                print(f"step {step}: loss {history[-1]:.4g} {terms}")
    return net, history


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


#: Bin side of the cull (:class:`~loosefit.geometry.ray_cull.AxisRayCuller`), metres. Finer bins leave fewer
#: candidates (10k-vertex garments skinned to the walking Anny proxy: 87-349 a frame at 1.25 cm against 160-467 at
#: 2 cm, the skirt's 402 down to 93) but cost more to rasterise: over a motion the two sizes take the same time
#: within 0.06 ms except for the skirt, 0.13-0.22 ms faster at 1.25 cm (benchmarks/collision.py,
#: ``collision-speed-30k.json``, ``collision-speed-32-30k.json``). With a margin, fewer candidates also means fewer
#: vertices moved that the cull could have proved outside.
CULL_CELL = 0.0125


def correct_frame(verts: np.ndarray, resolver: CollisionResolver, sdf: SDFFunction, frame=None,
                  culler: AxisRayCuller | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Collision handling of one world frame: SwinGar Eq. 10 where the garment may be inside the body.

    Args:
        verts: ``(V, 3)`` world garment vertices, metres.
        resolver: the garment's :class:`CollisionResolver`.
        sdf: the field, in its own frame (:meth:`BodySDFNet.bind` in the canonical frame, :class:`ExactSDF`).
        frame: ``(rot (3, 3), origin (3,))``: the field's frame, ``p_sdf = (p - origin) @ rot``; None: the world.
        culler: the posed collision body's :class:`~loosefit.geometry.ray_cull.AxisRayCuller`, updated to this
            frame: the vertices it proves outside are never given to the field (they could not be moved
            anyway); None: every vertex is evaluated.

    Returns:
        ``(V, 3)`` float32 corrected world vertices and the ``(V,)`` bool mask of the vertices moved.
    """
    world = np.ascontiguousarray(verts, np.float32)
    candidates = None if culler is None else ~culler.outside(world)
    if frame is not None:
        sdf = FramedSDF(sdf, *frame)
    out, inside = resolver(torch.from_numpy(world), sdf, candidates)
    return out.numpy(), inside.numpy()


#: Frames corrected in one pass of the network by :func:`correct_motion`: enough that Python's per-call overhead
#: is paid rarely, few enough that a chunk's ``(T V, 3)`` arrays stay small and a short motion still gives both
#: workers a chunk.
FRAME_CHUNK = 32


def correct_motion(verts: np.ndarray, resolver: CollisionResolver, net: "BodySDFNet", code, rot, origin,
                   posed: np.ndarray | None = None, culler: AxisRayCuller | None = None, margin: float = 0.0,
                   workers: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """SwinGar Eq. 10 with the network on every frame of an animated garment, :data:`FRAME_CHUNK` frames a
    pass (:class:`MotionBodySDF`, :meth:`CollisionResolver.frames`): what :func:`correct_frame` gives frame by
    frame, up to float rounding.

    Args:
        verts: ``(T, V, 3)`` world garment vertices, metres.
        resolver: the garment's :class:`CollisionResolver`.
        net: the body SDF network; ``code (T, C)``, ``rot (T, 3, 3)``, ``origin (T, 3)``: its inputs per frame
            (:func:`motion_sdf_inputs`).
        posed, culler: the posed collision proxy ``(T, Vb, 3)`` and its
            :class:`~loosefit.geometry.ray_cull.AxisRayCuller`: only the vertices it cannot prove outside reach
            the network; None: every vertex does.
        margin: metres, the network's surface moved outwards (:meth:`BoundBodySDF.offset`).
        workers: threads correcting chunks side by side (Warp's kernels, torch and NumPy's large operations run
            without Python's lock, so two use two cores; each has its own culler and one torch thread); 1: one
            chunk after another, with torch's thread count as it is.

    Returns:
        ``(T, V, 3)`` float32 corrected vertices and the ``(T, V)`` bool mask of the vertices moved.
    """
    if workers < 1:
        raise InputError(f"collision workers must be >= 1, got {workers}")
    world = np.array(verts, np.float32, copy=True)
    T = len(world)
    inside = np.zeros(world.shape[:2], bool)
    if resolver.sigma is None and T:  # set before the threads share the resolver
        resolver.sigma = resolver.mean_edge(torch.from_numpy(world[0]))
    chunks = [slice(s, min(s + FRAME_CHUNK, T)) for s in range(0, T, FRAME_CHUNK)]
    workers = min(workers, len(chunks)) or 1
    cullers = queue.SimpleQueue()  # one culler (its map buffers) per running chunk
    for k in range(workers if culler is not None else 0):
        cullers.put(culler if k == 0 else culler.twin())

    def correct(chunk: slice) -> None:  # frames of one chunk, written in place (chunks do not overlap)
        if culler is None:
            cand = np.ones((chunk.stop - chunk.start, world.shape[1]), bool)
        else:
            mine = cullers.get()
            try:
                cand = ~mine.update(posed[chunk], world[chunk]).outside(world[chunk])  # the chunk's frames at once
            finally:
                cullers.put(mine)
        field = MotionBodySDF(net, code[chunk], rot[chunk], origin[chunk]).offset(margin)
        moved, hit = resolver.frames(torch.from_numpy(world[chunk]), field, cand)
        world[chunk], inside[chunk] = moved.numpy(), hit.numpy()

    if workers == 1:
        for chunk in chunks:
            correct(chunk)
    else:  # one torch thread a worker: measured faster than two each on two cores (benchmarks/collision.py)
        with torch_threads(1), ThreadPoolExecutor(workers) as pool:
            list(pool.map(correct, chunks))  # list(): an exception in a chunk is raised here
    return world, inside


def handle_motion_collisions(verts: np.ndarray, faces: np.ndarray, body, motion, mode: str = "exact",
                             net: BodySDFNet | None = None, push_distance: float = 0.004,
                             cull: bool = True, margin: float = 0.0, cull_cell=CULL_CELL) -> np.ndarray:
    """Collision post-process of an animated garment, any method: world ``verts (T, V, 3)`` on ``body`` (an
    Anny body of the right shape) following ``motion`` -> corrected ``(T, V, 3)`` float32.

    ``mode``: ``"neural"`` (SwinGar Eq. 10 with ``net``, in the canonical frame, the code from the motion),
    ``"exact"`` (SwinGar Eq. 10 with libigl's distance to the posed collision proxy) or ``"pushout"`` (the
    fixed-distance baseline). With ``cull`` (the default) SwinGar Eq. 10 evaluates its field only at the
    vertices that the posed proxy's :class:`~loosefit.geometry.ray_cull.AxisRayCuller` cannot prove outside
    (:func:`correct_frame`); the network runs on :data:`FRAME_CHUNK` frames a pass (:func:`correct_motion`); the
    Gaussian width is the mean edge length of the first frame. ``cull_cell``: the cull's bin side, metres (one
    or ``(x, y, z)``).

    ``margin`` (metres, ``"neural"`` only; ours, 0 in the paper): Eq. 10 on the network's surface moved that far
    outwards, ``S - margin``: a vertex the network puts less than ``margin`` outside is corrected too, and moved
    to ``margin + delta_i``. A network that is millimetres off near the surface misses the shallow collisions
    on the wrong side of its zero level; the margin catches them (the cull still skips every vertex it proves
    outside the proxy, so no vertex far from the body moves).
    """
    if mode not in ("neural", "exact", "pushout"):
        raise InputError(f"collision mode must be 'neural', 'exact' or 'pushout', got {mode!r}")
    if mode == "neural" and net is None:
        raise InputError("neural collision handling needs a body SDF network")
    if not (np.isfinite(margin) and margin >= 0):
        raise InputError(f"collision margin must be a non-negative number of metres, got {margin!r}")
    proxy = body.collision_proxy()
    out = np.array(verts, np.float32, copy=True)
    posed = proxy.pose(motion).verts if (cull or mode != "neural") else None
    culler = AxisRayCuller(posed[0], proxy.faces, cull_cell) if cull and mode != "pushout" else None
    resolver = CollisionResolver(faces, out.shape[1])
    if mode == "neural":
        code, rot, origin = motion_sdf_inputs(body, motion, net.num_bones > 0)
        return correct_motion(out, resolver, net.eval(), code, rot, origin, posed, culler, margin)[0]
    for t in range(len(out)):
        mesh = BodySDF(posed[t], proxy.faces)
        if mode == "pushout":
            out[t] = push_out(out[t], mesh, push_distance)[0]
        else:
            out[t] = correct_frame(out[t], resolver, ExactSDF(mesh), None,
                                   culler.update(posed[t], out[t]) if culler else None)[0]
    return out


#: The files of a body SDF run folder (``loosefit train --method collision``).
SDF_FILE, SDF_META = "body_sdf.pt", "model.json"


#: The share of inside points of a validation set that the calibrated margin catches (:func:`calibrate_margin`).
CALIBRATION_QUANTILE = 0.8


def calibrate_margin(net: BodySDFNet, shapes, motions, quantile: float = CALIBRATION_QUANTILE, depth: float = 0.02,
                     frames: int = 4, points: int = 2000, seed: int = 11) -> dict:
    """The margin (metres) the network needs on poses it never saw: posed Anny bodies of ``shapes`` along
    ``motions`` (``frames`` each), points within ``depth`` inside them (libigl's distance), and the value below
    which the network puts ``quantile`` of those points. With that margin (:meth:`BoundBodySDF.offset`),
    SwinGar Eq. 10 corrects that share of the shallow collisions on such poses; without one, only those the
    network calls inside (``caught_without_margin``).

    Returns ``{"margin_m", "quantile", "depth_m", "inside_points", "caught_without_margin", "caught_at_10mm"}``.
    """
    if not 0 < quantile < 1:
        raise InputError(f"the calibration quantile must be in (0, 1), got {quantile}")
    config = SDFTrainConfig(frames=frames, surface=0, near=points, inside=0, near_sigma=depth / 2, seed=seed)
    samples = body_sdf_samples(shapes, motions, config)
    values = []
    for pts, sdf, code in zip(samples["points"], samples["sdf"], samples_code(samples, net.num_bones > 0)):
        inside = (sdf < 0) & (sdf > -depth)
        with torch.no_grad():
            values.append(net.bind(torch.from_numpy(code))(torch.from_numpy(pts[inside])).numpy())
    v = np.concatenate(values).astype(np.float64)
    if not len(v):
        raise InputError("margin calibration found no point inside the bodies")
    return {"margin_m": float(max(np.quantile(v, quantile), 0.0)), "quantile": quantile, "depth_m": depth,
            "inside_points": int(len(v)), "caught_without_margin": float((v < 0).mean()),
            "caught_at_10mm": float((v < 0.01).mean())}


def calibration_set(shapes, config: SDFTrainConfig) -> tuple[list, list]:
    """The validation set of :func:`calibrate_margin` for a network trained on ``shapes`` (the store's bodies):
    those and 4 random Anny shapes, in ``config.calibration_motions`` procedural motions whose seeds no training
    motion has (:func:`random_procedural_motions`)."""
    from loosefit.body import AnnyBody

    return (list(shapes) + random_anny_shapes(4, config.seed + 99),
            random_procedural_motions(config.calibration_motions, config.seed + 4000, AnnyBody(),
                                      config.random_motion_seconds))


def calibrate_sdf_run(sdf_run) -> dict:
    """:func:`calibrate_margin` for a trained run folder (one trained before runs measured it): its network on
    the validation set of its config and store bodies; the result is added to its ``model.json``."""
    import json
    from pathlib import Path

    from loosefit.body import AnnyShape
    from loosefit.data.store import DatasetStore
    from loosefit.paths import atomic_path

    meta, summary = _sdf_summary(sdf_run)
    try:
        fields = SDFTrainConfig.__dataclass_fields__
        config = SDFTrainConfig(**{k: v for k, v in summary["config"].items() if k in fields})
        store = DatasetStore.open(summary["data"], mode="r")
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise InputError(f"cannot read the body SDF run's summary: {e}", meta) from None
    config = SDFTrainConfig(**{**vars(config), "calibration_motions": config.calibration_motions or 6})
    shapes = [AnnyShape.from_array(store.body(b)) for b in summary["bodies"]]
    summary["calibration"] = calibrate_margin(load_body_sdf(Path(sdf_run) / SDF_FILE), *calibration_set(shapes, config))
    with atomic_path(meta) as tmp:
        tmp.write_text(json.dumps(summary, indent=2))
    return summary["calibration"]


def _sdf_summary(sdf_run) -> tuple:
    """``(path, dict)`` of a body SDF run folder's ``model.json``; an unreadable one is an :class:`InputError`."""
    import json
    from pathlib import Path

    meta = Path(sdf_run) / SDF_META
    try:
        summary = json.loads(meta.read_text())
        if not isinstance(summary, dict):
            raise ValueError("not a JSON object")
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read the body SDF run's summary: {e}", meta) from None
    return meta, summary


def collision_margin(sdf_run, value: str | float) -> float:
    """The margin of ``loosefit animate --collision-margin``: metres, or ``"auto"``: the one
    :func:`calibrate_margin` measured when the network of run folder ``sdf_run`` was trained."""
    if str(value).strip().lower() == "auto":
        if sdf_run is None:
            raise InputError("--collision-margin auto needs a body SDF run")
        meta, summary = _sdf_summary(sdf_run)
        calibration = summary.get("calibration")
        if not calibration or "margin_m" not in calibration:
            raise InputError("this body SDF run has no calibrated margin (trained with train.calibration_motions=0 "
                             "or by an older loosefit): give the margin in metres", meta)
        return float(calibration["margin_m"])
    try:
        margin = float(value)
    except (TypeError, ValueError):
        raise InputError(f"--collision-margin must be metres or 'auto', got {value!r}") from None
    if not (np.isfinite(margin) and margin >= 0):
        raise InputError(f"--collision-margin must be a non-negative number of metres, got {value!r}")
    return margin


@dataclass(frozen=True)
class SDFRunConfig:
    """What ``loosefit train --method collision`` reads: ``train`` (:class:`SDFTrainConfig`) and ``net``
    (:class:`BodySDFConfig`), e.g. ``--set train.steps=500 --set net.hidden=256``."""

    train: SDFTrainConfig = SDFTrainConfig()
    net: BodySDFConfig = BodySDFConfig()


def train_sdf_run(data, out, run_config: SDFRunConfig = SDFRunConfig(), progress: bool = True) -> dict:
    """``loosefit train --method collision``: fit the body SDF network on every body shape and training motion
    of a dataset store (the collision proxy of each, canonical); write ``out/body_sdf.pt`` and ``out/model.json``.
    Returns the summary written to ``model.json``."""
    import json
    from pathlib import Path

    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.data.store import DatasetStore
    from loosefit.paths import atomic_path

    store = DatasetStore.open(data, mode="r")
    train = store.sequence_names(split="train")
    bodies = sorted({store.sequence(n).body for n in train})
    motions = sorted({store.sequence(n).motion for n in train})
    if not bodies or not motions:
        raise InputError("no training sequences: the body SDF trains on their bodies and motions", store.path)
    config, net_config = run_config.train, run_config.net
    shapes = [AnnyShape.from_array(store.body(b)) for b in bodies]
    shapes += random_anny_shapes(config.random_shapes, config.seed + 1)
    extra = random_procedural_motions(config.random_motions, config.seed + 2, AnnyBody(),
                                      config.random_motion_seconds) if config.random_motions else []
    samples = body_sdf_samples(shapes, [store.motion(m) for m in motions] + extra, config)
    net, history = train_body_sdf(samples, config, net_config, progress)
    calibration = calibrate_margin(net.eval(), *calibration_set(shapes[:len(bodies)], config)) \
        if config.calibration_motions else None
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    save_body_sdf(out / SDF_FILE, net)
    summary = {"method": "collision", "data": str(Path(data).resolve()), "bodies": bodies,
               "random_shapes": [s.to_array().tolist() for s in shapes[len(bodies):]], "motions": motions,
               "random_motions": [m.name for m in extra], "calibration": calibration,
               "frames": int(len(samples["code"])), "first_loss": history[0] if history else None,
               "final_loss": history[-1] if history else None,
               "config": dict(vars(config)), "net": dict(vars(net_config))}
    with atomic_path(out / SDF_META) as tmp:
        tmp.write_text(json.dumps(summary, indent=2))
    return summary
