"""Training frames of many garments on many bodies for FitGar (a static, multi-garment method).

:class:`GarmentFrames` reads every sequence of a split of a prepared store (the layout of
``configs/datasets/garments.yaml``: each sequence names its garment entry, fitted to one body shape,
its body shape and its motion) and serves single frames: FitGar predicts each frame on its own. An item
holds the frame's inputs (:mod:`loosefit.models.fitgar_inputs`) and its targets, in the heading frame:

- ``verts (V, 3)``: the simulated garment, metres;
- ``smooth (V, 3)``: the same smoothed by the ``fitgar`` preset (FitGar Sec. 5.1: diffusion 0.12, 40
  iterations; pinned vertices kept), the coarse generator's target.
- ``anchor_code ()``: which anchors the pair was built with (:func:`anchor_code`).

:func:`collate_frames` batches frames of any garments into one disjoint graph (nodes of every frame one
after the other, edges and faces shifted): node arrays ``(N, ...)`` with ``batch (N,)`` naming each
node's frame, frame arrays ``(G, ...)``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import torch
from torch.utils.data import Dataset

from loosefit.data.store import DatasetStore
from loosefit.errors import InputError
from loosefit.geometry.garment_batch import GarmentBatch
from loosefit.geometry.smoothing import get_preset, smoothing_operator
from loosefit.models.fitgar_inputs import (ANCHOR_MODES, DEFAULT_ANCHOR, GarmentBodyPair, PosedSkeleton,
                                          check_anchor_mode, pose_motion)
from loosefit.motion.heading import to_canonical

#: Per-node arrays of an item and of a batch.
NODE_KEYS = ("anchor", "body_normal", "body_rel", "garment_rel", "verts", "smooth")
#: Per-frame arrays.
FRAME_KEYS = ("joints", "pose", "shape", "alpha", "anchor_code")
#: Smallest standard deviation of an input normalised per feature (body shape values, fit factors).
STD_FLOOR = 1e-2


def load_body(model: str):
    """The body model a store's bodies belong to (their ``model`` attribute): Anny is the one built in."""
    if model.startswith("anny"):
        from loosefit.body import AnnyBody

        return AnnyBody()
    raise InputError(f"FitGar data on {model!r} bodies needs that body model passed in (body=...)")


class Smoother:
    """The ``fitgar`` smoothing of one garment's frames ``(..., V, 3)`` (operator built once)."""

    def __init__(self, faces: np.ndarray, num_verts: int, fixed: np.ndarray | None, preset: str = "fitgar"):
        p = get_preset(preset)
        self.operator: sp.csr_matrix = smoothing_operator(faces, num_verts, p.coefficient, fixed=fixed)
        self.iterations = p.iterations

    def __call__(self, verts: np.ndarray) -> np.ndarray:
        V = verts.shape[-2]
        x = np.moveaxis(np.asarray(verts, np.float64).reshape(-1, V, 3), 1, 0).reshape(V, -1)
        for _ in range(self.iterations):
            x = self.operator @ x
        return np.moveaxis(x.reshape(V, -1, 3), 0, 1).reshape(verts.shape).astype(np.float32)


def check_frame_choice(frame_stride: int, frame_offset: int) -> None:
    """Raise :class:`InputError` unless ``frame_stride >= 1`` and ``0 <= frame_offset < frame_stride``."""
    if frame_stride < 1:
        raise InputError(f"frame_stride must be >= 1, got {frame_stride}")
    if not 0 <= frame_offset < frame_stride:
        raise InputError(f"frame_offset must be in [0, frame_stride = {frame_stride}), got {frame_offset}")


