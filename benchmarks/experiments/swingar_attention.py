"""SwinGar's attention and capacity on a small simulated multi-garment store, on a CPU.

Five measurements, each a subcommand writing ``benchmarks/results/<name>.json``:

- ``entropy``: each GAT-LN layer's mean attention entropy per vertex (nats), next to that of a uniform
  attention over the same neighbourhoods (its maximum: equal means the layer is a neighbourhood mean), for
  each attention design of :data:`DESIGNS` at initialisation, on the training garments' first window. For the
  garment encoder also with the garment's positions taken relative to its centroid (``first+centroid``): the
  input-scaling alternative to centred scores.
- ``curve``: the alpha curve of SwinGar Fig. 9 (alpha 0, 1, 2, 3 and plain GAT) with two seeds each, trained on
  the store's training garments with ``configs/models/swingar-cpu.yaml`` (and the budget below), scored on the
  held-out garments (RMSE over every frame, animated from the rest garment, next to body-LBS) with each layer's
  attention entropy on them; ``--design`` picks the attention design.
- ``bands``: :func:`cmd_bands`: the curve's runs scored band by band (the smooth garment and its wrinkles) on the
  held-out garments, the seeds' mean and spread per variant.
- ``memorise``: :func:`memorise`: a handful of training frames learnt by heart (Adam on them alone), the
  RMSE on them over the steps, with the coarse stage's share; ``--set`` / ``--patch`` for the hypotheses.
- ``scale``: :func:`cmd_scale`: the held-out error against the training garments (``--counts`` 1, 2, 4: x1, x2,
  x4 of the training garments, taken one of each kind in turn) and the steps: each count trains the CPU preset
  with the curve's budget (``--set`` after it), validating on the test split only to draw the held-out curve
  per epoch (``val_rmse_mm`` of the test windows against the optimiser steps); the final score is the last
  checkpoint's, animated from the rest garment on every test sequence, next to body-LBS.

Store (see ``/work/stores/swingar-attention.yaml`` for the plan used)::

    .venv/bin/loosefit simulate PLAN.yaml --out STORE.zarr
    .venv/bin/python benchmarks/experiments/swingar_attention.py entropy --data STORE.zarr
    .venv/bin/python benchmarks/experiments/swingar_attention.py curve --data STORE.zarr --runs RUNS
    .venv/bin/python benchmarks/experiments/swingar_attention.py bands --data STORE.zarr --runs RUNS --match alpha-0,plain-gat
    .venv/bin/python benchmarks/experiments/swingar_attention.py memorise --data STORE.zarr --garment skirt-0+average
    .venv/bin/python benchmarks/experiments/swingar_attention.py scale --data STORE.zarr --runs RUNS [--counts 1,2,4]
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np
import torch
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts
from _common import save_results  # noqa: E402
from swingar_gpu import window_errors  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
CPU_CONFIG = ROOT / "configs" / "models" / "swingar-cpu.yaml"
#: GAT-LN designs (:class:`loosefit.models.swingar.SwinGarConfig`'s four attention keys).
DESIGNS = {
    "first": {"attention_norm": "graph", "attention_centred": False, "concat_heads": False, "gate_attention": "shared"},
    "graph-raw": {"attention_norm": "graph", "attention_centred": False, "concat_heads": True,
                  "gate_attention": "per_gate"},
    "node-raw": {"attention_norm": "node", "attention_centred": False, "concat_heads": True, "gate_attention": "per_gate"},
    "graph-centred": {"attention_norm": "graph", "attention_centred": True, "concat_heads": True,
                      "gate_attention": "per_gate"},
    "node-centred": {"attention_norm": "node", "attention_centred": True, "concat_heads": True,
                     "gate_attention": "per_gate"},
    "row-centred": {"attention_norm": "row", "attention_centred": True, "concat_heads": True,
                    "gate_attention": "per_gate"},
}
ALPHAS = {"alpha-0": "0.0", "alpha-1": "1.0", "alpha-2": "2.0", "alpha-3": "3.0", "plain-gat": "null"}
#: The curve's training budget on top of the CPU preset (small store: more epochs of fewer windows).
CURVE_SETTINGS = ["data.window=4", "data.stride=24", "train.stages.supervised.epochs=4", "train.stages.all.epochs=1",
                  "train.batch_size=4", "train.progress=false", "train.tensorboard=false", "train.device=cpu"]


def design_overrides(design: str) -> list[str]:
    """``--set`` overrides of a design; ``gate_attention`` first (``per_gate`` is refused without ``concat_heads``,
    and each override is checked as it is applied)."""
    keys = sorted(DESIGNS[design], key=lambda k: k != "gate_attention")
    return [f"model.{k}={str(DESIGNS[design][k]).lower()}" for k in keys]


def load_cfg(overrides, config: Path = CPU_CONFIG):
    from loosefit.config import load_config
    from loosefit.models.swingar import Config

    return load_config(Config, config, list(overrides))


def windows_of(data, cfg, window: int, stride: int):
    from loosefit.models.multi_garment import MultiWindowDataset

    history = cfg.model.motion_frames - 1 + cfg.model.corrective_frames - 1
    return MultiWindowDataset(data, window, stride, history)


def entropy_table(model, groups) -> dict:
    """``{layer: {"entropy", "uniform", "ratio"}}``: each GAT-LN's attention entropy over ``groups`` (collated
    batches, one forward pass each), as :func:`loosefit.models.layers.gat_ln.recording_attention` records it."""
    from loosefit.models.layers.gat_ln import recording_attention

    with torch.no_grad(), recording_attention(model) as log:
        for group in groups:
            model.predict_batch(group)
    table = {}
    for name, values in log.items():
        if values:
            e, u = np.mean([v[0] for v in values]), np.mean([v[1] for v in values])
            table[name] = {"entropy": float(e), "uniform": float(u), "ratio": float(e / u)}
    return table


def _collate(items):
    from loosefit.models.multi_garment import collate_by_graph

    return collate_by_graph(items)


def entropy_at_init(store: Path, designs, alpha: str = "2.0", seed: int = 0) -> dict:
    """Each design's per-layer attention entropy at initialisation on the first window of every training garment."""
    from loosefit.models.multi_garment import MultiGarmentData
    from loosefit.models.swingar import SwinGar

    out = {}
    data = None
    for design in designs:
        cfg = load_cfg([*design_overrides(design), f"model.alpha={alpha}"])
        if data is None:
            data = MultiGarmentData(store, "train", **cfg.model.graph_settings())
            ds = windows_of(data, cfg, 4, 10_000)
            firsts = {}
            for k, (gi, _, _) in enumerate(ds.index):
                firsts.setdefault(gi, k)
            groups = [_collate([ds[k]])[0] for k in firsts.values()]
        torch.manual_seed(seed)
        model = SwinGar.from_data(data, cfg.model)
        out[design] = entropy_table(model, groups)
        if design == "first":  # the input-scaling alternative: positions relative to each garment's centroid
            from loosefit.models.layers.gat_ln import recording_attention

            with torch.no_grad(), recording_attention(model.graph_encoder) as log:
                for group in groups:
                    g = dict(group["graph_tensors"])
                    g["rest"] = g["rest"] - g["rest"].mean(0)
                    model.garment_features(g)
            out["first+centroid"] = {f"graph_encoder.{k}": {
                "entropy": float(np.mean([v[0] for v in vals])), "uniform": float(np.mean([v[1] for v in vals])),
                "ratio": float(np.mean([v[0] for v in vals]) / np.mean([v[1] for v in vals]))}
                for k, vals in log.items() if vals}
    return out


