"""Training the body SDF network (SwinGar Eqs. 8-9) and measuring the margin it needs.

- :func:`sdf_samples`, :func:`body_sdf_samples`: points on, near and inside posed Anny bodies (the collision
  proxy), with their true signed distances and gradients, in each frame's canonical frame.
- :func:`sdf_loss`: SwinGar Eqs. 8-9 (``mu_e = 0.15``); :func:`train_body_sdf`: Adam on it.
- :func:`calibrate_margin`: the margin (ours, 0 in the paper) by which SwinGar Eq. 10 must move the network's
  surface outwards to catch a given share of the shallow collisions on poses it never saw.
- :func:`train_sdf_run`, :func:`calibrate_sdf_run`, :func:`collision_margin`: a run folder (``loosefit train
  --method collision``: :data:`SDF_FILE` and :data:`SDF_META`) and the margin read from it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from loosefit.errors import InputError
from loosefit.geometry.signed_distance import BodySDF
from loosefit.models.collision.fast_eval import flushed_denormals
from loosefit.models.collision.network import (BodySDFConfig, BodySDFNet, body_code, bone_frame_code, load_body_sdf,
                                               save_body_sdf)

#: Weight of the Eikonal term, ``mu_e`` of SwinGar Eq. 8.
EIKONAL_WEIGHT = 0.15

def sdf_loss(net: BodySDFNet, points: torch.Tensor, target: torch.Tensor, normals: torch.Tensor,
             code: torch.Tensor | None = None, eikonal: float = EIKONAL_WEIGHT) -> tuple[torch.Tensor, dict]:
    """SwinGar Eqs. 8-9 on ``points (N, 3)`` with true signed distances ``target (N,)`` and true gradients
    ``normals (N, 3)`` (unit): ``mean(|S - s| + |grad S - n|) + mu_e mean((|grad S| - 1)^2)``."""
    with torch.enable_grad():
        x = points.detach().requires_grad_(True)
        s = net(x, code)
        (g,) = torch.autograd.grad(s.sum(), x, create_graph=True)
    value = (s - target).abs().mean()  # SwinGar Eq. 8, value term
    normal = (g - normals).norm(dim=-1).mean()  # SwinGar Eq. 8, gradient term
    eik = ((g.norm(dim=-1) - 1) ** 2).mean()  # SwinGar Eq. 9
    terms = {"value": float(value.detach()), "normal": float(normal.detach()), "eikonal": float(eik.detach())}
    return value + normal + eikonal * eik, terms  # SwinGar Eq. 8


def sdf_samples(body: BodySDF, surface: int, near: int, inside: int, near_sigma: float = 0.02,
                seed: int = 0) -> dict[str, np.ndarray]:
    """Training points for the SDF network around one posed body: ``surface`` points on it, ``near`` points
    within about ``near_sigma`` metres of it, and ``inside`` points uniformly inside it.

    Returns ``points (N, 3)``, ``sdf (N,)`` (negative inside) and ``normals (N, 3)`` (the unit gradient of the
    true field: outward from the closest point; the face normal on the surface), float32.
    """
    rng = np.random.default_rng(seed)
    v, f = body.verts, body.faces
    tri = v[f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    n_on = surface + near
    face = rng.choice(len(f), n_on, p=area / area.sum())
    a, b = rng.random((2, n_on))
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    on = tri[face, 0] + a[:, None] * (tri[face, 1] - tri[face, 0]) + b[:, None] * (tri[face, 2] - tri[face, 0])
    on[surface:] += rng.normal(0.0, near_sigma, (near, 3))
    lo, hi = v.min(0), v.max(0)
    found = np.zeros((0, 3))
    for _ in range(100):
        if len(found) >= inside:
            break
        cand = rng.uniform(lo, hi, (max(4 * inside, 64), 3))
        found = np.concatenate([found, cand[body.query(cand) < 0]])
    points = np.concatenate([on, found[:inside]])
    dist, closest, fid = body.closest(points)  # SwinGar Eq. 7's s(x), negative inside here
    dist[:surface] = 0.0
    away = points - closest
    norm = np.linalg.norm(away, axis=1, keepdims=True)
    normals = np.where(norm > 1e-6, away / np.maximum(norm, 1e-12) * np.sign(dist)[:, None], body.face_normals[fid])
    normals[:surface] = body.face_normals[face[:surface]]
    return {"points": points.astype(np.float32), "sdf": dist.astype(np.float32), "normals": normals.astype(np.float32)}


@dataclass(frozen=True)
class SDFTrainConfig:
    """How :func:`train_body_sdf` samples posed bodies and fits the network.

    Attributes:
        frames: posed frames drawn from each (shape, motion) pair.
        random_shapes: Anny shapes drawn at random (:func:`random_anny_shapes`) beside the store's bodies, so
            that the network learns bodies no sequence has (SwinGar trains it on many bodies and poses).
        random_motions: procedural motions (:func:`random_procedural_motions`, ``random_motion_seconds`` long)
            beside the store's training motions (ours): poses no training sequence has, for a network that meets
            the poses of unseen motions.
        calibration_motions: procedural motions of a validation set (:func:`calibrate_margin`: the training
            bodies and 4 random ones, in poses no training sample has) on which ``loosefit train`` measures the
            margin the network needs (``--collision-margin auto``); 0: none.
        surface, near, inside: sample points per posed frame (:func:`sdf_samples`).
        near_sigma: metres. steps, lr, batch_frames: Adam steps, learning rate, frames per step. seed.
    """

    frames: int = 8
    random_shapes: int = 0
    random_motions: int = 0
    random_motion_seconds: float = 4.0
    calibration_motions: int = 6
    surface: int = 2048
    near: int = 2048
    inside: int = 512
    near_sigma: float = 0.02
    steps: int = 2000
    lr: float = 5e-4
    batch_frames: int = 4
    seed: int = 0


def random_anny_shapes(count: int, seed: int) -> list:
    """``count`` Anny shapes with every phenotype value drawn uniformly from ``[0.05, 0.95]`` (seeded)."""
    from loosefit.body import AnnyShape

    if count < 0:
        raise InputError(f"random_shapes must be >= 0, got {count}")
    values = np.random.default_rng(seed).uniform(0.05, 0.95, (count, len(AnnyShape.names())))
    return [AnnyShape.from_array(v) for v in values]


def random_procedural_motions(count: int, seed: int, body, seconds: float = 4.0) -> list:
    """``count`` procedural motions of ``body`` (:func:`~loosefit.motion.procedural.generate`), every kind in
    turn from one picked by ``seed``, each with its own seed from ``1000 + seed`` on (far from the seeds of the
    dataset plans' motions)."""
    from loosefit.motion.procedural import KINDS, generate

    if count < 0:
        raise InputError(f"random_motions must be >= 0, got {count}")
    return [generate(KINDS[(seed + k) % len(KINDS)], seconds, 1000 + seed + k, body) for k in range(count)]


def body_sdf_samples(shapes, motions, config: SDFTrainConfig) -> dict[str, np.ndarray]:
    """Samples of many posed Anny bodies (the collision proxy), canonical: ``points (P, N, 3)``, ``sdf (P, N)``,
    ``normals (P, N, 3)``, ``code (P, C)`` and ``bones (P, 12 J)`` (:func:`bone_frame_code`) for ``P`` posed
    frames (``config.frames`` per shape and motion)."""
    from loosefit.body import AnnyBody
    from loosefit.models.motion_features import motion_features
    from loosefit.motion.heading import heading_frames, to_canonical

    rng = np.random.default_rng(config.seed)
    out: dict[str, list] = {"points": [], "sdf": [], "normals": [], "code": [], "bones": []}
    for shape in shapes:
        proxy = AnnyBody(shape, resolution="low")
        for motion in motions:
            feats = motion_features(motion)
            rot, origin = heading_frames(motion)
            frames = np.sort(rng.choice(motion.num_frames, min(config.frames, motion.num_frames), replace=False))
            posed_body = proxy.pose(motion)
            posed = to_canonical(posed_body.verts[frames], rot[frames], origin[frames])
            code = body_code(shape.to_array(), feats["root"][frames], feats["joints"][frames])
            bones = bone_frame_code(posed_body.joint_transforms[frames], rot[frames], origin[frames])
            for k, verts in enumerate(posed):
                s = sdf_samples(BodySDF(verts, proxy.faces), config.surface, config.near, config.inside,
                                config.near_sigma, seed=int(rng.integers(2**31)))
                for key in ("points", "sdf", "normals"):
                    out[key].append(s[key])
                out["code"].append(code[k])
                out["bones"].append(bones[k])
    return {k: np.stack(v) for k, v in out.items()}


def samples_code(samples: dict[str, np.ndarray], bone_frames: bool) -> np.ndarray:
    """The network codes ``(P, C)`` of :func:`body_sdf_samples`: ``code``, then with ``bone_frames`` ``bones``."""
    return np.concatenate([samples["code"], samples["bones"]], 1) if bone_frames else samples["code"]


def train_body_sdf(samples: dict[str, np.ndarray], config: SDFTrainConfig = SDFTrainConfig(),
                   net_config: BodySDFConfig = BodySDFConfig(), progress: bool = False) -> tuple[BodySDFNet, list]:
    """Fit a :class:`BodySDFNet` to :func:`body_sdf_samples` with SwinGar Eqs. 8-9 (Adam). Returns the network
    and the loss per step."""
    torch.manual_seed(config.seed)
    pts, sdf, nrm = (torch.from_numpy(samples[k]) for k in ("points", "sdf", "normals"))
    code = torch.from_numpy(samples_code(samples, net_config.bone_frames))
    num_bones = samples["bones"].shape[1] // 12 if net_config.bone_frames else 0
    net = BodySDFNet(code.shape[1], net_config, num_bones)
    opt = torch.optim.Adam(net.parameters(), config.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, config.steps)
    gen = torch.Generator().manual_seed(config.seed)
    history = []
    with flushed_denormals():  # as at inference: Softplus(beta=100) makes denormals, slow on x86 (~10 % a step)
        for step in range(config.steps):
            pick = torch.randperm(len(pts), generator=gen)[:config.batch_frames]
            loss, terms = sdf_loss(net, pts[pick], sdf[pick], nrm[pick], code[pick])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            history.append(float(loss.detach()))
            if progress and step % 100 == 0:
                print(f"step {step}: loss {history[-1]:.4g} {terms}")
    return net, history


#: The files of a body SDF run folder (``loosefit train --method collision``).
SDF_FILE, SDF_META = "body_sdf.pt", "model.json"


#: The share of inside points of a validation set that the calibrated margin catches (:func:`calibrate_margin`).
CALIBRATION_QUANTILE = 0.8


def calibrate_margin(net: BodySDFNet, shapes, motions, quantile: float = CALIBRATION_QUANTILE, depth: float = 0.02,
                     frames: int = 4, points: int = 2000, seed: int = 11) -> dict:
    """The margin (metres) the network needs on poses it never saw: posed Anny bodies of ``shapes`` along
    ``motions`` (``frames`` each), points within ``depth`` inside them (libigl's distance), and the value below
    which the network puts ``quantile`` of those points. With that margin (:meth:`BoundBodySDF.offset`),
    SwinGar Eq. 10 corrects that share of the shallow collisions on such poses; without one, only those the
    network calls inside (``caught_without_margin``).

    Returns ``{"margin_m", "quantile", "depth_m", "inside_points", "caught_without_margin", "caught_at_10mm"}``.
    """
    if not 0 < quantile < 1:
        raise InputError(f"the calibration quantile must be in (0, 1), got {quantile}")
    config = SDFTrainConfig(frames=frames, surface=0, near=points, inside=0, near_sigma=depth / 2, seed=seed)
    samples = body_sdf_samples(shapes, motions, config)
    values = []
    for pts, sdf, code in zip(samples["points"], samples["sdf"], samples_code(samples, net.num_bones > 0)):
        inside = (sdf < 0) & (sdf > -depth)
        with torch.no_grad():
            values.append(net.bind(torch.from_numpy(code))(torch.from_numpy(pts[inside])).numpy())
    v = np.concatenate(values).astype(np.float64)
    if not len(v):
        raise InputError("margin calibration found no point inside the bodies")
    return {"margin_m": float(max(np.quantile(v, quantile), 0.0)), "quantile": quantile, "depth_m": depth,
            "inside_points": int(len(v)), "caught_without_margin": float((v < 0).mean()),
            "caught_at_10mm": float((v < 0.01).mean())}


def calibration_set(shapes, config: SDFTrainConfig) -> tuple[list, list]:
    """The validation set of :func:`calibrate_margin` for a network trained on ``shapes`` (the store's bodies):
    those and 4 random Anny shapes, in ``config.calibration_motions`` procedural motions whose seeds no training
    motion has (:func:`random_procedural_motions`)."""
    from loosefit.body import AnnyBody

    return (list(shapes) + random_anny_shapes(4, config.seed + 99),
            random_procedural_motions(config.calibration_motions, config.seed + 4000, AnnyBody(),
                                      config.random_motion_seconds))


def calibrate_sdf_run(sdf_run) -> dict:
    """:func:`calibrate_margin` for a trained run folder (one trained before runs measured it): its network on
    the validation set of its config and store bodies; the result is added to its ``model.json``."""
    import json
    from pathlib import Path

    from loosefit.body import AnnyShape
    from loosefit.data.store import DatasetStore
    from loosefit.paths import atomic_path

    meta, summary = _sdf_summary(sdf_run)
    try:
        fields = SDFTrainConfig.__dataclass_fields__
        config = SDFTrainConfig(**{k: v for k, v in summary["config"].items() if k in fields})
        store = DatasetStore.open(summary["data"], mode="r")
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise InputError(f"cannot read the body SDF run's summary: {e}", meta) from None
    config = SDFTrainConfig(**{**vars(config), "calibration_motions": config.calibration_motions or 6})
    shapes = [AnnyShape.from_array(store.body(b)) for b in summary["bodies"]]
    summary["calibration"] = calibrate_margin(load_body_sdf(Path(sdf_run) / SDF_FILE), *calibration_set(shapes, config))
    with atomic_path(meta) as tmp:
        tmp.write_text(json.dumps(summary, indent=2))
    return summary["calibration"]


def _sdf_summary(sdf_run) -> tuple:
    """``(path, dict)`` of a body SDF run folder's ``model.json``; an unreadable one is an :class:`InputError`."""
    import json
    from pathlib import Path

    meta = Path(sdf_run) / SDF_META
    try:
        summary = json.loads(meta.read_text())
        if not isinstance(summary, dict):
            raise ValueError("not a JSON object")
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read the body SDF run's summary: {e}", meta) from None
    return meta, summary


def collision_margin(sdf_run, value: str | float) -> float:
    """The margin of ``loosefit animate --collision-margin``: metres, or ``"auto"``: the one
    :func:`calibrate_margin` measured when the network of run folder ``sdf_run`` was trained."""
    if str(value).strip().lower() == "auto":
        if sdf_run is None:
            raise InputError("--collision-margin auto needs a body SDF run")
        meta, summary = _sdf_summary(sdf_run)
        calibration = summary.get("calibration")
        if not calibration or "margin_m" not in calibration:
            raise InputError("this body SDF run has no calibrated margin (trained with train.calibration_motions=0 "
                             "or by an older loosefit): give the margin in metres", meta)
        return float(calibration["margin_m"])
    try:
        margin = float(value)
    except (TypeError, ValueError):
        raise InputError(f"--collision-margin must be metres or 'auto', got {value!r}") from None
    if not (np.isfinite(margin) and margin >= 0):
        raise InputError(f"--collision-margin must be a non-negative number of metres, got {value!r}")
    return margin


@dataclass(frozen=True)
class SDFRunConfig:
    """What ``loosefit train --method collision`` reads: ``train`` (:class:`SDFTrainConfig`) and ``net``
    (:class:`BodySDFConfig`), e.g. ``--set train.steps=500 --set net.hidden=256``."""

    train: SDFTrainConfig = SDFTrainConfig()
    net: BodySDFConfig = BodySDFConfig()


def train_sdf_run(data, out, run_config: SDFRunConfig = SDFRunConfig(), progress: bool = True) -> dict:
    """``loosefit train --method collision``: fit the body SDF network on every body shape and training motion
    of a dataset store (the collision proxy of each, canonical); write ``out/body_sdf.pt`` and ``out/model.json``.
    Returns the summary written to ``model.json``."""
    import json
    from pathlib import Path

    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.data.store import DatasetStore
    from loosefit.paths import atomic_path

    store = DatasetStore.open(data, mode="r")
    train = store.sequence_names(split="train")
    bodies = sorted({store.sequence(n).body for n in train})
    motions = sorted({store.sequence(n).motion for n in train})
    if not bodies or not motions:
        raise InputError("no training sequences: the body SDF trains on their bodies and motions", store.path)
    config, net_config = run_config.train, run_config.net
    shapes = [AnnyShape.from_array(store.body(b)) for b in bodies]
    shapes += random_anny_shapes(config.random_shapes, config.seed + 1)
    extra = random_procedural_motions(config.random_motions, config.seed + 2, AnnyBody(),
                                      config.random_motion_seconds) if config.random_motions else []
    samples = body_sdf_samples(shapes, [store.motion(m) for m in motions] + extra, config)
    net, history = train_body_sdf(samples, config, net_config, progress)
    calibration = calibrate_margin(net.eval(), *calibration_set(shapes[:len(bodies)], config)) \
        if config.calibration_motions else None
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    save_body_sdf(out / SDF_FILE, net)
    summary = {"method": "collision", "data": str(Path(data).resolve()), "bodies": bodies,
               "random_shapes": [s.to_array().tolist() for s in shapes[len(bodies):]], "motions": motions,
               "random_motions": [m.name for m in extra], "calibration": calibration,
               "frames": int(len(samples["code"])), "first_loss": history[0] if history else None,
               "final_loss": history[-1] if history else None,
               "config": dict(vars(config)), "net": dict(vars(net_config))}
    with atomic_path(out / SDF_META) as tmp:
        tmp.write_text(json.dumps(summary, indent=2))
    return summary