class GarmentFrames(Dataset):
    """Frames of every garment-body-motion sequence of ``split`` in a prepared store.

    Args:
        store: a :class:`DatasetStore` or its path, prepared (the fit attribute is read from it).
        split: ``"train"``, ``"val"``, ``"test"`` or None (all).
        body: the body model of the store's bodies (default: from their ``model`` attribute).
        sim_params: keep only sequences simulated with exactly these parameters.
        names: restrict to these sequence names.
        frame_stride: keep every ``frame_stride``-th frame of each sequence (frames are taken one by one).
        frame_offset: the first frame kept, ``0 <= frame_offset < frame_stride`` (a held-pose plan's settled
            frames: stride ``transition + frames``, offset one less; :mod:`loosefit.motion.hold`).
        smoothing: preset of the coarse target.
        anchor: where garment vertices are anchored on the body (:data:`~loosefit.models.fitgar_inputs.ANCHOR_MODES`).
    """

    def __init__(self, store, split: str | None = "train", body=None, sim_params: dict | None = None,
                 names: list[str] | None = None, frame_stride: int = 1, frame_offset: int = 0,
                 smoothing: str = "fitgar", anchor: str = DEFAULT_ANCHOR):
        from loosefit.rig.prepared import load_fit_attribute

        check_frame_choice(frame_stride, frame_offset)
        self.anchor = check_anchor_mode(anchor)
        self.store = store if isinstance(store, DatasetStore) else DatasetStore.open(store, mode="r")
        self.fit_model, alphas = load_fit_attribute(self.store)
        selected = [n for n in self.store.sequence_names(split=split)
                    if (names is None or n in names)
                    and (sim_params is None or self.store.sequence(n).sim_params == sim_params)]
        if not selected:
            raise InputError(f"no {split or 'usable'} sequences in the store", self.store.path)
        self.sequence_names = selected
        self.pairs: dict[tuple[str, str], GarmentBodyPair] = {}
        self.smoothers: dict[str, Smoother] = {}
        self._posed: dict[tuple[str, str], PosedSkeleton] = {}
        self.sequences: list[dict] = []
        self.index: list[tuple[int, int]] = []
        for name in selected:
            seq = self.store.sequence(name)
            key = (seq.garment, seq.body)
            if key not in alphas:
                raise InputError(f"the fit attribute has no pair {key}: run `loosefit prepare` again", self.store.path)
            if key not in self.pairs:
                if body is None:
                    body = load_body(str(self.store.read_attrs(f"bodies/{seq.body}").get("model", "anny")))
                garment = self.store.garment(seq.garment)
                self.pairs[key] = GarmentBodyPair.build(garment.verts, garment.faces, body, self.store.body(seq.body),
                                                        alphas[key], anchor=anchor)
                if seq.garment not in self.smoothers:
                    self.smoothers[seq.garment] = Smoother(garment.faces, len(garment.verts), garment.pinned, smoothing)
            pose_key = (seq.body, seq.motion)
            if pose_key not in self._posed:
                pair = self.pairs[key]
                self._posed[pose_key] = pose_motion(pair.rest_joints, pair.parents, self.store.motion(seq.motion))
            i = len(self.sequences)
            self.sequences.append({"name": name, "pair": key, "pose": pose_key, "garment": seq.garment,
                                   "verts": np.asarray(seq.verts[:], np.float32)})
            self.index += [(i, t) for t in range(frame_offset, seq.num_frames, frame_stride)]

    def __len__(self) -> int:
        return len(self.index)

    def __getitem__(self, k: int) -> dict:
        i, t = self.index[k]
        s = self.sequences[i]
        pair = self.pairs[s["pair"]]
        posed = self._posed[s["pose"]][t:t + 1]
        item = {key: value[0] for key, value in pair.inputs(posed).items() if key not in ("rot", "origin")}
        verts = to_canonical(s["verts"][t:t + 1], posed.rot, posed.origin)[0]
        item.update(verts=verts, smooth=self.smoothers[s["garment"]](verts), shape=pair.shape, alpha=pair.alpha,
                    edges=pair.edges, faces=pair.faces, anchor_code=anchor_code(pair))
        return item

    def feature_stats(self, samples: int = 256) -> dict[str, np.ndarray]:
        """Statistics the model normalises with, from up to ``samples`` frames spread over the set:
        ``rel_mean (3,)``, ``rel_std (3,)`` (relative skinning features per axis, metres); ``dist_mean ()``,
        ``dist_std ()`` (distances from the coarse target's vertices to the joints); ``shape_mean/std (S,)``,
        ``alpha_mean/std (F,)`` (over the pairs); root mean square lengths, metres, of the coarse
        displacement ``smooth - anchor`` (``coarse_scale ()``), of ``verts - smooth`` (``detail_scale ()``)
        and of ``verts - anchor`` (``full_scale ()``)."""
        picks = np.unique(np.linspace(0, len(self) - 1, min(samples, len(self))).round().astype(int))
        shapes = np.stack([p.shape for p in self.pairs.values()])
        alphas = np.stack([p.alpha for p in self.pairs.values()])
        return frame_statistics([self[int(k)] for k in picks], shapes, alphas)

    @property
    def sizes(self) -> dict:
        """``num_joints`` J, ``num_shape`` S, ``num_fit_factors`` F, ``pose_features`` P of the data."""
        pair = next(iter(self.pairs.values()))
        return {"num_joints": int(len(pair.rest_joints)), "num_shape": int(len(pair.shape)),
                "num_fit_factors": int(len(pair.alpha)), "pose_features": int(6 * len(pair.rest_joints))}


