"""``loosefit animate`` for a multi-garment static method (FitGar): a trained run folder + any garment
+ any body shape + motions -> garment mesh sequences, each frame predicted on its own.

The garment must be in the rest pose of the body shape it is animated on (``loosefit garment make``
with that ``--shape``, or an imported garment aligned to it). Its fit attribute comes from the factor
analysis kept in the checkpoint (FitGar Sec. 4.1), computed once per garment-body pair.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from loosefit.animate import load_run
from loosefit.device import resolve_device
from loosefit.errors import InputError
from loosefit.geometry.garment_batch import GarmentBatch
from loosefit.models.fitgar_data import collate_frames, frame_items
from loosefit.models.fitgar_inputs import DEFAULT_ANCHOR, GarmentBodyPair
from loosefit.motion.heading import to_world
from loosefit.models.registry import model_class
from loosefit.train.protocol import to_device
from loosefit.motion.motion import Motion
from loosefit.motion_range import range_warnings
from loosefit.threads import torch_threads
from loosefit.training import MODEL_META

#: Vertex outputs a caller may ask for: the detail mesh (FitGar Eq. 9) or the coarse one (FitGar Eq. 5).
OUTPUTS = ("verts", "coarse")


def body_shape_values(body) -> np.ndarray:
    """The shape values ``(S,)`` float32 a body was built with (Anny: its six phenotype values)."""
    shape = getattr(body, "shape", None)
    if shape is not None and hasattr(shape, "to_array"):
        return shape.to_array()
    betas = getattr(body, "betas", None)
    if betas is not None:
        return np.asarray(betas, np.float32).reshape(-1)
    raise InputError(f"cannot tell the shape values of body {getattr(body, 'name', body)!r}")


class AnyGarmentAnimator:
    """A trained multi-garment model ready to animate any garment on any body shape.

    Args:
        run_dir: a folder written by ``loosefit train --method fitgar``.
        checkpoint: ``"last"``, ``"best"`` (falls back to ``"last"``) or a checkpoint path.
        threads: torch CPU threads while animating.
        frames_per_pass: frames batched into one forward pass (frames never interact).
        device: ``"cpu"``, ``"cuda"`` or ``"auto"`` (:func:`loosefit.device.resolve_device`).
    """

    def __init__(self, run_dir: str | Path, checkpoint: str = "last", threads: int | None = 1,
                 frames_per_pass: int = 16, device: str = "cpu"):
        self.meta, model, _ = load_run(run_dir, checkpoint)
        if not getattr(type(model), "static", False):
            raise InputError(f"{self.meta['method']} animates along a motion: use loosefit.animate.Animator", run_dir)
        self._use(model, threads, frames_per_pass, device)

    @classmethod
    def from_model(cls, model, threads: int | None = 1, frames_per_pass: int = 16,
                   device: str = "cpu") -> "AnyGarmentAnimator":
        """An animator around an in-memory model, without a run folder."""
        animator = cls.__new__(cls)
        animator.meta = {"method": model.method, "sizes": model.sizes()}
        animator._use(model, threads, frames_per_pass, device)
        return animator

    def _use(self, model, threads, frames_per_pass: int, device: str = "cpu") -> None:
        if frames_per_pass < 1:
            raise InputError(f"frames_per_pass must be >= 1, got {frames_per_pass}")
        self.device = resolve_device(device)
        model.eval()
        self.fit_model = model.fit_attribute_model()
        self.model, self.threads, self.frames_per_pass = model.to(self.device), threads, frames_per_pass

    @property
    def method(self) -> str:
        return self.meta["method"]

    def range_warnings(self, motion: Motion, label=None) -> list[str]:
        """One line per root quantity of ``motion`` outside the run's training range (see
        :meth:`loosefit.animate.Animator.range_warnings`)."""
        return range_warnings(self.meta, motion, label)

    def pair(self, garment_verts: np.ndarray, faces: np.ndarray, body) -> GarmentBodyPair:
        """The garment ``(V, 3)`` / ``(F, 3)`` in the rest pose of ``body`` (its own shape), with its fit attribute."""
        shape = body_shape_values(body)
        sizes = self.meta["sizes"]
        if len(shape) != sizes["num_shape"] or body.num_joints != sizes["num_joints"]:
            raise InputError(f"the model was trained on bodies of {sizes['num_shape']} shape values and "
                             f"{sizes['num_joints']} joints; this body has {len(shape)} and {body.num_joints}")
        alpha = self.fit_model.attribute(garment_verts, faces, body.rest_verts())
        # the anchors the run was trained on (runs recorded before surface anchors used body vertices)
        anchor = getattr(self.model, "anchor", None) or DEFAULT_ANCHOR
        return GarmentBodyPair.build(garment_verts, faces, body, shape, alpha, anchor=anchor)

    def animate(self, pair: GarmentBodyPair, motion: Motion, output: str = "verts") -> np.ndarray:
        """World vertices ``(T, V, 3)`` float32 of ``pair`` along ``motion``: ``output`` ``"verts"`` (the
        detail mesh) or ``"coarse"``."""
        return self.animate_outputs(pair, motion, (output,))[output]

    def animate_outputs(self, pair: GarmentBodyPair, motion: Motion, outputs=OUTPUTS) -> dict[str, np.ndarray]:
        """Several vertex outputs of one pass: ``{name: (T, V, 3) world float32}`` for names in ``outputs``."""
        unknown = sorted(set(outputs) - set(OUTPUTS))
        if unknown:
            raise InputError(f"{self.method} has no vertex output {unknown} (it has {list(OUTPUTS)})")
        inputs = pair.frames(motion)
        items = frame_items(pair, inputs)
        chunks: dict[str, list[torch.Tensor]] = {name: [] for name in outputs}
        with torch_threads(self.threads), torch.no_grad():
            for start in range(0, len(items), self.frames_per_pass):
                batch = to_device(collate_frames(items[start:start + self.frames_per_pass]), self.device)
                out = self.model(batch)
                frames = GarmentBatch(batch["counts"])  # one garment per frame, all the pair's: padding adds no row
                for name in outputs:
                    chunks[name].append(frames.padded(out[name]))
        return {name: to_world(torch.cat(c).cpu().numpy(), inputs["rot"], inputs["origin"]) for name, c in chunks.items()}

def is_static_run(run_dir: str | Path) -> bool:
    """Whether the run folder holds a static any-garment method, FitGar (False when it is no run folder)."""
    path = Path(run_dir) / MODEL_META
    if not path.is_file():
        return False
    try:
        method = json.loads(path.read_text())["method"]
        return bool(getattr(model_class(method), "static", False))
    except (ValueError, KeyError, TypeError, InputError):  # a corrupt record: Animator's load_run says what is wrong
        return False