def memorise(store: Path, garment: str, overrides=(), frames: int = 4, windows: int = 1, steps: int = 600,
             lr: float = 1e-3, stage: str = "supervised", seed: int = 0, every: int = 50, patch: dict | None = None,
             threads: int = 1, schedule: str = "constant", config: Path = CPU_CONFIG) -> dict:
    """SwinGar learning ``windows`` windows of ``frames`` frames of one training garment by heart.

    The model (``config``, by default ``swingar-cpu.yaml``, with ``overrides``) is trained with Adam at ``lr`` (``schedule``: constant, or
    ``"cosine"``: decayed to zero over the steps) on those windows alone for ``steps`` steps (loss of ``stage``), and scored on the same frames: the RMSE of the output,
    of the coarse stage alone (LBS of the blend shapes with the dynamic weights) and the gradient norm of each
    top-level module at the first step. ``patch``: module constants of :mod:`loosefit.models.swingar` set for the
    run (e.g. ``{"OUTPUT_INIT": 1.0}``), restored after.

    Returns ``{"curve": [{step, rmse_mm, coarse_rmse_mm, loss}], "final_rmse_mm", "grad_norms", ...}``.
    """
    import loosefit.models.swingar as sw
    from loosefit.models.multi_garment import MultiGarmentData

    saved = {k: getattr(sw, k) for k in (patch or {})}
    for k, v in (patch or {}).items():
        setattr(sw, k, v)
    try:
        torch.set_num_threads(threads)
        cfg = load_cfg(overrides, config)
        data = MultiGarmentData(store, "train", [garment], **cfg.model.graph_settings())
        ds = windows_of(data, cfg, frames, 17)
        picks = np.linspace(0, len(ds) - 1, windows).round().astype(int)
        batch = _collate([ds[int(k)] for k in picks])
        torch.manual_seed(seed)
        model = sw.SwinGar.from_data(data, cfg.model)
        opt = torch.optim.Adam(model.parameters(), lr)
        decay = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps) if schedule == "cosine" else None
        curve, grads, t0 = [], {}, time.time()

        def score(step, loss):
            curve.append({"step": step, **window_errors(model, batch), "loss": loss, "seconds": time.time() - t0})

        for step in range(steps + 1):
            loss, _ = model.training_loss(batch, stage)
            if step % every == 0 or step == steps:
                score(step, float(loss))
                print(curve[-1], flush=True)
            if step == steps:
                break
            opt.zero_grad()
            loss.backward()
            if step == 0:
                for name, module in model.named_children():
                    g = [p.grad.norm() ** 2 for p in module.parameters() if p.grad is not None]
                    grads[name] = float(torch.stack(g).sum().sqrt()) if g else None
            opt.step()
            if decay is not None:
                decay.step()
        verts = sum(int(g["graph_tensors"]["rest"].shape[0]) for g in batch[:1])
        return {"garment": garment, "vertices": verts, "frames": frames * windows, "steps": steps, "lr": lr,
                "schedule": schedule, "config": str(config),
                "stage": stage, "overrides": list(overrides), "patch": patch or {}, "curve": curve,
                "final_rmse_mm": curve[-1]["rmse_mm"], "best_rmse_mm": min(c["rmse_mm"] for c in curve),
                "grad_norms_step0": grads}
    finally:
        for k, v in saved.items():
            setattr(sw, k, v)


