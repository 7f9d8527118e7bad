"""Accuracy and speed of the multi-garment graph methods on a multi-garment store (FitGar; SwinGar adds
its own entry to :data:`EVALUATORS` and :data:`VARIANTS`).

For ``--data`` (a simulated, prepared store such as ``configs/datasets/garments.yaml``, whose test split
holds garments, bodies and motions the training never saw):

1. every variant of :data:`VARIANTS` is trained into ``--runs/<variant>`` (resumed when there) from
   ``--config`` plus its overrides plus ``--set``; training runs without validation (the test split never
   picks a checkpoint) and the last checkpoint is evaluated;
2. each test sequence is animated frame by frame and compared with its simulation: mean per-vertex error
   in mm of the coarse mesh (against the simulation and against its ``fitgar`` smoothing) and of the
   detail mesh (against the simulation);
3. the tables of FitGar's Table 1 (grouped by body shape) and Table 2 (grouped by garment, each test
   garment on its body and motions), and the targets: detail at most 0.6 x coarse (the paper: 1.52
   against 3.01 mm), the full model better than the plain-output ablation;
4. speed (frames per second of the paper-size network, per vertex and thread count) is measured by
   ``benchmarks/graph_speed.py``.

Say which data a result is: ``--set-name dynamic`` for motions as simulated, ``quasi-static`` for a store
of slow motions or poses held until the cloth settles (a static method is judged where it applies).

Run: .venv/bin/python benchmarks/accuracy_graph.py --data DATA.zarr --runs RUNS [--variants full,plain]
         [--config configs/models/fitgar.yaml] [--set train.epochs=5 ...] [--set-name dynamic]
         [--name accuracy-graph]
(writes benchmarks/results/<name>.json)
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import save_results  # noqa: E402

import torch  # noqa: E402

from loosefit.animate_any import AnyGarmentAnimator  # noqa: E402
from loosefit.body import AnnyBody, AnnyShape  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.models.fitgar_data import Smoother  # noqa: E402
from loosefit.training import train_model  # noqa: E402

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "models"
#: Variant -> (method, overrides on top of the config): the full model and FitGar Sec. 5.3's ablations.
VARIANTS = {
    "full": ("fitgar", []),
    "plain": ("fitgar", ["model.output=plain"]),
    "limited": ("fitgar", ["model.output=limited"]),
    "concat": ("fitgar", ["model.parser_mode=concat"]),
    "no-parser": ("fitgar", ["model.parser_mode=nodes"]),
    "one-step": ("fitgar", ["model.two_step=false"]),
    "no-pool": ("fitgar", ["model.pooling=false"]),
}
#: Detail error at most this times the coarse error (the project's floor; the FitGar paper reaches 0.50).
DETAIL_OVER_COARSE = 0.6


def mean_error_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    return float(np.linalg.norm(pred - gt, axis=-1).mean() * 1e3)


def fitgar_errors(run: Path, store: DatasetStore, names: list[str]) -> list[dict]:
    """One row per sequence: coarse and detail mean per-vertex errors (mm)."""
    animator = AnyGarmentAnimator(run)
    rows, bodies = [], {}
    for name in names:
        seq = store.sequence(name)
        if seq.body not in bodies:
            bodies[seq.body] = AnnyBody(AnnyShape.from_array(store.body(seq.body)))
        garment = store.garment(seq.garment)
        pair = animator.pair(garment.verts, garment.faces, bodies[seq.body])
        out = animator.animate_outputs(pair, store.motion(seq.motion))
        gt = np.asarray(seq.verts[:], np.float32)
        smooth = Smoother(garment.faces, len(garment.verts), garment.pinned)(gt)
        rows.append({"sequence": name, "garment": seq.garment, "body": seq.body, "motion": seq.motion,
                     "coarse_mm": mean_error_mm(out["coarse"], gt), "coarse_vs_smooth_mm": mean_error_mm(out["coarse"], smooth),
                     "detail_mm": mean_error_mm(out["verts"], gt)})
    return rows


#: Method -> its evaluator ``(run, store, test sequence names) -> rows`` with ``coarse_mm`` and ``detail_mm``.
EVALUATORS = {"fitgar": fitgar_errors}


def table(rows: list[dict], key: str) -> dict:
    """Mean coarse and detail errors per value of ``key`` (frames weigh equally within a sequence)."""
    groups = defaultdict(list)
    for r in rows:
        groups[r[key]].append(r)
    return {k: {m: float(np.mean([r[m] for r in g])) for m in ("coarse_mm", "detail_mm")} | {"sequences": len(g)}
            for k, g in sorted(groups.items())}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, help="a simulated, prepared multi-garment store")
    p.add_argument("--runs", type=Path, help="folder of the variants' run folders")
    p.add_argument("--variants", default="full,plain", help=f"comma-separated, of {sorted(VARIANTS)}")
    p.add_argument("--config", type=Path, default=CONFIGS / "fitgar.yaml")
    p.add_argument("--set", action="append", default=[], help="config override for every variant (repeatable)")
    p.add_argument("--set-name", default="dynamic", help="what the data is: dynamic or quasi-static")
    p.add_argument("--name", default="accuracy-graph")
    args = p.parse_args()
    results: dict = {"set": args.set_name}
    if args.data is not None:
        store = DatasetStore.open(args.data)
        names = store.sequence_names(split="test")
        results["variants"] = {}
        for variant in args.variants.split(","):
            method, overrides = VARIANTS[variant]
            run = args.runs / variant
            started = time.perf_counter()
            train_model(method, args.data, None, run, config=args.config, overrides=[*overrides, *args.set],
                        resume=True, val_split=None)
            rows = EVALUATORS[method](run, store, names)
            results["variants"][variant] = {"train_s": time.perf_counter() - started, "rows": rows,
                                            "by_body": table(rows, "body"), "by_garment": table(rows, "garment"),
                                            "coarse_mm": float(np.mean([r["coarse_mm"] for r in rows])),
                                            "detail_mm": float(np.mean([r["detail_mm"] for r in rows]))}
        full = results["variants"].get("full")
        if full:
            targets = [{"target": f"detail <= {DETAIL_OVER_COARSE} x coarse", "measured": full["detail_mm"] / full["coarse_mm"],
                        "passed": full["detail_mm"] <= DETAIL_OVER_COARSE * full["coarse_mm"]}]
            if "plain" in results["variants"]:
                plain = results["variants"]["plain"]["detail_mm"]
                targets.append({"target": "full beats plain output", "measured": [full["detail_mm"], plain],
                                "passed": full["detail_mm"] < plain})
            results["targets"] = targets
    save_results(args.name, results)


if __name__ == "__main__":
    main()
