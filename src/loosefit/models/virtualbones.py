"""VirtualBones (Pan et al. 2022): bone-driven motion networks for loose garments.

The garment's low-frequency shape is carried by free virtual bones fitted by SSDR
(:mod:`loosefit.rig.virtual_bones`); a network maps body motion to their motion, and a second one adds
the high-frequency detail. Everything happens in the canonical heading frame
(:mod:`loosefit.models.motion_features`); shapes below for a batch of ``N`` windows of ``T`` frames,
``V`` vertices, ``B`` bones, ``J`` body joints.

Low-frequency module (Sec. 4.2): a GRU and a linear layer map the normalised motion features (root height,
root displacement and heading change since the previous frame, root tilt, joint rotations; with
``root_history``, not in the paper, also their recent averages) to each bone's rotation, a 6D residual on the
identity (the rest transform), and position, the place its rest centroid ``c_j`` moves to as an offset from
that bone's mean position over the training frames in units of the pooled standard deviation. The translation
follows: ``T_j = c'_j - R_j c_j`` (a rotation error then does not move the bone). This output parameterisation
is loosefit's: the paper says only that the module gives the bones' motions. Linear blend skinning of the
rig's rest mesh with the SSDR weights gives the canonical low-frequency mesh. Loss (VirtualBones Eq. 2): mean
vertex distance to the low-frequency target plus ``laplacian_weight`` times the mean distance between the
uniform-Laplacian coordinates of the two meshes; optionally ``bone_weight`` times the mean squared difference
between the network's normalised outputs and those of the SSDR bone transforms (not in the paper: off by
default).

High-frequency module (Sec. 4.3): a GRU over the predicted bone motions (the low-frequency module's
normalised outputs) and a linear layer give a global feature for every vertex; EdgeConv layers over
the mesh edges of the low-frequency mesh give local features; a shared per-vertex MLP maps both to a
displacement (in units of the training high-frequency offsets' standard deviation) added to the
low-frequency mesh. The EdgeConv input is each vertex's position (VirtualBones Sec. 4.3), here
standardised by the training low-frequency meshes' mean and standard deviation: a departure from the
authors' released code, which feeds raw positions. Loss: mean vertex distance to the simulated mesh
(``hf_target="residual"``: between the offsets and the simulation's high-frequency part) plus
``collision_weight`` times the body penetration term ``max(margin - n_k . (v_i - b_k), 0)``.

Training (trainer stages ``["low", "high"]``): "low" optimises the low-frequency module alone; "high"
optimises the high-frequency module with the low-frequency module frozen and its output detached.
Windows with a burn-in give truncated back-propagation through time over long sequences: by default windows
of 64 frames from a zero state, the first 16 warming the GRUs up; ``data.carry_state`` trains consecutive
windows of each sequence instead, each from the state the previous one ended in (:mod:`loosefit.models.streams`).
Measured on ``configs/datasets/memory.yaml`` (1.2k-vertex skirt, 8 training motions of 6-8 s; held out a 10 s
spin and a 10 s jump; 32 bones, the CPU preset, 40 + 15 epochs; ``benchmarks/results/memory-comparison.json``),
held-out RMSE spin / jump: zero-state windows of 64 every 48, 107.4 / 48.5 mm (275 steps); the state carried
over windows of 64, 112.8 / 47.2 mm (220 steps); windows of 176 every 88 with 48 warm-up frames, 121.6 / 53.6 mm
(110 steps). The training spins are fitted to 37-59 mm in every case: the held-out spin's error is
generalisation from two training spins, not memory. Those were test motions, so the comparison decides nothing;
the zero-state windows stay the default until validation motions choose.

The garment's own state fed back (``feedback_frames > 0``; our departure from the paper, after subspace neural
physics, Holden et al. 2019): the low-frequency module also reads its own normalised bone outputs of the previous
``feedback_frames`` frames (zeros, the mean bone motion, before the first frame), so it runs frame by frame. It
trains on its own rollouts through each window, with Gaussian noise of ``feedback_noise`` (normalised units) on
the fed-back outputs so that it learns to recover from its own errors; inference feeds back without noise. Off by
default: on held-out subjects of real capture (``bench-real-small.yaml``, validation only) two frames fed back
validated at 65.6 mm against 58.0 for the preset at 300 s of one core, 60.1 against 55.4 at 1,200 s; the rollout
runs at half the steps a second and fits the training motions worse per step (``benchmarks/experiments/LOG.md``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np
import torch
from torch import nn

from loosefit.errors import InputError
from loosefit.geometry.rotations import matrix_to_sixd, sixd_to_matrix
from loosefit.models.base import GarmentModel
from loosefit.models.body_lbs import training_body
from loosefit.models.streams import MemoryWindowConfig, StateCarry, window_mask
from loosefit.models.dataset import GarmentSequences
from loosefit.models.motion_features import HISTORY_FRAMES, check_history
from loosefit.models.pins import PIN_RADIUS, check_pin_radius
from loosefit.motion.heading import check_frame
from loosefit.models.ensemble import EnsembleConfig
from loosefit.models.layers.edge_conv import EdgeConv, neighbour_table
from loosefit.models.layers.gru import GRUHead
from loosefit.models.layers.mlp import MLP, NEGATIVE_SLOPE
from loosefit.rig.normalization import RunningStats
from loosefit.rig.prepared import load_rig
from loosefit.train import StageConfig, TrainConfig
from loosefit.train.losses import (
    collision_loss,
    laplacian_difference,
    laplacian_operator,
    masked_errors_mm,
    vertex_distance,
)

#: The identity rotation in the 6D representation (its first two columns).
IDENTITY_6D = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
#: Per bone, the low-frequency module outputs a 6D rotation residual and a 3D position offset.
BONE_OUTPUTS = 9
#: Initial scale of the read-out layers: the networks start near the mean bone motion and a zero offset.
OUT_SCALE = 0.1
#: Floors of the output scales, metres (a bone or an offset that never moves must not get a zero scale).
MIN_POSITION_STD = 1e-3
MIN_OFFSET_STD = 1e-4
#: The body joints VirtualBones does not read by default: arms, hands, neck and head (chosen on validation subjects of
#: real capture, benchmarks/experiments/LOG.md; the shoulders stay, for garments held by them).
EXCLUDED_JOINTS = ("Arm", "Hand", "Thumb", "Finger", "Neck", "Head")
#: A joint this close to the rest garment (metres) is read even when excluded: a sleeve follows its arm, a collar its
#: neck (a limb's surface is 5-12 cm from its joint; the bench skirt's nearest arm joint, the elbow, is 20 cm away).
GARMENT_REACH_M = 0.15
#: What the high-frequency stage's position term compares with (see ``VirtualBonesConfig.hf_target``).
HF_TARGETS = ("residual", "simulation")


@dataclass(frozen=True)
class VirtualBonesConfig:
    """VirtualBones hyper-parameters.

    Attributes:
        lf_hidden: GRU units of the low-frequency module. The paper gives one GRU layer and a linear
            layer (Sec. 5); the size, 600, is that of the authors' released networks.
        hf_hidden: GRU units of the high-frequency module ("a similar structure", Sec. 5; 600 released).
        global_channels: global feature channels per vertex (10 in the released networks).
        global_rank: 0 maps the high-frequency GRU state to every vertex's global feature by one
            linear layer, as released; its ``hf_hidden x V x global_channels`` weights dominate the
            streaming cost (3.7k vertices: 89 MB read per frame, about 60% of the time). ``r > 0``
            factorises that layer through ``r`` channels (not in the paper).
        edge_channels: output channels of the EdgeConv layers. The paper stacks three (Sec. 5); the
            released networks' widths are 8 and 16, the third keeps 16.
        head_hidden: hidden widths of the shared per-vertex MLP on [local, global]; empty for a single
            linear layer, as released.
        laplacian_weight: lambda_Lap of VirtualBones Eq. 2. The paper does not give it; 1.0 here (both terms are
            mean distances in metres).
        collision_weight: weight of the collision term of Sec. 4.3 (not given in the paper).
        collision_margin: distance below which a vertex counts as penetrating, metres (0 in the paper).
        bone_weight: weight of the optional supervision of the bone transforms by their SSDR values
            (0: not used, as in the paper).
        hf_loss_frames: frames of each training window (after the burn-in) on which the high-frequency
            stage evaluates its loss, drawn at random each step; 0 for all of them. Not in the paper: on
            a CPU the per-vertex part (skinning, EdgeConv, head) over every frame dominates a step, and
            a random subset gives an unbiased estimate of the same loss for a fraction of the cost. The
            GRU still runs over the whole window.
        hf_target: what the high-frequency stage's position term compares with. ``"simulation"`` (the
            paper's reading: its position and collision terms are on the estimated vertices): the final
            mesh, the predicted low-frequency mesh plus the offsets, against the simulated mesh; the module
            then also learns to repair the low-frequency mesh (skinning artefacts on thin parts such as
            straps). ``"residual"``: the offsets against the simulation's own high-frequency part
            ``G - G_LF`` (Sec. 4.1's split). Measured on the bench skirt (80 bones, CPU preset): the same
            held-out RMSE either way, within 0.2 mm per test motion.
        root_history: read the motion's history among the root features (:mod:`loosefit.models.motion_features`:
            recent turning and velocity, exponential moving averages; ours, not in the paper). Compared on the demo's
            spin (``benchmarks/experiments/LOG.md``, "Motion history"), which was then a test motion and is now the demo's
            validation spin: the comparison is a validation one only from that change on.
        history_frames: the averages' time constants, frames (6, 15, 30: 0.2, 0.5 and 1 s at 30 fps).
        history_vertical: average the vertical root displacement too (rising and falling, as in a jump).
        feedback_frames: previous frames of the low-frequency module's own bone outputs among its inputs (0: none,
            as in the paper; see the module docstring).
        feedback_noise: std of the noise on the fed-back outputs while training, normalised units.
        pose_noise: std (normalised units) of a random offset on each read joint's rotation features, the same
            through a training window (ours; 0: none, as the paper; :meth:`GarmentModel.normalise`). Chosen on two
            validation sets, equal steps: the dress's held-out capture subject, 105.0 / 99.5 / 88.8 / 84.7 / 90.8 mm
            at 0 / 0.2 / 0.5 / 1 / 2 (0 and 0.5 again with another seed: 129.1 and 89.0), and the demo's
            validation motions, 52.3 / 52.6 / 56.6 mm at 0 / 0.5 / 1 (``benchmarks/experiments/LOG.md``).
        pin_radius: keep the garment's pinned vertices where the simulation holds them, skinned to the body, and
            fade the network's garment into them over this many metres along it (ours; :mod:`loosefit.models.pins`;
            applied where the garment is animated, not in training); None: none, as the paper. Default
            :data:`~loosefit.models.pins.PIN_RADIUS`, chosen on the real-capture dress's validation subject and the
            demo's validation motions.
        exclude_joints: parts of body joint names (any case, e.g. ``"Arm"``, ``"Hand"``; as JointNet's) whose
            rotations the low-frequency module does not read (their features held at zero; ours): a skirt moves with
            the hips and legs, and arm poses it never met are then no input it can misread. A joint within
            :data:`GARMENT_REACH_M` of the rest garment is read all the same (sleeves, collars). Default
            :data:`EXCLUDED_JOINTS`; empty: every joint, as the paper.
        frame: where the network predicts the garment (ours; :mod:`loosefit.motion.heading`): ``"heading"`` (the
            heading frame on the floor, as the paper's canonical space), ``"raised"`` (the default: the heading frame
            at the root joint, so that crouching carries the garment) or ``"pelvis"`` (the root joint's whole frame:
            leaning does too). Chosen on the dress's validation subject of real capture, equal steps: validation RMSE
            152.5 / 105.0 / 117.7 mm (``benchmarks/experiments/LOG.md``, "The frame the garment is predicted in").
    """

    lf_hidden: int = 600
    hf_hidden: int = 600
    global_channels: int = 10
    global_rank: int = 0
    edge_channels: tuple[int, ...] = (8, 16, 16)
    head_hidden: tuple[int, ...] = ()
    laplacian_weight: float = 1.0
    collision_weight: float = 1.0
    collision_margin: float = 0.0
    bone_weight: float = 0.0
    hf_loss_frames: int = 0
    hf_target: str = "simulation"
    root_history: bool = True
    history_frames: tuple[float, ...] = HISTORY_FRAMES
    history_vertical: bool = False
    feedback_frames: int = 0
    feedback_noise: float = 0.0
    pose_noise: float = 0.5
    exclude_joints: tuple[str, ...] = EXCLUDED_JOINTS
    frame: str = "raised"
    pin_radius: Optional[float] = PIN_RADIUS

    def __post_init__(self):
        check_history(self.history_frames)
        check_frame(self.frame)
        sizes = (self.lf_hidden, self.hf_hidden, self.global_channels, *self.edge_channels, *self.head_hidden)
        if min(sizes) < 1 or not self.edge_channels or self.global_rank < 0:
            raise InputError(f"layer sizes must be >= 1 (global_rank >= 0) and edge_channels non-empty, got {self}")
        for name in ("laplacian_weight", "collision_weight", "collision_margin", "bone_weight", "hf_loss_frames",
                     "feedback_frames", "feedback_noise", "pose_noise"):
            if not getattr(self, name) >= 0:
                raise InputError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.hf_target not in HF_TARGETS:
            raise InputError(f"hf_target must be one of {HF_TARGETS}, got {self.hf_target!r}")
        check_pin_radius(self.pin_radius)


def _default_train() -> TrainConfig:
    return TrainConfig(grad_clip=1.0, stages={"low": StageConfig(epochs=50), "high": StageConfig(epochs=50)})


@dataclass(frozen=True)
class Config:
    """Everything ``loosefit train --method virtualbones`` reads (``configs/models/virtualbones.yaml``).

    Attributes:
        model: the network (:class:`VirtualBonesConfig`).
        train: the trainer (stages ``low`` and ``high``).
        data: the training windows.
        ensemble: the simulation-parameter ensemble (Sec. 4.4) over networks trained per parameter set.
    """

    model: VirtualBonesConfig = field(default_factory=VirtualBonesConfig)
    train: TrainConfig = field(default_factory=_default_train)
    data: MemoryWindowConfig = field(default_factory=MemoryWindowConfig)
    ensemble: EnsembleConfig = field(default_factory=EnsembleConfig)


def joints_read(names: list[str] | None, exclude: tuple[str, ...], num_joints: int,
                reached: tuple[str, ...] = ()) -> torch.Tensor:
    """``(J-1, 1)`` float32: 1 for each non-root joint of ``names`` (the body's ``J`` joint names) whose name contains
    none of the parts ``exclude`` (any case) or that is among ``reached`` (the joints the garment reaches), else 0;
    all ones without ``names``.

    Parts in no joint's name are skipped, as JointNet's (the default names Anny's joints; on SMPL it leaves out the
    hands, neck and head).

    Raises:
        InputError: no part of ``exclude`` is in any joint's name, or ``names`` does not have ``num_joints`` entries.
    """
    if names is None or not exclude:
        return torch.ones(num_joints - 1, 1)
    if len(names) != num_joints:
        raise InputError(f"sizes give {len(names)} joint names for {num_joints} joints")
    parts = [p.lower() for p in exclude]
    matched = [any(p in n.lower() for p in parts) for n in names[1:]]
    if not any(matched):
        raise InputError(f"exclude_joints {list(exclude)} match no joint of the body: {list(names[1:])}")
    return torch.tensor([[float(not m or n in reached)] for n, m in zip(names[1:], matched)])


def output_statistics(sequences, rig) -> dict[str, np.ndarray]:
    """The statistics VirtualBones scales its inputs and outputs by, from training ``sequences``
    (:class:`~loosefit.models.dataset.SequenceData` with canonical bone transforms) and their ``rig``
    (:class:`~loosefit.rig.virtual_bones.VirtualBoneRig`), float32, metres:

    ``position_mean (B, 3)``: each bone's mean canonical position (where its rest centroid went, ``R c + T``);
    ``position_std (3,)``: per axis, the root mean square over bones of each bone's std about its own mean
    (floored at :data:`MIN_POSITION_STD`); ``offset_std (3,)``: per axis, the std of the high-frequency
    offsets ``verts - lf`` over every vertex and frame (floored at :data:`MIN_OFFSET_STD`); ``lf_mean (3,)``:
    the mean low-frequency vertex; ``lf_std ()``: the std of every low-frequency coordinate together.
    """
    B = rig.num_bones
    # one pass over the sequences (no concatenated copy of every frame)
    positions, offsets = RunningStats.empty((B, 3)), RunningStats.empty((3,))
    lf_axes, lf_all = RunningStats.empty((3,)), RunningStats.empty(())
    for s in sequences:
        positions.update((s.bone_rot @ rig.bone_rest_positions[:, :, None])[..., 0] + s.bone_trans)
        offsets.update(s.verts - s.lf)
        lf_axes.update(s.lf)
        lf_all.update(s.lf.reshape(-1))
    pooled = np.sqrt((positions.std**2).mean(0))  # per axis, over bones (each bone about its own mean)
    f32 = lambda x: np.asarray(x, np.float32)  # noqa: E731
    return {"position_mean": f32(positions.mean), "position_std": f32(np.maximum(pooled, MIN_POSITION_STD)),
            "offset_std": f32(np.maximum(offsets.std, MIN_OFFSET_STD)), "lf_mean": f32(lf_axes.mean),
            "lf_std": f32(lf_all.std)}


class VirtualBones(GarmentModel):
    """The VirtualBones motion network of one garment (see the module docstring).

    ``forward(root (N,T,R), joints (N,T,J-1,6), state)`` returns ``verts`` and ``lf`` ``(N,T,V,3)``
    canonical metres, ``bones`` = (rotations ``(N,T,B,3,3)``, translations ``(N,T,B,3)``) mapping rest
    mesh points ``p`` to ``R p + T``, and ``state`` = (low-frequency GRU state, high-frequency GRU state).
    """

    method = "virtualbones"
    Config = VirtualBonesConfig
    needs_rig = True

    def __init__(self, sizes: dict, config: VirtualBonesConfig):
        super().__init__(sizes, config)
        V, J, B = sizes["num_verts"], sizes["num_joints"], sizes["num_bones"]
        self.register_buffer("rest_verts", torch.zeros(V, 3))  # the rig's (smoothed) rest mesh
        self.register_buffer("skin_weights", torch.zeros(V, B))
        self.register_buffer("bone_rest", torch.zeros(B, 3))  # rest centroid of each bone
        self.register_buffer("position_mean", torch.zeros(B, 3))  # mean canonical bone position
        self.register_buffer("position_std", torch.ones(3))
        self.register_buffer("offset_std", torch.ones(3))  # high-frequency offsets
        self.register_buffer("lf_mean", torch.zeros(3))  # low-frequency vertices, for the EdgeConv input
        self.register_buffer("lf_std", torch.ones(()))
        self.register_buffer("neighbours", torch.zeros(V, sizes["max_degree"], dtype=torch.long))
        self.register_buffer("identity_6d", torch.tensor(IDENTITY_6D))
        # (J-1, 1): 1 for each joint read, 0 for each excluded; a run from before sizes held the body's joint
        # names read every joint (as it was trained), whatever its config says
        self.register_buffer("joint_read", joints_read(sizes.get("joint_names"), config.exclude_joints, J,
                                                       tuple(sizes.get("joints_reached", ()))), persistent=False)
        c = config
        fed = c.feedback_frames * BONE_OUTPUTS * B
        self.low = GRUHead(self.root_features + 6 * (J - 1) + fed, c.lf_hidden, BONE_OUTPUTS * B, out_scale=OUT_SCALE)
        self.high_gru = GRUHead(BONE_OUTPUTS * B, c.hf_hidden, c.global_rank or V * c.global_channels)
        self.global_out = nn.Linear(c.global_rank, V * c.global_channels) if c.global_rank else nn.Identity()
        widths = (3, *c.edge_channels)
        self.edge_convs = nn.ModuleList(EdgeConv(a, b) for a, b in zip(widths[:-1], widths[1:]))
        self.head = MLP((c.edge_channels[-1] + c.global_channels, *c.head_hidden, 3))
        with torch.no_grad():  # small offsets at the start (starting them at exactly zero measured no better)
            self.head[-1].weight.mul_(OUT_SCALE)
            self.head[-1].bias.mul_(OUT_SCALE)
        self._laplacian: torch.Tensor | None = None  # built from the faces when a loss first needs it
        self.carry = StateCarry(state_dim=1)  # stateful training: (h_low, h_high) at each window's end

    # ------------------------------------------------------------------ construction

    @classmethod
    def data_sizes(cls, data: GarmentSequences) -> dict:
        sizes = super().data_sizes(data)
        sizes["num_bones"] = load_rig(data.store, data.garment_name).num_bones
        sizes["max_degree"] = int(neighbour_table(data.faces, sizes["num_verts"]).shape[1])
        body = training_body(data)
        sizes["joint_names"] = list(body.joint_names)
        reach = np.linalg.norm(body.rest_joints()[:, None] - data.garment.verts[None], axis=-1).min(1)
        sizes["joints_reached"] = [n for n, d in zip(body.joint_names, reach) if d < GARMENT_REACH_M]
        return sizes

    def init_from_data(self, data: GarmentSequences) -> None:
        """Rig, output scales and mesh graph from the training data (which must carry bone transforms)."""
        super().init_from_data(data)
        rig = load_rig(data.store, data.garment_name)
        V, B = self._sizes["num_verts"], self._sizes["num_bones"]
        if rig.num_verts != V or rig.num_bones != B:
            raise InputError(f"the rig of {data.garment_name!r} has {rig.num_verts} vertices and {rig.num_bones} "
                             f"bones, the model {V} and {B}", data.store.path)
        if any(s.bone_rot is None for s in data.sequences):
            raise InputError("VirtualBones trains on sequences with bone transforms: load the training split "
                             "with bones=True", data.store.path)
        stats = output_statistics(data.sequences, rig)
        with torch.no_grad():
            self.rest_verts.copy_(torch.from_numpy(rig.rest_verts))
            self.skin_weights.copy_(torch.from_numpy(rig.dense_weights()))
            self.bone_rest.copy_(torch.from_numpy(rig.bone_rest_positions))
            for name in ("position_mean", "position_std", "offset_std", "lf_mean", "lf_std"):
                getattr(self, name).copy_(torch.from_numpy(stats[name]))
            self.neighbours.copy_(torch.from_numpy(neighbour_table(data.faces, V)))
        self._laplacian = None

    # ------------------------------------------------------------------ prediction

    def _inputs(self, root: torch.Tensor, joints: torch.Tensor, pose_noise: float = 0.0) -> torch.Tensor:
        """Normalised features ``(N, T, R + 6(J-1))``, ``R`` = :attr:`root_features` (``pose_noise``:
        :meth:`normalise`)."""
        root, joints = self.normalise(root, joints, pose_noise)
        return torch.cat([root, (joints * self.joint_read).flatten(-2)], -1)

    def low_frequency(self, x: torch.Tensor, h=None, frames: torch.Tensor | None = None, noise: float = 0.0):
        """Low-frequency module: features ``x (N,T,F)`` -> ``(raw (N,T,B,9), rotations, translations, lf, h)``.

        ``raw`` holds the normalised outputs (6D residual, position offset), the bone motion that the
        high-frequency module reads. With ``frames`` (``(T',)`` indices) the bone transforms and the
        mesh are those of these frames only; ``raw`` keeps all ``T``. With fed-back outputs the state ``h``
        is ``(GRU state, fed (N, feedback_frames * B * 9))`` and ``noise`` the std added to what is fed back.
        """
        out, h = self.low(x, h) if not self.config.feedback_frames else self._low_rollout(x, h, noise)
        raw = out.unflatten(-1, (-1, BONE_OUTPUTS))
        rot, trans = self.decode_bones(raw if frames is None else raw[:, frames])
        return raw, rot, trans, self.skin(self.rest_verts, rot, trans), h

    def _low_rollout(self, x: torch.Tensor, state, noise: float):
        """The low-frequency GRU (one layer, torch's equations) frame by frame, each frame reading the outputs of
        the frames before it; the motion's share of the input gates is computed for all frames at once."""
        h, fed = (None, None) if state is None else state
        gru, F = self.low.gru, x.shape[-1]
        h = x.new_zeros(x.shape[0], gru.hidden_size) if h is None else h[0]
        if fed is None:  # before the first frame: zeros, the mean bone motion
            fed = x.new_zeros(x.shape[0], gru.input_size - F)
        drive = x @ gru.weight_ih_l0[:, :F].T + gru.bias_ih_l0  # (N, T, 3H)
        w_fed, w_hh = gru.weight_ih_l0[:, F:].T, gru.weight_hh_l0.T
        out = []
        for t in range(x.shape[1]):
            seen = fed + noise * torch.randn_like(fed) if noise > 0 else fed
            i_r, i_z, i_n = (drive[:, t] + seen @ w_fed).chunk(3, -1)
            h_r, h_z, h_n = (h @ w_hh + gru.bias_hh_l0).chunk(3, -1)
            r, z = torch.sigmoid(i_r + h_r), torch.sigmoid(i_z + h_z)
            h = (1 - z) * torch.tanh(i_n + r * h_n) + z * h
            out.append(self.low.out(h))
            fed = torch.cat([out[-1], fed[:, : fed.shape[1] - out[-1].shape[-1]]], -1)  # newest first
        return torch.stack(out, 1), (h[None], fed)

    def decode_bones(self, raw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Normalised outputs ``(..., B, 9)`` -> bone rotations ``(..., B, 3, 3)`` and translations ``(..., B, 3)``."""
        rot = sixd_to_matrix(self.identity_6d + raw[..., :6])
        position = self.position_mean + raw[..., 6:] * self.position_std
        return rot, position - (rot @ self.bone_rest[:, :, None])[..., 0]

    def encode_bones(self, rotations: torch.Tensor, translations: torch.Tensor) -> torch.Tensor:
        """The inverse of :meth:`decode_bones`: the normalised outputs that give these bone transforms."""
        position = (rotations @ self.bone_rest[:, :, None])[..., 0] + translations
        offset = (position - self.position_mean) / self.position_std
        return torch.cat([matrix_to_sixd(rotations) - self.identity_6d, offset], -1)

    def high_frequency(self, raw: torch.Tensor, lf: torch.Tensor, h: torch.Tensor | None = None,
                       frames: torch.Tensor | None = None):
        """High-frequency module: bone motion ``raw (N,T,B,9)`` and mesh ``lf (N,T,V,3)`` -> ``(offsets (N,T,V,3), h)``.

        With ``frames`` (``(T',)`` indices into ``T``), ``lf`` holds those frames only ``(N,T',V,3)`` and
        so do the offsets; the GRU still runs over all ``T`` frames.
        """
        out, h = self.high_gru(raw.flatten(-2), h)
        if frames is not None:
            out = out[:, frames]
        glob = nn.functional.leaky_relu(self.global_out(out).unflatten(-1, (lf.shape[-2], -1)), NEGATIVE_SLOPE)
        local = (lf - self.lf_mean) / self.lf_std
        for conv in self.edge_convs:
            local = conv(local, self.neighbours)
        return self.head(torch.cat([local, glob], -1)) * self.offset_std, h

    def forward(self, root: torch.Tensor, joints: torch.Tensor, state=None) -> dict:
        h_low, h_high = (None, None) if state is None else state
        raw, rot, trans, lf, h_low = self.low_frequency(self._inputs(root, joints), h_low)
        offsets, h_high = self.high_frequency(raw, lf, h_high)
        return {"verts": lf + offsets, "lf": lf, "bones": (rot, trans), "state": (h_low, h_high)}

    # ------------------------------------------------------------------ training

    def stages(self) -> list[str]:
        return ["low", "high"]

    def stage_parameters(self, stage: str):
        if stage == "low":
            return list(self.low.parameters())
        if stage == "high":
            return [*self.high_gru.parameters(), *self.global_out.parameters(), *self.edge_convs.parameters(),
                    *self.head.parameters()]
        raise ValueError(f"VirtualBones has stages 'low' and 'high', not {stage!r}")

    def laplacian(self) -> torch.Tensor:
        """The garment's uniform Laplacian (sparse ``(V, V)``), built once from the faces."""
        dtype = self.rest_verts.dtype  # a model in float64 (finite-difference checks) needs a float64 operator
        if self._laplacian is None or self._laplacian.device != self.faces.device or self._laplacian.dtype != dtype:
            L = laplacian_operator(self.faces.cpu().numpy(), self._sizes["num_verts"])
            self._laplacian = L.to(device=self.faces.device, dtype=dtype)
        return self._laplacian

    @staticmethod
    def mask(batch: dict) -> torch.Tensor:
        """``(B, T)`` counted frames: after the burn-in, before a stateful window's padding."""
        return window_mask(batch)

    def training_loss(self, batch: dict, stage: str):
        mask = self.mask(batch)
        c = self.config
        x = self._inputs(batch["root"], batch["joints"], c.pose_noise if stage == "low" else 0.0)
        h_low, h_high = self.carry.initial(batch) or (None, None)
        if stage == "low":
            raw, _, _, lf, h_low = self.low_frequency(x, h_low, noise=c.feedback_noise)
            self.carry.keep(batch, (h_low, None))
            vertex = vertex_distance(lf, batch["lf"], mask)
            lap = laplacian_difference(lf, batch["lf"], self.laplacian(), mask)
            loss = vertex + c.laplacian_weight * lap  # VirtualBones Eq. 2
            terms = {"vertex": vertex.item(), "laplacian": lap.item()}
            if c.bone_weight > 0:
                sq = ((raw - self.encode_bones(batch["bone_rot"], batch["bone_trans"])) ** 2).mean((-1, -2))
                bone = (sq * mask).sum() / mask.sum().clamp_min(1.0)
                loss = loss + c.bone_weight * bone
                terms["bone"] = bone.item()
            return loss, terms
        if stage == "high":
            frames = self.loss_frames(mask, self.config.hf_loss_frames)
            with torch.no_grad():  # the low-frequency module is frozen in this stage
                raw, _, _, lf, h_low = self.low_frequency(x, h_low, frames=frames)
            offsets, h_high = self.high_frequency(raw, lf, h_high, frames=frames)
            self.carry.keep(batch, (h_low, h_high))
            verts = lf + offsets
            mask = mask[:, frames]
            keys = ("verts", "body", "body_normals", "body_nearest") + (("lf",) if c.hf_target == "residual" else ())
            batch = {k: batch[k][:, frames] for k in keys if k in batch}
            if c.hf_target == "residual":
                vertex = vertex_distance(offsets, batch["verts"] - batch["lf"], mask)
            else:
                vertex = vertex_distance(verts, batch["verts"], mask)
            loss, terms = vertex, {"vertex": vertex.item()}
            if c.collision_weight > 0:
                if "body" not in batch:
                    raise InputError("the collision term needs the posed body: load the data with body=True "
                                     "or set collision_weight to 0")
                coll = collision_loss(verts, batch["body"], batch["body_normals"], batch["body_nearest"],
                                      c.collision_margin, mask)
                loss = loss + c.collision_weight * coll
                terms["collision"] = coll.item()
            return loss, terms
        raise ValueError(f"VirtualBones has stages 'low' and 'high', not {stage!r}")

    def validation_metrics(self, batch: dict, stage: str) -> dict[str, float]:
        """``rmse_mm`` and ``mean_vertex_error_mm`` of the output against the simulated mesh (in stage
        "low" the output is the low-frequency mesh alone: the high-frequency module is not trained
        yet); ``lf_rmse_mm`` of the low-frequency mesh against the simulated mesh (what the high-frequency
        offsets must improve on) and ``lf_target_rmse_mm`` against the low-frequency target (the smoothed
        simulation the low stage learns)."""
        with torch.no_grad():
            out = self(batch["root"], batch["joints"], self.carry.initial(batch))
            self.carry.keep(batch, out["state"])
            pred = out["lf"] if stage == "low" else out["verts"]
            mask = self.mask(batch)
            errors = masked_errors_mm(pred, batch["verts"], mask)
            lf = errors if stage == "low" else masked_errors_mm(out["lf"], batch["verts"], mask)
            return {**errors, "lf_rmse_mm": lf["rmse_mm"],
                    "lf_target_rmse_mm": masked_errors_mm(out["lf"], batch["lf"], mask)["rmse_mm"]}
