"""JointNet's association sparsity: the weight of its sparsity term (JointNet Eq. 6, 8) against its robustness to
an irrelevant joint and its held-out accuracy, seed by seed.

For every ``--lambdas`` value and ``--seeds`` seed, JointNet is trained as the demo trains it
(:data:`loosefit.demo.DEMO_TRAINING`, ``model.lambda_sparse`` set; runs ``<runs>/jointnet-sparse<lambda>-seed<k>``,
resumed) on a demo-sized store (``configs/datasets/memory.yaml``'s), beside VirtualBones with the demo's settings
(``virtualbones-demo-seed<k>``, the runs of ``demo_seeds.py``). Each run is scored on every held-out sequence
of the store (RMSE against the simulation and against the mean of its reference runs) and by the accuracy
benchmark's robustness test (``accuracy.py``: the left arm turned by a smooth 30-45 degree offset, the mean
change of the garment below the knees). The association itself is summarised by

- ``association_l1``: the sum of the association bones read over all bones and joints (``||relu(A)||_1``; with
  ``--association hoyer`` the rows sum to 1, so it counts the bones that listen to any joint);
- ``nudged_weight_below_knees``: the association weight that the garment below the knees receives from the
  perturbed joint and its two skeleton neighbours (the joints whose GRU inputs the perturbation changes),
  averaged over those vertices through the skinning weights: ``mean_v sum_b W[v, b] relu(A)[b, j]``;
- ``change_without_nudged_association_mm``: the robustness change with those joints' association columns set
  to zero, so the rest of the change is their joint-specific PSD (with ``--association hoyer`` the rows are then
  normalised again over the joints left).

``--association`` and ``--radius`` set the association's form and start (``JointNetConfig.association``,
``association_radius``) of every JointNet run; the run folders are named after them
(``jointnet-hoyer-r0.2-1e-4-seed0``).

Run: .venv/bin/python benchmarks/experiments/jointnet_sparsity.py --data memory.zarr --runs RUNS [--lambdas 1e-5,1e-4,3e-4,1e-3]
         [--seeds 0,1] [--association l1|hoyer] [--radius 0.2] [--name jointnet-sparsity]
(writes benchmarks/results/<name>.json)
"""

from __future__ import annotations

import argparse
import multiprocessing
import statistics
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts

from _common import save_results  # noqa: E402

#: The perturbed joint and its skeleton neighbours in the rig (their GRUs read its rotation).
JOINT = "LeftArm"
NUDGED = ("LeftShoulder", "LeftArm", "LeftForeArm")
DEGREES = (30.0, 45.0)


def association_summary(model, below: np.ndarray) -> dict:
    """``association_l1`` and ``nudged_weight_below_knees`` (module docstring) of a JointNet model."""
    import torch

    A = model.association_matrix().detach()
    reach = (model.skin_weights[torch.from_numpy(below)] @ A).mean(0)  # (J_s,)
    nudged = [model.joint_names.index(n) for n in NUDGED]
    return {"association_l1": float(A.sum()), "nudged_weight_below_knees": float(reach[nudged].sum()),
            "weight_below_knees": float(reach.sum()), "nonzero_fraction": float((A > 0).float().mean())}


def score(store, garment: str, run: Path, names: list[str], below: np.ndarray) -> dict:
    """Held-out RMSE per sequence (against the simulation and the runs' mean) and the robustness change;
    ``below (V,)``: the garment vertices below the knees."""
    from accuracy import robustness
    from loosefit.animate import Animator
    from loosefit.metrics.errors import rmse_mm
    from loosefit.metrics.reference import mean_run

    animator = Animator(run)
    out = {"sequences": {}}
    for name in names:
        seq = store.sequence(name)
        gt, predicted = np.asarray(seq.verts[:]), animator.animate(store.motion(seq.motion))
        refs = store.references(name)
        mean = mean_run([gt, *refs]) if len(refs) else None
        out["sequences"][name] = {"rmse_mm": rmse_mm(predicted, gt),
                                  "rmse_vs_mean_mm": rmse_mm(predicted, mean) if mean is not None else None}
    out["change_below_knees_mm"] = robustness(store, garment, {"m": animator}, names, JOINT, DEGREES)[
        "mean_change_mm"]["m"]
    if animator.method == "jointnet":
        model = animator.model
        out.update(association_summary(model, below))
        with_columns = model.association.data.clone()
        model.association.data[:, [model.joint_names.index(n) for n in NUDGED]] = -1.0  # relu -> 0
        out["change_without_nudged_association_mm"] = robustness(store, garment, {"m": animator}, names, JOINT,
                                                                 DEGREES)["mean_change_mm"]["m"]
        model.association.data.copy_(with_columns)
    return out


