"""One animation frame as a self-contained torch graph: body pose in, world garment out, state carried.

:class:`StepGraph` is the frame-by-frame path of :class:`loosefit.animate.AnimationStream` (the motion
features of :class:`~loosefit.models.motion_features.FeatureStream`, the model's forward pass on one frame, the
model's frame put back: :mod:`loosefit.motion.heading`) written so that every quantity a frame
needs from the frames before it lives in one flat float32 ``state (S,)`` vector, in and out. Traced once, it is an
ONNX model a game engine or a web page steps without Python (:mod:`loosefit.export_onnx`).

Per frame, all float32::

    joint_rotations (J, 3) axis-angle rad, root_position (3,) m, state (S,)
        -> vertices (V, 3) world m, next_state (S,), bone_transforms (B, 4, 4) world

The state's fields, in order (:meth:`StepGraph.layout`): ``started`` (0 before the first frame: the graph then
takes the frame as its own predecessor, zero displacement and heading change, and zeroes the averages and the
recurrent state, as :class:`FeatureStream` does at a motion's start), the previous root position and heading,
the motion history's moving averages (:mod:`loosefit.models.motion_features`, world axes) and the network's
recurrent state (VirtualBones: two GRU states, Sec. 4.2 and 4.3; JointNet: one GRU state per selected joint).
Bone transforms are the world matrices of the bones' nodes: bone ``b`` at rest sits at ``c_b`` with the world
axes (``bone_rest``), so a rest point ``p`` goes to ``M_b [I | -c_b] p`` (the skinned glTF's inverse bind matrix);
for body-LBS the bones are the body's joints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from loosefit.errors import InputError
from loosefit.geometry.lbs import forward_kinematics
from loosefit.geometry.rotations import axis_angle_to_matrix, sixd_to_matrix
from loosefit.models.layers.mlp import NEGATIVE_SLOPE

#: The methods :class:`StepGraph` runs (the per-garment recurrent ones and the baseline).
STEP_METHODS = ("body-lbs", "virtualbones", "jointnet")


@dataclass(frozen=True)
class StateField:
    """One named block of the flat state: ``offset`` into it, ``shape``, ``unit`` and what its axes are."""

    name: str
    offset: int
    shape: tuple[int, ...]
    unit: str
    axes: str

    @property
    def size(self) -> int:
        return int(np.prod(self.shape)) if self.shape else 1

    def to_json(self) -> dict:
        return {"name": self.name, "offset": self.offset, "shape": list(self.shape), "unit": self.unit,
                "axes": self.axes}


def gru_cell(x: torch.Tensor, h: torch.Tensor, w_ih, w_hh, b_ih, b_hh) -> torch.Tensor:
    """One step of torch's GRU (gates r, z, n; :mod:`loosefit.models.layers.gru_bptt`): ``x (..., in)``,
    ``h (..., H)`` -> ``(..., H)``; weights ``(3H, in)``, ``(3H, H)``, biases ``(3H,)``."""
    gi = nn.functional.linear(x, w_ih, b_ih)  # one Gemm with the weights as stored: the fastest matrix-vector here
    gh = nn.functional.linear(h, w_hh, b_hh)
    H = h.shape[-1]
    r = torch.sigmoid(gi[..., :H] + gh[..., :H])
    z = torch.sigmoid(gi[..., H:2 * H] + gh[..., H:2 * H])
    n = torch.tanh(gi[..., 2 * H:] + r * gh[..., 2 * H:])
    return n + z * (h - n)  # (1 - z) n + z h


def skin_dense(rest: torch.Tensor, weights: torch.Tensor, rotations: torch.Tensor, translations: torch.Tensor):
    """Linear blend skinning as one product: ``rest (V, 3)``, ``weights (V, B)``, ``rotations (B, 3, 3)``,
    ``translations (B, 3)`` -> ``(V, 3)`` (VirtualBones Eq. 1): the blended ``[R | T]`` rows ``(V, 12)`` are
    ``weights @ [R | T]``; each vertex then needs three dot products, done element-wise (no per-vertex product)."""
    blend = (weights @ torch.cat([rotations, translations[:, :, None]], -1).reshape(-1, 12)).reshape(-1, 3, 4)
    return (blend[:, :, :3] * rest[:, None, :]).sum(-1) + blend[:, :, 3]


def _sixd(R: torch.Tensor) -> torch.Tensor:
    """``(..., 3, 3)`` -> 6D ``(..., 6)``: first column then second (as
    :func:`loosefit.geometry.rotations.matrix_to_sixd`)."""
    return torch.cat([R[..., :, 0], R[..., :, 1]], -1)


class StepGraph(nn.Module):
    """One frame of a trained per-garment model (module doc), ready for :func:`torch.onnx.export`.

    Args:
        model: a :class:`~loosefit.models.body_lbs.BodyLBS`, :class:`~loosefit.models.virtualbones.VirtualBones`
            or :class:`~loosefit.models.jointnet.JointNet` with its weights, in eval mode.
        bones: also return the bones' world transforms ``(B, 4, 4)``.
    """

    def __init__(self, model, bones: bool = False):
        super().__init__()
        if model.method not in STEP_METHODS:
            raise InputError(f"{model.method} has no one-frame graph; methods: {', '.join(STEP_METHODS)}")
        self.model = model.eval()
        self.method = model.method
        self.bones = bones
        self.frame = getattr(model, "frame", "heading")  # the frame the garment is in (motion.heading.FRAMES)
        self.num_joints = int(model.sizes()["num_joints"])
        history = model.history
        frames = history.frames if history else ()
        self.channels = history.channels if history else 0
        self.register_buffer("decay", torch.tensor(np.exp(-1.0 / np.asarray(frames, np.float64)), dtype=torch.float32)
                             .reshape(-1, 1))
        fields = [("started", (1,), "1", "0 before the first frame, 1 after"),
                  ("previous_root_position", (3,), "m", "x, y, z world (Z up)"),
                  ("previous_heading", (1,), "rad", "yaw about Z of the root, 0 facing -Y")]
        if frames:
            axes = ("per time constant: heading change (rad/frame), root displacement x, y"
                    + (", z" if self.channels == 4 else "") + " (m/frame, world)")
            fields.append(("history", (len(frames), self.channels), "mixed", axes))
        fields += self._network_fields()
        offset, self._fields = 0, []
        for name, shape, unit, axes in fields:
            f = StateField(name, offset, tuple(int(s) for s in shape), unit, axes)
            self._fields.append(f)
            offset += f.size
        self.state_size = offset

    def _network_fields(self) -> list[tuple]:
        m = self.model
        if self.method == "virtualbones":
            return [("gru_low", (m.low.gru.num_layers, m.low.gru.hidden_size), "1", "layer, unit: low-frequency GRU"),
                    ("gru_high", (m.high_gru.gru.num_layers, m.high_gru.gru.hidden_size), "1",
                     "layer, unit: high-frequency GRU")] + ([
                    ("fed_back", (m.config.feedback_frames, m.bone_rest.shape[0], 9), "1",
                     "frame (newest first), bone, normalised output: the low-frequency module's own outputs")]
                    if m.config.feedback_frames else [])
        if self.method == "jointnet":
            return [("gru_joints", (len(m.selected), m.gru.hidden), "1", "selected joint, unit: per-joint GRUs")]
        return []

    def layout(self) -> list[StateField]:
        """The state's fields in order (module doc)."""
        return list(self._fields)

    def initial_state(self) -> np.ndarray:
        """The state before a motion's first frame: all zeros (``started`` = 0), ``(S,)`` float32."""
        return np.zeros(self.state_size, np.float32)

    def _field(self, state: torch.Tensor, name: str) -> torch.Tensor:
        f = next(f for f in self._fields if f.name == name)
        return state[f.offset:f.offset + f.size].reshape(f.shape)

    # ------------------------------------------------------------------ the frame

    def forward(self, joint_rotations: torch.Tensor, root_position: torch.Tensor, state: torch.Tensor):
        """``joint_rotations (J, 3)``, ``root_position (3,)``, ``state (S,)`` -> ``(vertices (V, 3), next_state (S,))``
        and with ``bones`` also ``bone_transforms (B, 4, 4)`` (module doc)."""
        R = axis_angle_to_matrix(joint_rotations)  # (J, 3, 3)
        root_rot = R[0]
        # heading psi: the rest forward -Y turned by the root, projected on the floor (motion.heading.heading_angles)
        psi = torch.atan2(-root_rot[0, 1], root_rot[1, 1])
        c, s = torch.cos(psi), torch.sin(psi)
        zero, one = torch.zeros_like(c), torch.ones_like(c)
        Rh = torch.stack([torch.stack([c, -s, zero]), torch.stack([s, c, zero]), torch.stack([zero, zero, one])])
        started = self._field(state, "started")[0] > 0.5
        prev_pos = torch.where(started, self._field(state, "previous_root_position"), root_position)
        prev_psi = torch.where(started, self._field(state, "previous_heading")[0], psi)
        disp = root_position - prev_pos
        turn = psi - prev_psi
        dpsi = turn - (2 * math.pi) * torch.floor((turn + math.pi) / (2 * math.pi))  # wrapped to [-pi, pi)
        tilt = Rh.T @ root_rot
        parts = [root_position[2:3], disp @ Rh, dpsi[None], _sixd(tilt)]
        next_parts = [one[None], root_position, psi[None]]
        if self.channels:
            averages = self._recurrent(state, "history", started)  # zero at a motion's first frame
            x = torch.cat([dpsi[None], disp])[: self.channels]
            averages = self.decay * averages + (1 - self.decay) * x  # m_t = a m_{t-1} + (1 - a) x_t
            horizontal = averages[:, 1:3] @ Rh[:2, :2]  # world -> heading frame
            parts.append(torch.cat([averages[:, :1], horizontal, averages[:, 3:]], 1).reshape(-1))
            next_parts.append(averages.reshape(-1))
        root = torch.cat(parts)
        joints = _sixd(R[1:])  # (J-1, 6)
        network = getattr(self, "_" + self.method.replace("-", "_"))
        verts, bone_R, bone_T, recurrent = network(root, joints, state, started)
        verts = self.model.pinned(verts, root, joints)  # the garment's pins kept, as animate keeps them
        origin = torch.cat([root_position[:2], zero[None]]) if self.frame == "heading" else root_position
        if self.frame == "pelvis":
            Rh = root_rot
        world = verts @ Rh.T + origin
        next_state = torch.cat(next_parts + [r.reshape(-1) for r in recurrent])
        if not self.bones:
            return world, next_state
        rot_w = Rh @ bone_R  # (B, 3, 3)
        trans_w = bone_T @ Rh.T + origin
        centre = self.bone_rest_positions()
        position = (rot_w * centre[:, None, :]).sum(-1) + trans_w  # where the bone's rest position went
        B = rot_w.shape[0]
        bottom = torch.cat([torch.zeros(B, 1, 3), torch.ones(B, 1, 1)], -1)
        return world, next_state, torch.cat([torch.cat([rot_w, position[:, :, None]], -1), bottom], 1)

    def bone_rest_positions(self) -> torch.Tensor:
        """``(B, 3)`` rest positions of the bones the graph outputs (body-LBS: the body joints), metres."""
        return self.model.rest_joints if self.method == "body-lbs" else self.model.bone_rest

    def _recurrent(self, state: torch.Tensor, name: str, started: torch.Tensor) -> torch.Tensor:
        """Field ``name`` of the state, zeros before the first frame (whatever the caller passed)."""
        h = self._field(state, name)
        return torch.where(started, h, torch.zeros_like(h))

    # ------------------------------------------------------------------ per method: canonical frame

    def _body_lbs(self, root, joints, state, started):
        """Body-LBS (:class:`~loosefit.models.body_lbs.BodyLBS`): forward kinematics in the heading frame and
        linear blend skinning; the canonical skinning transforms' rotations and translations are the bones'."""
        m = self.model
        local = sixd_to_matrix(torch.cat([root[None, 5:11], joints]))[None]  # (1, J, 3, 3)
        origin = torch.cat([torch.zeros(2), root[:1]])[None]
        world = forward_kinematics(local, origin, m.rest_joints, m.parents)[0]  # (J, 4, 4)
        rot = world[:, :3, :3]
        trans = world[:, :3, 3] - (rot * m.rest_joints[:, None, :]).sum(-1)
        return skin_dense(m.template, m.weights, rot, trans), rot, trans, []

    def _virtualbones(self, root, joints, state, started):
        """VirtualBones (Sec. 4.2, 4.3) on one frame: :meth:`VirtualBones.forward` with ``T`` = 1."""
        m = self.model
        root_n = (root[: m.root_features] - m.root_mean) / m.root_std
        joints_n = (joints - m.joints_mean) / m.joints_std
        joints_n = joints_n * m.joint_read  # the joints not read held at zero
        x = torch.cat([root_n, joints_n.reshape(-1)])
        fed = self._recurrent(state, "fed_back", started).reshape(-1) if m.config.feedback_frames else None
        if fed is not None:
            x = torch.cat([x, fed])
        h_low = self._gru_stack(m.low.gru, x, self._recurrent(state, "gru_low", started))
        raw = m.low.out(h_low[-1]).reshape(-1, 9)
        rot, trans = m.decode_bones(raw)
        lf = skin_dense(m.rest_verts, m.skin_weights, rot, trans)
        h_high = self._gru_stack(m.high_gru.gru, raw.reshape(-1), self._recurrent(state, "gru_high", started))
        glob = nn.functional.leaky_relu(m.global_out(m.high_gru.out(h_high[-1])).reshape(lf.shape[0], -1),
                                        NEGATIVE_SLOPE)
        local = (lf - m.lf_mean) / m.lf_std
        order = m.neighbours.reshape(-1)  # vertex-major: the max runs over each vertex's contiguous neighbours
        for conv in m.edge_convs:  # (EdgeConv.forward; 1.8x faster in onnxruntime than a neighbour-major gather)
            C = conv.in_channels
            w_centre, w_edge = conv.linear.weight[:, :C], conv.linear.weight[:, C:]
            other = local @ w_edge.T
            nearest = other.index_select(0, order).reshape(m.neighbours.shape[0], -1, other.shape[-1]).amax(1)
            local = nn.functional.leaky_relu(local @ (w_centre - w_edge).T + conv.linear.bias + nearest, NEGATIVE_SLOPE)
        offsets = m.head(torch.cat([local, glob], -1)) * m.offset_std
        fed_next = [] if fed is None else [torch.cat([raw.reshape(-1), fed[: fed.shape[0] - raw.numel()]])]
        return lf + offsets, rot, trans, [h_low, h_high, *fed_next]

    @staticmethod
    def _gru_stack(gru: nn.GRU, x: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        """``nn.GRU`` layers on one frame: ``x (in,)``, ``h (layers, H)`` -> the new states ``(layers, H)``."""
        out = []
        for k in range(gru.num_layers):
            weights = (getattr(gru, f"{name}_l{k}") for name in ("weight_ih", "weight_hh", "bias_ih", "bias_hh"))
            x = gru_cell(x, h[k], *weights)
            out.append(x)
        return torch.stack(out)

    def _jointnet(self, root, joints, state, started):
        """JointNet (Sec. 3) on one frame: :meth:`JointNet.forward` with ``T`` = 1, two products rearranged (same
        function): each joint's GRU and read-out as a row vector times its transposed weights (one batched product,
        1.4x faster in onnxruntime than the weights times a column), and the bone MLP's first layer applied to the
        ``J_s`` joint features before the association mixes them into ``B`` bones (``W [A psi, f] = A (psi W_a^T) +
        W_f f``, the garment prior's part a constant), which saves most of that layer's work for ``B > J_s``."""
        m = self.model
        # (J_s, C), its shape spelled out: the exported graph then knows it (the int8 rewrite needs it)
        G, _, C = (int(d) for d in m.gru.weight_ih.shape)
        x = m.joint_inputs(root[None, None], joints[None, None])[0, 0].reshape(G, C)
        h = self._recurrent(state, "gru_joints", started)  # (J_s, H)
        g = m.gru
        gi = (x[:, None] @ g.weight_ih.transpose(1, 2))[:, 0] + g.bias_ih[:, 0]
        gh = (h[:, None] @ g.weight_hh.transpose(1, 2))[:, 0] + g.bias_hh[:, 0]
        H = h.shape[-1]
        r = torch.sigmoid(gi[:, :H] + gh[:, :H])
        z = torch.sigmoid(gi[:, H:2 * H] + gh[:, H:2 * H])
        n = torch.tanh(gi[:, 2 * H:] + r * gh[:, 2 * H:])
        h = n + z * (h - n)
        psi = (h[:, None] @ m.joint_out_weight.transpose(1, 2))[:, 0] + m.joint_out_bias[:, 0]  # (J_s, K)
        R, trans = self._bones(psi)
        weights = m.psd_mlp(psi)  # (J_s, |X|)
        basis = m.psd_basis.reshape(-1, m.psd_basis[0, 0].numel())  # (J_s |X|, 3V), or (J_s |X|, 3k) in modes
        displacement = nn.functional.linear(weights.reshape(1, -1), basis.T).reshape(-1, 3)
        if m.psd_mode_count:  # the mode coefficients to the vertices
            displacement = m.psd_modes @ displacement
        rest = m.rig_rest + displacement
        return skin_dense(rest, m.skin_weights, R, trans), R, trans, [h]

    def _bones(self, psi: torch.Tensor):
        """JointNet's bone rotations ``(B, 3, 3)`` and translations ``(B, 3)`` from the joint features ``psi (J_s, K)``
        (:meth:`JointNet.bone_transforms` of :meth:`JointNet.join_prior`, the first layer rearranged: see above)."""
        m = self.model
        first = m.bone_mlp[0]
        K = psi.shape[-1]
        A = m.association_matrix()  # (B, J_s)
        prior = m.fourier_features()  # (B, K)
        if m.config.fourier == "add":
            hidden = A @ (psi @ first.weight.T) + nn.functional.linear(prior, first.weight, first.bias)
        else:
            hidden = A @ (psi @ first.weight[:, :K].T) + nn.functional.linear(prior, first.weight[:, K:], first.bias)
        for layer in list(m.bone_mlp)[1:]:  # the activation after the first layer, then the others
            hidden = layer(hidden)
        return m.bone_outputs(hidden)
