"""SwinGar's settings: the network's hyper-parameters (:class:`SwinGarConfig`, SwinGar Sec. IV), its data
windows and its training stages, as ``configs/models/swingar.yaml`` gives them (:class:`Config`). The network is
:mod:`loosefit.models.swingar`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from loosefit.errors import InputError
from loosefit.models.layers.gat_ln import NORMS
from loosefit.models.multi_garment import DEFAULT_DENSITY
from loosefit.train import StageConfig, TrainConfig

STAGES = ("supervised", "all")
#: Values of :attr:`SwinGarConfig.global_descriptor` (SwinGar Table I), and the descriptor distance each reads
#: (None: the garment graph carries no descriptor).
GLOBAL_DESCRIPTORS = {"spectral": "geodesic", "euclidean": "euclidean", "pooling": None, "none": None}
#: Values of :attr:`SwinGarConfig.gate_attention`.
GATE_ATTENTION = ("per_gate", "shared")
#: What each value of :attr:`SwinGarConfig.attention_design` means: the norm's index in ``NORMS``, then three
#: flags, each unset and set.
_DESIGN_WORDS = (("per-graph norm", "per-node norm", "score-row norm"), ("raw scores", "centred scores"),
                 ("averaged heads", "concatenated heads"), ("gates sharing a GAT-LN", "a GAT-LN per gate"))


@dataclass(frozen=True)
class SwinGarConfig:
    """SwinGar's hyper-parameters (defaults: the paper's Sec. IV, unless noted).

    Attributes:
        graph_hidden, graph_heads: garment graph encoder GAT-LN sizes and heads ([64, 128], [24, 24]).
        shape_mlp: shape encoder sizes ([256, 128, 24]); its last size is the shape feature size.
        motion_hidden: motion encoder LSTM size (128); equals ``graph_hidden[-1]`` (they are multiplied).
        motion_frames: poses the motion encoder sees, ``m`` (64).
        body_mlp: body encoder sizes ([256, 128, 64]).
        state_hidden, state_heads: garment state encoder (128, 24).
        blend_hidden, blend_heads: unposed blend shape GAT-LN layers ([256, 128], 3); the last size
            equals ``motion_hidden``.
        corrective_hidden, corrective_heads: LSTM-GAT-LN (64, 8); ``corrective_hidden`` equals ``body_mlp[-1]``.
        corrective_layers: single-head GAT-LN sizes after it ([64, 3]; the last must be 3).
        corrective_frames: coarse meshes the LSTM-GAT-LN runs over (3).
        alpha: GAT-LN score scale (2); null: plain GAT layers (the ablation of SwinGar Fig. 8, 9).
        descriptor_samples: spectral descriptor length ``z`` (256); used by ``spectral`` and ``euclidean`` only.
        global_descriptor: the garment's global feature ``a`` (SwinGar Table I): ``spectral`` (the paper's
            geodesic spectral descriptor), ``euclidean`` (the descriptor with straight-line distances),
            ``pooling`` (max-pooled fully connected layer on the graph features ``G``) or ``none`` (ones).
        k_vert, k_edge, k_bend, k_gravity, k_collision: loss weights (50, 10, 3, 0.2, 1.5).
        collision_eps: ``epsilon`` of SwinGar Eq. 14, metres (the paper: "a small positive value"; ours 2 mm).
        density: fabric density for the vertex masses of the gravity term, kg/m^2 (ours).
        skinning_prior: start the dynamic skinning weights from the garment's body-LBS weights (ours; see the
            module doc). False: the paper's predictor alone.
        attention_norm: GAT-LN's normaliser (:mod:`loosefit.models.layers.gat_ln`): ``node``, per vertex, as the
            Lipschitz normalisation SwinGar cites; ``graph``, one per graph and head, as Eq. 4's matrix norms read;
            ``row`` (ours), per vertex by its score row's norm alone, so that ``alpha`` sets the sharpness.
        attention_centred: GAT-LN scores from neighbourhood-centred features (ours; without it the attention of
            every layer stays a neighbourhood mean: see the module doc).
        concat_heads: concatenate each GAT-LN's heads (GAT's way; the width split among the heads) instead of
            averaging them.
        gate_attention: ``per_gate``, a GAT-LN per LSTM-GAT-LN gate (SwinGar Eq. 6; needs ``concat_heads``), or
            ``shared``, one per map serving the four gates.
        corrective_fourier: frequencies ``F`` of the rest-position Fourier features added to the corrective's node
            features (ours; 0, the paper's inputs): ``sin, cos(2 pi 2^k x_i)`` for ``k < F`` cycles per metre and
            each rest coordinate, ``6 F`` values per vertex that tell apart vertices the smooth inputs do not.

    ``attention_norm: graph``, ``attention_centred: false``, ``concat_heads: false``, ``gate_attention: shared``
    is the attention of runs trained before these keys existed: their ``method.yaml`` needs those four lines to
    load (:meth:`SwinGar.load_state_dict` refuses them otherwise).
    """

    graph_hidden: list[int] = field(default_factory=lambda: [64, 128])
    graph_heads: list[int] = field(default_factory=lambda: [24, 24])
    shape_mlp: list[int] = field(default_factory=lambda: [256, 128, 24])
    motion_hidden: int = 128
    motion_frames: int = 64
    body_mlp: list[int] = field(default_factory=lambda: [256, 128, 64])
    state_hidden: int = 128
    state_heads: int = 24
    blend_hidden: list[int] = field(default_factory=lambda: [256, 128])
    blend_heads: int = 3
    corrective_hidden: int = 64
    corrective_heads: int = 8
    corrective_layers: list[int] = field(default_factory=lambda: [64, 3])
    corrective_frames: int = 3
    alpha: Optional[float] = 2.0
    descriptor_samples: int = 256
    global_descriptor: str = "spectral"
    k_vert: float = 50.0
    k_edge: float = 10.0
    k_bend: float = 3.0
    k_gravity: float = 0.2
    k_collision: float = 1.5
    collision_eps: float = 0.002
    density: float = DEFAULT_DENSITY
    skinning_prior: bool = False
    attention_norm: str = "node"
    attention_centred: bool = True
    concat_heads: bool = True
    gate_attention: str = "per_gate"
    corrective_fourier: int = 0

    def __post_init__(self):
        sizes = [*self.graph_hidden, *self.graph_heads, *self.shape_mlp, self.motion_hidden, self.motion_frames,
                 *self.body_mlp, self.state_hidden, self.state_heads, *self.blend_hidden, self.blend_heads,
                 self.corrective_hidden, self.corrective_heads, *self.corrective_layers, self.corrective_frames,
                 self.descriptor_samples]
        if min(sizes) < 1:
            raise InputError(f"SwinGar sizes must be >= 1, got {sizes}")
        if self.corrective_fourier < 0:
            raise InputError(f"model.corrective_fourier must be >= 0 (0: none), got {self.corrective_fourier}")
        if len(self.graph_hidden) != len(self.graph_heads) or not self.graph_hidden:
            raise InputError(f"graph_hidden {self.graph_hidden} and graph_heads {self.graph_heads} must be equally long")
        if not (self.graph_hidden[-1] == self.motion_hidden == self.blend_hidden[-1]):
            raise InputError(f"graph_hidden[-1] ({self.graph_hidden[-1]}), motion_hidden ({self.motion_hidden}) and "
                             f"blend_hidden[-1] ({self.blend_hidden[-1]}) must be equal: they are multiplied")
        if self.body_mlp[-1] != self.corrective_hidden:
            raise InputError(f"body_mlp[-1] ({self.body_mlp[-1]}) must equal corrective_hidden ({self.corrective_hidden})")
        if self.corrective_layers[-1] != 3:
            raise InputError(f"corrective_layers must end with 3 (a displacement), got {self.corrective_layers}")
        weights = (self.k_vert, self.k_edge, self.k_bend, self.k_gravity, self.k_collision, self.collision_eps)
        if min(weights) < 0 or (self.alpha is not None and self.alpha < 0) or not self.density > 0:
            raise InputError("loss weights, collision_eps and alpha must be >= 0 and density > 0")
        if self.attention_norm not in NORMS:
            raise InputError(f"model.attention_norm must be one of {list(NORMS)}, got {self.attention_norm!r}")
        if self.gate_attention not in GATE_ATTENTION:
            raise InputError(f"model.gate_attention must be one of {list(GATE_ATTENTION)}, got {self.gate_attention!r}")
        if self.gate_attention == "per_gate" and not self.concat_heads:
            raise InputError("model.gate_attention per_gate needs model.concat_heads true")
        if self.concat_heads:
            narrow = [(w, h) for w, h in [*zip(self.graph_hidden, self.graph_heads), (self.state_hidden, self.state_heads),
                                          *((b, self.blend_heads) for b in self.blend_hidden),
                                          (self.corrective_hidden, self.corrective_heads)] if w < h]
            if narrow:
                raise InputError(f"with concatenated heads every GAT-LN needs at least one channel per head; "
                                 f"(width, heads) {narrow}")
        if self.global_descriptor not in GLOBAL_DESCRIPTORS:
            raise InputError(f"model.global_descriptor must be one of {sorted(GLOBAL_DESCRIPTORS)}, "
                             f"got {self.global_descriptor!r}")

    @property
    def attention_design(self) -> tuple[int, int, int, int]:
        """The GAT-LN design as four values: the norm (0 graph, 1 node, 2 row), then flags for centred scores,
        concatenated heads and a GAT-LN per gate; all zero for the attention of runs trained before the four keys
        existed."""
        return (NORMS.index(self.attention_norm), int(self.attention_centred), int(self.concat_heads),
                int(self.gate_attention == "per_gate"))

    def attention_options(self) -> dict:
        """:class:`~loosefit.models.layers.gat_ln.GATLN` keyword arguments of every GAT-LN layer."""
        return {"norm": self.attention_norm, "centred": self.attention_centred, "concat": self.concat_heads}

    @property
    def descriptor_distance(self) -> str | None:
        """The spectral descriptor's distance this model reads (``"geodesic"``, ``"euclidean"``), or None."""
        return GLOBAL_DESCRIPTORS[self.global_descriptor]

    def graph_settings(self) -> dict:
        """Keyword arguments of :func:`~loosefit.models.multi_garment.garment_graph` and
        :class:`~loosefit.models.multi_garment.MultiGarmentData` for this model: training and animation
        build garments with the same descriptor."""
        return {"descriptor_samples": self.descriptor_samples, "density": self.density,
                "descriptor_distance": self.descriptor_distance}


def _paper_training() -> TrainConfig:
    # Adam 1e-3 with cosine annealing (paper Sec. IV); batch 64 there, epochs per stage ours.
    return TrainConfig(optimizer="adam", lr=1e-3, batch_size=8, schedule="cosine", monitor="rmse_mm",
                       stages={"supervised": StageConfig(epochs=50), "all": StageConfig(epochs=50)})


@dataclass(frozen=True)
class DataConfig:
    """Training windows: ``window`` frames every ``stride``; each carries its motion history, so no burn-in."""

    window: int = 32
    stride: int = 32

    def __post_init__(self):
        if self.window < 1 or self.stride < 1:
            raise InputError(f"window and stride must be >= 1, got {self.window}, {self.stride}")


@dataclass(frozen=True)
class Config:
    """Everything ``loosefit train --method swingar`` reads (``configs/models/swingar.yaml``)."""

    model: SwinGarConfig = field(default_factory=SwinGarConfig)
    train: TrainConfig = field(default_factory=_paper_training)
    data: DataConfig = field(default_factory=DataConfig)
