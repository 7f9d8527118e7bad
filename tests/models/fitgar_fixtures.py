"""Tiny FitGar data made in the tests: small template garments on the Anny body (two shapes), a few
poses of a procedural walk, and a synthetic target (skinned garment plus a pose-dependent ripple)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from loosefit.models.fitgar import FitGarConfig
from loosefit.models.fitgar_data import Smoother, frame_items
from loosefit.models.fitgar_inputs import GarmentBodyPair

#: A FitGar small enough for tests (the paper's structure, every width cut down).
TINY = FitGarConfig(heads=2, coarse_first=8, coarse_blocks=(16, 8), coarse_dense=(8,), parser=(16, 16),
                    detail_first=16, detail_blocks=(8, 8, 8, 8), detail_dense=(8,))
#: The same in a config file, with a short training (``loosefit train --config``).
TINY_CONFIG = Path(__file__).parents[2] / "configs" / "models" / "fitgar-tiny.yaml"


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
    model.rel_std.copy_(torch.from_numpy(rel.std(0)))
    model.dist_mean.fill_(float(dist.mean()))
    model.dist_std.fill_(float(dist.std()))
    coarse = np.concatenate([np.sum((it["smooth"] - it["anchor"]) ** 2, -1) for it in items])
    detail = np.concatenate([np.sum((it["verts"] - it["smooth"]) ** 2, -1) for it in items])
    if model.coarse is None:  # one step: the detail generator predicts the whole displacement
        full = np.concatenate([np.sum((it["verts"] - it["anchor"]) ** 2, -1) for it in items])
        model.detail.output.scale.fill_(float(np.sqrt(full.mean())))
        return
    model.coarse.output.scale.fill_(float(np.sqrt(coarse.mean())))
    model.detail.output.scale.fill_(float(np.sqrt(detail.mean())))


def synthetic_store(path, body, seconds: float = 0.5):
    """A prepared multi-garment store laid out as ``configs/datasets/garments.yaml`` makes them, with the
    synthetic target instead of a simulation (no Blender): garment entries ``skirt+average``,
    ``skirt+heavy``, ``dress+average`` on two body shapes, motions ``walk`` and ``sway``; the dress
    sways in the test split, everything else trains."""
    import torch as _torch

    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.data.store import DatasetStore
    from loosefit.garment import make_garment
    from loosefit.geometry.lbs import linear_blend_skinning
    from loosefit.motion.procedural import generate
    from loosefit.models.fitgar_inputs import pose_motion
    from loosefit.rig.prepare import prepare

    store = DatasetStore.create(path)
    shapes = {"average": AnnyShape(), "heavy": AnnyShape(weight=0.85, height=0.3)}
    motions = {"walk": generate("walk", seconds, 0, body), "sway": generate("sway", seconds, 1, body)}
    for name, motion in motions.items():
        store.add_motion(name, motion)
    plan = [("skirt", "average", ["walk", "sway"]), ("skirt", "heavy", ["walk"]), ("dress", "average", ["walk", "sway"])]
    for kind, shape_name, motion_names in plan:
        shape = shapes[shape_name]
        fitted = body if shape == body.shape else AnnyBody(shape)
        store.add_body(shape_name, shape.to_array())
        garment = make_garment(kind, fitted, seed=0, edge_length=0.06)
        entry = f"{kind}+{shape_name}"
        store.add_garment(entry, garment)
        rest = fitted.rest_verts()
        nearest = np.linalg.norm(garment.verts[:, None] - rest[None], axis=-1).argmin(1)
        weights = _torch.from_numpy(fitted.skinning_weights()[nearest]).double()
        for m in motion_names:
            posed = pose_motion(fitted.rest_joints(), fitted.parents, motions[m])
            skinned = linear_blend_skinning(_torch.from_numpy(garment.verts).double(), weights,
                                            _torch.from_numpy(posed.transforms)).numpy()
            ripple = 0.01 * np.sin(25.0 * skinned[..., 2] + 3.0 * posed.pose[:, 6:].mean(1)[:, None])
            verts = skinned + np.stack([ripple, 0.5 * ripple, 0 * ripple], -1)
            split = "test" if (kind, m) == ("dress", "sway") else "train"
            store.write_sequence(f"{entry}+{m}+default", verts.astype(np.float32), garment=entry, body=shape_name,
                                 motion=m, sim_params={}, stats={}, split=split)
    prepare(path, bones=2, body=body, progress=False, iterations=2, transform_iterations=2, max_solve_frames=8,
            descriptor_samples=16)
    return path
