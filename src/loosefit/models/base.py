"""What every per-garment model shares: sizes read from the data, feature normalisation, the trainer
protocol (:mod:`loosefit.train.protocol`) and the canonical-frame prediction interface used by animation.

A model predicts *canonical* garment vertices (in the heading frame, or the frame the model was trained
in, :attr:`GarmentModel.frame`: :mod:`loosefit.motion.heading`) from normalised
motion features, frame by frame with a recurrent state::

    out = model(root (B, T, R), joints (B, T, J-1, 6), state=None)
    out["verts"]  (B, T, V, 3) canonical vertices, metres;  out["state"]  the recurrent state after frame T-1

so that running ``T`` frames at once or one frame at a time (passing the state along) gives the same
vertices. ``R`` is 11, or more with the motion's history (:class:`~loosefit.models.motion_features.MotionHistory`,
the model's :attr:`GarmentModel.history`); a model reads the first :attr:`GarmentModel.root_features` of them, as
many as it was trained with, so that a model without history can be given either. Everything a model needs at
run time (rig, normalisation statistics, faces) is a buffer, so a checkpoint plus :meth:`GarmentModel.sizes`
rebuild it without the dataset.
"""

from __future__ import annotations

from typing import Any, ClassVar

import torch
from torch import nn

from loosefit.errors import InputError
from loosefit.models.dataset import GarmentSequences
from loosefit.models.motion_features import HISTORY_FRAMES, ROOT_FEATURES, MotionHistory
from loosefit.models.pins import Pins, pin_sizes
from loosefit.motion.heading import FRAMES
from loosefit.rig.virtual_bones import skin_bones, sparse_weights
from loosefit.train.losses import frame_mask, masked_errors_mm


def _history_of(sizes: dict, root_features: int, method: str) -> MotionHistory | None:
    """The motion history that ``sizes`` record (see :class:`GarmentModel`), checked against ``root_features``."""
    frames = sizes.get("history_frames", HISTORY_FRAMES if root_features > ROOT_FEATURES else ())
    history = MotionHistory(tuple(frames), bool(sizes.get("history_vertical", False))) if len(frames) else None
    if (history.root_features if history else ROOT_FEATURES) != root_features:
        raise InputError(f"{method}: {root_features} root features do not match the motion history {history} "
                         f"(sizes {sizes})")
    return history


