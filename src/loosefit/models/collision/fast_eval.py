"""Evaluating a trained body SDF network fast, for inference: values and gradients without autograd.

SwinGar Eq. 10 needs the field's value at many garment vertices and its gradient at the few inside the body,
every frame. Evaluated by the module and autograd, that is the network's whole cost at every vertex; here:

- :class:`BoundBodySDF`: the network bound to one body code. The code branch and its share of the first fusion
  layer run once per code; a point costs only the point branch and the fusion layers. The gradient is the chain
  rule written out (Softplus' derivative is ``sigmoid(beta z)``), taken only at the rows asked for, from the
  activations of the pass that gave the values (:meth:`BoundBodySDF.value_and_gradient_fn`).
- :class:`MotionBodySDF`: bound to every frame of a motion at once, read in the world: the world-to-canonical
  map (and the bone frames) fold into a per-frame first layer, so the points of many frames go through one pass.
- :class:`FramedSDF`: any field defined in another frame, read in the world.
- :func:`flushed_denormals`: Softplus(beta=100) makes many denormal floats, which the CPU computes with slowly;
  they are flushed to zero while the network runs.
- :func:`sdf_and_gradient`, :func:`value_and_gradient_fn`: a field's value and gradient, by its own routine when
  it has one, else by autograd.

Values equal the module's (:class:`~loosefit.models.collision.network.BodySDFNet`) up to float rounding.
"""

from __future__ import annotations

import copy
from contextlib import contextmanager

import numpy as np
import torch
from torch import nn

from loosefit.errors import InputError
from loosefit.models.collision.network import BodySDFNet, SDFFunction, fold_bone_frames

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
        rot: ``(3, 3)``, origin: ``(3,)``: the frame, as :func:`~loosefit.motion.heading.to_canonical`
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

