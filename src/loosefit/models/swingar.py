"""SwinGar (Li et al. 2024): one dynamic deformation network for many garments of any topology.

Per frame ``t`` and garment (``V`` vertices, any count), in the canonical heading frame of
:mod:`loosefit.models.motion_features` (SwinGar Sec. III-C and IV):

1. **Garment information** (once per garment, at rest). Graph encoder ``E_g``: two GAT-LN layers
   ([64, 128], 24 heads; :mod:`loosefit.models.layers.gat_ln`) on ``[n_i, x_i, a_i]`` (normal, position, fit
   attribute) -> ``G (V, 128)``. Shape encoder ``E_a``: fully connected [256, 128, 24] on the spectral
   descriptor ``lambda`` (:mod:`loosefit.rig.spectral`) -> ``a (24,)``.
2. **Body information.** Motion encoder ``E_m``: an LSTM (128) over the poses of frames ``t-63 .. t``
   (64 frames; pose = the frame's motion features: root height, displacement and heading change since
   the previous frame, root tilt, joint rotations) -> ``m_t (128,)``. Body encoder ``E_b``: fully
   connected [256, 128, 64] on the body shape and the current pose -> ``b_t (64,)``.
3. **Coarse deformation.** State encoder ``E_s``: GAT-LN (128, 24 heads) on ``G * m_t`` -> ``S_t``.
   Dynamic skinning weights: ``W_t = softmax_J(P(Q(S_t) * a))`` (``Q``: 128 -> 24, ``P``: 24 -> J, the body's
   joints). Unposed blend shapes: two GAT-LN layers ([256, 128], 3 heads) on ``S_t``, times ``m_t``, then
   a linear map to ``B_t (V, 3)``. Linear blend skinning of ``rest + B_t`` with ``W_t`` by the body's joint
   transforms, the root held at its rest position -> ``M_c^t``.
4. **Corrective.** Node features ``[M_c^t, |M_c^t - joint_k|]`` (position and distances to every joint); an
   LSTM-GAT-LN (64, 8 heads; :mod:`loosefit.models.layers.lstm_gat_ln`) over ``M_c^{t-2}, M_c^{t-1}, M_c^t``,
   times ``b_t``, then two single-head GAT-LN layers [64, 3] -> the correction, added to ``M_c^t``.
5. **Root translation last**: the root's canonical position minus its rest position.

Every GAT-LN layer uses tanh and ``alpha = 2``; fully connected layers ReLU (SwinGar Sec. IV).
GAT-LN weights are Glorot-initialised, the motion LSTM's weights Kaiming-uniform with its default
settings, linear layers torch's default (Kaiming-uniform with ``a = sqrt(5)``); the two layers whose
outputs are displacements start scaled by :data:`OUTPUT_INIT` (ours: the garment starts near its skinned
rest shape).

Losses (SwinGar Eqs. 11-14), each averaged over frames: vertex ``k_v mean_i |X_i - X_i^GT|^2``; consistency
``k_e mean_e (|e| - |e^GT|)^2 + k_b mean_f |(L N)_f|^2`` (``L`` the uniform Laplacian of the face adjacency,
``N`` the face normals); gravity ``k_g g sum_i m_i (z_i - z_i^GT)`` (SwinGar Eq. 13 less its value at the
simulation, a constant: zero at the ground truth, the same gradient); collision
``k_c mean_i min(h_i - eps, 0)^2`` with ``h_i`` the signed distance along the normal of the body vertex
closest to the simulated vertex. Training stage ``supervised`` uses the vertex term only, stage ``all``
every term (SwinGar switches when the vertex error falls by less than 2 % over 50 epochs; here each stage
has its epochs).

Global descriptor ablation (SwinGar Table I; ``global_descriptor``): ``spectral`` (the above, the default);
``euclidean``, the same with straight-line instead of geodesic distances in the descriptor's affinity
(:mod:`loosefit.rig.spectral`); ``pooling``, a fully connected layer with ReLU on ``G`` then the maximum over
the vertices, ``a = max_i ReLU(F G_i)`` of size ``shape_mlp[-1]``, in place of the descriptor's features;
``none``, ``a = 1`` (the skinning weights read the garment state alone). The paper concatenates the pooled
feature to the local features of ``E_g``; here it takes the place of ``a``, so that the four variants
differ in the global feature alone.

Skinning prior (``skinning_prior``, ours, off by default): the weight logits are added to the log of the
garment's body-LBS weights (each vertex's nearest rest body vertex, ``W_t = softmax_J(P(Q(S_t) * a) + log
W_body)``) and ``P`` starts at zero, so that an untrained network skins like body-LBS and training learns
the departure from it; ``a`` is then taken at unit root mean square (:func:`rms_normalized` says why). The
paper learns the weights from nothing, which needs far more epochs than a CPU budget allows, and from a
uniform start they need ``a``'s free scale to sharpen (normalised, the unseen garments' RMSE at the CPU
budget rose from 122 to 136 mm), so without the prior ``a`` is left as the paper has it.

Rest-position Fourier features (``corrective_fourier``, ours, off by default): :func:`rest_fourier` of the rest
garment appended to the corrective's node features. The paper's node inputs are smooth over the garment, and the
folds left for the corrective are the high frequencies a network learns last: with 6 frequencies the CPU preset
learns four frames of a skirt to 4.6 mm in 6,000 Adam steps, where it stalls at 6.7 without
(``benchmarks/experiments/LOG.md``, SwinGar's capacity and memorisation). They describe the training garments' absolute positions, and what they do on unseen garments is
not measured.

Departures, named: the pose is loosefit's heading-invariant motion feature vector (6D rotations) rather
than axis-angles; the fit attribute ``a_i`` is each vertex's rest distance to the body (FitGar's
quantity before its factor analysis, which describes a garment, not a vertex). GAT-LN (by default; the config's
four attention keys, :class:`SwinGarConfig`): scores from neighbourhood-centred features (ours: on raw positions
and the smooth features after them every attention stayed a mean filter and ``alpha`` changed nothing), one
normaliser per vertex (the Lipschitz normalisation SwinGar cites, where Eq. 4 reads as one per graph), heads
concatenated with the width split among them (SwinGar's widths are not multiples of its head counts), and a
GAT-LN per LSTM-GAT-LN gate as Eq. 6 writes (:mod:`loosefit.models.layers.gat_ln`,
:mod:`loosefit.models.layers.lstm_gat_ln`). In the losses, every term is a mean
(over vertices, edges, faces and frames) where SwinGar Eqs. 12 and 14 write squared norms, sums over the
edges, faces and vertices: the terms' balance then does not move with a garment's resolution (summed, the
edge term would add about 3 V squares against Eq. 11's mean over V vertices); and the bending term applies
the graph Laplacian of the face adjacency (``(L N)_f = sum_{g ~ f} (n_g - n_f)``, unweighted) to the face
normals, where the paper names the Laplace-Beltrami operator.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn

from loosefit.errors import InputError
from loosefit.geometry.lbs import forward_kinematics, skinning_transforms
from loosefit.geometry.normals import face_normals_torch
from loosefit.geometry.rotations import sixd_to_matrix
from loosefit.models.cuda_graph import capture_or_none, clone_outputs, graphs_enabled
from loosefit.models.layers.gat_ln import GATLN
from loosefit.models.layers.lstm_gat_ln import LSTMGATLN
from loosefit.models.layers.mlp import MLP
from loosefit.models.multi_garment import MultiGarmentData, collate_by_graph
# the settings, re-exported: `from loosefit.models.swingar import Config` is how training finds a method's config
from loosefit.models.swingar_config import _DESIGN_WORDS, STAGES, Config, SwinGarConfig  # noqa: F401

GRAVITY = 9.8  # m/s^2, along -Z
#: Scale of the initial weights of the layers whose outputs are displacements (metres): the garment
#: starts from its skinned rest shape.
OUTPUT_INIT = 1e-2
#: Smallest prior weight whose log enters the skinning logits (a zero weight would be -inf for good).
PRIOR_FLOOR = 1e-4


def rms_normalized(a: torch.Tensor) -> torch.Tensor:
    """``a (..., n)`` divided by its root mean square over the last axis (zeros stay zeros).

    With the skinning prior, the global feature ``a`` multiplies the departure from the prior's logits
    (``P(Q(S_t) * a)``). Unnormalised, the shape encoder scales it freely: it reached ``a ~ 50`` within 250 Adam
    steps at lr 1e-3, where every step moves the logits by whole units, and the weights left the prior for
    good (a long shirt's sleeves skinned to the chest, on training sequences too: 87 mm against body-LBS's
    41). At unit RMS the logits move at ``P``'s pace alone."""
    return a / a.square().mean(-1, keepdim=True).sqrt().clamp_min(1e-8)