def held_out_scores(store: Path, run: Path, body, baseline: dict | None = None, checkpoint: str = "best") -> dict:
    """RMSE (mm, every frame, animated from the rest garment) of a run on each test sequence, and the attention
    entropy of its layers on the held-out garments' first windows."""
    from loosefit.animate import Animator
    from loosefit.data.store import DatasetStore

    store_ = DatasetStore.open(store)
    rows, animators = {}, {}
    for name in sorted(store_.sequence_names()):
        seq = store_.sequence(name)
        if seq.split != "test":
            continue
        garment, motion, truth = store_.garment(seq.garment), store_.motion(seq.motion), seq.verts[:]
        if seq.garment not in animators:
            animators[seq.garment] = Animator(run, garment=garment, body=body, checkpoint=checkpoint)
        pred = animators[seq.garment].animate(motion)
        rows[name] = float(np.sqrt(((pred - truth) ** 2).sum(-1).mean()) * 1e3)
    return {"rmse_mm": rows, "mean_rmse_mm": float(np.mean(list(rows.values()))),
            "entropy": held_out_entropy(store, run, checkpoint)}


def held_out_entropy(store: Path, run: Path, checkpoint: str = "best") -> dict:
    """:func:`entropy_table` of a run's layers on the first 4-frame window of each held-out garment."""
    from loosefit.animate import load_run
    from loosefit.models.multi_garment import MultiGarmentData

    _, model, cfg = load_run(run, checkpoint)
    data = MultiGarmentData(store, "test", body=False, **cfg.model.graph_settings())
    ds = windows_of(data, cfg, 4, 10_000)
    firsts = {}
    for k, (gi, _, _) in enumerate(ds.index):
        firsts.setdefault(gi, k)
    return entropy_table(model, [_collate([ds[k]])[0] for k in firsts.values()])