class GarmentModel(nn.Module):
    """Base class of the per-garment methods.

    Subclasses set ``method`` (the CLI name) and ``Config`` (their hyper-parameter dataclass), implement
    ``__init__(sizes, config)``, :meth:`forward`, :meth:`training_loss`, and may override :meth:`stages`,
    :meth:`stage_parameters`, :meth:`init_from_data`.

    ``sizes`` (JSON-able dict) holds at least ``num_verts`` (V), ``num_joints`` (J, root included) and
    ``num_faces`` (F), ``root_features`` (R; runs made before it existed read 11), and the motion history among
    them: ``history_frames`` (its time constants, frames; [] for none; runs made before it existed read none for
    11 root features and :data:`HISTORY_FRAMES` for 20), ``history_vertical`` (runs before it: false) and ``frame``
    (where the garment is predicted, :data:`~loosefit.motion.heading.FRAMES`; absent: heading); methods
    add theirs (``num_bones``...). Never hard-code them.
    """

    method: ClassVar[str] = ""
    Config: ClassVar[type] = object
    #: Whether the method needs the virtual-bone rig of a prepared store.
    needs_rig: ClassVar[bool] = False

    def __init__(self, sizes: dict, config):
        super().__init__()
        self._sizes = dict(sizes)
        self.config = config
        J, V, F = sizes["num_joints"], sizes["num_verts"], sizes["num_faces"]
        self.root_features = int(sizes.get("root_features", ROOT_FEATURES))
        #: the motion history among the root features (None: none)
        self.history = _history_of(sizes, self.root_features, self.method)
        #: the frame the canonical garment is in (:func:`loosefit.motion.heading.motion_frames`)
        self.frame = str(sizes.get("frame", "heading"))
        if self.frame not in FRAMES:
            raise InputError(f"{self.method}: unknown frame {self.frame!r} (sizes {sizes}; one of {FRAMES})")
        self.register_buffer("root_mean", torch.zeros(self.root_features))
        self.register_buffer("root_std", torch.ones(self.root_features))
        self.register_buffer("joints_mean", torch.zeros(J - 1, 6))
        self.register_buffer("joints_std", torch.ones(J - 1, 6))
        self.register_buffer("faces", torch.zeros(F, 3, dtype=torch.long))
        self.register_buffer("template", torch.zeros(V, 3))  # the garment's rest mesh
        #: the garment's pins kept where it is animated (:mod:`loosefit.models.pins`; sizes ``pins``:
        #: :func:`~loosefit.models.pins.pin_sizes`); None for a model configured without them and for runs before them
        pins = sizes.get("pins")
        if pins and not (isinstance(pins, dict) and {"vertices", "parents", "radius"} <= set(pins)):
            raise InputError(f"{self.method}: sizes' pins need radius, parents and vertices, got {pins!r}")
        self.pins = Pins(pins["vertices"], pins["parents"], self.frame) if pins else None

    # ------------------------------------------------------------------ construction

    @classmethod
    def data_sizes(cls, data: GarmentSequences) -> dict:
        """The sizes of ``data``; subclasses add their own (call ``super()``)."""
        first = data.sequences[0]
        return {"num_verts": int(first.verts.shape[1]), "num_joints": int(first.joints.shape[1] + 1),
                "num_faces": int(len(data.faces)), "root_features": int(first.root.shape[1]),
                "history_frames": list(data.history.frames) if data.history else [],
                "history_vertical": bool(data.history and data.history.vertical),
                **({"frame": data.frame} if data.frame != "heading" else {})}  # heading runs keep their sizes

    @classmethod
    def config_sizes(cls, data: GarmentSequences, config) -> dict:
        """:meth:`data_sizes` and what ``config`` adds to them: the garment's pins (:mod:`loosefit.models.pins`)
        where it has a ``pin_radius`` and the garment pinned vertices; subclasses add theirs (call ``super()``)."""
        sizes = cls.data_sizes(data)
        radius = getattr(config, "pin_radius", None)
        if radius is not None and data.garment.pinned.any():
            from loosefit.models.body_lbs import training_body

            sizes["pins"] = pin_sizes(data.garment, training_body(data), radius)
        return sizes

    @classmethod
    def from_data(cls, data: GarmentSequences, config) -> "GarmentModel":
        """A model sized for ``data`` and ``config`` (:meth:`config_sizes`) with its buffers (statistics, faces,
        rig...) filled from the data."""
        model = cls(cls.config_sizes(data, config), config)
        model.init_from_data(data)
        return model

    def init_from_data(self, data: GarmentSequences) -> None:
        """Fill the buffers from the training data (subclasses extend, calling ``super()``)."""
        stats = data.feature_stats()
        with torch.no_grad():
            for key in ("root", "joints"):
                getattr(self, f"{key}_mean").copy_(torch.from_numpy(stats[key][0]))
                getattr(self, f"{key}_std").copy_(torch.from_numpy(stats[key][1]))
            self.faces.copy_(torch.from_numpy(data.faces))
            self.template.copy_(torch.from_numpy(data.garment.verts))
        if self.pins is not None:
            from loosefit.models.body_lbs import training_body

            self.pins.fill(data.garment.verts, data.faces, data.garment.pinned, training_body(data),
                           self._sizes["pins"]["radius"])

    def sizes(self) -> dict:
        return dict(self._sizes)

    # ------------------------------------------------------------------ prediction

    def normalise(self, root: torch.Tensor, joints: torch.Tensor,
                  pose_noise: float = 0.0) -> tuple[torch.Tensor, torch.Tensor]:
        """Standardised features: ``root (B,T,R)`` -> its first :attr:`root_features`, ``joints (B,T,J-1,6)``.

        ``pose_noise`` (training only; ours, not in the papers): the std of an offset added to each standardised
        joint rotation feature, drawn per window and the same in every frame. Each person's capture holds a pose
        with its own calibration; a network that keys on exact angles learns its training subjects."""
        if root.shape[-1] < self.root_features:
            raise InputError(f"{self.method} reads {self.root_features} root features, got {root.shape[-1]}: "
                             f"compute them with motion_features(..., {self.history})")
        root = root[..., : self.root_features]
        joints = (joints - self.joints_mean) / self.joints_std
        if pose_noise > 0:
            joints = joints + pose_noise * torch.randn_like(joints[:, :1])
        return (root - self.root_mean) / self.root_std, joints

    def forward(self, root: torch.Tensor, joints: torch.Tensor, state: Any = None) -> dict:
        """Raw (un-normalised) features -> ``{"verts": (B,T,V,3) canonical, "state": ..., other outputs}``."""
        raise NotImplementedError

    def pinned(self, verts: torch.Tensor, root: torch.Tensor, joints: torch.Tensor) -> torch.Tensor:
        """Canonical ``verts (..., V, 3)`` with the garment's pins kept (:class:`~loosefit.models.pins.Pins`) from
        the same frames' raw features; unchanged for a model without pins. What is animated, not what trains."""
        return verts if self.pins is None else self.pins(verts, root, joints)

    # ------------------------------------------------------------------ trainer protocol

    def stages(self) -> list[str]:
        return ["all"]

    def stage_parameters(self, stage: str):
        return self.parameters()

    def training_loss(self, batch: dict, stage: str):
        raise NotImplementedError

    def loss_weight(self, batch: dict) -> float:
        """What the batch weighs in a training loss: its counted frames (the losses are means over them).
        Distributed training weighs each process's loss by it, so that N processes take the same steps as one."""
        return float(self.mask(batch).sum())

    @staticmethod
    def mask(batch: dict) -> torch.Tensor:
        """``(B, T)`` frames that count in losses and metrics (burn-in frames excluded)."""
        return frame_mask(batch["burn_in"], batch["verts"].shape[1])

    @staticmethod
    def loss_frames(mask: torch.Tensor, count: int) -> torch.Tensor:
        """Indices ``(T',)`` of the window frames a training loss sees this step: all ``T`` of them when
        ``count`` is 0, else ``count`` drawn (from torch's global generator, which checkpoints save, so a
        resumed run draws the same) among the frames that count in every window of the ``mask (B, T)``.

        The models' per-frame, per-vertex work then runs on those frames only: an unbiased estimate
        of the full loss for a fraction of the cost (recurrent layers still run over every frame).
        """
        counted = torch.nonzero(mask.bool().all(0)).flatten()
        if count == 0 or count >= len(counted):
            return torch.arange(mask.shape[1], device=mask.device)
        return counted[torch.randperm(len(counted))[:count].sort().values.to(counted.device)]

    def validation_metrics(self, batch: dict, stage: str) -> dict[str, float]:
        """``rmse_mm`` (true root mean square) and ``mean_vertex_error_mm`` over the counted frames."""
        with torch.no_grad():
            return masked_errors_mm(self(batch["root"], batch["joints"])["verts"], batch["verts"], self.mask(batch))

    def skin(self, rest: torch.Tensor, rotations: torch.Tensor, translations: torch.Tensor) -> torch.Tensor:
        """:func:`loosefit.rig.skin_bones` with the model's ``skin_weights (V, B)`` buffer (methods driven
        by virtual bones have one). The sparse table that speeds up streaming is rebuilt whenever the
        buffer changes (a loaded checkpoint, another device)."""
        weights = self.skin_weights
        key = (weights.data_ptr(), weights._version, weights.device)
        if getattr(self, "_sparse_key", None) != key:
            self._sparse_skin, self._sparse_key = sparse_weights(weights), key
        return skin_bones(rest, weights, rotations, translations, self._sparse_skin)

    def batch_size(self, batch: dict) -> int:
        return int(batch["root"].shape[0])

