"""FitGar (Li, Shi, Kanai 2023, "Detail-aware deep clothing animations infused with multi-source
attributes"): one graph network for any garment on any body shape in any pose, frame by frame.

Inputs of a frame (:mod:`loosefit.models.fitgar_inputs`, all in the frame's heading frame), ``N`` garment
vertices, ``J`` joints, batched as a disjoint graph (:func:`loosefit.models.fitgar_data.collate_frames`):

Coarse generator (FitGar Eqs. 5-6). A graph on the body vertices under the garment vertices (the
indicator ``I``), joined by the garment's edges; node features ``[n_b, p_b, a_1]`` (7): the body normal,
the body's relative skinning feature and the fit attribute's first factor. A GAT block (self stream +
multi-head attention, :class:`~loosefit.models.layers.gat_block.GATBlock`; FitGar Sec. 5.1: 256 = 128 +
4 x 32) with Tanh, then two branches of GAT blocks ([512, 512, 256]) and fully connected layers ([256,
128] then 1 or 3), ReLU after every layer of the magnitude branch and Tanh after every layer of the
direction branch, multiplied (FitGar Eq. 4, :mod:`~loosefit.models.layers.decomposed_output`):
``M_coarse = I M_b + Delta_coarse``.

Attribute parser (FitGar Eq. 7). The fit attribute ``alpha (F,)``, body shape ``beta (S,)`` and pose
``theta (6 J,)`` through fully connected layers ([256, 512, 1024], ReLU) give a detail-aware encoding
per frame.

Detail generator (FitGar Eqs. 7-9). A graph on the coarse garment (its mesh edges), node features
``[n, p, x]`` (6 + J): the coarse mesh's vertex normal, the garment's relative skinning feature and the
distances from the coarse vertex to every joint. A GAT block (1024) with Tanh whose output is multiplied
feature by feature with the parser's encoding (FitGar Eq. 7), then two branches of four GAT blocks
([256, 256, 128, 96]) with one edge-contraction pooling (about half the vertices) after the first and
its unpooling before the last (:mod:`~loosefit.models.layers.edge_pool`), and fully connected layers
([128, 64] then 1 or 3), as in the coarse generator: ``M_detail = M_coarse + Delta_detail`` (FitGar Eq. 9).

Losses: the mean squared error of each displacement, ``Delta_coarse`` against the ``fitgar``-smoothed
simulation minus ``I M_b`` and ``Delta_detail`` against the simulation minus the predicted coarse mesh,
each divided by the square of its training displacements' root mean square length (a constant: the
loss is then near 1 for a zero prediction whatever the units). Trainer stages ``["coarse", "detail"]``:
the coarse generator first, then the parser and the detail generator together with the coarse
generator frozen (FitGar Sec. 4.4).

The ablations of FitGar Sec. 5.3 are config switches (:class:`FitGarConfig`): ``output`` (a plain or a
limited 3-vector instead of FitGar Eq. 4), ``parser_mode`` (concatenation instead of FitGar Eq. 7's product, or the
attributes on every node without a parser), ``two_step`` (no coarse generator) and ``pooling``.

Choices the paper leaves open, made here: the split of every GAT block into half self stream, half
attention heads; the place of the pooling (after the first of the four detail blocks, unpooling before
the last); Tanh after the detail generator's first block; the direction branch's "normalisation" as
scaling the direction to unit length, so that the magnitude branch gives the displacement's length;
the magnitude in units of the training displacements' root mean square length; everything in the
heading frame of each frame (as every loosefit method), so the pose ``theta`` holds the root's tilt
but not its heading.

Departures from the paper, named:

- the fit attribute keeps the factors the store was prepared with, 4 by default
  (:data:`loosefit.rig.fit_attribute.DEFAULT_FACTORS`), where Sec. 5.1 uses ``alpha`` in R^3: the coarse graph
  reads ``a_1`` either way, the parser one value more;
- the parser's ReLU follows every layer, its last included (Sec. 5.1: three layers "and ReLU"), so the
  encoding is never negative and FitGar Eq. 7's product can only gate a feature (scale it down, up or shut
  it), never flip its sign;
- the anchors ``I M_b`` are each garment vertex's projection onto the body surface along its interpolated normals
  (a triangle and barycentric coordinates, the normal and skinning weights interpolated), the few that coincide
  moved apart, where the paper subdivides SMPL to 27,554 vertices and takes the closest vertex;
  :mod:`loosefit.models.fitgar_inputs` measures the choices (the projection alone, the closest surface point and
  the closest Anny vertex stay selectable, ``anchor="normal"``, ``"surface"`` and ``"vertex"``, for runs recorded
  before);
- ``beta`` is the body model's shape vector and ``theta`` 6D rotations (SMPL: 10 and 72 axis-angle values).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
from torch import nn

from loosefit.errors import InputError
from loosefit.geometry.normals import vertex_normals_torch
from loosefit.models.fitgar_data import GarmentFrames, check_frame_choice, collate_frames
from loosefit.models.cuda_graph import graphs_enabled
from loosefit.models.fitgar_inputs import ANCHOR_MODES, check_anchor_mode
from loosefit.models.fitgar_stream import FitGarStream
from loosefit.models.layers.decomposed_output import DIRECT_MODES, DecomposedOutput, DirectOutput
from loosefit.models.layers.edge_pool import EdgeContractionPooling
from loosefit.models.layers.gat_block import GATBlock
from loosefit.models.layers.mlp import MLP
from loosefit.rig.fit_attribute import FitAttributeModel
from loosefit.train import StageConfig, TrainConfig
from loosefit.train.losses import masked_errors_mm

#: Coarse node features: body normal (3), relative skinning feature (3), first fit factor (1).
COARSE_FEATURES = 7
#: Output reconstructions: FitGar Eq. 4, and the two direct outputs of its ablation.
OUTPUT_MODES = ("decomposed", *DIRECT_MODES)
#: Last activation of the magnitude branches: FitGar Sec. 5.1's ReLU, or a softplus that never closes.
MAGNITUDE_ACTIVATIONS = ("relu", "softplus")
#: How the attributes reach the detail generator: FitGar Eq. 7, and the two ablations.
PARSER_MODES = ("multiply", "concat", "nodes")


@dataclass(frozen=True)
class FitGarConfig:
    """FitGar's network sizes (defaults: FitGar Sec. 5.1) and loss weights.

    At the defaults, with 31 joints: 2.79 M parameters (coarse generator 1.25 M, parser 0.71 M, detail
    generator 0.83 M), 11 MB of float32, where the paper reports 37.4 MB (18.4 + 19 MB); it does not say
    how its wider blocks split between the two streams, so the difference is in that split or in what
    its files hold besides the weights.

    Attributes:
        heads: attention heads of every GAT block.
        self_fraction: share of a GAT block's width in its self stream (the paper's first block: 128 of 256).
        coarse_first: width of the coarse generator's first GAT block.
        coarse_blocks: GAT block widths of each coarse branch.
        coarse_dense: hidden sizes of each coarse branch's fully connected layers (they end in 1 or 3).
        parser: fully connected sizes of the attribute parser; the last equals ``detail_first`` (FitGar Eq. 7).
        detail_first: width of the detail generator's first GAT block.
        detail_blocks: GAT block widths of each detail branch.
        pool_before, unpool_before: the detail branch pools before block ``pool_before`` and unpools
            before block ``unpool_before`` (indices into ``detail_blocks``).
        pooling: False drops the pooling (the paper's "w/o pooling" ablation).
        detail_dense: hidden sizes of each detail branch's fully connected layers.
        magnitude_bias: initial bias of the magnitude branches' last layer (their ReLU starts open).
        magnitude_activation: the magnitude branches' last activation: ``"relu"`` (FitGar Sec. 5.1, after every
            layer) or ``"softplus"`` (positive too, but never closed: a vertex whose ReLU output closes gets no
            gradient and stays on its anchor; see ``benchmarks/experiments/capacity.py``).
        coarse_weight, detail_weight: weights of the two loss terms.
        output: ``"decomposed"`` (FitGar Eq. 4); the ablations of FitGar Sec. 5.3 (one branch, no FitGar Eq. 4):
            ``"plain"`` (a 3-vector, unbounded) and ``"limited"`` (within plus or minus ``limit_factor``
            times the output scale).
        limit_factor: the ``"limited"`` output's bound in output scales (the paper divides by 5).
        parser_mode: ``"multiply"`` (FitGar Eq. 7); ablations: ``"concat"`` (encodings concatenated to
            the first block's features) and ``"nodes"`` (no parser: the attributes appended to every
            detail node's features).
        two_step: False is the "w/o two steps" ablation: no coarse generator, the detail generator runs on
            the body graph's anchors ``I M_b`` and predicts the whole displacement (one stage, ``detail``).
    """

    heads: int = 4
    self_fraction: float = 0.5
    coarse_first: int = 256
    coarse_blocks: tuple[int, ...] = (512, 512, 256)
    coarse_dense: tuple[int, ...] = (256, 128)
    parser: tuple[int, ...] = (256, 512, 1024)
    detail_first: int = 1024
    detail_blocks: tuple[int, ...] = (256, 256, 128, 96)
    pool_before: int = 1
    unpool_before: int = 3
    pooling: bool = True
    detail_dense: tuple[int, ...] = (128, 64)
    magnitude_bias: float = 0.5
    magnitude_activation: str = "relu"
    coarse_weight: float = 1.0
    detail_weight: float = 1.0
    output: str = "decomposed"
    limit_factor: float = 5.0
    parser_mode: str = "multiply"
    two_step: bool = True

    def __post_init__(self):
        if self.output not in OUTPUT_MODES or self.parser_mode not in PARSER_MODES:
            raise InputError(f"output must be one of {OUTPUT_MODES} and parser_mode one of {PARSER_MODES}, "
                             f"got {self.output!r}, {self.parser_mode!r}")
        if self.magnitude_activation not in MAGNITUDE_ACTIVATIONS:
            raise InputError(f"magnitude_activation must be one of {MAGNITUDE_ACTIVATIONS}, "
                             f"got {self.magnitude_activation!r}")
        if not self.limit_factor > 0:
            raise InputError(f"limit_factor must be > 0, got {self.limit_factor}")
        sizes = (self.heads, self.coarse_first, self.detail_first, *self.coarse_blocks, *self.detail_blocks,
                 *self.parser, *self.coarse_dense, *self.detail_dense)
        if min(sizes) < 1 or not self.coarse_blocks or not self.detail_blocks or not self.parser:
            raise InputError(f"FitGar sizes must be >= 1 and the block lists non-empty, got {self}")
        if self.parser_mode == "multiply" and self.parser[-1] != self.detail_first:
            raise InputError(f"the parser's last size ({self.parser[-1]}) must equal detail_first "
                             f"({self.detail_first}): FitGar Eq. 7 multiplies them feature by feature")
        if self.pooling and not 0 < self.pool_before < self.unpool_before <= len(self.detail_blocks) - 1:
            raise InputError(f"pooling needs 0 < pool_before < unpool_before < {len(self.detail_blocks)}, "
                             f"got {self.pool_before}, {self.unpool_before}")
        if not 0 < self.self_fraction < 1:
            raise InputError(f"self_fraction must be in (0, 1), got {self.self_fraction}")
        if min(self.coarse_weight, self.detail_weight) < 0:
            raise InputError("loss weights must be >= 0")


@dataclass(frozen=True)
class FramesConfig:
    """Which frames train FitGar: every ``frame_stride``-th frame of each sequence from ``frame_offset``."""

    frame_stride: int = 1
    frame_offset: int = 0

    def __post_init__(self):
        check_frame_choice(self.frame_stride, self.frame_offset)


def _default_train() -> TrainConfig:
    return TrainConfig(batch_size=8, lr=1e-4, grad_clip=1.0,
                       stages={"coarse": StageConfig(epochs=20), "detail": StageConfig(epochs=20)})


@dataclass(frozen=True)
class Config:
    """Everything ``loosefit train --method fitgar`` reads (``configs/models/fitgar.yaml``)."""

    model: FitGarConfig = field(default_factory=FitGarConfig)
    train: TrainConfig = field(default_factory=_default_train)
    data: FramesConfig = field(default_factory=FramesConfig)


class Branch(nn.Module):
    """GAT blocks with ``activation`` after each, optionally pooled and unpooled between them:
    ``(x (N, C), edge_index, batch) -> (N, widths[-1])``."""

    def __init__(self, in_channels: int, widths, activation: type[nn.Module], heads: int, self_fraction: float,
                 pool_before: int | None = None, unpool_before: int | None = None):
        super().__init__()
        sizes = (in_channels, *widths)
        self.blocks = nn.ModuleList(GATBlock.of_width(a, b, heads, self_fraction) for a, b in zip(sizes[:-1], sizes[1:]))
        self.activation = activation()
        self.pool_before, self.unpool_before = pool_before, unpool_before
        self.pool = EdgeContractionPooling(sizes[pool_before]) if pool_before is not None else None

    def forward(self, x: torch.Tensor, edge_index: torch.Tensor, batch: torch.Tensor) -> torch.Tensor:
        edges, info = edge_index, None
        for k, block in enumerate(self.blocks):
            if k == self.pool_before:
                x, edges, batch, info = self.pool(x, edges, batch)
            if k == self.unpool_before:
                x, edges = self.pool.unpool(x, info), info.edge_index
            x = self.activation(block(x, edges))
        return x


class Generator(nn.Module):
    """A FitGar generator after its first block: two branches and the output reconstruction (FitGar Eq. 4),
    or, for the ablations' direct outputs, one branch (Tanh) and :class:`DirectOutput`."""

    def __init__(self, in_channels: int, widths, dense, c: FitGarConfig, pool: bool):
        super().__init__()
        where = dict(pool_before=c.pool_before, unpool_before=c.unpool_before) if pool else {}
        self.magnitude = None
        if c.output == "decomposed":
            self.magnitude = Branch(in_channels, widths, nn.ReLU, c.heads, c.self_fraction, **where)
        self.direction = Branch(in_channels, widths, nn.Tanh, c.heads, c.self_fraction, **where)
        if c.output == "decomposed":
            self.output = DecomposedOutput(widths[-1], widths[-1], dense, magnitude_bias=c.magnitude_bias)
            if c.magnitude_activation == "softplus":
                self.output.magnitude[-1] = nn.Softplus()  # the last layer's ReLU
        else:
            self.output = DirectOutput(widths[-1], dense, c.output, limit=c.limit_factor)

    def forward(self, x, edge_index, batch) -> torch.Tensor:
        """``(N, 3)`` displacement, metres."""
        if self.magnitude is None:
            return self.output(self.direction(x, edge_index, batch))["displacement"]
        return self.output(self.magnitude(x, edge_index, batch), self.direction(x, edge_index, batch))["displacement"]


class FitGar(nn.Module):
    """The FitGar network (see the module docstring).

    ``forward(batch)`` (a :func:`~loosefit.models.fitgar_data.collate_frames` batch) returns canonical
    ``coarse (N, 3)`` and ``verts (N, 3)`` (the detail mesh) in metres and the two displacements
    ``coarse_displacement``, ``detail_displacement (N, 3)``.

    ``sizes``: ``num_joints`` J, ``num_shape`` S, ``num_fit_factors`` F, ``pose_features`` P, and
    ``fit_length`` (the fit attribute model's distance-vector length, kept so that a new garment's
    ``alpha`` comes from the checkpoint).
    """

    method = "fitgar"
    Config = FitGarConfig
    #: Trained on many garments at once (a :class:`GarmentFrames` store), not one.
    multi_garment = True
    #: Static: each frame on its own, from the pose alone (:mod:`loosefit.animate_any`), no recurrent state.
    static = True

    def __init__(self, sizes: dict, config: FitGarConfig):
        super().__init__()
        self._sizes = dict(sizes)
        self.config = c = config
        # Sizes from a store record the anchors (data_sizes); a run recorded before they were (it has a fit seed,
        # no anchor) was trained on body vertices; sizes made by hand (no fit seed) are not checked.
        self.anchor = sizes.get("anchor", "vertex" if "fit_seed" in sizes else None)
        if self.anchor is not None:
            check_anchor_mode(self.anchor)
        J, S, F, P = (int(sizes[k]) for k in ("num_joints", "num_shape", "num_fit_factors", "pose_features"))
        n = int(sizes["fit_length"])
        for name, shape in [("rel_mean", (3,)), ("shape_mean", (S,)), ("alpha_mean", (F,)), ("dist_mean", ())]:
            self.register_buffer(name, torch.zeros(shape))
        for name, shape in [("rel_std", (3,)), ("shape_std", (S,)), ("alpha_std", (F,)), ("dist_std", ())]:
            self.register_buffer(name, torch.ones(shape))
        self.register_buffer("fit_mean", torch.zeros(n, dtype=torch.float64))
        self.register_buffer("fit_components", torch.zeros(F, n, dtype=torch.float64))
        self.register_buffer("fit_noise", torch.ones(n, dtype=torch.float64))
        self.coarse_first = self.coarse = None
        if c.two_step:
            self.coarse_first = GATBlock.of_width(COARSE_FEATURES, c.coarse_first, c.heads, c.self_fraction)
            self.coarse = Generator(c.coarse_first, c.coarse_blocks, c.coarse_dense, c, pool=False)
        attributes = F + S + P
        # ReLU after the last layer too: the encodings are >= 0, so FitGar Eq. 7 gates (see the module doc)
        self.parser = MLP((attributes, *c.parser), nn.ReLU, final_activation=True) if c.parser_mode != "nodes" else None
        node_features = 6 + J + (attributes if c.parser_mode == "nodes" else 0)
        self.detail_first = GATBlock.of_width(node_features, c.detail_first, c.heads, c.self_fraction)
        branch_in = c.detail_first + (c.parser[-1] if c.parser_mode == "concat" else 0)
        self.detail = Generator(branch_in, c.detail_blocks, c.detail_dense, c, pool=c.pooling)

    # ------------------------------------------------------------------ construction

    @classmethod
    def data_sizes(cls, data: GarmentFrames) -> dict:
        return {**data.sizes, "fit_length": int(data.fit_model.length), "fit_seed": int(data.fit_model.seed),
                "anchor": data.anchor}

    @classmethod
    def from_data(cls, data: GarmentFrames, config: FitGarConfig) -> "FitGar":
        model = cls(cls.data_sizes(data), config)
        model.init_from_data(data)
        return model

    def init_from_data(self, data: GarmentFrames) -> None:
        """Input statistics, output scales and the fit attribute model from the training frames."""
        stats = data.feature_stats()
        with torch.no_grad():
            for key in ("rel_mean", "rel_std", "dist_mean", "dist_std", "shape_mean", "shape_std", "alpha_mean",
                        "alpha_std"):
                getattr(self, key).copy_(torch.from_numpy(np.asarray(stats[key])))
            if self.coarse is not None:
                self.coarse.output.scale.fill_(float(stats["coarse_scale"]))
            self.detail.output.scale.fill_(float(stats["detail_scale" if self.coarse is not None else "full_scale"]))
            fa = data.fit_model
            self.fit_mean.copy_(torch.from_numpy(fa.mean))
            self.fit_components.copy_(torch.from_numpy(fa.components))
            self.fit_noise.copy_(torch.from_numpy(fa.noise_variance))

    def sizes(self) -> dict:
        return dict(self._sizes)

    def fit_attribute_model(self) -> FitAttributeModel:
        """The training data's factor analysis (FitGar Eq. 3), for the ``alpha`` of new garment-body pairs."""
        return FitAttributeModel(self.fit_mean.numpy().copy(), self.fit_components.numpy().copy(),
                                 self.fit_noise.numpy().copy(), int(self._sizes.get("fit_seed", 0)))

    # ------------------------------------------------------------------ prediction

    def coarse_displacement(self, batch: dict) -> torch.Tensor:
        """FitGar Eq. 6: ``Delta_coarse (N, 3)`` metres from the body graph (zeros without a coarse generator)."""
        if self.coarse is None:
            return torch.zeros_like(batch["anchor"])
        a1 = ((batch["alpha"][:, :1] - self.alpha_mean[:1]) / self.alpha_std[:1])[batch["batch"]]
        x = torch.cat([batch["body_normal"], (batch["body_rel"] - self.rel_mean) / self.rel_std, a1], -1)
        h = torch.tanh(self.coarse_first(x, batch["edge_index"]))
        return self.coarse(h, batch["edge_index"], batch["batch"])  # FitGar Eq. 6

    def attributes(self, batch: dict) -> torch.Tensor:
        """The normalised multi-source attributes ``(G, F + S + P)``: ``alpha``, ``beta``, ``theta``."""
        return torch.cat([(batch["alpha"] - self.alpha_mean) / self.alpha_std,
                          (batch["shape"] - self.shape_mean) / self.shape_std, batch["pose"]], -1)

    def encoding(self, batch: dict) -> torch.Tensor:
        """The attribute parser: detail-aware encodings ``(G, parser[-1])`` of ``(alpha, beta, theta)``."""
        return self.parser(self.attributes(batch))

    def detail_displacement(self, batch: dict, coarse: torch.Tensor) -> torch.Tensor:
        """FitGar Eqs. 7-8: ``Delta_detail (N, 3)`` metres from the coarse garment ``coarse (N, 3)``."""
        idx = batch["batch"]
        dist = (coarse[:, None] - batch["joints"][idx]).norm(dim=-1)
        parts = [vertex_normals_torch(coarse, batch["faces"]), (batch["garment_rel"] - self.rel_mean) / self.rel_std,
                 (dist - self.dist_mean) / self.dist_std]
        mode = self.config.parser_mode
        if mode == "nodes":
            parts.append(self.attributes(batch)[idx])
        h = torch.tanh(self.detail_first(torch.cat(parts, -1), batch["edge_index"]))
        if mode == "multiply":
            h = h * self.encoding(batch)[idx]  # FitGar Eq. 7
        elif mode == "concat":
            h = torch.cat([h, self.encoding(batch)[idx]], -1)
        return self.detail(h, batch["edge_index"], idx)  # FitGar Eq. 8

    def check_anchor(self, batch: dict) -> None:
        """Refuse frames whose garment-body pairs were anchored otherwise than this model's training frames."""
        code = batch.get("anchor_code")
        if self.anchor is None or code is None or len(code) == 0:
            return
        given = ANCHOR_MODES[int(round(float(code[0])))]
        if given != self.anchor or bool((code != code[0]).any()):
            old = "" if "anchor" in self._sizes else " (a run recorded before anchors were: its sizes name none)"
            raise InputError(f"this FitGar was trained on {self.anchor!r} anchors{old}, the frames were built with "
                             f"{given!r} ones: build the garment-body pairs with GarmentBodyPair.build(..., "
                             f"anchor={self.anchor!r}), or train the model again")

    #: On CUDA with autograd off, frames run through :class:`~loosefit.models.fitgar_stream.FitGarStream` (a
    #: captured CUDA graph per garment graph); False: always the eager pass below.
    use_graphs = True

    def forward(self, batch: dict) -> dict[str, torch.Tensor]:
        if self.use_graphs and graphs_enabled(batch["anchor"].device):
            stream = getattr(self, "_stream", None)
            if stream is None or not stream.matches(batch):
                self._stream = stream = FitGarStream(self, batch)
            return stream(batch)
        self.check_anchor(batch)
        coarse_disp = self.coarse_displacement(batch)
        coarse = batch["anchor"] + coarse_disp  # FitGar Eq. 5
        detail_disp = self.detail_displacement(batch, coarse)
        return {"coarse": coarse, "verts": coarse + detail_disp,  # FitGar Eq. 9
                "coarse_displacement": coarse_disp, "detail_displacement": detail_disp}

    # ------------------------------------------------------------------ trainer protocol

    def stages(self) -> list[str]:
        return ["coarse", "detail"] if self.coarse is not None else ["detail"]

    def stage_parameters(self, stage: str):
        if stage == "coarse" and self.coarse is not None:
            return [*self.coarse_first.parameters(), *self.coarse.parameters()]
        if stage == "detail":
            parser = [] if self.parser is None else list(self.parser.parameters())
            return [*parser, *self.detail_first.parameters(), *self.detail.parameters()]
        raise ValueError(f"unknown stage {stage!r}")

    @staticmethod
    def collate(items: list[dict]) -> dict:
        return collate_frames(items)

    @staticmethod
    def batch_size(batch: dict) -> int:
        return int(batch["counts"].shape[0])

    def loss_terms(self, batch: dict, stage: str) -> dict[str, torch.Tensor]:
        """The stage's loss term, unweighted: ``coarse`` (FitGar Sec. 4.3) or ``detail`` (Sec. 4.4), each the
        mean squared displacement error over vertices and coordinates in units of its output scale squared."""
        if stage == "coarse":
            pred = self.coarse_displacement(batch)
            target = batch["smooth"] - batch["anchor"]
            return {"coarse": ((pred - target) ** 2).mean() / self.coarse.output.scale ** 2}
        if stage == "detail":
            with torch.no_grad():
                coarse = batch["anchor"] + self.coarse_displacement(batch)
            pred = self.detail_displacement(batch, coarse)
            return {"detail": ((pred - (batch["verts"] - coarse)) ** 2).mean() / self.detail.output.scale ** 2}
        raise ValueError(f"unknown stage {stage!r}")

    def training_loss(self, batch: dict, stage: str):
        terms = self.loss_terms(batch, stage)
        weights = {"coarse": self.config.coarse_weight, "detail": self.config.detail_weight}
        loss = sum(weights[k] * v for k, v in terms.items())
        return loss, {k: float(v.detach()) for k, v in terms.items()}

    def validation_metrics(self, batch: dict, stage: str) -> dict[str, float]:
        """Mean per-vertex errors in mm: ``coarse_error_mm`` (coarse against its smoothed target),
        ``coarse_sim_error_mm`` and, in the detail stage, ``detail_error_mm`` (against the simulation);
        ``rmse_mm`` and ``mean_vertex_error_mm`` of the stage's own output against its target."""
        with torch.no_grad():
            coarse = batch["anchor"] + self.coarse_displacement(batch)
            out = {"coarse_error_mm": float((coarse - batch["smooth"]).norm(dim=-1).mean() * 1e3),
                   "coarse_sim_error_mm": float((coarse - batch["verts"]).norm(dim=-1).mean() * 1e3)}
            pred, target = coarse, batch["smooth"]
            if stage == "detail":
                pred, target = coarse + self.detail_displacement(batch, coarse), batch["verts"]
                out["detail_error_mm"] = float((pred - target).norm(dim=-1).mean() * 1e3)
            out.update(masked_errors_mm(pred, target))
        return out

