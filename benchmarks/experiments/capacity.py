"""Can a method fit what it has seen? Anchor sharing, memorisation and a small scale curve.

Seven measurements, each a section of one JSON (``benchmarks/results/<name>.json``; a section run again
replaces only itself, so the sections can be run one at a time):

1. ``anchors`` (FitGar, no store needed): ``shared_anchor_fraction`` of the seed-0 template of every kind
   (skirt, dress, long_shirt, jumpsuit) at ``--edge-length`` (3 cm) on the average Anny body, for each
   anchor (:data:`loosefit.models.fitgar_inputs.ANCHOR_MODES`): the share of garment vertices whose rest
   anchor another vertex's is within 1 mm of, and the largest group of such vertices; beside them the closest
   vertex of the body subdivided once (the paper's way, FitGar Sec. 5.1);
2. ``memorise`` (``--method``, :data:`MEMORISE`): the method trained on a handful of training frames
   (``--samples`` spread over ``--sequences``) with the whole handful as one batch, and its error on exactly
   those frames after each of ``--steps`` steps. FitGar: its coarse stage then its detail stage (coarse
   frozen), mean per-vertex errors in mm of the coarse mesh against its target (the ``fitgar``-smoothed
   simulation) and of the detail mesh against the simulation; beside them what no training can change: the
   error of the anchors alone (a zero displacement) and the error of the best displacement that is one
   value per group of vertices sharing an anchor (a network that reads a node's own features alone can do
   no better);
3. ``scale`` (FitGar): trained on every ``k``-th training frame (``--strides``, e.g. 8, 4, 2: x1, x2, x4
   samples) of ``--sequences`` in minibatches of ``--batch``, the coarse and detail errors on the training frames
   used and on every ``--test-stride``-th frame of the test sequences of the same garments, after each of
   ``--scale-checkpoints`` steps of the coarse stage and at the end of ``--detail-steps`` detail steps (as many
   as the last checkpoint unless given)
   (``--save-run DIR``: the trained model kept as a run folder, to animate and render);
4. ``twins`` (FitGar's data): is the garment a function of the pose? (:func:`pose_twins`);
5. ``lookup`` (FitGar's data): the held-out coarse error of no learning at all, a lookup of the nearest training
   pose, beside the anchors and their mean displacement (:func:`pose_lookup`);
6. ``repeats`` (FitGar's data): where one pose was simulated many times (the rests of a ``from_rest`` plan), the
   floor of any function of the pose: the drapes' spread about their mean (:func:`pose_repeats`);
7. ``against-mean`` (a saved FitGar run): its held-out errors against the base run and against the mean drape of
   each held-out pose over its runs (other paths, perturbed starts), beside their floor (:func:`against_mean`).

Every run uses one torch thread (``--device cuda`` trains on a GPU, same widths and steps), the config file's
widths (``configs/models/fitgar-cpu.yaml`` by default), its learning rate and gradient clip (``--set train.lr=...``
and model keys override), Adam, seed 0.

Run:
    .venv/bin/python benchmarks/experiments/capacity.py anchors --name capacity-fitgar
    .venv/bin/python benchmarks/experiments/capacity.py memorise --method fitgar --data S.zarr \
        --sequences skirt-0+average+walk+default \
        --samples 4 --steps 50,100,200,400 --anchor surface --label surface --name capacity-fitgar
    .venv/bin/python benchmarks/experiments/capacity.py scale --data S.zarr --strides 8,4,2 --name capacity-fitgar
    .venv/bin/python benchmarks/experiments/capacity.py twins --data S.zarr --name capacity-fitgar
    .venv/bin/python benchmarks/experiments/capacity.py lookup --data FS.zarr --strides 8,2 --test-stride 12 --anchor spread \
        --label fitgar-static --name capacity-fitgar
(the conclusions are in benchmarks/experiments/LOG.md, "FitGar: data, capacity and the detail generator")
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts
from _common import RESULTS, save_results  # noqa: E402

from loosefit.config import load_config  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.models.fitgar import Config, FitGar  # noqa: E402
from loosefit.models.fitgar_data import GarmentFrames, collate_frames  # noqa: E402
from loosefit.training import save_trained_frames_run  # noqa: E402
from loosefit.models.fitgar_inputs import ANCHOR_MODES, GarmentBodyPair, shared_anchor_fraction  # noqa: E402
from loosefit.train.protocol import to_device  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
KINDS = ("skirt", "dress", "long_shirt", "jumpsuit")
#: Where the networks train (``--device``; the widths and steps do not depend on it).
DEVICE = torch.device("cpu")


# ---------------------------------------------------------------------- anchors

def subdivided_sharing(garment_verts: np.ndarray, body) -> dict:
    """The paper's way (FitGar Sec. 5.1), for comparison: the closest vertex of the body subdivided once (each
    triangle into four at its edge midpoints); the same statistics as :func:`shared_anchor_fraction`."""
    import igl
    from scipy.spatial import cKDTree

    verts, _ = igl.upsample(body.rest_verts().astype(np.float64), np.asarray(body.faces, np.int64))
    nearest = cKDTree(verts).query(garment_verts)[1]
    count = np.bincount(nearest)
    return {"fraction": float((count[nearest] > 1).mean()), "largest": int(count.max()),
            "vertices": int(len(garment_verts)), "body_vertices": int(len(verts))}


def anchor_sharing(edge_length: float = 0.03, seed: int = 0, kinds=KINDS) -> dict:
    """``{kind: {anchor: {"fraction", "largest", "vertices"}}}`` for the templates on the average Anny body, and
    ``subdivided_vertex`` (:func:`subdivided_sharing`)."""
    from loosefit.body import AnnyBody
    from loosefit.garment import make_garment

    body = AnnyBody()
    out = {}
    for kind in kinds:
        garment = make_garment(kind, body, seed=seed, edge_length=edge_length)
        out[kind] = {}
        pairs = {}
        for anchor in ANCHOR_MODES:
            pairs[anchor] = pair = GarmentBodyPair.build(garment.verts, garment.faces, body, body.shape.to_array(),
                                                         np.zeros(1), anchor=anchor)
            out[kind][anchor] = shared_anchor_fraction(pair)
            if anchor == "spread":  # how far the spreading moved anchors from their projection along the normals
                move = np.linalg.norm(pair.rest_anchors() - pairs["normal"].rest_anchors(), axis=1)
                out[kind][anchor].update(moved=int((move > 0).sum()), largest_move_mm=float(move.max() * 1e3))
            print(f"{kind} {anchor}: {out[kind][anchor]}", flush=True)
        out[kind]["subdivided_vertex"] = subdivided_sharing(garment.verts, body)
        print(f"{kind} subdivided_vertex: {out[kind]['subdivided_vertex']}", flush=True)
    return out


# ---------------------------------------------------------------------- FitGar training pieces

def fitgar_model(data: GarmentFrames, config: Path, overrides) -> tuple[FitGar, Config]:
    cfg = load_config(Config, config, overrides)
    torch.manual_seed(cfg.train.seed)
    np.random.seed(cfg.train.seed)
    return FitGar.from_data(data, cfg.model).to(DEVICE), cfg


def distance_mm(a: np.ndarray, b: np.ndarray) -> float:
    """Mean per-vertex distance, mm, of two meshes ``(..., V, 3)`` metres (broadcast)."""
    return float(np.linalg.norm(a - b, axis=-1).mean() * 1e3)


def errors_mm(model: FitGar, batches: list[dict]) -> dict[str, float]:
    """Mean per-vertex errors (mm) over the frames of ``batches``: ``coarse_mm`` (coarse against the smoothed
    simulation), ``coarse_sim_mm`` and ``detail_mm`` (against the simulation), weighted by vertex count."""
    device = next(model.parameters()).device
    sums = {"coarse_mm": 0.0, "coarse_sim_mm": 0.0, "detail_mm": 0.0}
    n = 0
    model.eval()
    with torch.no_grad():
        for b in batches:
            b = to_device(b, device)
            out = model(b)
            k = len(b["verts"])
            sums["coarse_mm"] += float((out["coarse"] - b["smooth"]).norm(dim=-1).sum()) * 1e3
            sums["coarse_sim_mm"] += float((out["coarse"] - b["verts"]).norm(dim=-1).sum()) * 1e3
            sums["detail_mm"] += float((out["verts"] - b["verts"]).norm(dim=-1).sum()) * 1e3
            n += k
    model.train()
    return {key: value / n for key, value in sums.items()}


def reference_floors(data: GarmentFrames, indices, batches: list[dict]) -> dict[str, float]:
    """What training cannot change, mm: ``zero_displacement_mm`` (the anchors against the coarse target) and
    ``anchor_group_floor_mm`` (the best displacement that is constant over each group of vertices sharing an
    anchor, frame by frame: its group's mean target)."""
    zero, floor, n = 0.0, 0.0, 0
    frames = [data[int(k)] for k in indices]
    for k, item in zip(indices, frames):
        pair = data.pairs[data.sequences[data.index[int(k)][0]]["pair"]]
        target = item["smooth"] - item["anchor"]
        zero += float(np.linalg.norm(target, axis=1).sum())
        # groups: vertices whose rest anchors coincide to 1 mm (rounded positions, as shared_anchor_fraction)
        _, group = np.unique(np.round(pair.rest_anchors() / 1e-3).astype(np.int64), axis=0, return_inverse=True)
        group = group.reshape(-1)
        sums = np.zeros((group.max() + 1, 3))
        np.add.at(sums, group, target)
        mean = sums / np.bincount(group)[:, None]
        floor += float(np.linalg.norm(target - mean[group], axis=1).sum())
        n += len(target)
    return {"zero_displacement_mm": zero / n * 1e3, "anchor_group_floor_mm": floor / n * 1e3}


def train_stage(model: FitGar, stage: str, batches: list[dict], steps: int, lr: float, clip: float,
                checkpoints, evaluate, log: list) -> None:
    """``steps`` Adam steps of ``stage`` cycling over ``batches``; ``evaluate()`` appended to ``log`` at each
    step count in ``checkpoints``."""
    params = list(model.stage_parameters(stage))
    for p in model.parameters():
        p.requires_grad_(False)
    for p in params:
        p.requires_grad_(True)
    opt = torch.optim.Adam(params, lr=lr)
    start = time.perf_counter()
    for step in range(1, steps + 1):
        loss, terms = model.training_loss(to_device(batches[(step - 1) % len(batches)], params[0].device), stage)
        opt.zero_grad()
        loss.backward()
        if clip:
            torch.nn.utils.clip_grad_norm_(params, clip)
        opt.step()
        if step in checkpoints:
            row = {"stage": stage, "step": step, "loss": float(loss.detach()), "seconds": time.perf_counter() - start,
                   **evaluate()}
            log.append(row)
            print(row, flush=True)


def dead_magnitude_fraction(model: FitGar, batch: dict) -> float:
    """Share of the coarse generator's output vertices whose magnitude is exactly zero (ReLU closed)."""
    with torch.no_grad():
        seen = {}
        hook = model.coarse.output.magnitude.register_forward_hook(lambda m, i, o: seen.setdefault("m", o))
        model.coarse_displacement(to_device(batch, DEVICE))
        hook.remove()
    return float((seen["m"] <= 0).float().mean())


# ---------------------------------------------------------------------- memorise

def fitgar_memorise(args) -> dict:
    """Section 2 for FitGar (see the module docstring)."""
    names = args.sequences.split(",") if args.sequences else None
    data = GarmentFrames(args.data, "train", names=names, anchor=args.anchor)
    picks = np.unique(np.linspace(0, len(data) - 1, args.samples).round().astype(int))
    model, cfg = fitgar_model(data, args.config, args.set or [])
    batch = to_device(collate_frames([data[int(k)] for k in picks]), DEVICE)
    steps = sorted(int(s) for s in args.steps.split(","))
    log: list = []
    evaluate = lambda: errors_mm(model, [batch])  # noqa: E731
    train_stage(model, "coarse", [batch], steps[-1], cfg.train.lr, cfg.train.grad_clip, set(steps), evaluate, log)
    dead = dead_magnitude_fraction(model, batch)
    train_stage(model, "detail", [batch], steps[-1], cfg.train.lr, cfg.train.grad_clip, set(steps), evaluate, log)
    return {"method": "fitgar", "anchor": args.anchor, "config": str(args.config), "overrides": args.set or [],
            "sequences": data.sequence_names, "samples": [list(map(int, data.index[int(k)])) for k in picks],
            "vertices": int(batch["counts"].sum()), "lr": cfg.train.lr, "steps": log,
            "dead_coarse_magnitude_fraction": dead, **reference_floors(data, picks, [batch])}


#: Memorisation per method: ``function(args) -> dict`` (a SwinGar entry is added beside FitGar's).
MEMORISE = {"fitgar": fitgar_memorise}


# ---------------------------------------------------------------------- scale

def batches_of(data: GarmentFrames, indices, size: int) -> list[dict]:
    return [to_device(collate_frames([data[int(k)] for k in indices[i:i + size]]), DEVICE)
            for i in range(0, len(indices), size)]


def fitgar_scale(args, save=None) -> dict:
    """Section 3 (see the module docstring); ``save(result)`` after each training size, when given."""
    rows = []
    store = DatasetStore.open(args.data, mode="r")
    garments = None if not args.sequences else {store.sequence(n).garment for n in args.sequences.split(",")}
    tests = [n for n in store.sequence_names(split="test") if garments is None or store.sequence(n).garment in garments]
    test = GarmentFrames(store, "test", names=tests, anchor=args.anchor, frame_stride=args.test_stride,
                         frame_offset=args.frame_offset)
    test_batches = batches_of(test, np.arange(len(test)), 8)
    checkpoints = sorted(int(s) for s in args.scale_checkpoints.split(","))
    if args.save_run and "," in args.strides:
        raise SystemExit("capacity.py scale: --save-run keeps one model: give one --strides")
    for stride in (int(s) for s in args.strides.split(",")):
        names = args.sequences.split(",") if args.sequences else None
        data = GarmentFrames(args.data, "train", names=names, anchor=args.anchor, frame_stride=stride,
                             frame_offset=args.frame_offset)
        model, cfg = fitgar_model(data, args.config, args.set or [])
        rng = np.random.default_rng(0)
        order = rng.permutation(len(data))
        batches = batches_of(data, order, args.batch)
        seen = batches_of(data, np.arange(len(data)), 8)
        log: list = []
        evaluate = lambda: {**{f"train_{k}": v for k, v in errors_mm(model, seen).items()},  # noqa: E731
                            **{f"test_{k}": v for k, v in errors_mm(model, test_batches).items()}}
        steps, detail_steps = checkpoints[-1], args.detail_steps or checkpoints[-1]
        train_stage(model, "coarse", batches, steps, cfg.train.lr, cfg.train.grad_clip, set(checkpoints), evaluate, log)
        train_stage(model, "detail", batches, detail_steps, cfg.train.lr, cfg.train.grad_clip, {detail_steps},
                    evaluate, log)
        if args.save_run:
            save_trained_frames_run(args.save_run, "fitgar", model.cpu(), cfg, data, args.data)
        rows.append({"frame_stride": stride, "samples": len(data), "sequences": data.sequence_names,
                     "batch": args.batch,
                     "steps": log})
        if save is not None:
            save(scale_result(args, test, test_batches, rows))
    return scale_result(args, test, test_batches, rows)


def scale_result(args, test: GarmentFrames, test_batches: list[dict], rows: list[dict]) -> dict:
    return {"method": "fitgar", "anchor": args.anchor, "config": str(args.config), "overrides": args.set or [],
            "test_sequences": test.sequence_names,
            "test_frames": int(sum(len(b["counts"]) for b in test_batches)), "test_stride": args.test_stride,
            "frame_offset": args.frame_offset,
            "curve": rows}


# ---------------------------------------------------------------------- pose twins

def pose_twins(args) -> dict:
    """Is the garment a function of the pose? Per sequence (every 3rd frame): for each frame, the frame at least
    ``--twin-gap`` frames away whose pose features (FitGar's ``theta`` and the root joint's canonical position) are
    closest; the mean per-vertex distance (mm) between their ``fitgar``-smoothed garments, and that pose distance."""
    data = GarmentFrames(args.data, None, frame_stride=3, anchor=args.anchor)
    by: dict = {}
    for k, (i, t) in enumerate(data.index):
        by.setdefault(data.sequences[i]["name"], []).append(k)
    out = {}
    for name, ks in by.items():
        items = [data[k] for k in ks]
        pose = np.stack([np.concatenate([it["pose"], it["joints"][0]]) for it in items])
        smooth = np.stack([it["smooth"] for it in items])
        gap, garment = [], []
        for a in range(len(items)):
            far = [b for b in range(len(items)) if abs(b - a) * 3 >= args.twin_gap]
            d = np.linalg.norm(pose[far] - pose[a], axis=1)
            b = far[int(d.argmin())]
            gap.append(float(d.min()))
            garment.append(float(np.linalg.norm(smooth[a] - smooth[b], axis=1).mean() * 1e3))
        out[name] = {"frames": len(items), "pose_distance_median": float(np.median(gap)),
                     "garment_difference_mm": float(np.mean(garment))}
        print(name, out[name], flush=True)
    return {"twin_gap": args.twin_gap, "sequences": out}


def pose_lookup(args) -> dict:
    """What a held-out coarse error can be read against: per garment, on every ``--test-stride``-th test frame,
    the mean per-vertex distance (mm) to the coarse target of the anchors alone (``anchors``), the anchors plus
    the training frames' mean displacement (``mean_displacement``), and the anchors plus the displacement of the
    training frame (every ``k``-th, ``--strides``, of ``--sequences`` or all) whose pose ``theta`` is nearest
    (``nearest_pose``: a lookup, no learning); beside them the simulation's distance to its own coarse target
    (``detail_magnitude``, what a detail generator adds). ``all``: the same means over every garment's vertices."""
    test = GarmentFrames(args.data, "test", frame_stride=args.test_stride, frame_offset=args.frame_offset,
                         anchor=args.anchor)
    out: dict = {}
    for stride in (int(s) for s in args.strides.split(",")):
        train = GarmentFrames(args.data, "train", frame_stride=stride, frame_offset=args.frame_offset,
                              anchor=args.anchor,
                              names=args.sequences.split(",") if args.sequences else None)
        frames: dict = {}
        for k, (i, _) in enumerate(train.index):
            it = train[k]
            frames.setdefault(train.sequences[i]["garment"], []).append((it["pose"], it["smooth"] - it["anchor"]))
        # per garment: the training poses (n, P) and displacements (n, V, 3)
        seen = {g: tuple(np.stack(column) for column in zip(*pairs)) for g, pairs in frames.items()}
        rows, totals, n = {}, {}, 0
        for k, (i, _) in enumerate(test.index):
            garment, it = test.sequences[i]["garment"], test[k]
            poses, disp = seen[garment]
            nearest = disp[int(((poses - it["pose"]) ** 2).sum(1).argmin())]
            errors = {"anchors": it["anchor"], "mean_displacement": it["anchor"] + disp.mean(0),
                      "nearest_pose": it["anchor"] + nearest, "detail_magnitude": it["verts"]}
            row = rows.setdefault(garment, {"frames": 0, "training_frames": len(disp)})
            row["frames"] += 1
            for key, pred in errors.items():
                total = float(np.linalg.norm(pred - it["smooth"], axis=1).sum() * 1e3)
                row[key] = row.get(key, 0.0) + total / len(pred)
                totals[key] = totals.get(key, 0.0) + total
            n += len(it["smooth"])
        for row in rows.values():
            for key in totals:
                row[key] /= row["frames"]
        rows["all"] = {key: value / n for key, value in totals.items()}
        out[f"stride-{stride}"] = rows
        print(f"stride {stride}:", json.dumps(rows), flush=True)
    return {"test_stride": args.test_stride, "frame_offset": args.frame_offset, "anchor": args.anchor,
            "by_training_stride": out}


def pose_repeats(args) -> dict:
    """The floor of any function of the pose, where one pose is simulated many times: the frames every ``--strides``
    from ``--frame-offset`` of each sequence must all be one pose (the settled rests of a ``from_rest`` plan:
    stride = frames a key, offset = half of it, minus 1), told apart only by the path the cloth took. Per sequence
    (mean per-vertex distances, mm, in the heading frame): ``detail_floor`` the simulated drapes to their mean (what
    the best function of the pose misses of the simulation), ``coarse_floor`` the smoothed drapes to their mean (of
    the coarse target), ``coarse_sim_floor`` the smoothed mean to the simulated drapes (the best coarse mesh against
    the simulation), ``detail_magnitude`` each drape to its own smoothing, and ``pose_spread`` the largest distance
    of a frame's pose ``theta`` from the first one's (zero for true repeats). ``all``: the sequences' means."""
    stride = int(args.strides.split(",")[0])
    data = GarmentFrames(args.data, None, frame_stride=stride, frame_offset=args.frame_offset, anchor=args.anchor,
                         names=args.sequences.split(",") if args.sequences else None)
    by: dict = {}
    for k, (i, _) in enumerate(data.index):
        by.setdefault(data.sequences[i]["name"], []).append(data[k])
    out = {}
    for name, items in by.items():
        raw, smooth = np.stack([it["verts"] for it in items]), np.stack([it["smooth"] for it in items])
        pose = np.stack([it["pose"] for it in items])
        row = {"frames": len(items), "pose_spread": float(np.abs(pose - pose[0]).max()),
               "detail_floor": distance_mm(raw, raw.mean(0)), "coarse_floor": distance_mm(smooth, smooth.mean(0)),
               "coarse_sim_floor": distance_mm(raw, smooth.mean(0)), "detail_magnitude": distance_mm(raw, smooth)}
        row["detail_over_coarse_floor"] = row["detail_floor"] / row["coarse_sim_floor"]
        out[name] = row
        print(name, json.dumps({k: round(v, 3) for k, v in row.items()}), flush=True)
    out["all"] = {key: float(np.mean([row[key] for row in out.values()])) for key in next(iter(out.values()))}
    print("all", json.dumps({k: round(v, 3) for k, v in out["all"].items()}), flush=True)
    return {"frame_stride": stride, "frame_offset": args.frame_offset, "anchor": args.anchor, "sequences": out}


def against_mean(args) -> dict:
    """A saved FitGar run (``--run``, e.g. from ``scale --save-run``) on every ``--test-stride``-th frame from
    ``--frame-offset`` of the test sequences, scored against the base run as everywhere above and against the mean
    drape of its pose (:mod:`loosefit.metrics.reference`: a network trained on single chaotic runs learns their
    mean). The mean of a pose is over every run of it in the test split: each test frame with that pose ``theta``
    (the same key visited along other paths: ``hold.order_seed``) and their sequences' perturbed reference runs
    (the plan's ``references``). Mean per-vertex distances, mm, in the heading frame: ``coarse`` (against the
    smoothed base, or the smoothed mean), ``coarse_sim`` (against the base, or the mean), ``detail`` (the same);
    ``floor_detail`` the runs' distance to their mean and ``floor_coarse`` that of their smoothings (what no
    deterministic model removes from the base figures)."""
    from loosefit.animate import load_run
    from loosefit.motion.heading import to_canonical

    store = DatasetStore.open(args.data, mode="r")
    _, model, _ = load_run(args.run, checkpoint="last")
    model.to(DEVICE).eval()
    test = GarmentFrames(store, "test", anchor=args.anchor, frame_stride=args.test_stride,
                         frame_offset=args.frame_offset)
    runs = [np.concatenate([s["verts"][None], store.references(s["name"])]) for s in test.sequences]  # (N, T, V, 3)
    items, groups = [], {}
    for k, (i, t) in enumerate(test.index):
        item, seq = test[k], test.sequences[i]
        posed = test._posed[seq["pose"]][t:t + 1]
        n = len(runs[i])
        canonical = to_canonical(runs[i][:, t], np.repeat(posed.rot, n, 0), np.repeat(posed.origin, n, 0))
        assert np.allclose(canonical[0], item["verts"], atol=1e-6), "the base run in another frame"
        key = (seq["garment"], np.round(item["pose"], 4).tobytes())
        groups.setdefault(key, []).append(canonical)
        items.append((item, key))
    runs_of, means, smooth_means, floor_detail, floor_coarse = [], {}, {}, [], []
    for key, members in groups.items():  # each pose's runs: their mean, its smoothing, their spread about it
        every, smoother = np.concatenate(members), test.smoothers[key[0]]
        means[key], smooth_means[key] = every.mean(0), smoother(every.mean(0))
        runs_of.append(len(every))
        floor_detail.append(distance_mm(every, means[key]))
        floor_coarse.append(distance_mm(smoother(every), smooth_means[key]))
    sums: dict = {}
    with torch.no_grad():
        for item, key in items:
            mean, smooth_mean = means[key], smooth_means[key]
            out = model(to_device(collate_frames([item]), DEVICE))
            coarse, detail = out["coarse"].cpu().numpy(), out["verts"].cpu().numpy()
            row = {"coarse_mm": distance_mm(coarse, item["smooth"]),
                   "coarse_mean_mm": distance_mm(coarse, smooth_mean),
                   "coarse_sim_mm": distance_mm(coarse, item["verts"]), "coarse_sim_mean_mm": distance_mm(coarse, mean),
                   "detail_mm": distance_mm(detail, item["verts"]), "detail_mean_mm": distance_mm(detail, mean)}
            for name, value in row.items():
                sums[name] = sums.get(name, 0.0) + value / len(items)
    sums["floor_detail_mm"], sums["floor_coarse_mm"] = float(np.mean(floor_detail)), float(np.mean(floor_coarse))
    sums["detail_over_coarse"] = sums["detail_mm"] / sums["coarse_sim_mm"]
    sums["detail_over_coarse_mean"] = sums["detail_mean_mm"] / sums["coarse_sim_mean_mm"]
    print(json.dumps({k: round(v, 2) for k, v in sums.items()}), flush=True)
    return {"run": str(args.run), "test_sequences": test.sequence_names, "test_frames": len(items),
            "poses": len(groups), "runs_per_pose": [min(runs_of), max(runs_of)], "test_stride": args.test_stride,
            "frame_offset": args.frame_offset, **sums}


# ---------------------------------------------------------------------- script

def merge(name: str, section: str, value, label: str | None) -> dict:
    """The JSON's results so far with ``section`` (or ``section[label]``) replaced."""
    path = RESULTS / f"{name}.json"
    results = json.loads(path.read_text())["results"] if path.exists() else {}
    if label is None:
        results[section] = value
    else:
        results.setdefault(section, {})[label] = value
    return results


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("section", choices=["anchors", "memorise", "scale", "twins", "lookup", "repeats", "against-mean"])
    p.add_argument("--method", default="fitgar", choices=sorted(MEMORISE))
    p.add_argument("--data", default=None, help="a simulated, prepared store (memorise, scale)")
    p.add_argument("--config", type=Path, default=ROOT / "configs" / "models" / "fitgar-cpu.yaml")
    p.add_argument("--set", action="append", help="config override, e.g. train.lr=3e-4 (repeatable)")
    p.add_argument("--anchor", default="surface", choices=ANCHOR_MODES)
    p.add_argument("--edge-length", type=float, default=0.03)
    p.add_argument("--sequences", default=None, help="comma-separated training sequences (default: all)")
    p.add_argument("--samples", type=int, default=4)
    p.add_argument("--steps", default="50,100,200,400")
    p.add_argument("--strides", default="8,4,2")
    p.add_argument("--batch", type=int, default=4)
    p.add_argument("--scale-checkpoints", default="100,200")
    p.add_argument("--detail-steps", type=int, default=None, help="scale: detail steps (default: the coarse ones)")
    p.add_argument("--test-stride", type=int, default=6)
    p.add_argument("--frame-offset", type=int, default=0,
                   help="scale, lookup: the first frame kept of every sequence, training and test (a held-pose "
                        "plan's settled frames: stride = frames a key, offset = stride - 1)")
    p.add_argument("--twin-gap", type=int, default=15, help="twins: frames between a frame and its pose twin")
    p.add_argument("--run", default=None, help="against-mean: a saved FitGar run folder")
    p.add_argument("--save-run", default=None, help="scale: keep the trained model as a run folder (one stride)")
    p.add_argument("--label", default=None, help="key of this run inside its section (default: the anchor)")
    p.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    p.add_argument("--name", default="capacity-fitgar")
    args = p.parse_args(argv)
    global DEVICE
    DEVICE = torch.device(args.device)
    torch.set_num_threads(1)
    if args.section != "anchors" and not args.data:
        p.error(f"{args.section} needs --data")
    start = time.perf_counter()
    if args.section == "anchors":
        value, label = {"edge_length": args.edge_length, "body": "Anny, average", "seed": 0,
                        "kinds": anchor_sharing(args.edge_length)}, None
    elif args.section == "memorise":
        value, label = MEMORISE[args.method](args), args.label or f"{args.method}-{args.anchor}"
    elif args.section == "twins":
        value, label = pose_twins(args), None
    elif args.section == "lookup":
        value, label = pose_lookup(args), args.label or Path(args.data).stem
    elif args.section == "repeats":
        value, label = pose_repeats(args), args.label or Path(args.data).stem
    elif args.section == "against-mean":
        value, label = against_mean(args), args.label or Path(args.run).name
    else:
        label = args.label or args.anchor
        value = fitgar_scale(args, lambda partial: save_results(args.name, merge(args.name, "scale", partial, label)))
    value = {**value, "wall_seconds": time.perf_counter() - start} if isinstance(value, dict) else value
    save_results(args.name, merge(args.name, args.section, value, label))


if __name__ == "__main__":
    main()