def rest_fourier(rest: torch.Tensor, frequencies: int) -> torch.Tensor:
    """Fourier features ``(V, 6 F)`` of rest positions ``rest (V, 3)`` in metres: ``sin(2 pi 2^k x)`` then
    ``cos(2 pi 2^k x)`` for ``k = 0 .. F-1`` (cycles per metre) and each coordinate, ordered ``[sin k=0 xyz,
    ..., sin k=F-1 xyz, cos ...]``. A network learns the high frequencies of a function of smooth inputs last
    (its spectral bias); these give each vertex an identity down to a period of ``2^-(F-1)`` m."""
    scales = 2.0 * torch.pi * 2.0 ** torch.arange(frequencies, dtype=rest.dtype, device=rest.device)
    angles = (rest[:, None, :] * scales[:, None]).flatten(-2)  # (V, 3 F)
    return torch.cat([angles.sin(), angles.cos()], -1)


def _graph(g: dict) -> tuple[torch.Tensor, torch.Tensor]:
    return g["table"], g["valid"]


class SwinGar(nn.Module):
    """SwinGar (see the module doc). Garment-independent: the garment comes with every call.

    ``sizes``: ``num_joints`` (J, root included), ``parents`` (J parent indices, -1 for the root),
    ``shape_values`` (S, the body shape vector's length).

    Buffers: ``root_mean/std (11,)``, ``joints_mean/std (J-1, 6)``: motion feature statistics.
    """

    method: ClassVar[str] = "swingar"
    Config: ClassVar[type] = SwinGarConfig
    needs_rig: ClassVar[bool] = False
    multi_garment: ClassVar[bool] = True

    def __init__(self, sizes: dict, config: SwinGarConfig):
        super().__init__()
        self._sizes = dict(sizes)
        self.config = c = config
        J, S = int(sizes["num_joints"]), int(sizes["shape_values"])
        self.parents = np.asarray(sizes["parents"], np.int64)
        if len(self.parents) != J:
            raise InputError(f"sizes give {len(self.parents)} parents for {J} joints")
        self.register_buffer("root_mean", torch.zeros(11))
        self.register_buffer("root_std", torch.ones(11))
        self.register_buffer("joints_mean", torch.zeros(J - 1, 6))
        self.register_buffer("joints_std", torch.ones(J - 1, 6))
        pose = 11 + 6 * (J - 1)
        a, att = c.alpha, c.attention_options()
        if any(c.attention_design):  # marks the checkpoint: runs of the first design load only as that design
            self.register_buffer("attention_design", torch.tensor(c.attention_design, dtype=torch.int64))
        chans = [7, *c.graph_hidden]
        self.graph_encoder = nn.ModuleList(GATLN(i, o, h, a, **att)
                                           for i, o, h in zip(chans[:-1], chans[1:], c.graph_heads))
        if c.descriptor_distance is not None:
            self.shape_encoder = MLP([c.descriptor_samples, *c.shape_mlp], nn.ReLU, final_activation=True)
        elif c.global_descriptor == "pooling":
            self.pool = nn.Sequential(nn.Linear(c.graph_hidden[-1], c.shape_mlp[-1]), nn.ReLU())
        self.motion_encoder = nn.LSTM(pose, c.motion_hidden, batch_first=True)
        self.body_encoder = MLP([S + pose, *c.body_mlp], nn.ReLU, final_activation=True)  # SwinGar Sec. IV: ReLU after each
        self.state_encoder = GATLN(c.graph_hidden[-1], c.state_hidden, c.state_heads, a, **att)
        self.weight_state = nn.Linear(c.state_hidden, c.shape_mlp[-1])
        self.weight_out = nn.Linear(c.shape_mlp[-1], J)
        chans = [c.state_hidden, *c.blend_hidden]
        self.blend_layers = nn.ModuleList(GATLN(i, o, c.blend_heads, a, **att) for i, o in zip(chans[:-1], chans[1:]))
        self.blend_out = nn.Linear(c.blend_hidden[-1], 3)
        self.corrective_lstm = LSTMGATLN(3 + J + 6 * c.corrective_fourier, c.corrective_hidden, c.corrective_heads, a,
                                         per_gate=c.gate_attention == "per_gate", **att)
        chans = [c.corrective_hidden, *c.corrective_layers]
        self.corrective_layers = nn.ModuleList(GATLN(i, o, 1, a, **att) for i, o in zip(chans[:-1], chans[1:]))
        with torch.no_grad():
            for name, w in self.motion_encoder.named_parameters():
                if name.startswith("weight"):
                    nn.init.kaiming_uniform_(w)  # SwinGar Sec. IV: Kaiming for the LSTM, default settings
            self.blend_out.weight.mul_(OUTPUT_INIT)
            self.blend_out.bias.zero_()
            self.corrective_layers[-1].weight.mul_(OUTPUT_INIT)
            if c.skinning_prior:  # the weights start as the prior's
                self.weight_out.weight.zero_()
                self.weight_out.bias.zero_()

    # ------------------------------------------------------------------ construction

    @classmethod
    def data_sizes(cls, data: MultiGarmentData) -> dict:
        from loosefit.models.body_lbs import training_body

        body = training_body(data.sequences[0])
        return {"num_joints": data.num_joints, "parents": [int(p) for p in body.parents],
                "shape_values": int(len(data.graphs[0].body_shape))}

    @classmethod
    def from_data(cls, data: MultiGarmentData, config: SwinGarConfig) -> "SwinGar":
        sizes = cls.data_sizes(data)
        for graph in data.graphs:
            check_graph(graph, config, sizes["num_joints"])
        model = cls(sizes, config)
        stats = data.feature_stats()
        with torch.no_grad():
            for key in ("root", "joints"):
                getattr(model, f"{key}_mean").copy_(torch.from_numpy(stats[key][0]))
                getattr(model, f"{key}_std").copy_(torch.from_numpy(stats[key][1]))
        return model

    def sizes(self) -> dict:
        return dict(self._sizes)

    def load_state_dict(self, state_dict, strict: bool = True, assign: bool = False):
        """``nn.Module.load_state_dict``, refusing (``RuntimeError``, which :func:`~loosefit.train.run.load_weights`
        reports as the checkpoint not fitting) a checkpoint of another GAT-LN design than this model's: a run
        trained before ``attention_norm`` and the three keys after it existed has the same parameter shapes as
        some of the new designs, but other outputs."""
        def words(design):
            flags = [0, 0, 0, 0] if design is None else [int(v) for v in design]
            return ", ".join(names[f] for f, names in zip(flags, _DESIGN_WORDS))

        theirs, mine = state_dict.get("attention_design"), getattr(self, "attention_design", None)
        if (theirs is None) != (mine is None) or (mine is not None and theirs.tolist() != mine.tolist()):
            hint = ("; a run trained before model.attention_norm existed loads with model.attention_norm: graph, "
                    "attention_centred: false, concat_heads: false, gate_attention: shared in its method.yaml"
                    if theirs is None else "")
            raise RuntimeError(f"the checkpoint's GAT-LN design is {words(theirs)}; this model's is {words(mine)}{hint}")
        return super().load_state_dict(state_dict, strict=strict, assign=assign)

    # ------------------------------------------------------------------ the garment, once

    def garment_features(self, g: dict) -> tuple[torch.Tensor, torch.Tensor]:
        """Graph features ``G (V, graph_hidden[-1])`` and global features ``a (shape_mlp[-1],)`` of a garment
        (:meth:`GarmentGraph.tensors`); ``a`` as ``config.global_descriptor`` says (see the module doc)."""
        x = torch.cat([g["normals"], g["rest"], g["fit"][:, None]], -1)
        for layer in self.graph_encoder:
            x = layer(x, *_graph(g))
        mode = self.config.global_descriptor
        if mode == "none":
            return x, x.new_ones(self.config.shape_mlp[-1])
        if mode == "pooling":
            a = self.pool(x).amax(-2)  # max over the vertices
        else:
            descriptor = g["descriptor"]
            if descriptor.shape[-1] != self.config.descriptor_samples:
                raise InputError(f"the garment's spectral descriptor has {descriptor.shape[-1]} values, the model "
                                 f"takes {self.config.descriptor_samples}")
            a = self.shape_encoder(descriptor * descriptor.shape[-1])  # the eigenvalues sum to 1: mean 1
        return x, rms_normalized(a) if self.config.skinning_prior else a

    # ------------------------------------------------------------------ per frame

    def poses(self, root: torch.Tensor, joints: torch.Tensor) -> torch.Tensor:
        """Standardised pose vectors ``(B, T, 11 + 6 (J-1))`` from raw features."""
        r = (root - self.root_mean) / self.root_std
        j = (joints - self.joints_mean) / self.joints_std
        return torch.cat([r, j.flatten(-2)], -1)

    def motion_features(self, poses: torch.Tensor, frames: int) -> torch.Tensor:
        """``m_t (B, frames, motion_hidden)`` of the last ``frames`` of ``poses (B, H + frames, P)`` (``H =
        motion_frames - 1`` poses of history first): the LSTM run from zero over each frame's last
        ``motion_frames`` poses."""
        m = self.config.motion_frames
        windows = poses.unfold(1, m, 1)[:, -frames:]  # (B, frames, P, m)
        B = windows.shape[0]
        seq = windows.permute(0, 1, 3, 2).reshape(B * frames, m, -1)
        out, _ = self.motion_encoder(seq)
        return out[:, -1].reshape(B, frames, -1)

    def joint_transforms(self, root: torch.Tensor, joints: torch.Tensor, rest_joints: torch.Tensor):
        """Canonical skinning transforms ``(B, T, J, 4, 4)`` and joint positions ``(B, T, J, 3)``, the root held
        at its rest position ``rest_joints[0]`` (translation comes last), from raw features."""
        B, T = root.shape[:2]
        local = torch.cat([sixd_to_matrix(root[..., None, 5:11]), sixd_to_matrix(joints)], 2)  # (B, T, J, 3, 3)
        rest = rest_joints.to(local.dtype)
        world = forward_kinematics(local.flatten(0, 1), rest[0].expand(B * T, 3), rest, self.parents)
        return skinning_transforms(world, rest).unflatten(0, (B, T)), world[..., :3, 3].unflatten(0, (B, T))

    def coarse(self, g: dict, G: torch.Tensor, shape: torch.Tensor, m: torch.Tensor, root: torch.Tensor,
               joints: torch.Tensor) -> dict:
        """The first stage for frames with motion features ``m (B, T, motion_hidden)``: ``weights`` (skinning,
        ``(B, T, V, J)``), ``blend`` (``(B, T, V, 3)``), ``coarse`` (``M_c (B, T, V, 3)``) and ``nodes`` (the corrective
        node features ``(B, T, V, 3 + J + 6 F)``: position, distance to every joint and, with
        ``corrective_fourier`` ``F`` > 0, :func:`rest_fourier`)."""
        table, valid = _graph(g)
        S = self.state_encoder(G * m[:, :, None], table, valid)  # (B, T, V, state)
        logits = self.weight_out(self.weight_state(S) * shape)
        if self.config.skinning_prior:
            logits = logits + torch.log(g["skin_prior"].clamp_min(PRIOR_FLOOR))
        weights = torch.softmax(logits, -1)
        h = S
        for layer in self.blend_layers:
            h = layer(h, table, valid)
        blend = self.blend_out(h * m[:, :, None])
        A, joint_pos = self.joint_transforms(root, joints, g["rest_joints"])
        rest = g["rest"] + blend  # (B, T, V, 3)
        M = torch.einsum("btvj,btjxy->btvxy", weights, A[..., :3, :])  # (B, T, V, 3, 4)
        Mc = (M[..., :3] @ rest[..., None])[..., 0] + M[..., 3]
        dist = (Mc[..., :, None, :] - joint_pos[..., None, :, :]).norm(dim=-1)  # (B, T, V, J)
        nodes = [Mc, dist]
        if self.config.corrective_fourier:
            nodes.append(rest_fourier(g["rest"], self.config.corrective_fourier).expand(*Mc.shape[:-1], -1))
        return {"weights": weights, "blend": blend, "coarse": Mc, "nodes": torch.cat(nodes, -1)}

    def corrective(self, g: dict, gates: torch.Tensor, body: torch.Tensor) -> torch.Tensor:
        """Corrections ``(B, T, V, 3)`` from the LSTM-GAT-LN's input-to-state maps of the corrective node features,
        ``gates (B, K - 1 + T, V, 4 corrective_hidden)`` (``K = corrective_frames``; each frame's ``K - 1``
        predecessors first), and body features ``(B, T, body)``: per frame the cell runs from a zero state over
        its last ``K`` frames."""
        table, valid = _graph(g)
        K = self.config.corrective_frames
        T = gates.shape[1] - (K - 1)
        state = None
        for k in range(K):
            state = self.corrective_lstm.cell(None, table, valid, state, x_gates=gates[:, k:k + T])
        h = state[0] * body[:, :, None]
        for layer in self.corrective_layers:
            h = layer(h, table, valid)
        return h

    def forward(self, g: dict, root: torch.Tensor, joints: torch.Tensor, body_shape: torch.Tensor | None = None,
                state: Any = None, features: tuple[torch.Tensor, torch.Tensor] | None = None) -> dict:
        """Predict ``T`` frames of one garment.

        Args:
            g: the garment, :meth:`GarmentGraph.tensors`.
            root ``(B, T, 11)``, joints ``(B, T, J-1, 6)``: raw motion features.
            body_shape: ``(B, S)``; None: the garment's own body (``g["body_shape"]``).
            state: None at the start of a motion (the first frame's pose repeated before it), or the
                ``"state"`` of the previous call: ``{"root": (B, m-1, 11), "joints": (B, m-1, J-1, 6)}``
                (the poses before this call) and optionally ``"gates": (B, K-1, V, 4 corrective_hidden)`` (the
                LSTM-GAT-LN's input-to-state maps of the last ``K-1`` frames' corrective node features; without
                it they are computed from ``K-1`` more poses of history).
            features: ``garment_features(g)`` when already computed (they do not change with the motion).

        Returns:
            ``{"verts": (B, T, V, 3) canonical, "coarse": M_c (B, T, V, 3), "weights": (B, T, V, J),
            "blend": (B, T, V, 3), "correction": (B, T, V, 3), "state": ...}``.
        """
        B, T = root.shape[:2]
        K, m = self.config.corrective_frames, self.config.motion_frames
        if root.shape[-1] != 11 or joints.shape[-2:] != self.joints_mean.shape or joints.shape[:2] != (B, T):
            raise InputError(f"SwinGar expects root (B, T, 11) and joints (B, T, {self.joints_mean.shape[0]}, 6), "
                             f"got {tuple(root.shape)} and {tuple(joints.shape)}")
        G, shape = self.garment_features(g) if features is None else features
        if body_shape is None:
            body_shape = g["body_shape"].expand(B, -1)
        if state is None:
            extra = 0
            hist_root, hist_joints = root[:, :1].expand(B, m - 1, -1), joints[:, :1].expand(B, m - 1, -1, -1)
        else:
            hist_root, hist_joints = state["root"], state["joints"]
            extra = 0 if "gates" in state else K - 1
            if hist_root.shape[1] != m - 1 + extra:
                raise InputError(f"SwinGar state holds {hist_root.shape[1]} poses, expected {m - 1 + extra}")
        all_root, all_joints = torch.cat([hist_root, root], 1), torch.cat([hist_joints, joints], 1)
        poses = self.poses(all_root, all_joints)
        n = T + extra  # frames whose coarse mesh is computed
        mfeat = self.motion_features(poses, n)
        out = self.coarse(g, G, shape, mfeat, all_root[:, -n:], all_joints[:, -n:])
        gates = self.corrective_lstm.input_map(out.pop("nodes"), *_graph(g))  # each frame's input map once
        if state is None:
            gates = torch.cat([gates[:, :1].expand(-1, K - 1, -1, -1), gates], 1)
        elif extra == 0:
            gates = torch.cat([state["gates"], gates], 1)
        else:
            out = {k: v[:, extra:] for k, v in out.items()}
        body = self.body_encoder(torch.cat([body_shape[:, None].expand(-1, T, -1), poses[:, -T:]], -1))
        correction = self.corrective(g, gates, body)
        translation = torch.stack([-g["rest_joints"][0, 0].expand(B, T), -g["rest_joints"][0, 1].expand(B, T),
                                   root[..., 0] - g["rest_joints"][0, 2]], -1)  # canonical root minus rest root
        verts = out["coarse"] + correction + translation[:, :, None]
        new_state = {"root": all_root[:, -(m - 1):], "joints": all_joints[:, -(m - 1):], "gates": gates[:, -(K - 1):]}
        return {"verts": verts, "coarse": out["coarse"], "weights": out["weights"], "blend": out["blend"],
                "correction": correction, "state": new_state}

    # ------------------------------------------------------------------ losses (SwinGar Eqs. 11-14)

    def loss_terms(self, pred: torch.Tensor, batch: dict) -> dict[str, torch.Tensor]:
        """Unweighted terms of SwinGar Eqs. 11-14 for ``pred (B, T, V, 3)`` against ``batch``: ``vert`` (m^2),
        ``edge`` (m^2), ``bend``, ``gravity`` (J), ``collision`` (m^2; 0 without a body in the batch)."""
        g, target = batch["graph_tensors"], batch["verts"]
        terms = {"vert": ((pred - target) ** 2).sum(-1).mean()}  # SwinGar Eq. 11
        e = g["edges"]

        def lengths(x):
            return (x[..., e[:, 0], :] - x[..., e[:, 1], :]).norm(dim=-1)

        terms["edge"] = ((lengths(pred) - lengths(target)) ** 2).mean()  # SwinGar Eq. 12, edge term
        n = face_normals_torch(pred, g["faces"])
        pairs = g["face_pairs"]
        diff = n[..., pairs[:, 1], :] - n[..., pairs[:, 0], :]
        lap = torch.zeros_like(n).index_add_(-2, pairs[:, 0], diff).index_add_(-2, pairs[:, 1], -diff)
        terms["bend"] = lap.square().sum(-1).mean()  # SwinGar Eq. 12, bending term
        terms["gravity"] = GRAVITY * (g["mass"] * (pred[..., 2] - target[..., 2])).sum(-1).mean()  # SwinGar Eq. 13
        if "body" in batch:
            idx = batch["body_nearest"][..., None].expand(-1, -1, -1, 3)
            b, bn = torch.gather(batch["body"], 2, idx), torch.gather(batch["body_normals"], 2, idx)
            h = ((pred - b) * bn).sum(-1)
            terms["collision"] = torch.clamp(h - self.config.collision_eps, max=0.0).square().mean()  # SwinGar Eq. 14
        else:
            terms["collision"] = pred.new_zeros(())
        return terms

    def weights(self) -> dict[str, float]:
        c = self.config
        return {"vert": c.k_vert, "edge": c.k_edge, "bend": c.k_bend, "gravity": c.k_gravity, "collision": c.k_collision}

    def predict_batch(self, batch: dict) -> torch.Tensor:
        """Predicted canonical vertices ``(B, T, V, 3)`` of a collated group (history in the batch)."""
        K = self.config.corrective_frames
        state = {"root": batch["history_root"], "joints": batch["history_joints"]}
        if state["root"].shape[1] != self.config.motion_frames - 1 + K - 1:
            raise InputError("the windows' history does not match the model's motion and corrective frames")
        return self(batch["graph_tensors"], batch["root"], batch["joints"], state=state)["verts"]

    # ------------------------------------------------------------------ trainer protocol

    def stages(self) -> list[str]:
        return list(STAGES)

    def collate(self, items: list[dict]) -> list[dict]:
        return collate_by_graph(items)

    def batch_size(self, batch: list[dict]) -> int:
        return int(sum(b["root"].shape[0] for b in batch))

    def training_loss(self, batch: list[dict], stage: str):
        weights = self.weights()
        total, logged, count = 0.0, {}, self.batch_size(batch)
        for group in batch:
            share = group["root"].shape[0] / count
            terms = self.loss_terms(self.predict_batch(group), group)
            used = ("vert",) if stage == "supervised" else tuple(terms)
            total = total + share * sum(weights[k] * terms[k] for k in used)
            for k, v in terms.items():
                logged[k] = logged.get(k, 0.0) + share * float(v.detach())
        return total, logged

    def validation_metrics(self, batch: list[dict], stage: str) -> dict[str, float]:
        """``rmse_mm`` and ``mean_vertex_error_mm`` over every frame of the batch."""
        sq = dist = frames = 0.0
        with torch.no_grad():
            for group in batch:
                err = self.predict_batch(group) - group["verts"]
                sq += float((err ** 2).sum(-1).mean(-1).sum())
                dist += float(err.norm(dim=-1).mean(-1).sum())
                frames += err.shape[0] * err.shape[1]
        return {"rmse_mm": (sq / frames) ** 0.5 * 1e3, "mean_vertex_error_mm": dist / frames * 1e3}


