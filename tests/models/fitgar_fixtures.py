"""Tiny FitGar data made in the tests: small template garments on the Anny body (two shapes), a few
poses of a procedural walk, and a synthetic target (skinned garment plus a pose-dependent ripple)."""

from __future__ import annotations

import numpy as np
import torch

from loosefit.models.fitgar import FitGarConfig
from loosefit.models.fitgar_data import Smoother, frame_items
from loosefit.models.fitgar_inputs import GarmentBodyPair

#: A FitGar small enough for tests (the paper's structure, every width cut down).
TINY = FitGarConfig(heads=2, coarse_first=8, coarse_blocks=(16, 8), coarse_dense=(8,), parser=(16, 16),
                    detail_first=16, detail_blocks=(8, 8, 8, 8), detail_dense=(8,))
#: The same as ``loosefit train --set`` overrides.
TINY_OVERRIDES = ["model.heads=2", "model.coarse_first=8", "model.coarse_blocks=[16, 8]", "model.coarse_dense=[8]",
                  "model.parser=[16, 16]", "model.detail_first=16", "model.detail_blocks=[8, 8, 8, 8]",
                  "model.detail_dense=[8]"]


def synthetic_target(items: list[dict], smoother: Smoother) -> list[dict]:
    """Give frames a target: the garment skinned by its body vertices' weights plus a ripple of up to
    1 cm across the body axis whose phase follows the pose, and its ``fitgar`` smoothing."""
    for it in items:
        lift = it["anchor"][0] - it["body_rel"][0]  # skinned position = relative feature + root height
        skinned = it["garment_rel"] + lift
        radial = skinned[:, :2] - skinned[:, :2].mean(0)
        radial /= np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-6)
        phase = 3.0 * float(it["pose"][6:].sum()) / len(it["pose"])
        ripple = 0.01 * np.sin(25.0 * skinned[:, 2] + phase)
        it["verts"] = (skinned + np.concatenate([radial * ripple[:, None], np.zeros((len(skinned), 1))], 1)).astype(np.float32)
        it["smooth"] = smoother(it["verts"])
    return items


def make_frames(body, garment, motion, frames, alpha) -> tuple[GarmentBodyPair, list[dict]]:
    """The pair of ``garment`` on ``body`` (its own shape) and the target frames ``frames`` of ``motion``."""
    pair = GarmentBodyPair.build(garment.verts, garment.faces, body, body.shape.to_array(), alpha)
    items = [frame_items(pair, pair.frames(motion))[t] for t in frames]
    return pair, synthetic_target(items, Smoother(garment.faces, len(garment.verts), garment.pinned))


def set_stats(model, items: list[dict]) -> None:
    """Input statistics and output scales from the items, as :meth:`FitGar.init_from_data` does from a dataset."""
    rel = np.concatenate([np.concatenate([it["body_rel"], it["garment_rel"]]) for it in items])
    dist = np.concatenate([np.linalg.norm(it["smooth"][:, None] - it["joints"][None], axis=-1).ravel() for it in items])
    model.rel_mean.copy_(torch.from_numpy(rel.mean(0)))
    model.rel_std.fill_(float(rel.std()))
    model.dist_mean.fill_(float(dist.mean()))
    model.dist_std.fill_(float(dist.std()))
    coarse = np.concatenate([np.sum((it["smooth"] - it["anchor"]) ** 2, -1) for it in items])
    detail = np.concatenate([np.sum((it["verts"] - it["smooth"]) ** 2, -1) for it in items])
    model.coarse.output.scale.fill_(float(np.sqrt(coarse.mean())))
    model.detail.output.scale.fill_(float(np.sqrt(detail.mean())))
