"""JointNet (Diao et al. 2024): joint-wise motion features, a sparse joint-to-bone association and
joint-specific pose-space deformation, on top of the garment's virtual bones.

Per frame, in the canonical heading frame (:mod:`loosefit.models.motion_features`); shapes for ``N``
windows of ``T`` frames, ``V`` vertices, ``B`` virtual bones, ``J`` body joints of which ``J_s`` selected:

1. **Joint-wise encoding.** Each selected body joint ``j`` (by default every non-root joint but the fingers and
   thumbs) sees the root features, its own rotation and those of its skeleton neighbours (its parent, the root's
   tilt for children of the root, and its selected children, zero-padded to a fixed count). One GRU per joint
   (hidden 600) and one linear layer per joint (480) give its feature ``psi_j (K,)``, all ``J_s`` GRUs as one
   grouped GRU (:class:`JointGRU`).
2. **Association.** A learnt matrix ``A (B, J_s)`` through a ReLU maps joint features to bones: ``relu(A) @ psi``
   (JointNet Eq. 2), rows normalised to sum 1 by default. A sparsity penalty (Eq. 8's L1, or by default the rows'
   L1/L2) keeps it sparse: a bone listens to few joints (an arm does not swing the hem of a skirt).
3. **Garment prior.** Fourier features of each bone's rest position, ``[alpha_m cos(2 pi c_m . p),
   alpha_m sin(2 pi c_m . p)]`` with fixed random frequencies ``c_m`` and learnt ``alpha_m``, are
   concatenated with the bone features, as the paper's Fig. 2 and Sec. 3.2 text have it (``F`` reads
   ``2 K`` values); its Eq. 4 writes a sum, ``fourier="add"`` (``F`` reads ``K``).
4. **Bone transforms.** A per-bone (shared) MLP ``F`` (2K, 1024, 2048, 1024, 6) gives three Euler angles
   (or, with ``rotation="sixd"``, ours, a 6D rotation: ``F`` ends in 9) and a three-vector offset, both
   standardised by the training statistics of the rig's bone transforms. The bone rotates about its rest position
   ``c`` and moves by the offset: ``R = euler(angles)``, translation ``c + offset - R c`` (decoupled).
5. **Joint-specific PSD.** A shared MLP ``phi`` (K, 480, 128, |X|) gives ``|X|`` blend weights per joint; with a
   learnt basis ``D_j (|X|, V, 3)`` per joint, the rest mesh becomes ``U + sum_j phi(psi_j) D_j``, before skinning.
6. **Skinning.** Linear blend skinning of that mesh by the bones with the rig's SSDR weights.

Loss: ``L1(vertices) + lambda_norm * normal loss + lambda_s * ||relu(A)||_1``, against the full
simulated garment. Training has two stages (paper Sec. 4.2): ``stage1`` without the PSD (its output is
zero and its parameters are not optimised), ``stage2`` everything.

Departures from the paper, named:

- a joint's input is the root features (height, displacement and heading change since the previous frame,
  tilt), its own rotation, its parent's and those of all its selected children, as 6D rotations; the paper
  concatenates the root position, the joint's axis-angle and those of its two skeleton neighbours;
- the Euler angles and offsets are standardised by the rig's training statistics (the paper does not say);
- ``rotation="sixd"`` (an option, a tie on validation): the bone rotation as its matrix's first two columns (Zhou et
  al. 2019), continuous where an Euler angle jumps by 2 pi (13 % of a dress's hem-bone frames on a spin);
- the association (``association="hoyer"``, the default): bones read the rows of ``relu(A)`` normalised to sum 1
  and the sparsity term is the rows' L1/L2 (the paper: ``relu(A)`` and its L1), and ``A`` starts from the bones'
  rest distances to the joints (``association_radius``); ``association="l1"``, ``association_radius=0`` is the
  paper's form;
- ``L_cloth`` (JointNet Eq. 7) is averaged over vertices and coordinates rather than summed over the mesh, so
  that the loss weights (not in the paper) do not depend on the vertex count;
- the garment's pins kept where it is animated (``pin_radius``, :mod:`loosefit.models.pins`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Optional

import numpy as np
import torch
from torch import nn

from loosefit.errors import InputError
from loosefit.geometry.laplacian import smoothest_modes
from loosefit.geometry.rotations import euler_to_matrix, matrix_to_euler, matrix_to_sixd, sixd_to_matrix
from loosefit.models.base import GarmentModel
from loosefit.models.body_lbs import training_body
from loosefit.models.streams import MemoryWindowConfig, StateCarry, window_mask
from loosefit.models.dataset import GarmentSequences
from loosefit.models.pins import PIN_RADIUS, check_pin_radius
from loosefit.models.motion_features import HISTORY_FRAMES, check_history
from loosefit.motion.heading import check_frame
from loosefit.models.layers.gru_bptt import by_hand, gru_layers
from loosefit.models.layers.mlp import MLP
from loosefit.rig.prepared import load_rig
from loosefit.train import StageConfig, TrainConfig
from loosefit.train.losses import masked_errors_mm, normal_loss, vertex_l1

STAGES = ("stage1", "stage2")
#: Standard deviation of the initial PSD displacement bases, metres: small enough to leave the
#: skinned garment as it is (about 0.1 mm in all), non-zero so that gradients reach ``phi`` at once.
PSD_INIT_STD = 1e-5
#: Smallest standard deviation of a bone output (radians or metres): bones that barely move in the
#: training data still get a usable output scale.
MIN_OUTPUT_STD = 1e-3
#: How the bone MLP gives a rotation (:attr:`JointNetConfig.rotation`), with the numbers it outputs for it.
ROTATION_SIZE = {"euler": 3, "sixd": 6}
ROTATIONS = tuple(ROTATION_SIZE)


@dataclass(frozen=True)
class JointNetConfig:
    """JointNet's hyper-parameters (defaults from the paper, Sec. 3 and 4.2, unless noted).

    Attributes:
        joints: names of the body joints that get a GRU; ``None``: every non-root joint of the rig
            whose name contains none of ``exclude_joints`` (the paper drops the hand joints).
        exclude_joints: name fragments of the joints left out when ``joints`` is ``None``.
        gru_hidden: hidden size of each joint's GRU (600).
        features: ``K``, the per-joint feature size after the per-joint linear layer (480); also the
            size of the bone features and of the Fourier features (``K / 2`` frequencies), so even.
        bone_mlp: hidden sizes of the per-bone MLP ``F`` (1024, 2048, 1024; LeakyReLU: the paper names none).
        psd_mlp: hidden sizes of the PSD weight MLP ``phi`` (480, 128).
        psd_shapes: ``|X|``, displacement bases per joint (64 in the authors' code; not in the paper).
        psd_modes: 0: each displacement basis ``D_j`` is a free ``(|X|, V, 3)`` array, as in the paper; ``k > 0``
            (ours): it lives in the span of the garment's ``k`` smoothest vibration modes ``Phi (V, k)``
            (:func:`loosefit.geometry.laplacian.smoothest_modes` of the rig's rest mesh; at most ``V - 1``),
            ``D_j = Phi C_j`` with learnt coefficients ``C_j (|X|, k, 3)``. A free basis memorises the training
            subjects' wrinkles and replays them out of place on new motions (a lumpy surface for no accuracy; its
            projection, :func:`~loosefit.models.jointnet_psd.project_psd`, removes them, and the shipped JointNet
            garments are projected); training in modes from the start did worse on the demo's validation motions,
            so the default stays the paper's free basis (``benchmarks/experiments/LOG.md``).
        fourier_scale: standard deviation of the Fourier frequencies ``c_m``, cycles per metre (not in
            the paper; 2 separates bones about 10 cm apart on a garment about 1 m across).
        fourier: how the Fourier features join the bone features: ``"concat"`` (the paper's Fig. 2 and
            Sec. 3.2 text: ``F`` reads ``2 K`` values) or ``"add"`` (its Eq. 4: ``F`` reads ``K``).
        bone_init: the initial last layer of ``F``: ``"zero"`` (every bone starts at its mean training
            transform) or ``"torch"`` (drawn as any linear layer).
        euler_order: intrinsic axis order of the predicted Euler angles.
        rotation: ``"euler"`` (the paper: three angles) or ``"sixd"`` (ours: 6D); a run's sizes keep it (absent: Euler).
        lambda_norm: weight of the normal loss (not in the paper: then about a third of the L1 vertex term).
        lambda_sparse: weight of the association's sparsity term (not in the paper). Shipped: 1e-4 with the
            ``"hoyer"`` term and ``association_radius`` 0.4 m: an arm nudge moved the skirt below the knees 0.06-0.12x
            as much as VirtualBones' (``benchmarks/experiments/LOG.md``, JointNet's association sparsity).
        association: ``"l1"`` (the paper): bones read ``relu(A) psi`` and the loss holds ``||relu(A)||_1``;
            or ``"hoyer"`` (ours): bones read each row of ``relu(A)`` normalised to sum 1 (a weighted mean of
            joint features, on the same scale however few joints a bone listens to) and the loss holds the
            rows' ``||r||_1 / ||r||_2 - 1`` (0 for a bone that listens to one joint), which, unlike the L1,
            cannot be lowered by shrinking ``A`` while the next layers grow.
        association_radius: 0: ``A`` starts random, rows summing to 1 on average; > 0 (metres,
            ours): each row starts as a Gaussian of the rest distance from the bone to each selected joint with
            that radius, summing to 1, so that a bone first listens to the joints near it and the sparsity term
            prunes the far ones first (the paper does not say how ``A`` starts). Shipped: 0.4 m, on the
            ``memory.yaml`` store as robust as 0.2 m and 5-15 mm better on the held-out spin on each of three seeds.
        pose_noise: std (normalised units) of a random offset on each joint's rotation features, the same
            through a training window (ours; 0: none; :meth:`GarmentModel.normalise`).
        loss_frames: frames of each training window (after the burn-in) that the losses see, drawn at
            random each step (:meth:`GarmentModel.loss_frames`); 0 for all. Not in the paper: on a CPU
            the bone MLP, PSD and skinning of every frame dominate a step; the GRUs still run over all.
        root_history: read the motion's history among the root features (:mod:`loosefit.models.motion_features`:
            recent turning and velocity, exponential moving averages; ours, not in the paper). Measured on the
            demo's held-out spin (``benchmarks/experiments/LOG.md``, "Motion history").
        history_frames: the averages' time constants, frames (6, 15, 30: 0.2, 0.5 and 1 s at 30 fps).
        history_vertical: average the vertical root displacement too (rising and falling, as in a jump).
        frame: where the network predicts the garment (ours; :mod:`loosefit.motion.heading`): ``"heading"`` (the
            heading frame on the floor, the paper's root-relative input read as a canonical space), ``"raised"`` (the
            default, as VirtualBones': the heading frame at the root joint) or ``"pelvis"`` (the root's whole frame).
    """

    joints: Optional[list[str]] = None
    exclude_joints: list[str] = field(default_factory=lambda: ["Finger", "Thumb"])
    gru_hidden: int = 600
    features: int = 480
    bone_mlp: list[int] = field(default_factory=lambda: [1024, 2048, 1024])
    psd_mlp: list[int] = field(default_factory=lambda: [480, 128])
    psd_shapes: int = 64
    psd_modes: int = 0
    fourier_scale: float = 2.0
    fourier: str = "concat"
    bone_init: str = "torch"
    euler_order: str = "xyz"
    rotation: str = "euler"
    lambda_norm: float = 0.05
    lambda_sparse: float = 1e-4
    association: str = "hoyer"
    association_radius: float = 0.4
    loss_frames: int = 0
    pose_noise: float = 0.0
    root_history: bool = True
    history_frames: tuple[float, ...] = HISTORY_FRAMES
    history_vertical: bool = False
    frame: str = "raised"
    pin_radius: Optional[float] = PIN_RADIUS

    def __post_init__(self):
        check_history(self.history_frames)
        check_frame(self.frame)
        sizes = [self.gru_hidden, self.features, self.psd_shapes, *self.bone_mlp, *self.psd_mlp]
        if min(sizes) < 1:
            raise InputError(f"JointNet layer sizes must be >= 1, got {sizes}")
        if self.features % 2:
            raise InputError(f"features must be even (half cosines, half sines), got {self.features}")
        if sorted(self.euler_order.lower()) != ["x", "y", "z"]:
            raise InputError(f"euler_order must be a permutation of 'xyz', got {self.euler_order!r}")
        if self.rotation not in ROTATIONS:
            raise InputError(f"rotation must be one of {ROTATIONS}, got {self.rotation!r}")
        if self.fourier not in ("concat", "add"):
            raise InputError(f"fourier must be 'concat' or 'add', got {self.fourier!r}")
        if self.bone_init not in ("zero", "torch"):
            raise InputError(f"bone_init must be 'zero' or 'torch', got {self.bone_init!r}")
        if not (self.fourier_scale > 0 and min(self.lambda_norm, self.lambda_sparse, self.loss_frames,
                                               self.pose_noise) >= 0):
            raise InputError("fourier_scale must be > 0, lambda_norm, lambda_sparse, loss_frames and pose_noise >= 0")
        if self.psd_modes < 0:
            raise InputError(f"psd_modes must be >= 0 (0: a free basis per vertex), got {self.psd_modes}")
        if not self.association_radius >= 0:
            raise InputError(f"association_radius must be >= 0 metres, got {self.association_radius}")
        if self.association not in ("l1", "hoyer"):
            raise InputError(f"association must be 'l1' or 'hoyer', got {self.association!r}")
        check_pin_radius(self.pin_radius)


def _paper_training() -> TrainConfig:
    # RMSProp, batch 8, lr 1e-3 times 0.7 every 30 epochs (paper Sec. 4.2 and the authors' code: the paper's
    # "decays by 70%" read as the code has it, not as times 0.3); the epochs per stage are not in the paper.
    return TrainConfig(optimizer="rmsprop", lr=1e-3, batch_size=8, schedule="step", step_epochs=30, step_gamma=0.7,
                       stages={"stage1": StageConfig(epochs=150), "stage2": StageConfig(epochs=60)})


@dataclass(frozen=True)
class Config:
    """Everything ``loosefit train --method jointnet`` reads (``configs/models/jointnet.yaml``).

    ``data``: stateful truncated back-propagation through time over 50 frames, the paper's truncation length
    (Sec. 4.2, after Williams and Peng 1990): consecutive windows of 50 frames of each sequence, each starting
    from the GRU state the previous one ended in (``carry_state``, :mod:`loosefit.models.streams`). Measured
    against windows of 60 frames every 50 from a zero state with 10 warm-up frames, on
    ``configs/datasets/memory.yaml`` (1.2k-vertex skirt, 8 training motions of 6-8 s; held out a 10 s spin and
    a 10 s jump; the demo's sizes, 20 + 8 epochs, the same 140 steps; ``benchmarks/results/memory-comparison.json``):
    held-out RMSE spin 128.1 mm against 128.9, jump 54.5 against 57.4.
    """

    model: JointNetConfig = field(default_factory=JointNetConfig)
    train: TrainConfig = field(default_factory=_paper_training)
    data: MemoryWindowConfig = field(
        default_factory=lambda: MemoryWindowConfig(window=50, stride=50, burn_in=10, carry_state=True))


def select_joints(names: list[str], config: JointNetConfig) -> list[int]:
    """Indices (into ``names``, root excluded) of the joints that get a GRU, in rig order."""
    if config.joints is None:
        excluded = [e.lower() for e in config.exclude_joints]
        return [j for j, n in enumerate(names) if j > 0 and not any(e in n.lower() for e in excluded)]
    unknown = sorted(set(config.joints) - set(names[1:]))
    if unknown:
        raise InputError(f"joints {unknown} are not non-root joints of the rig ({names[1:]})")
    return [j for j, n in enumerate(names) if j > 0 and n in config.joints]


def nearby_association(bones: np.ndarray, joints: np.ndarray, radius: float) -> np.ndarray:
    """``(B, J_s)`` initial association: ``exp(-d^2 / (2 radius^2))`` of the rest distance ``d`` from each bone
    ``bones (B, 3)`` to each joint ``joints (J_s, 3)`` (metres), rows normalised to sum 1."""
    d2 = ((bones[:, None].astype(np.float64) - joints[None]) ** 2).sum(-1)
    w = np.exp(-(d2 - d2.min(1, keepdims=True)) / (2 * radius ** 2))  # shifted: no row underflows to zeros
    return (w / w.sum(1, keepdims=True)).astype(np.float32)


def neighbour_table(selected: list[int], parents: list[int]) -> np.ndarray:
    """``(J_s, 2 + C)`` int64 rows of the rotation table each joint reads: itself, its parent, its
    selected children padded to the largest count ``C``. Rotation table rows: 0 the root's tilt, ``j``
    joint ``j``, ``J`` zeros (padding). A parent outside the selection (and not the root) is padding
    too: left-out joints are not inputs at all."""
    J = len(parents)
    chosen = set(selected)
    children = {j: [c for c in selected if parents[c] == j] for j in selected}
    width = max(len(c) for c in children.values())
    rows = []
    for j in selected:
        p = parents[j]
        parent = p if p == 0 or p in chosen else J
        rows.append([j, parent] + children[j] + [J] * (width - len(children[j])))
    return np.asarray(rows, np.int64)


class JointGRU(nn.Module):
    """``G`` independent single-layer GRUs (torch's gate equations) evaluated together.

    ``forward(x (N, T, G, C), h (N, G, H) or None) -> (outputs (N, T, G, H), last state (N, G, H))``.

    Three evaluation orders give the same numbers. One frame (streaming) is one grouped product per
    weight matrix for all joints (:meth:`all_joints_per_frame`). Training on the CPU runs all joints frame by
    frame too, with the hand-written backward pass of :mod:`~loosefit.models.layers.gru_bptt`
    (:meth:`all_joints_by_hand`). Many frames without autograd (batched animation) run each joint's GRU through
    torch's own GRU kernel in turn (:meth:`joint_by_joint`):
    the joint's weights then stay in cache over the frames instead of all joints' weights being read
    again every frame (under torch's autograd, one CPU thread, 22 joints, 256 units, 8 windows of 60 frames:
    forward and backward 1.84 s frame by frame, 0.59 s joint by joint). On CUDA every call runs frame by frame:
    cuDNN's GRU computes in TF32 on Ampere and newer GPUs (``torch.backends.cudnn.allow_tf32`` is on by
    default), about 1e-3 relative, so the batched and the streamed animation would differ (measured on an
    NVIDIA H100: 2e-5 on this class's unit test, 0.61 m on a diverged JointNet), while the grouped products
    stay in float32.
    """

    def __init__(self, groups: int, input_size: int, hidden: int):
        super().__init__()
        bound = 1.0 / math.sqrt(hidden)  # torch.nn.GRU's initialisation
        self.hidden = hidden
        self.weight_ih = nn.Parameter(torch.empty(groups, 3 * hidden, input_size).uniform_(-bound, bound))
        self.weight_hh = nn.Parameter(torch.empty(groups, 3 * hidden, hidden).uniform_(-bound, bound))
        self.bias_ih = nn.Parameter(torch.empty(groups, 1, 3 * hidden).uniform_(-bound, bound))
        self.bias_hh = nn.Parameter(torch.empty(groups, 1, 3 * hidden).uniform_(-bound, bound))

    def forward(self, x: torch.Tensor, h: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        if by_hand(x) and x.shape[1] > 1:
            return self.all_joints_by_hand(x, h)
        if x.shape[1] == 1 or x.is_cuda:
            return self.all_joints_per_frame(x, h)
        return self.joint_by_joint(x, h)

    def all_joints_by_hand(self, x: torch.Tensor, h: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`forward` for training on the CPU: all joints frame by frame in one batched product, differentiated
        by :mod:`~loosefit.models.layers.gru_bptt` (whose weight gradients are formed once per window, not per
        frame: ``benchmarks/experiments/gru_speed.py``)."""
        N, T, G, _ = x.shape
        h = x.new_zeros(G, N, self.hidden) if h is None else h.transpose(0, 1)  # (G, N, H)
        out, last = gru_layers(x.permute(2, 0, 1, 3), h, self.weight_ih, self.weight_hh, self.bias_ih[:, 0],
                               self.bias_hh[:, 0])
        return out.permute(1, 2, 0, 3), last.transpose(0, 1)

    def joint_by_joint(self, x: torch.Tensor, h: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`forward` evaluated one joint at a time with torch's GRU kernel (the ``nn.GRU`` call)."""
        N, T, G, _ = x.shape
        # contiguous: CUDA's GRU kernel refuses a strided hidden state ("hx is not contiguous")
        h = x.new_zeros(G, N, self.hidden) if h is None else h.transpose(0, 1).contiguous()  # (G, N, H)
        outputs, last = [], []
        for g in range(G):
            weights = [self.weight_ih[g], self.weight_hh[g], self.bias_ih[g, 0], self.bias_hh[g, 0]]
            # arguments: has_biases, num_layers, dropout, train, bidirectional, batch_first
            out, h_g = torch._VF.gru(x[:, :, g].contiguous(), h[g][None], weights, True, 1, 0.0, self.training, False, True)
            outputs.append(out)
            last.append(h_g[0])
        return torch.stack(outputs, 2), torch.stack(last, 1)

    def all_joints_per_frame(self, x: torch.Tensor, h: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`forward` evaluated frame by frame, all joints in one grouped product per weight matrix."""
        N, T, G, _ = x.shape
        h = x.new_zeros(G, N, self.hidden) if h is None else h.transpose(0, 1)  # (G, N, H)
        # every frame's input gates at once: (G, T, N, 3H)
        gates_x = (grouped_linear(self.weight_ih, x.permute(2, 1, 0, 3).flatten(1, 2)) + self.bias_ih).unflatten(1, (T, N))
        outputs = []
        for t in range(T):
            gates_h = grouped_linear(self.weight_hh, h) + self.bias_hh
            xr, xz, xn = gates_x[:, t].chunk(3, -1)
            hr, hz, hn = gates_h.chunk(3, -1)
            r, z = torch.sigmoid(xr + hr), torch.sigmoid(xz + hz)
            n = torch.tanh(xn + r * hn)
            h = n + z * (h - n)  # (1 - z) n + z h
            outputs.append(h)
        return torch.stack(outputs, 2).permute(1, 2, 0, 3), h.transpose(0, 1)


def grouped_linear(weight: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """``x (G, N, I)`` times each group's ``weight (G, O, I)`` transposed -> ``(G, N, O)``.

    Written as ``weight @ x^T``: in streaming (``N = 1``) this reads each matrix row by row, measured 1.5x
    faster than ``x @ weight^T`` on one CPU thread (the weights, not the arithmetic, bound the time).
    """
    return torch.bmm(weight, x.transpose(1, 2)).transpose(1, 2)


def bone_output_statistics(sequences, bone_rest: np.ndarray, euler_order: str,
                           rotation: str = "euler") -> dict[str, np.ndarray]:
    """Mean and std over every training frame of what JointNet's bone MLP outputs, float64: ``euler_mean/std``
    (``(B, 3)`` radians, the canonical bone rotations as Euler angles in ``euler_order``; with ``rotation="sixd"``
    ``sixd_mean/std (B, 6)``, their matrices' first two columns) and ``offset_mean/std`` (``(B, 3)`` metres, where
    each bone's rest position ``c`` went: ``R c + T - c``), the stds floored at :data:`MIN_OUTPUT_STD`.
    ``sequences``: :class:`~loosefit.models.dataset.SequenceData` with canonical bone transforms; ``bone_rest
    (B, 3)``: the rig's bone rest positions."""
    centre = bone_rest.astype(np.float64)
    rot = np.concatenate([s.bone_rot for s in sequences]).astype(np.float64)
    trans = np.concatenate([s.bone_trans for s in sequences]).astype(np.float64)
    if rotation == "sixd":
        angles = matrix_to_sixd(torch.from_numpy(rot)).numpy()
    else:
        angles = matrix_to_euler(torch.from_numpy(rot), euler_order).numpy()
    offset = np.einsum("tbij,bj->tbi", rot, centre) + trans - centre  # where each bone's rest position went
    out = {}
    for name, values in ((rotation, angles), ("offset", offset)):
        out[f"{name}_mean"], out[f"{name}_std"] = values.mean(0), np.maximum(values.std(0), MIN_OUTPUT_STD)
    return out


class JointNet(GarmentModel):
    """JointNet on one garment (see the module doc).

    ``sizes`` adds to the base sizes ``num_bones`` (B, the rig's bones), ``joint_names`` (the ``J``
    names of the body rig, in the order of the features) and ``parents`` (``J`` parent indices, -1 for
    the root); the selected joints follow from them and the config.

    Buffers (filled by :meth:`init_from_data`): ``rig_rest (V, 3)`` the rig's rest mesh, ``skin_weights
    (V, B)``, ``bone_rest (B, 3)`` bone rest positions, ``psd_modes (V, k)`` with ``sizes["psd_modes"]`` = k > 0 (the PSD's
    vibration modes; a run's sizes without the entry: none), ``euler_mean/std (B, 3)`` radians (with
    ``sizes["rotation"]`` = ``"sixd"``: ``sixd_mean/std (B, 6)``) and
    ``offset_mean/std (B, 3)`` metres (the bone outputs' training statistics), ``fourier_freqs (K/2, 3)``.
    """

    method: ClassVar[str] = "jointnet"
    Config: ClassVar[type] = JointNetConfig
    needs_rig: ClassVar[bool] = True

    def __init__(self, sizes: dict, config: JointNetConfig):
        super().__init__(sizes, config)
        V, B, J = sizes["num_verts"], sizes["num_bones"], sizes["num_joints"]
        names, parents = list(sizes["joint_names"]), [int(p) for p in sizes["parents"]]
        if len(names) != J or len(parents) != J:
            raise InputError(f"sizes give {len(names)} joint names and {len(parents)} parents for {J} joints")
        self.selected = select_joints(names, config)
        if not self.selected:
            raise InputError(f"no joint is selected from {names[1:]} (config joints / exclude_joints)")
        self.joint_names = [names[j] for j in self.selected]
        self.register_buffer("neighbours", torch.from_numpy(neighbour_table(self.selected, parents)), persistent=False)
        G, K, H = len(self.selected), config.features, config.gru_hidden
        input_size = self.root_features + 6 * self.neighbours.shape[1]

        self.gru = JointGRU(G, input_size, H)
        bound = 1.0 / math.sqrt(H)
        self.joint_out_weight = nn.Parameter(torch.empty(G, K, H).uniform_(-bound, bound))
        self.joint_out_bias = nn.Parameter(torch.empty(G, 1, K).uniform_(-bound, bound))
        # Rows summing to 1 on average: a bone starts from the mean of the joint features.
        self.association = nn.Parameter(torch.rand(B, G) * (2.0 / G))
        self.fourier_alpha = nn.Parameter(torch.randn(K // 2))
        self.register_buffer("fourier_freqs", torch.randn(K // 2, 3) * config.fourier_scale)
        # sizes, not config: a run made before the 6D rotation has no entry and Euler angles
        self.rotation = str(sizes.get("rotation", "euler"))
        if self.rotation not in ROTATIONS:
            raise InputError(f"jointnet: unknown bone rotation {self.rotation!r} (sizes; one of {ROTATIONS})")
        rotation_size = ROTATION_SIZE[self.rotation]
        self.bone_mlp = MLP([2 * K if config.fourier == "concat" else K, *config.bone_mlp, rotation_size + 3])
        if config.bone_init == "zero":  # every bone starts at its mean training transform
            nn.init.zeros_(self.bone_mlp[-1].weight)
            nn.init.zeros_(self.bone_mlp[-1].bias)
        self.psd_mlp = MLP([K, *config.psd_mlp, config.psd_shapes])
        # JointNet Eq. 5's D_j: per vertex, or coefficients of the smoothest modes (psd_modes, ours)
        # sizes, not config: a run made before psd_modes existed has none in its sizes and a free basis
        modes = self.psd_mode_count = int(sizes.get("psd_modes", 0))
        self.psd_basis = nn.Parameter(torch.randn(G, config.psd_shapes, modes or V, 3) * PSD_INIT_STD)
        if modes:
            self.register_buffer("psd_modes", torch.zeros(V, modes))

        self.register_buffer("rig_rest", torch.zeros(V, 3))
        self.register_buffer("skin_weights", torch.zeros(V, B))
        self.register_buffer("bone_rest", torch.zeros(B, 3))
        for name, size in ((self.rotation, rotation_size), ("offset", 3)):
            self.register_buffer(f"{name}_mean", torch.zeros(B, size))
            self.register_buffer(f"{name}_std", torch.ones(B, size))
        self.carry = StateCarry(state_dim=0)  # stateful training: the GRU state at each window's end

    # ------------------------------------------------------------------ construction

    @classmethod
    def data_sizes(cls, data: GarmentSequences) -> dict:
        body = training_body(data)
        return {**super().data_sizes(data), "num_bones": load_rig(data.store, data.garment_name).num_bones,
                "joint_names": list(body.joint_names), "parents": [int(p) for p in body.parents]}

    @classmethod
    def config_sizes(cls, data: GarmentSequences, config: JointNetConfig) -> dict:
        """As :meth:`GarmentModel.config_sizes`, the PSD's mode count (``config.psd_modes``, at most ``V - 1``: a coarse
        garment has fewer modes) recorded among the sizes, so that the run's model.json rebuilds the same model."""
        sizes = super().config_sizes(data, config)
        sizes["psd_modes"] = min(config.psd_modes, sizes["num_verts"] - 1)
        if config.rotation != "euler":  # Euler runs keep the sizes they had
            sizes["rotation"] = config.rotation
        return sizes

    def init_from_data(self, data: GarmentSequences) -> None:
        """Rig buffers and the statistics of the bone outputs over every training frame."""
        super().init_from_data(data)
        if any(s.bone_rot is None for s in data.sequences):
            raise InputError("JointNet trains on the bone transforms of a prepared store's training sequences "
                             "(load the data with bones=True)", data.store.path)
        rig = load_rig(data.store, data.garment_name)
        stats = bone_output_statistics(data.sequences, rig.bone_rest_positions, self.config.euler_order, self.rotation)
        with torch.no_grad():
            self.rig_rest.copy_(torch.from_numpy(rig.rest_verts))
            if self.psd_mode_count:
                self.psd_modes.copy_(torch.from_numpy(smoothest_modes(rig.rest_verts, data.faces, self.psd_mode_count)))
            self.skin_weights.copy_(torch.from_numpy(rig.dense_weights()))
            self.bone_rest.copy_(torch.from_numpy(rig.bone_rest_positions))
            for name, value in stats.items():
                getattr(self, name).copy_(torch.from_numpy(value))
            if self.config.association_radius > 0:
                self.association.copy_(torch.from_numpy(nearby_association(
                    rig.bone_rest_positions, training_body(data).rest_joints()[self.selected],
                    self.config.association_radius)))

    # ------------------------------------------------------------------ prediction

    def association_matrix(self) -> torch.Tensor:
        """``(B, J_s)``: how much each bone listens to each selected joint (``self.joint_names``): ``relu(A)``, or
        its rows normalised to sum 1 (``association="hoyer"``; a bone with no joint left reads zeros)."""
        A = torch.relu(self.association)
        if self.config.association == "hoyer":
            return A / A.sum(-1, keepdim=True).clamp_min(1e-12)
        return A

    def fourier_features(self) -> torch.Tensor:
        """Garment prior ``(B, K)`` from the bone rest positions (JointNet Eq. 3)."""
        phase = 2 * math.pi * self.bone_rest @ self.fourier_freqs.T  # (B, K/2)
        # JointNet Eq. 3
        return torch.cat([self.fourier_alpha * torch.cos(phase), self.fourier_alpha * torch.sin(phase)], -1)

    def join_prior(self, features: torch.Tensor) -> torch.Tensor:
        """Joint features of the bones ``relu(A) psi (..., B, K)`` joined with the garment prior: ``[relu(A) psi,
        f_V] (..., B, 2K)`` (``fourier="concat"``, Fig. 2) or ``relu(A) psi + f_V (..., B, K)`` (``"add"``, Eq. 4)."""
        prior = self.fourier_features()
        if self.config.fourier == "add":
            return features + prior  # JointNet Eq. 4
        return torch.cat([features, prior.expand(features.shape[:-1] + prior.shape[-1:])], -1)

    def joint_inputs(self, root: torch.Tensor, joints: torch.Tensor, pose_noise: float = 0.0) -> torch.Tensor:
        """Raw features -> ``(N, T, J_s, R + 6 * (2 + C))`` per-joint GRU inputs (standardised; ``R`` =
        :attr:`root_features`; ``pose_noise``: :meth:`normalise`)."""
        root, joints = self.normalise(root, joints, pose_noise)
        pad = joints.new_zeros(joints.shape[:2] + (1, 6))
        table = torch.cat([root[:, :, None, 5:11], joints, pad], 2)  # (N, T, J + 1, 6): rows as in neighbour_table
        gathered = table[:, :, self.neighbours].flatten(-2)  # (N, T, J_s, 6 * (2 + C))
        return torch.cat([root[:, :, None].expand(-1, -1, gathered.shape[2], -1), gathered], -1)

    def bone_transforms(self, bone_features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(N, T, B, 2K or K)`` bone features (:meth:`join_prior`) -> rotations ``(N, T, B, 3, 3)`` and
        translations ``(N, T, B, 3)``."""
        return self.bone_outputs(self.bone_mlp(bone_features))

    def bone_outputs(self, out: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The bone MLP's standardised ``(..., B, 6 or 9)`` -> rotations ``(..., B, 3, 3)`` about each bone's rest
        position and translations ``(..., B, 3)`` (the rest position moved by the offset)."""
        n = ROTATION_SIZE[self.rotation]
        if self.rotation == "sixd":
            R = sixd_to_matrix(self.sixd_mean + self.sixd_std * out[..., :n])
        else:
            R = euler_to_matrix(self.euler_mean + self.euler_std * out[..., :n], self.config.euler_order)
        offset = self.offset_mean + self.offset_std * out[..., n:]
        return R, self.bone_rest + offset - (R @ self.bone_rest[:, :, None])[..., 0]

    def forward(self, root: torch.Tensor, joints: torch.Tensor, state: Any = None, psd: bool = True,
                frames: torch.Tensor | None = None, pose_noise: float = 0.0) -> dict:
        """Raw features ``root (N, T, R)`` (the first :attr:`root_features` read), ``joints (N, T, J-1, 6)`` and the
        GRU state ``(N, J_s, H)`` (None: zeros, the start of a motion) -> ``{"verts": (N, T, V, 3) canonical,
        "bones": (rotations (N, T, B, 3, 3), translations (N, T, B, 3)), "association": (B, J_s), "displacement":
        (N, T, V, 3) PSD offsets of the rest mesh (None with ``psd=False``: stage 1 runs without the PSD), "state":
        (N, J_s, H)}``. With ``frames`` (``(T',)`` indices) the outputs hold those frames only; the GRUs run over all
        ``T``. ``pose_noise``: :meth:`normalise` (training)."""
        hidden, state = self.gru(self.joint_inputs(root, joints, pose_noise), state)
        if frames is not None:
            hidden = hidden[:, frames]
        N, T, G, _ = hidden.shape
        psi = grouped_linear(self.joint_out_weight, hidden.transpose(0, 2).flatten(1, 2)) + self.joint_out_bias
        psi = psi.unflatten(1, (T, N)).permute(2, 1, 0, 3)  # (N, T, J_s, K)
        association = self.association_matrix()
        # JointNet Eq. 2 (its Eq. 4 with fourier="add", in join_prior)
        bone_features = self.join_prior(association @ psi)  # (N, T, B, 2K) or (N, T, B, K)
        R, trans = self.bone_transforms(bone_features)
        rest, displacement = self.rig_rest, None
        if psd:
            # JointNet Eq. 5: the joint-specific PSD, added in the canonical rest space
            displacement = self.psd_displacement(self.psd_mlp(psi))  # psd_mlp: phi, (N, T, J_s, |X|)
            rest = rest + displacement
        verts = self.skin(rest, R, trans)  # JointNet Eq. 1
        return {"verts": verts, "bones": (R, trans), "association": association, "displacement": displacement, "state": state}

    def psd_displacement(self, weights: torch.Tensor) -> torch.Tensor:
        """Blend weights ``phi(psi) (..., J_s, |X|)`` -> rest-space displacement ``sum_j phi_j D_j (..., V, 3)``
        metres (JointNet Eq. 5); with ``psd_modes`` the sum runs over the mode coefficients, then ``Phi`` maps
        them to the vertices."""
        summed = (weights.flatten(-2) @ self.psd_basis.flatten(0, 1).flatten(-2)).unflatten(-1, (-1, 3))
        return self.psd_modes @ summed if self.psd_mode_count else summed

    # ------------------------------------------------------------------ trainer protocol

    def stages(self) -> list[str]:
        return list(STAGES)

    def stage_parameters(self, stage: str):
        """``stage1``: everything but the PSD (``psd_mlp``, ``psd_basis``); ``stage2``: everything."""
        if stage == "stage2":
            return self.parameters()
        return [p for n, p in self.named_parameters() if not n.startswith(("psd_mlp.", "psd_basis"))]

    def sparsity_loss(self) -> torch.Tensor:
        """``||relu(A)||_1`` (JointNet Eq. 8), or with ``association="hoyer"`` the sum over bones of
        ``||r||_1 / ||r||_2 - 1`` of each row ``r`` of ``relu(A)`` (0 for a bone with one joint or none)."""
        A = torch.relu(self.association)
        if self.config.association == "hoyer":
            l1, l2 = A.sum(-1), A.norm(dim=-1)
            return torch.where(l2 > 0, l1 / l2.clamp_min(1e-12) - 1, torch.zeros_like(l1)).sum()
        return A.sum()  # JointNet Eq. 8

    @staticmethod
    def mask(batch: dict) -> torch.Tensor:
        """``(B, T)`` counted frames: after the burn-in, before a stateful window's padding."""
        return window_mask(batch)

    def training_loss(self, batch: dict, stage: str):
        mask = self.mask(batch)
        frames = self.loss_frames(mask, self.config.loss_frames)
        out = self(batch["root"], batch["joints"], self.carry.initial(batch), psd=stage == "stage2", frames=frames,
                   pose_noise=self.config.pose_noise)
        self.carry.keep(batch, out["state"])
        pred = out["verts"]
        target, mask = batch["verts"][:, frames], mask[:, frames]
        l1 = vertex_l1(pred, target, mask)  # JointNet Eq. 7
        normal = normal_loss(pred, target, self.faces, mask)
        sparse = self.sparsity_loss()
        loss = l1 + self.config.lambda_norm * normal + self.config.lambda_sparse * sparse  # JointNet Eq. 6
        return loss, {"l1_mm": l1.item() * 1e3, "normal": normal.item(), "sparsity": sparse.item()}

    def validation_metrics(self, batch: dict, stage: str) -> dict[str, float]:
        """The base metrics (``rmse_mm``, ``mean_vertex_error_mm``), with the PSD only once it trains (``stage2``)."""
        with torch.no_grad():
            out = self(batch["root"], batch["joints"], self.carry.initial(batch), psd=stage == "stage2")
            self.carry.keep(batch, out["state"])
            return masked_errors_mm(out["verts"], batch["verts"], self.mask(batch))