def frame_statistics(items: list[dict], shapes: np.ndarray, alphas: np.ndarray) -> dict[str, np.ndarray]:
    """The statistics of :meth:`GarmentFrames.feature_stats` (keys and units there), float32, from frame
    ``items`` (with ``body_rel (Nb, 3)``, ``garment_rel (V, 3)``, ``smooth``, ``verts``, ``anchor (V, 3)`` and
    ``joints (J, 3)``) and the pairs' ``shapes (P, S)`` and ``alphas (P, F)``: means and stds (floored at
    :data:`STD_FLOOR`) over every row, and the output scales as root mean square displacement lengths
    (floored at 0.1 mm)."""
    rel = np.concatenate([np.concatenate([it["body_rel"], it["garment_rel"]]) for it in items]).astype(np.float64)
    dist = np.concatenate([np.linalg.norm(it["smooth"][:, None] - it["joints"][None], axis=-1).ravel()
                           for it in items])
    coarse = np.concatenate([np.sum((it["smooth"] - it["anchor"]) ** 2, -1) for it in items])
    detail = np.concatenate([np.sum((it["verts"] - it["smooth"]) ** 2, -1) for it in items])
    full = np.concatenate([np.sum((it["verts"] - it["anchor"]) ** 2, -1) for it in items])
    shapes, alphas = np.asarray(shapes, np.float64), np.asarray(alphas, np.float64)
    f32 = lambda x: np.asarray(x, np.float32)  # noqa: E731
    return {
        "rel_mean": f32(rel.mean(0)), "rel_std": f32(np.maximum(rel.std(0), STD_FLOOR)),
        "dist_mean": f32(dist.mean()), "dist_std": f32(max(dist.std(), STD_FLOOR)),
        "shape_mean": f32(shapes.mean(0)), "shape_std": f32(np.maximum(shapes.std(0), STD_FLOOR)),
        "alpha_mean": f32(alphas.mean(0)), "alpha_std": f32(np.maximum(alphas.std(0), STD_FLOOR)),
        "coarse_scale": f32(max(np.sqrt(coarse.mean()), 1e-4)),
        "detail_scale": f32(max(np.sqrt(detail.mean()), 1e-4)),
        "full_scale": f32(max(np.sqrt(full.mean()), 1e-4)),
    }


def collate_frames(items: list[dict]) -> dict:
    """Frames (items of :class:`GarmentFrames` or :func:`frame_items`) -> one batched disjoint graph of tensors, the
    packed form of the frames' garments (:class:`~loosefit.geometry.garment_batch.GarmentBatch`; ``GarmentBatch(
    batch["counts"])`` converts a node array to the padded form and back): node arrays ``(N, ...)`` float32,
    ``batch (N,)`` int64, ``edge_index (2, E)``, ``faces (F, 3)`` (shifted to the batch's node numbering),
    ``counts (G,)`` vertices per frame; frame arrays ``(G, ...)`` float32."""
    garments = GarmentBatch.from_list(faces=[it["faces"] for it in items], edges=[it["edges"] for it in items],
                                      features={key: [it[key] for it in items] for key in NODE_KEYS if key in items[0]},
                                      feature_dtype=torch.float32)
    out = dict(garments.features)
    for key in (k for k in FRAME_KEYS if k in items[0]):
        out[key] = torch.from_numpy(np.stack([it[key] for it in items]).astype(np.float32))
    out.update(garments.graph())
    return out


def anchor_code(pair: GarmentBodyPair) -> np.ndarray:
    """An item's ``anchor_code ()``: the index of its pair's anchor in :data:`ANCHOR_MODES` (the model refuses
    frames built with anchors other than those it was trained on)."""
    return np.float32(ANCHOR_MODES.index(pair.anchor))


def frame_items(pair: GarmentBodyPair, inputs: dict[str, np.ndarray]) -> list[dict]:
    """The frames of ``pair.frames(motion)`` as items for :func:`collate_frames` (no targets): animation."""
    T = len(inputs["anchor"])
    return [{**{k: inputs[k][t] for k in ("anchor", "body_normal", "body_rel", "garment_rel", "joints", "pose")},
             "shape": pair.shape, "alpha": pair.alpha, "edges": pair.edges, "faces": pair.faces,
             "anchor_code": anchor_code(pair)} for t in range(T)]
