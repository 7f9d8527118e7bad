"""Accuracy of the multi-garment graph methods (FitGar and SwinGar) on a multi-garment store.

For ``--data`` (a simulated, prepared store such as ``configs/datasets/garments.yaml``, whose test split
holds garments, bodies and motions the training never saw):

1. every variant of :data:`VARIANTS` (or of a group of :data:`GROUPS`) is trained into ``--runs/<variant>``
   (resumed when there) from its method's config file of ``--preset`` (:data:`PRESETS`:
   ``cpu``, CPU-sized networks; ``paper``, the paper's sizes in ``configs/models/<method>.yaml``), then the
   variant's overrides, then the ``--set METHOD:key=value`` ones; ``--config METHOD:PATH`` replaces the
   preset's file. Training runs without validation (the test split never picks a checkpoint) and the last
   checkpoint is evaluated;
2. each test sequence is animated and compared with its simulation (:data:`EVALUATORS`):
   FitGar frame by frame, the mean per-vertex error in mm of the coarse mesh (against the simulation and
   against its ``fitgar`` smoothing) and of the detail mesh; SwinGar along the motion from the garment's
   rest mesh alone, RMSE (mm), SwinGar's E_dist (cm) and E_norm (degrees, :mod:`loosefit.metrics.surface`),
   next to the same of body-LBS (the garment skinned with its nearest rest body vertex's weights);
3. per variant: the rows, their means, tables by garment and by body (FitGar's Table 1 groups by body
   shape, its Table 2 by garment); FitGar's targets (detail at most 0.6 x coarse, the paper: 1.52
   against 3.01 mm; the full model better than the plain-output ablation); SwinGar's Table I beside
   ours (:data:`SWINGAR_TABLE_I`, on the test garments no training sequence wears: all test sequences
   when there are none) and its targets: spectral descriptor E_dist at most :data:`SPECTRAL_OVER_NONE` x
   no descriptor's (the paper: 1.90 / 2.37 = 0.80), GAT-LN with ``alpha = 2`` below plain GAT in RMSE
   (SwinGar Fig. 9a); reported beside them (``checks``, not targets): graph pooling and Euclidean
   distance between the two (as in Table I), RMSE at ``alpha`` 1, 2 and 3 (Fig. 9: 2 slightly best),
   SwinGar below body-LBS;
4. with ``--vb-data`` (a second store holding a test garment's own training sequences on its test body,
   under the same garment entry name as in ``--data``'s test split, e.g. ``skirt-6+thin``): that store is
   prepared and VirtualBones trained on each such garment as ``benchmarks/accuracy.py`` does (its prepare
   step and ``--preset``), and SwinGar's RMSE on the garment's test sequences of ``--data`` is compared
   with VirtualBones' on the same sequences: target SwinGar at most :data:`SWINGAR_OVER_VB` x
   VirtualBones (one network for every garment against one trained for this garment);
5. speed (frames per second of the paper-size networks, per vertex and thread count) is measured by
   ``benchmarks/graph_speed.py``.

Say which data a result is: ``--set-name dynamic`` for motions as simulated, ``quasi-static`` for a store
of slow motions or poses held until the cloth settles (a static method is judged where it applies).
``--also quasi-static=STATIC.zarr`` evaluates the same runs on a second store's test sequences as well (the
quasi-static walks of ``configs/datasets/garments-static.yaml``: the same test garments and bodies, walks
played four times slower). ``--also-train`` evaluates them on their own training sequences too
(``train_split``): an error as high there as on the test set is under-fitting, not a failure to generalise.

Run: .venv/bin/python benchmarks/accuracy_graph.py --data DATA.zarr --runs RUNS [--variants full,plain]
         [--preset cpu|paper] [--config swingar:configs/models/swingar.yaml ...]
         [--set swingar:train.stages.all.epochs=5 ...] [--vb-data VB.zarr] [--bones 80] [--set-name dynamic]
         [--also quasi-static=STATIC.zarr] [--also-train] [--name accuracy-graph]
     SwinGar's ablations: --variants swingar-all (= swingar, swingar-no-descriptor, swingar-pooling,
         swingar-euclidean, swingar-plain-gat, swingar-alpha-1, swingar-alpha-3) --name accuracy-graph-swingar
(writes benchmarks/results/<name>.json)
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import accuracy  # noqa: E402  (benchmarks/accuracy.py: VirtualBones' CPU preset and training)
from _common import RESULTS, save_results  # noqa: E402

from loosefit.animate import Animator  # noqa: E402
from loosefit.animate_any import AnyGarmentAnimator  # noqa: E402
from loosefit.body import AnnyBody, AnnyShape  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.errors import InputError  # noqa: E402
from loosefit.metrics.errors import rmse_mm  # noqa: E402
from loosefit.metrics.surface import e_dist_cm, e_norm_deg  # noqa: E402
from loosefit.motion.motion import Motion  # noqa: E402
from loosefit.models.fitgar_data import Smoother  # noqa: E402
from loosefit.rig.prepare import prepare  # noqa: E402
from loosefit.rig.virtual_bones import DEFAULT_BONES  # noqa: E402
from loosefit.sim.attach import body_lbs  # noqa: E402
from loosefit.sim.plan import SEPARATOR  # noqa: E402
from loosefit.training import train_model  # noqa: E402

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "models"
#: Variant -> (method, overrides on top of the method's config): FitGar's full model and its Sec. 5.3
#: ablations; SwinGar's full model, its global-descriptor ablation (Table I) and its GAT-LN ablation
#: (Fig. 8, 9: plain GAT, and alpha 0, 1 and 3 beside the paper's 2); SwinGar with its skinning weights
#: started from body-LBS (``model.skinning_prior``, ours: not in the paper, so not in ``swingar-all``); and
#: SwinGar with the GAT-LN design of runs trained before the attention keys existed (``swingar-first-attention``:
#: one normaliser per graph, raw scores, averaged heads, gates sharing a GAT-LN).
VARIANTS = {
    "full": ("fitgar", []),
    "plain": ("fitgar", ["model.output=plain"]),
    "limited": ("fitgar", ["model.output=limited"]),
    "concat": ("fitgar", ["model.parser_mode=concat"]),
    "no-parser": ("fitgar", ["model.parser_mode=nodes"]),
    "one-step": ("fitgar", ["model.two_step=false"]),
    "no-pool": ("fitgar", ["model.pooling=false"]),
    "swingar": ("swingar", []),
    "swingar-no-descriptor": ("swingar", ["model.global_descriptor=none"]),
    "swingar-pooling": ("swingar", ["model.global_descriptor=pooling"]),
    "swingar-euclidean": ("swingar", ["model.global_descriptor=euclidean"]),
    "swingar-plain-gat": ("swingar", ["model.alpha=null"]),
    "swingar-alpha-0": ("swingar", ["model.alpha=0.0"]),
    "swingar-alpha-1": ("swingar", ["model.alpha=1.0"]),
    "swingar-alpha-3": ("swingar", ["model.alpha=3.0"]),
    "swingar-prior": ("swingar", ["model.skinning_prior=true"]),
    "swingar-first-attention": ("swingar", ["model.gate_attention=shared", "model.attention_norm=graph",
                                            "model.attention_centred=false", "model.concat_heads=false"]),
}
#: ``--variants`` shorthands.
GROUPS = {
    "fitgar-all": [v for v, (m, _) in VARIANTS.items() if m == "fitgar"],
    "swingar-table1": ["swingar", "swingar-no-descriptor", "swingar-pooling", "swingar-euclidean"],
    "swingar-alpha": ["swingar", "swingar-plain-gat", "swingar-alpha-0", "swingar-alpha-1", "swingar-alpha-3"],
    "swingar-all": [v for v, (m, _) in VARIANTS.items()
                    if m == "swingar" and v not in ("swingar-prior", "swingar-first-attention")],
}
#: ``--preset`` -> method -> config file.
#: ``cpu``: the CPU-sized networks of ``configs/models/<method>-cpu.yaml`` (SwinGar's: about 13 minutes of
#: training on one core for ``configs/datasets/garments.yaml``, see the file); ``paper``: the paper's sizes.
#: (The sizes are tied to each other, so they live in files: an override is checked on its own.)
PRESETS = {
    "cpu": {"fitgar": CONFIGS / "fitgar-cpu.yaml", "swingar": CONFIGS / "swingar-cpu.yaml"},
    "paper": {"fitgar": CONFIGS / "fitgar.yaml", "swingar": CONFIGS / "swingar.yaml"},
}
#: Detail error at most this times the coarse error (the project's floor; the FitGar paper reaches 0.50).
DETAIL_OVER_COARSE = 0.6
#: SwinGar Table I, E_dist (cm) and E_norm (degrees) on its test garments, by the variant that reproduces
#: each row.
SWINGAR_TABLE_I = {
    "swingar-no-descriptor": {"row": "w/o global desc.", "e_dist_cm": 2.37, "e_norm_deg": 9.02},
    "swingar-pooling": {"row": "w/ graph pooling", "e_dist_cm": 2.15, "e_norm_deg": 8.67},
    "swingar-euclidean": {"row": "w/ Euclidean distance", "e_dist_cm": 2.24, "e_norm_deg": 8.95},
    "swingar": {"row": "w/ spectr. desc. (ours)", "e_dist_cm": 1.90, "e_norm_deg": 7.53},
}
#: SwinGar's E_dist with the spectral descriptor at most this times without any global descriptor (the
#: paper: 1.90 / 2.37 = 0.80).
SPECTRAL_OVER_NONE = 0.85
#: SwinGar's RMSE on a garment at most this times that of a VirtualBones network trained for the garment.
SWINGAR_OVER_VB = 1.5
#: The metrics of each method's rows.
METRICS = {
    "fitgar": ("coarse_mm", "coarse_vs_smooth_mm", "detail_mm", "body_lbs_mm"),
    "swingar": ("rmse_mm", "e_dist_cm", "e_norm_deg", "body_lbs_rmse_mm", "body_lbs_e_dist_cm", "body_lbs_e_norm_deg"),
}


def mean_error_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    return float(np.linalg.norm(pred - gt, axis=-1).mean() * 1e3)


def every_nth_frame(motion: Motion, stride: int, offset: int = 0) -> Motion:
    """Frames ``offset, offset + stride, ...`` of ``motion`` (for a static method, whose frames are independent)."""
    return Motion(motion.rotations[offset::stride], motion.translation[offset::stride], motion.fps / stride,
                  motion.rig, motion.joint_names, motion.name)


def fitgar_errors(run: Path, store: DatasetStore, names: list[str], frame_stride: int = 1,
                  frame_offset: int = 0) -> list[dict]:
    """One row per sequence: coarse and detail mean per-vertex errors (mm) over every ``frame_stride``-th
    frame from ``frame_offset`` (FitGar is static: each frame is predicted on its own, so a stride only samples
    the frames; a held-pose store's settled frames are stride ``transition + frames``, offset one less)."""
    animator = AnyGarmentAnimator(run)
    rows, bodies = [], {}
    for name in names:
        seq = store.sequence(name)
        if seq.body not in bodies:
            bodies[seq.body] = AnnyBody(AnnyShape.from_array(store.body(seq.body)))
        garment = store.garment(seq.garment)
        pair = animator.pair(garment.verts, garment.faces, bodies[seq.body])
        motion = every_nth_frame(store.motion(seq.motion), frame_stride, frame_offset)
        out = animator.animate_outputs(pair, motion)
        gt = np.asarray(seq.verts[frame_offset::frame_stride], np.float32)
        lbs = body_lbs(garment.verts, bodies[seq.body], motion)
        smooth = Smoother(garment.faces, len(garment.verts), garment.pinned)(gt)
        rows.append({"sequence": name, "garment": seq.garment, "body": seq.body, "motion": seq.motion,
                     "coarse_mm": mean_error_mm(out["coarse"], gt), "coarse_vs_smooth_mm": mean_error_mm(out["coarse"], smooth),
                     "detail_mm": mean_error_mm(out["verts"], gt), "body_lbs_mm": mean_error_mm(lbs, gt),
                     "frames": int(len(gt)), "frame_stride": frame_stride, "frame_offset": frame_offset})
        print(f"   {name}: coarse {rows[-1]['coarse_mm']:.1f} mm, detail {rows[-1]['detail_mm']:.1f} mm", flush=True)
    return rows


def plan_garment(entry: str) -> str:
    """The plan's garment of a store garment entry (``skirt-6+thin`` -> ``skirt-6``)."""
    return entry.split(SEPARATOR)[0]


def unseen_garments(store: DatasetStore) -> set[str]:
    """Garment entries of the test split whose garment no training sequence wears (on any body)."""
    worn = {plan_garment(store.sequence(n).garment) for n in store.sequence_names(split="train")}
    return {g for g in (store.sequence(n).garment for n in store.sequence_names(split="test"))
            if plan_garment(g) not in worn}


def swingar_errors(run: Path, store: DatasetStore, names: list[str]) -> list[dict]:
    """One row per sequence: SwinGar's ``rmse_mm``, ``e_dist_cm`` and ``e_norm_deg`` of the garment animated from
    its rest mesh on the sequence's body along its motion, and the same of body-LBS
    (:func:`loosefit.sim.attach.body_lbs`) as ``body_lbs_*``; ``unseen_garment`` marks garments no training
    sequence wears."""
    animators, bodies, rows = {}, {}, []
    unseen = unseen_garments(store)
    for name in names:
        seq = store.sequence(name)
        motion = store.motion(seq.motion)
        key = (seq.body, motion.rig)
        if key not in bodies:
            bodies[key] = AnnyBody(AnnyShape.from_array(store.body(seq.body)), rig=motion.rig)
        garment = store.garment(seq.garment)
        if (seq.garment, key) not in animators:  # binds the garment: its graph and descriptor, once
            animators[seq.garment, key] = Animator(run, garment=garment, body=bodies[key])
        pred = animators[seq.garment, key].animate(motion)
        lbs = body_lbs(garment.verts, bodies[key], motion)
        gt = np.asarray(seq.verts[:], np.float32)
        rows.append({"sequence": name, "garment": seq.garment, "body": seq.body, "motion": seq.motion,
                     "unseen_garment": seq.garment in unseen, "frames": int(len(gt)), "vertices": int(gt.shape[1]),
                     "rmse_mm": rmse_mm(pred, gt), "e_dist_cm": e_dist_cm(pred, gt),
                     "e_norm_deg": e_norm_deg(pred, gt, garment.faces), "body_lbs_rmse_mm": rmse_mm(lbs, gt),
                     "body_lbs_e_dist_cm": e_dist_cm(lbs, gt), "body_lbs_e_norm_deg": e_norm_deg(lbs, gt, garment.faces)})
        print(f"   {name}: SwinGar {rows[-1]['rmse_mm']:.1f} mm, body-LBS {rows[-1]['body_lbs_rmse_mm']:.1f} mm", flush=True)
    return rows


#: Method -> its evaluator ``(run, store, test sequence names) -> rows`` (the row metrics: :data:`METRICS`).
EVALUATORS = {"fitgar": fitgar_errors, "swingar": swingar_errors}


def means(rows: list[dict], metrics) -> dict:
    """Mean of each metric over ``rows`` (sequences weigh equally; frames weigh equally within one)."""
    return {m: float(np.mean([r[m] for r in rows])) for m in metrics}


def table(rows: list[dict], key: str, metrics=METRICS["fitgar"]) -> dict:
    """:func:`means` of ``metrics`` per value of ``key``, with the sequence count."""
    groups = defaultdict(list)
    for r in rows:
        groups[r[key]].append(r)
    return {k: means(g, metrics) | {"sequences": len(g)} for k, g in sorted(groups.items())}


# ---------------------------------------------------------------- targets


def entry(target: str, garment: str, measured, limit, passed: bool) -> dict:
    """A target or check entry as :mod:`loosefit.report.claims` reads them."""
    return {"target": target, "garment": garment, "measured": measured, "limit": limit, "pass": bool(passed)}


def fitgar_targets(variants: dict) -> list[dict]:
    """FitGar's targets: detail at most :data:`DETAIL_OVER_COARSE` x coarse; the full model beats plain output."""
    full = variants.get("full")
    if not full:
        return []
    ratio = full["detail_mm"] / full["coarse_mm"]
    out = [entry("FitGar detail / coarse error", "test sequences", ratio, DETAIL_OVER_COARSE, ratio <= DETAIL_OVER_COARSE)]
    if "plain" in variants:
        plain = variants["plain"]["detail_mm"]
        out.append(entry("FitGar full detail error / plain-output detail error", "test sequences",
                         full["detail_mm"] / plain, 1.0, full["detail_mm"] < plain))
    return out


def swingar_rows(variant: dict) -> tuple[list[dict], str]:
    """The rows SwinGar's Table I and targets read: unseen garments' when any, else all; and their label."""
    unseen = [r for r in variant["rows"] if r["unseen_garment"]]
    return (unseen, "unseen test garments") if unseen else (variant["rows"], "all test sequences")


def swingar_table_i(variants: dict) -> dict:
    """SwinGar Table I beside ours: per row the paper's E_dist / E_norm and ours (None when not run)."""
    out = {}
    for name, paper in SWINGAR_TABLE_I.items():
        ours = None
        if name in variants:
            rows, label = swingar_rows(variants[name])
            ours = means(rows, ("e_dist_cm", "e_norm_deg", "rmse_mm")) | {"sequences": len(rows), "over": label}
        out[paper["row"]] = {"variant": name, "paper": {k: paper[k] for k in ("e_dist_cm", "e_norm_deg")}, "ours": ours}
    return out


def swingar_targets(variants: dict) -> tuple[list[dict], list[dict]]:
    """SwinGar's targets and reported checks (see the module doc) from the variants run."""
    targets, checks = [], []

    def mean(name, metric):
        rows, label = swingar_rows(variants[name])
        return float(np.mean([r[metric] for r in rows])), label

    if {"swingar", "swingar-no-descriptor"} <= set(variants):
        spectral, label = mean("swingar", "e_dist_cm")
        none, _ = mean("swingar-no-descriptor", "e_dist_cm")
        targets.append(entry("SwinGar spectral-descriptor E_dist / no-descriptor E_dist", label, spectral / none,
                             SPECTRAL_OVER_NONE, spectral <= SPECTRAL_OVER_NONE * none))
        for name, what in (("swingar-pooling", "graph pooling"), ("swingar-euclidean", "Euclidean-distance descriptor")):
            if name in variants:
                value, _ = mean(name, "e_dist_cm")
                checks.append(entry(f"SwinGar {what} E_dist (cm) between spectral and no descriptor (Table I)", label,
                                    value, [spectral, none], spectral <= value <= none))
    if {"swingar", "swingar-plain-gat"} <= set(variants):
        alpha2, label = mean("swingar", "rmse_mm")
        plain, _ = mean("swingar-plain-gat", "rmse_mm")
        targets.append(entry("SwinGar GAT-LN (alpha 2) RMSE / plain GAT RMSE", label, alpha2 / plain, 1.0, alpha2 < plain))
    alphas = {a: v for a, v in (("1", "swingar-alpha-1"), ("2", "swingar"), ("3", "swingar-alpha-3")) if v in variants}
    if len(alphas) > 1:
        rmse = {a: mean(v, "rmse_mm")[0] for a, v in alphas.items()}
        checks.append(entry("SwinGar RMSE (mm) by alpha: 2 lowest (Fig. 9)", swingar_rows(variants["swingar"])[1]
                            if "swingar" in variants else "", rmse, None, "2" in rmse and rmse["2"] == min(rmse.values())))
    if "swingar" in variants:
        ours, label = mean("swingar", "rmse_mm")
        lbs, _ = mean("swingar", "body_lbs_rmse_mm")
        checks.append(entry("SwinGar RMSE / body-LBS RMSE", label, ours / lbs, 1.0, ours < lbs))
    return targets, checks


# ---------------------------------------------------------------- VirtualBones on a test garment


#: SwinGar variants compared with VirtualBones when ``--vb-data`` is given (each one present), and how their
#: target reads.
VB_COMPARED = {"swingar": "SwinGar", "swingar-prior": "SwinGar with the skinning prior"}


def virtualbones_comparison(vb_data: Path, store: DatasetStore, names: list[str], swingar: dict[str, dict],
                            runs: Path, preset: str, sets: list[str], bones: int) -> dict:
    """VirtualBones trained on ``vb_data``'s sequences of each test garment of ``store`` it holds, against each
    SwinGar variant's rows (``swingar``: variant -> its result) on that garment's test sequences of ``store``.
    Returns the comparison, its targets under ``"targets"``."""
    prepared = prepare(vb_data, bones=bones)  # as benchmarks/accuracy.py prepares its data
    vb_store = DatasetStore.open(vb_data)
    tested = {store.sequence(n).garment for n in names}
    trained = {vb_store.sequence(n).garment for n in vb_store.sequence_names(split="train")}
    garments = sorted(tested & trained)
    if not garments:
        raise InputError(f"--vb-data holds training sequences of {sorted(trained)}, none of the test garments "
                         f"{sorted(tested)}", vb_data)
    overrides = accuracy.parse_sets(sets, preset)["virtualbones"]  # accuracy.py's preset, then --set virtualbones:...
    by_sequence = {v: {r["sequence"]: r["rmse_mm"] for r in result["rows"]} for v, result in swingar.items()}
    out, targets = {"prepare": prepared, "garments": {}}, []
    for garment in garments:
        run = runs / "virtualbones" / garment
        print(f"== VirtualBones on {garment} -> {run}", flush=True)
        training = accuracy.train_run("virtualbones", vb_data, garment, run, overrides)
        animator = Animator(run, checkpoint="last")
        rows = []
        for name in (n for n in names if store.sequence(n).garment == garment):
            seq = store.sequence(name)
            gt = np.asarray(seq.verts[:], np.float32)
            vb = rmse_mm(animator.animate(store.motion(seq.motion)), gt)
            rows.append({"sequence": name, "virtualbones_rmse_mm": vb,
                         **{f"{v}_rmse_mm": by_sequence[v][name] for v in swingar}})
        averages = {k: float(np.mean([r[k] for r in rows])) for k in rows[0] if k != "sequence"}
        out["garments"][garment] = {"training": training, "rows": rows, **averages,
                                    "train_sequences": [n for n in vb_store.sequence_names(split="train")
                                                        if vb_store.sequence(n).garment == garment]}
        vb_mean = averages["virtualbones_rmse_mm"]
        for v in swingar:
            ours = averages[f"{v}_rmse_mm"]
            targets.append(entry(f"{VB_COMPARED[v]} RMSE / VirtualBones RMSE (trained for the garment)", garment,
                                 ours / vb_mean, SWINGAR_OVER_VB, ours <= SWINGAR_OVER_VB * vb_mean))
    out["targets"] = targets
    return out


# ---------------------------------------------------------------- main


def add_targets(results: dict, vb: dict | None) -> None:
    """Add the targets and checks of ``results["variants"]`` (and of the VirtualBones comparison ``vb``:
    :func:`virtualbones_comparison`'s result) to ``results``, and print them."""
    done = results["variants"]
    targets, checks = fitgar_targets(done), []
    if any(VARIANTS[v][0] == "swingar" for v in done):
        results["swingar_table_i"] = swingar_table_i(done)
        more, checks = swingar_targets(done)
        targets += more
    if vb is not None:
        results["virtualbones"] = vb
        targets += vb["targets"]
    results["targets"], results["checks"] = targets, checks
    results["all_pass"] = all(t["pass"] for t in targets)
    for t in [*targets, *checks]:
        kind = "target" if t in targets else "check "
        print(f"{'PASS' if t['pass'] else 'FAIL'} {kind} {t['garment']}: {t['target']} = {t['measured']} "
              f"(limit {t['limit']})")


def variant_training(config: Path, own: list[str], sets: list[str], out: Path) -> tuple[Path, list[str]]:
    """The config file and overrides a variant trains with: ``config`` and ``own`` then ``sets``, except for
    FitGar's one-step model, which has no coarse stage (the trainer refuses stages a model lacks): a copy of
    ``config`` at ``out`` without it, and ``sets`` without its ``train.stages.coarse`` settings."""
    if "model.two_step=false" not in own:
        return config, [*own, *sets]
    import yaml

    doc = yaml.safe_load(config.read_text())
    doc.get("train", {}).get("stages", {}).pop("coarse", None)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(yaml.safe_dump(doc, sort_keys=False))
    return out, [*own, *(s for s in sets if not s.startswith("train.stages.coarse."))]


def variant_list(text: str) -> list[str]:
    """``--variants``: comma-separated variants and :data:`GROUPS`, expanded, in order, each once."""
    out = []
    for name in (v.strip() for v in text.split(",") if v.strip()):
        if name not in VARIANTS and name not in GROUPS:
            raise InputError(f"unknown variant {name!r}: choose from {sorted(VARIANTS)} or groups {sorted(GROUPS)}")
        out += [v for v in GROUPS.get(name, [name]) if v not in out]
    return out


def per_method(values: list[str], what: str) -> dict[str, list[str]]:
    """``METHOD:rest`` strings -> {method: [rest, ...]} (``--set`` and ``--config``)."""
    out = defaultdict(list)
    for value in values:
        method, sep, rest = value.partition(":")
        if not sep or not rest or method not in ("fitgar", "swingar", "virtualbones"):
            raise InputError(f"{what} takes METHOD:... with METHOD fitgar, swingar or virtualbones, got {value!r}")
        out[method].append(rest)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, help="a simulated, prepared multi-garment store")
    p.add_argument("--runs", type=Path, help="folder of the variants' run folders")
    p.add_argument("--variants", default="full,plain", help=f"comma-separated, of {sorted(VARIANTS)} or {sorted(GROUPS)}")
    p.add_argument("--preset", choices=sorted(PRESETS), default="cpu",
                   help="config files and overrides per method: cpu (CPU-sized networks) or paper (the paper's)")
    p.add_argument("--config", action="append", default=[], help="METHOD:PATH, replaces the preset's config file")
    p.add_argument("--set", action="append", default=[],
                   help="METHOD:section.key=value override of that method's variants (virtualbones: --vb-data's)")
    p.add_argument("--vb-data", type=Path, default=None,
                   help="a store of a test garment's own training sequences: VirtualBones against SwinGar on it")
    p.add_argument("--bones", type=int, default=DEFAULT_BONES, help="virtual bones per garment when preparing --vb-data")
    p.add_argument("--set-name", default="dynamic", help="what the data is: dynamic or quasi-static")
    p.add_argument("--also", action="append", default=[], metavar="NAME=STORE",
                   help="evaluate every variant on the test sequences of another store too, e.g. "
                        "quasi-static=DATA-STATIC.zarr (configs/datasets/garments-static.yaml): results under NAME")
    p.add_argument("--fitgar-frame-stride", type=int, default=1,
                   help="evaluate FitGar on every n-th frame of each test sequence (a static method: frames are independent)")
    p.add_argument("--fitgar-frame-offset", type=int, default=0,
                   help="the first frame of each test sequence FitGar is evaluated on (a held-pose store's settled frames: "
                        "--fitgar-frame-stride TRANSITION+FRAMES --fitgar-frame-offset TRANSITION+FRAMES-1)")
    p.add_argument("--from-results", default=None, metavar="NAME,NAME",
                   help="without --data: merge the variants of these result files (later ones win) and compute "
                        "their targets, e.g. an ablation run separately from the full model")
    p.add_argument("--also-train", action="store_true",
                   help="also evaluate each variant on its own training sequences (under- or over-fitting?)")
    p.add_argument("--name", default="accuracy-graph")
    args = p.parse_args()
    if not 0 <= args.fitgar_frame_offset < args.fitgar_frame_stride:
        p.error("--fitgar-frame-stride must be >= 1 and 0 <= --fitgar-frame-offset < --fitgar-frame-stride")
    options = {"fitgar": {"frame_stride": args.fitgar_frame_stride, "frame_offset": args.fitgar_frame_offset},
               "swingar": {}}
    variants = variant_list(args.variants)
    sets, configs = per_method(args.set, "--set"), per_method(args.config, "--config")
    if any(len(v) > 1 for v in configs.values()):
        p.error("--config: one file per method")
    if args.vb_data is not None and not set(VB_COMPARED) & set(variants):
        p.error(f"--vb-data compares VirtualBones with the variants {sorted(VB_COMPARED)}: add one to --variants")
    if any("=" not in a for a in args.also):
        p.error("--also takes NAME=STORE")
    if args.data is not None and args.runs is None:
        p.error("--data needs --runs")
    if args.data is not None and args.from_results:
        p.error("--from-results merges earlier results: leave out --data")

    def config_of(method: str) -> Path:
        return Path(configs[method][0]) if method in configs else PRESETS[args.preset][method]

    results: dict = {"set": args.set_name, "preset": args.preset, "fitgar_frame_stride": args.fitgar_frame_stride,
                     "fitgar_frame_offset": args.fitgar_frame_offset, "load_average_at_start": os.getloadavg()}
    started = time.perf_counter()
    if args.data is not None:
        store = DatasetStore.open(args.data)
        names = store.sequence_names(split="test")
        also = {label: DatasetStore.open(path) for label, path in (a.split("=", 1) for a in args.also)}
        results.update(data=str(args.data.resolve()), test_sequences=names, variants={})
        for variant in variants:
            method, own = VARIANTS[variant]
            config, overrides = variant_training(config_of(method), own, sets.get(method, []),
                                                 args.runs / f"{variant}.config.yaml")
            run = args.runs / variant
            print(f"== {variant}: train {method} -> {run}", flush=True)
            start = time.perf_counter()
            train_model(method, args.data, None, run, config=config, overrides=overrides, resume=True,
                        val_split=None)
            train_s = time.perf_counter() - start
            print(f"== {variant}: evaluate {len(names)} test sequences", flush=True)
            rows = EVALUATORS[method](run, store, names, **options[method])
            metrics = METRICS[method]
            results["variants"][variant] = {"method": method, "config": str(config_of(method)), "overrides": overrides,
                                            "train_s": train_s, "evaluate_s": time.perf_counter() - start - train_s,
                                            "rows": rows, **means(rows, metrics),
                                            "by_body": table(rows, "body", metrics),
                                            "by_garment": table(rows, "garment", metrics)}
            for label, other, split in [*((label, other, "test") for label, other in also.items()),
                                        *((("train_split", store, "train"),) if args.also_train else ())]:
                print(f"== {variant}: evaluate on {label}", flush=True)
                rows = EVALUATORS[method](run, other, other.sequence_names(split=split), **options[method])
                results["variants"][variant][label] = {"rows": rows, **means(rows, metrics),
                                                       "by_body": table(rows, "body", metrics),
                                                       "by_garment": table(rows, "garment", metrics)}
            # what is measured so far survives an interrupted run (targets and checks come at the end)
            save_results(args.name, results | {"partial": f"{len(results['variants'])} of {len(variants)} variants"})
        vb = None
        if args.vb_data is not None:
            compared = {v: results["variants"][v] for v in VB_COMPARED if v in results["variants"]}
            vb = virtualbones_comparison(args.vb_data, store, names, compared, args.runs,
                                         args.preset, [f"virtualbones:{s}" for s in sets.get("virtualbones", [])],
                                         args.bones)
        add_targets(results, vb)
    elif args.from_results:
        # variants measured by earlier runs (e.g. an ablation run separately): merged, then their targets
        names = args.from_results.split(",")
        earlier = [json.loads((RESULTS / f"{name}.json").read_text())["results"] for name in names]
        # how the runs were made is theirs (the first file's), not this call's defaults
        results.update({k: earlier[0].get(k) for k in ("data", "test_sequences", "set", "preset", "fitgar_frame_stride",
                                                         "fitgar_frame_offset")},
                       merged_from=names, variants={})
        vb, vb_targets = None, {}
        for doc in earlier:
            results["variants"].update(doc["variants"])
            if "virtualbones" in doc:  # the last file's comparison, with every file's targets (later ones win)
                vb = dict(doc["virtualbones"])
                vb_targets.update({(t["target"], t["garment"]): t for t in doc.get("targets", [])
                                   if "/ VirtualBones RMSE" in t["target"]})
        if vb is not None:
            vb["targets"] = list(vb_targets.values())
        add_targets(results, vb)
    results["wall_s"] = time.perf_counter() - started
    results["load_average_at_end"] = os.getloadavg()
    save_results(args.name, results)


if __name__ == "__main__":
    main()