def body_lbs_scores(store: Path, body) -> dict:
    from loosefit.data.store import DatasetStore
    from loosefit.sim.attach import body_lbs

    store_ = DatasetStore.open(store)
    rows = {}
    for name in sorted(store_.sequence_names()):
        seq = store_.sequence(name)
        if seq.split == "test":
            garment, motion = store_.garment(seq.garment), store_.motion(seq.motion)
            rows[name] = float(np.sqrt(((body_lbs(garment.verts, body, motion) - seq.verts[:]) ** 2).sum(-1).mean()) * 1e3)
    return rows


def cmd_curve(args) -> None:
    from loosefit.body import AnnyBody
    from loosefit.training import train_model

    torch.set_num_threads(1)
    body = AnnyBody()
    runs = Path(args.runs)
    lbs = body_lbs_scores(Path(args.data), body)
    results = {"design": args.design, "settings": [*CURVE_SETTINGS, *args.set], "body_lbs_mm": lbs,
               "body_lbs_mean_mm": float(np.mean(list(lbs.values()))), "variants": {}}
    for variant in args.variants.split(","):
        for seed in args.seeds.split(","):
            run = runs / f"{args.design}-{variant}-seed-{seed}"
            if not (run / "run.json").exists():
                t0 = time.time()
                train_model("swingar", args.data, None, run, CPU_CONFIG,
                            [*CURVE_SETTINGS, *design_overrides(args.design), f"model.alpha={ALPHAS[variant]}",
                             f"train.seed={seed}", *args.set], val_split=None)
                print(f"{run.name}: trained in {time.time() - t0:.0f} s", flush=True)
            with open(run / "metrics.csv", newline="") as f:
                train_curve = [float(r["train_loss"]) for r in csv.DictReader(f) if r.get("train_loss")]
            scores = held_out_scores(Path(args.data), run, body)
            scores["train_loss_by_epoch"] = train_curve
            scores["ratio_to_body_lbs"] = scores["mean_rmse_mm"] / results["body_lbs_mean_mm"]
            results["variants"].setdefault(variant, {})[f"seed-{seed}"] = scores
            print(variant, seed, scores["mean_rmse_mm"], flush=True)
            save_results(args.name, results)  # after every run: a stopped benchmark keeps what it measured
    for variant, seeds in results["variants"].items():
        values = [s["mean_rmse_mm"] for s in seeds.values()]
        results["variants"][variant]["summary"] = {"mean_rmse_mm": float(np.mean(values)),
                                                   "spread_mm": float(np.max(values) - np.min(values))}
    save_results(args.name, results)


