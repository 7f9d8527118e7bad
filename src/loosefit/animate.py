"""``loosefit animate``: a trained run folder + new motions -> garment mesh sequences.

:class:`Animator` rebuilds the model from the run folder alone (``model.json``, ``method.yaml`` and a
checkpoint), turns motions into features, runs the network and puts the canonical result back into the
world. Motions are animated in batches (padded at the end: the models are causal, so padding never
changes earlier frames), or streamed one frame at a time with :class:`AnimationStream` for real-time use.
Both give the same vertices.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import torch

from loosefit.device import resolve_device
from loosefit.errors import InputError
from loosefit.models.motion_features import FeatureStream, motion_features
from loosefit.motion.heading import garment_frames, motion_frames, to_world
from loosefit.models.registry import model_class, run_config_class
from loosefit.motion.motion import Motion
from loosefit.motion_range import range_warnings
from loosefit.pretrained import resolve_run
from loosefit.threads import torch_threads
from loosefit.training import METHOD_CONFIG, MODEL_META, load_run_config
from loosefit.train.run import RunDir, load_weights

log = logging.getLogger(__name__)


def load_run(run_dir: str | Path, checkpoint: str = "best"):
    """The trained model of a run folder: ``(meta (model.json), model with the checkpoint's weights, config)``.

    ``checkpoint``: ``"best"`` (the epoch the validation chose; ``"last"`` when the run validated on nothing),
    ``"last"`` (the end of training) or a checkpoint path. ``run_dir`` may name a shipped garment,
    ``pretrained:skirt`` (:mod:`loosefit.pretrained`).
    """
    run = RunDir(resolve_run(run_dir))
    meta = read_run_meta(run.path)
    try:
        cls = model_class(meta["method"])
    except InputError as e:
        raise InputError(f"run record is corrupt: {e.problem}", run.path / MODEL_META) from None
    cfg = load_run_config(run_config_class(meta["method"]), run.path / METHOD_CONFIG)
    try:
        model = cls(meta["sizes"], cfg.model)
    except (KeyError, TypeError, ValueError) as e:
        raise InputError(f"run record is corrupt: its sizes do not build a {meta['method']} model "
                         f"({type(e).__name__}: {e})", run.path / MODEL_META) from None
    path = {"best": run.best_checkpoint, "last": run.last_checkpoint}.get(checkpoint, Path(checkpoint))
    if checkpoint == "best" and not path.is_file():
        path = run.last_checkpoint
    load_weights(model, path)
    return meta, model, cfg


def read_run_meta(run_dir: str | Path) -> dict:
    """A run folder's ``model.json``: the method, the model's sizes and what it was trained on.

    Raises:
        InputError: no ``model.json`` (not a run folder), or a file that is truncated, not JSON, or lacks
            ``method`` (a string) or ``sizes`` (a mapping); the message names the file, as for a corrupt
            checkpoint.
    """
    run_dir = resolve_run(run_dir)
    path = run_dir / MODEL_META
    if not path.is_file():
        raise InputError(f"not a loosefit run folder (no {MODEL_META})", run_dir)
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise InputError(f"run record is corrupt or truncated ({type(e).__name__}: {e})", path) from None
    if not isinstance(meta, dict):
        raise InputError(f"run record is corrupt: expected a JSON object, got {type(meta).__name__}", path)
    if not isinstance(meta.get("method"), str):
        raise InputError("run record is corrupt: no 'method' name", path)
    if not isinstance(meta.get("sizes"), dict):
        raise InputError("run record is corrupt: no 'sizes' mapping", path)
    return meta


class Animator:
    """A trained garment model ready to animate.

    Args:
        run_dir: a folder written by :func:`loosefit.training.train_model`, or a shipped garment
            (``pretrained:skirt``, ``pretrained:dress/jointnet``: :mod:`loosefit.pretrained`).
        checkpoint: ``"best"`` (the best validation epoch; ``"last"`` when the run validated on nothing),
            ``"last"`` (the end of training) or a checkpoint path. Validation never sees a test motion unless
            the run was told to (:mod:`loosefit.train.validation`), so the best epoch flatters no test score.
        threads: torch CPU threads used while animating (1 is fastest for the graph layers here).
        device: ``"cpu"``, ``"cuda"`` or ``"auto"`` (:func:`loosefit.device.resolve_device`).
        garment: for a multi-garment method (SwinGar): the garment to animate, a
            :class:`~loosefit.garment.Garment`, a garment file (``.obj`` with its sidecar) or any ``.obj``
            in the body's rest pose; any vertex count, never seen in training if need be.
        body: the body the garment is worn on (its shape), for a multi-garment method; None: the average Anny body.
    """

    def __init__(self, run_dir: str | Path, checkpoint: str = "best", threads: int | None = 1, garment=None,
                 body=None, device: str = "cpu"):
        self.meta, model, cfg = load_run(run_dir, checkpoint)
        cls = type(model)
        if getattr(cls, "static", False):
            raise InputError(f"{self.meta['method']} animates frame by frame: use loosefit.animate_any.AnyGarmentAnimator",
                             run_dir)
        if getattr(cls, "multi_garment", False):
            model = _bind_garment(model, cfg.model, garment, body)
        elif garment is not None:
            raise InputError(f"{self.meta['method']} is trained for one garment; it cannot animate another")
        self._use(model, threads, device)

    @classmethod
    def from_model(cls, model, threads: int | None = 1, device: str = "cpu") -> "Animator":
        """An animator around an in-memory :class:`~loosefit.models.base.GarmentModel` (just built or
        trained), without a run folder; ``meta`` then holds only its method and sizes."""
        animator = cls.__new__(cls)
        animator.meta = {"method": model.method, "sizes": model.sizes()}
        animator._use(model, threads, device)
        return animator

    #: Frames per forward pass in :meth:`animate_batch` (32 measured fastest of 16-600 at 12k vertices).
    chunk_frames: int = 32

    def _use(self, model, threads: int | None, device: str = "cpu") -> None:
        self.device = resolve_device(device)
        self.faces = model.faces.cpu().numpy()
        model.eval()
        self.model = model.to(self.device)
        self.threads = threads
        # the motion history among the root features, where the model reads one
        self.history = getattr(model, "history", None)
        self.frame = getattr(model, "frame", "heading")  # the frame the model's garment is in

    @property
    def method(self) -> str:
        return self.meta["method"]

    @property
    def rest_garment(self) -> np.ndarray | None:
        """``(V, 3)`` float32 the garment's rest mesh on the rest body (the model's template), metres: what the
        collision handling skins to the body for cloth centimetres inside it (SwinGar's: its garment graph's rest
        mesh); None for a model that keeps none."""
        template = getattr(self.model, "template", None)
        if template is None:
            template = getattr(self.model, "g", {}).get("rest")
        return None if template is None else template.detach().cpu().numpy().astype(np.float32)

    @property
    def num_joints(self) -> int:
        return int(self.meta["sizes"]["num_joints"])

    def range_warnings(self, motion: Motion, label=None) -> list[str]:
        """One line per root quantity of ``motion`` outside the range the run was trained on, naming
        ``label`` (default: the motion's name); empty for a run without a recorded range
        (:func:`loosefit.motion_range.range_warnings`)."""
        return range_warnings(self.meta, motion, label)

    def _check(self, motion: Motion) -> None:
        if motion.num_joints != self.num_joints:
            raise InputError(f"motion {motion.name!r} has {motion.num_joints} joints, the model was trained on {self.num_joints}")

    def animate(self, motion: Motion, output: str = "verts") -> np.ndarray:
        """World garment vertices ``(T, V, 3)`` float32 for one motion (``output``: see :meth:`animate_batch`)."""
        return self.animate_batch([motion], output)[0]

    def animate_batch(self, motions: list[Motion], output: str = "verts") -> list[np.ndarray]:
        """World vertices ``(T_i, V, 3)`` for several motions, run as one batch, :attr:`chunk_frames` frames
        at a time with the recurrent state carried over (the same vertices as one pass over all frames;
        memory grows with the chunk, not with the motions' length).

        ``output`` names the model output returned: ``"verts"`` (the garment, with its pins kept:
        :meth:`GarmentModel.pinned`), or another canonical ``(B, T, V, 3)`` vertex output of the model, as it is,
        such as VirtualBones' low-frequency mesh ``"lf"``.
        """
        for m in motions:
            self._check(m)
        feats = [motion_features(m, self.history) for m in motions]
        T = max(m.num_frames for m in motions)

        def padded(key):
            return torch.from_numpy(np.stack([np.concatenate([f[key], np.repeat(f[key][-1:], T - len(f[key]), 0)]) for f in feats]))

        root, joints = padded("root").to(self.device), padded("joints").to(self.device)
        chunks, state = [], None
        with torch_threads(self.threads), torch.no_grad():
            for start in range(0, T, self.chunk_frames):
                part = slice(start, start + self.chunk_frames)
                outputs = self.model(root[:, part], joints[:, part], state)
                if start == 0:
                    shape = outputs["verts"].shape
                    vertex_outputs = sorted(k for k, v in outputs.items()
                                            if isinstance(v, torch.Tensor) and v.shape == shape)
                    if output not in vertex_outputs:
                        raise InputError(f"{self.method} has no vertex output {output!r} (it has {vertex_outputs})")
                chunks.append(self._pinned(outputs["verts"], root[:, part], joints[:, part]) if output == "verts"
                              else outputs[output])
                state = outputs["state"]
        canonical = torch.cat(chunks, 1).cpu().numpy()
        out = []
        for m, c in zip(motions, canonical):
            rot, origin = motion_frames(m, self.frame)
            out.append(to_world(c[: m.num_frames], rot, origin))
        return out

    def _pinned(self, verts: torch.Tensor, root: torch.Tensor, joints: torch.Tensor) -> torch.Tensor:
        """The per-garment model's pins kept (:meth:`GarmentModel.pinned`); a multi-garment model's as it is."""
        pinned = getattr(self.model, "pinned", None)
        return verts if pinned is None else pinned(verts, root, joints)

    def stream(self) -> "AnimationStream":
        """A frame-by-frame animator carrying the recurrent state (see :class:`AnimationStream`)."""
        return AnimationStream(self)


class AnimationStream:
    """Real-time use: ``step(rotations (J, 3), translation (3,)) -> vertices (V, 3)`` world, one frame at a time."""

    def __init__(self, animator: Animator):
        self.animator = animator
        self.features = FeatureStream(animator.history)
        self.state = None

    def step(self, rotations: np.ndarray, translation: np.ndarray) -> np.ndarray:
        rotations = np.asarray(rotations, np.float32)
        if rotations.shape != (self.animator.num_joints, 3):
            raise InputError(f"a frame needs rotations of shape ({self.animator.num_joints}, 3), got {rotations.shape}")
        root, joints, _ = self.features.step(rotations, translation)
        rot, origin = (f[0] for f in garment_frames(rotations[None, 0], np.reshape(translation, (1, 3)),
                                                      self.animator.frame))
        with torch_threads(self.animator.threads), torch.no_grad():
            device = self.animator.device
            out = self.animator.model(torch.from_numpy(root)[None, None].to(device),
                                      torch.from_numpy(joints)[None, None].to(device), self.state)
        self.state = out["state"]
        verts = self.animator._pinned(out["verts"], torch.from_numpy(root)[None, None].to(device),
                                      torch.from_numpy(joints)[None, None].to(device))
        return to_world(verts[0].cpu().numpy(), rot[None], origin[None])[0]


def _bind_garment(model, config, garment, body):
    """A multi-garment model bound to ``garment`` worn on ``body`` (see :class:`Animator`)."""
    from loosefit.body import AnnyBody
    from loosefit.garment import Garment
    from loosefit.garment.body_fit import refit
    from loosefit.garment.obj_io import read_obj
    from loosefit.models.multi_garment import garment_graph
    from loosefit.models.swingar import BoundSwinGar

    if garment is None:
        raise InputError("a multi-garment model animates the garment it is given: pass the garment (--garment)")
    body = AnnyBody() if body is None else body
    if not isinstance(garment, Garment):
        path = Path(garment)
        if Garment.sidecar_path(path).is_file():
            garment, fitted = refit(Garment.load(path), body, path)
            if fitted is not None:
                log.warning("%s: made on another Anny shape, draped onto this body first (%.1f%% of vertices more than "
                            "2 mm inside it before, %.1f%% after)", path, fitted["inside_before_percent"],
                            fitted["inside_after_percent"])
        else:
            verts, faces = read_obj(path)
            garment = Garment(verts, faces, np.zeros(len(verts), bool), "imported", name=path.stem)
    if not hasattr(body, "shape") or not hasattr(body.shape, "to_array"):
        raise InputError("a multi-garment model reads Anny bodies (their shape values)")
    # the descriptor the run was trained with (its method.yaml): spectral, Euclidean or none
    graph = garment_graph(garment.name or "garment", garment.verts, garment.faces, body.collision_proxy(),
                          body.shape.to_array(), **config.graph_settings())
    return BoundSwinGar(model, graph)