def summarise(rows: list[dict], vb_change: float) -> dict:
    """Means (and spreads) over seeds of the scalar figures of ``rows``."""
    summary = {}
    for key in ("change_below_knees_mm", "association_l1", "nudged_weight_below_knees"):
        values = [r[key] for r in rows if key in r]
        if values:
            summary[key] = {"mean": statistics.fmean(values), "min": min(values), "max": max(values)}
    for name in rows[0]["sequences"]:
        values = [r["sequences"][name]["rmse_mm"] for r in rows]
        summary[f"{name}/rmse_mm"] = {"mean": statistics.fmean(values), "min": min(values), "max": max(values)}
    ratios = [r["change_below_knees_mm"] / vb_change for r in rows]
    summary["change_over_virtualbones"] = {"mean": statistics.fmean(ratios), "max": max(ratios)}
    return summary


def main() -> None:
    from demo_seeds import train

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True, help="a demo-sized store with held-out sequences")
    ap.add_argument("--runs", required=True, help="folder of the runs (resumed)")
    ap.add_argument("--lambdas", default="1e-5,1e-4,3e-4,1e-3")
    ap.add_argument("--seeds", default="0,1")
    ap.add_argument("--association", choices=("l1", "hoyer"), default="l1", help="JointNet's association penalty")
    ap.add_argument("--radius", type=float, default=0.0, help="JointNet's association_radius (metres; 0: random start)")
    ap.add_argument("--name", default="jointnet-sparsity")
    a = ap.parse_args()
    from loosefit.data import DatasetStore

    store = DatasetStore.open(a.data)
    names = store.sequence_names(split="test")
    garment = store.sequence(names[0]).garment
    seeds, lambdas = [int(s) for s in a.seeds.split(",")], a.lambdas.split(",")
    runs = {("virtualbones", "demo", s): [] for s in seeds}
    runs.update({("jointnet", lam, s): [f"model.lambda_sparse={lam}", f"model.association={a.association}",
                                        f"model.association_radius={a.radius}"] for lam in lambdas for s in seeds})
    kind = ("sparse" if a.association == "l1" else a.association) + (f"-r{a.radius:g}-" if a.radius > 0 else "")

    def folder(method, tag, seed):
        return Path(a.runs) / (f"{method}-demo-seed{seed}" if tag == "demo" else f"{method}-{kind}{tag}-seed{seed}")

    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:  # one thread each
        for job in [pool.submit(train, m, s, a.data, garment, str(folder(m, t, s)), tuple(changes))
                    for (m, t, s), changes in runs.items()]:
            job.result()

    from accuracy import below_knees

    below = below_knees(store, garment, names[0])[2]
    vb = {s: score(store, garment, folder("virtualbones", "demo", s), names, below) for s in seeds}
    vb_change = statistics.fmean(r["change_below_knees_mm"] for r in vb.values())
    results = {"data": str(Path(a.data).resolve()), "garment": garment, "sequences": names, "joint": JOINT,
               "association": a.association, "association_radius": a.radius,
               "degrees": list(DEGREES), "virtualbones": {"seeds": {str(s): r for s, r in vb.items()},
                                                          "change_below_knees_mm": vb_change},
               "jointnet": {}}
    for lam in lambdas:
        rows = {s: score(store, garment, folder("jointnet", lam, s), names, below) for s in seeds}
        results["jointnet"][lam] = {"seeds": {str(s): r for s, r in rows.items()},
                                    "summary": summarise(list(rows.values()), vb_change)}
        print(lam, {k: round(v["mean"], 2) for k, v in results["jointnet"][lam]["summary"].items()}, flush=True)
    save_results(a.name, results)


if __name__ == "__main__":
    main()