def cmd_bands(args) -> None:
    """The curve's trained runs (every run folder under the ``--runs`` folders, comma-separated, whose name has one
    of ``--match``), scored on the held-out garments band by band: each test sequence's prediction and simulation
    split as ``loosefit prepare`` splits a garment (:func:`loosefit.geometry.smoothing.frequency_split`, the
    ``virtualbones`` preset unless the garment's rig says otherwise) into the smooth garment (``low``) and its
    wrinkles (``high``). The paper's claim for alpha is about the high frequencies (SwinGar Sec. 4.2, Eq. 5): RMSE
    over all frames, mm, per band, per run, and per variant (the folder name without its seed) the seeds' mean and
    spread, and its difference from ``--reference`` seed by seed (the seeds move every variant alike);
    ``high_signal_mm``: the wrinkles' own size (the high-band RMSE of a prediction without any)."""
    from loosefit.animate import Animator
    from loosefit.body import AnnyBody
    from loosefit.data.store import DatasetStore
    from loosefit.geometry.smoothing import frequency_split
    from loosefit.rig.prepared import prepared_split

    torch.set_num_threads(1)
    store, body = DatasetStore.open(args.data), AnnyBody()
    tests = [n for n in sorted(store.sequence_names()) if store.sequence(n).split == "test"]
    splits, truths = {}, {}
    for name in tests:
        seq = store.sequence(name)
        if seq.garment not in splits:
            _, smoothing, fixed = prepared_split(store, seq.garment)
            faces = store.garment(seq.garment).faces
            splits[seq.garment] = lambda x, f=faces, sm=smoothing, fx=fixed: frequency_split(x, f, sm, fixed=fx)
        truths[name] = splits[seq.garment](np.asarray(seq.verts[:], np.float32))
    rmse = lambda a, b: float(np.sqrt(((a - b) ** 2).sum(-1).mean()) * 1e3)  # noqa: E731
    runs = sorted((r for folder in args.runs.split(",") for r in Path(folder).iterdir()
                   if (r / "run.json").exists() and any(m in r.name for m in args.match.split(","))),
                  key=lambda r: r.name)
    signal = float(np.mean([rmse(0 * truth[1], truth[1]) for truth in truths.values()]))  # no wrinkles at all
    results: dict = {"store": args.data, "sequences": tests, "high_signal_mm": signal, "runs": {}, "variants": {}}
    for run in runs:
        rows, animators = {}, {}
        for name in tests:
            seq = store.sequence(name)
            if seq.garment not in animators:
                animators[seq.garment] = Animator(run, garment=store.garment(seq.garment), body=body)
            pred = animators[seq.garment].animate(store.motion(seq.motion))
            low, high = splits[seq.garment](pred)
            rows[name] = {"low": rmse(low, truths[name][0]), "high": rmse(high, truths[name][1])}
        mean = {band: float(np.mean([r[band] for r in rows.values()])) for band in ("low", "high")}
        results["runs"][run.name] = {"sequences": rows, **mean}
        print(run.name, {k: round(v, 3) for k, v in mean.items()}, flush=True)
        save_results(args.name, results)
    by_variant: dict = {}  # variant -> seed -> row
    for name, row in results["runs"].items():
        variant, seed = name.rsplit("-seed-", 1)
        by_variant.setdefault(variant, {})[seed] = row
    reference = by_variant.get(args.reference, {})
    for variant, seeds in by_variant.items():
        rows = list(seeds.values())
        summary = {f"{band}_{stat}": float(f([r[band] for r in rows])) for band in ("low", "high")
                   for stat, f in (("mean_mm", np.mean), ("spread_mm", np.ptp))} | {"seeds": len(rows)}
        # the seeds move every variant alike: each variant's difference from --reference at the same seed
        for band in ("low", "high"):
            summary[f"{band}_minus_reference_mm"] = {seed: seeds[seed][band] - reference[seed][band]
                                                     for seed in sorted(set(seeds) & set(reference))}
        results["variants"][variant] = summary
    save_results(args.name, results)


def scale_garments(store, counts: list[int]) -> dict[int, list[str]]:
    """The training garments of each count: the store's training garments ordered one of each kind in turn
    (kinds and names sorted), the first ``count``."""
    from loosefit.data.store import DatasetStore

    store_ = DatasetStore.open(store)
    names = sorted({store_.sequence(n).garment for n in store_.sequence_names(split="train")})
    by_kind: dict[str, list[str]] = {}
    for name in names:
        by_kind.setdefault(store_.garment(name).kind, []).append(name)
    order: list[str] = []
    queues = [list(v) for _, v in sorted(by_kind.items())]
    while any(queues):
        order += [q.pop(0) for q in queues if q]
    if max(counts) > len(order):
        raise SystemExit(f"--counts asks for {max(counts)} training garments, the store has {len(order)}")
    return {k: order[:k] for k in counts}