def check_graph(graph, config: SwinGarConfig, num_joints: int) -> None:
    """Refuse a :class:`~loosefit.models.multi_garment.GarmentGraph` built with another global descriptor
    than ``config`` asks for (build it with ``config.graph_settings()``), or with a skinning prior over another
    joint count than the model's ``num_joints``."""
    if config.skinning_prior and graph.skin_prior.shape[1] != num_joints:
        raise InputError(f"garment {graph.name!r} has skinning weights over {graph.skin_prior.shape[1]} joints; the "
                         f"model's body has {num_joints}")
    if config.descriptor_distance is not None and graph.descriptor_distance != config.descriptor_distance:
        raise InputError(f"garment {graph.name!r} carries a {graph.descriptor_distance} descriptor; the model's "
                         f"global_descriptor {config.global_descriptor!r} reads a {config.descriptor_distance} one")


class BoundSwinGar(nn.Module):
    """A trained :class:`SwinGar` bound to one garment on one body: the per-garment interface of
    :class:`~loosefit.models.base.GarmentModel` (``forward(root, joints, state) -> {"verts", "state", ...}``,
    ``faces``), so that :class:`loosefit.animate.Animator` animates it in batches or frame by frame.
    The garment's graph and shape features are computed once here.

    Streaming on CUDA (one frame per call with the previous call's state, autograd off) replays a CUDA graph of
    the frame, captured at the first such call per batch size (:mod:`loosefit.models.cuda_graph`): the same
    outputs as the eager step to float round-off, without the host launching each kernel. ``use_graphs = False``
    (or a failed capture, after one warning) runs every frame eagerly.

    Args:
        model: a (trained) SwinGar.
        graph: the garment on its body, :class:`~loosefit.models.multi_garment.GarmentGraph`; any vertex count.
    """

    method: ClassVar[str] = "swingar"

    def __init__(self, model: SwinGar, graph):
        super().__init__()
        check_graph(graph, model.config, model.sizes()["num_joints"])
        self.model, self.graph_name = model, graph.name
        self.g = graph.tensors()
        self.register_buffer("faces", self.g["faces"].clone())
        with torch.no_grad():
            self.features = model.garment_features(self.g)
        self.use_graphs = True
        self._graphs: dict = {}  # captured streaming steps by input shapes (None: the capture failed)

    def _apply(self, fn, recurse: bool = True):
        # The graph and its features are plain tensors, not buffers: move them with the module (``.to(cuda)``),
        # or the first CUDA forward pass mixes devices.
        super()._apply(fn, recurse)
        self.g = {k: fn(v) if torch.is_tensor(v) else v for k, v in self.g.items()}
        self.features = tuple(fn(t) for t in self.features)
        self._graphs = {}  # captured on the old tensors
        return self

    def sizes(self) -> dict:
        return {**self.model.sizes(), "num_verts": len(self.g["rest"]), "num_faces": len(self.g["faces"])}

    def forward(self, root: torch.Tensor, joints: torch.Tensor, state: Any = None) -> dict:
        """Raw features ``root (B, T, 11)``, ``joints (B, T, J-1, 6)`` -> :meth:`SwinGar.forward`'s outputs."""
        if (self.use_graphs and state is not None and "gates" in state and root.shape[1] == 1
                and graphs_enabled(root.device)):
            out = self._replay(root, joints, state)
            if out is not None:
                return out
        return self.model(self.g, root, joints, state=state, features=self.features)

    def stream_step(self, root: torch.Tensor, joints: torch.Tensor, hist_root: torch.Tensor,
                    hist_joints: torch.Tensor, gates: torch.Tensor) -> dict:
        """One streaming call on the state's tensors, ``hist_root (B, m-1, 11)``, ``hist_joints (B, m-1, J-1, 6)``
        and ``gates (B, K-1, V, 4 corrective_hidden)``, which it overwrites with the state after the call (the
        step a CUDA graph captures: the recurrent state stays in the same memory). Returns the outputs but the
        state."""
        out = self.model(self.g, root, joints, state={"root": hist_root, "joints": hist_joints, "gates": gates},
                         features=self.features)
        new = out.pop("state")
        hist_root.copy_(new["root"])
        hist_joints.copy_(new["joints"])
        gates.copy_(new["gates"])
        return out

    def _replay(self, root: torch.Tensor, joints: torch.Tensor, state: dict) -> dict | None:
        inputs = [root, joints, state["root"], state["joints"], state["gates"]]
        key = tuple((tuple(t.shape), t.dtype, t.device) for t in inputs)
        if key not in self._graphs:
            m, K = self.model.config.motion_frames, self.model.config.corrective_frames
            if state["root"].shape[1] != m - 1 or state["gates"].shape[1] != K - 1:
                return None  # the eager pass reports the malformed state
            self._graphs[key] = capture_or_none(self.stream_step, inputs, "SwinGar streaming step")
        captured = self._graphs[key]
        if captured is None:
            return None
        out = clone_outputs(captured(*inputs))
        r, j, gates = clone_outputs(captured.inputs[2:])  # the state after this frame, written by the graph
        out["state"] = {"root": r, "joints": j, "gates": gates}
        return out