def cmd_scale(args) -> None:
    from loosefit.body import AnnyBody
    from loosefit.training import train_model

    torch.set_num_threads(1)
    body = AnnyBody()
    counts = [int(c) for c in args.counts.split(",")]
    lbs = body_lbs_scores(Path(args.data), body)
    results = {"settings": [*CURVE_SETTINGS, *args.set], "body_lbs_mean_mm": float(np.mean(list(lbs.values()))),
               "counts": {}}
    for count, garments in scale_garments(Path(args.data), counts).items():
        run = Path(args.runs) / f"scale-{count}"
        if not (run / "run.json").exists():
            train_model("swingar", args.data, ",".join(garments), run, CPU_CONFIG, [*CURVE_SETTINGS, *args.set],
                        val_split="test")
        with open(run / "metrics.csv", newline="") as f:
            curve = [{"stage": r["stage"], "epoch": int(r["epoch"]), "step": int(r["step"]),
                      "val_rmse_mm": float(r["val_rmse_mm"])} for r in csv.DictReader(f) if r.get("val_rmse_mm")]
        scores = held_out_scores(Path(args.data), run, body, checkpoint="last")
        results["counts"][str(count)] = {"garments": garments, "held_out_curve": curve,
                                         "mean_rmse_mm": scores["mean_rmse_mm"], "rmse_mm": scores["rmse_mm"],
                                         "ratio_to_body_lbs": scores["mean_rmse_mm"] / results["body_lbs_mean_mm"]}
        print(count, garments, scores["mean_rmse_mm"], flush=True)
        save_results(args.name, results)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sp = sub.add_parser("entropy")
    sp.add_argument("--data", required=True)
    sp.add_argument("--designs", default=",".join(DESIGNS))
    sp.add_argument("--name", default="swingar-attention-entropy")
    sp = sub.add_parser("curve")
    sp.add_argument("--data", required=True)
    sp.add_argument("--runs", required=True)
    sp.add_argument("--design", default="node-centred", choices=list(DESIGNS))
    sp.add_argument("--variants", default=",".join(ALPHAS))
    sp.add_argument("--seeds", default="0,1")
    sp.add_argument("--set", action="append", default=[])
    sp.add_argument("--name", default="swingar-alpha-curve")
    sp = sub.add_parser("bands")
    sp.add_argument("--data", required=True)
    sp.add_argument("--runs", required=True)
    sp.add_argument("--match", required=True, help="comma-separated parts of run folder names, e.g. alpha-0,plain-gat")
    sp.add_argument("--reference", default="node-centred-alpha-0", help="the variant the others are paired with")
    sp.add_argument("--name", default="swingar-alpha-bands")
    sp = sub.add_parser("scale")
    sp.add_argument("--data", required=True)
    sp.add_argument("--runs", required=True)
    sp.add_argument("--counts", default="1,2,4")
    sp.add_argument("--set", action="append", default=[])
    sp.add_argument("--name", default="swingar-scale")
    sp = sub.add_parser("memorise")
    sp.add_argument("--data", required=True)
    sp.add_argument("--garment", required=True)
    sp.add_argument("--frames", type=int, default=4)
    sp.add_argument("--windows", type=int, default=1)
    sp.add_argument("--steps", type=int, default=600)
    sp.add_argument("--lr", type=float, default=1e-3)
    sp.add_argument("--stage", default="supervised")
    sp.add_argument("--set", action="append", default=[])
    sp.add_argument("--patch", action="append", default=[], help="NAME=VALUE: a module constant of models/swingar.py")
    sp.add_argument("--schedule", choices=("constant", "cosine"), default="constant", help="the learning rate over the steps")
    sp.add_argument("--config", type=Path, default=CPU_CONFIG, help="the SwinGar config (default: the CPU preset)")
    sp.add_argument("--name", default="swingar-memorise")
    args = parser.parse_args()
    torch.set_num_threads(1)
    if args.command == "entropy":
        save_results(args.name, {"store": args.data, "at_init": entropy_at_init(Path(args.data),
                                                                                 args.designs.split(","))})
    elif args.command == "scale":
        cmd_scale(args)
    elif args.command == "curve":
        cmd_curve(args)
    elif args.command == "bands":
        cmd_bands(args)
    else:
        patch = {k: yaml.safe_load(v) for k, v in (p.split("=", 1) for p in args.patch)}
        save_results(args.name, memorise(Path(args.data), args.garment, args.set, args.frames, args.windows,
                                         args.steps, args.lr, args.stage, patch=patch, schedule=args.schedule,
                                         config=args.config))


if __name__ == "__main__":
    main()
