"""Ship trained runs as pretrained garments (``loosefit.pretrained``): each run reduced to what animation reads,
with what it was trained on and its test scores from an ``accuracy.py`` JSON.

Run: .venv/bin/python scripts/ship_pretrained.py --accuracy benchmarks/results/accuracy-real-skirt.json \\
         --runs RUNS --garment skirt+average --name skirt [--methods virtualbones jointnet]
(writes src/loosefit/pretrained/<name>-<method>/)

``--psd-modes K`` ships a JointNet run trained with a free PSD basis with that basis projected onto the garment's K
smoothest modes (``loosefit.models.jointnet_psd.project_psd``): its smooth part, without the lumps the free basis adds
on new motions. ``--pin-radius R`` ships a run trained without pins keeping its garment's pins
(``loosefit.models.pins``; they are applied where the garment is animated, not in training, so the weights are the
run's); ``--pin-shipped GARMENT.obj --pin-radius R`` gives already shipped garments theirs (the garment file they were
trained on) where their runs and store are not at hand.

Each shipped garment is checked against its run on the test sequences of the JSON's store (when the store is here):
the largest vertex distance between the two animations and both RMSEs against the simulation, kept in its
``pretrained.json`` under ``storage_check``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np

from loosefit.pretrained import ROOT, ship


def projected_run(run: Path, out: Path, modes: int) -> Path:
    """A copy of the JointNet run folder ``run`` in ``out`` whose best checkpoint's free PSD basis is projected onto
    ``modes`` smoothest modes; its model.json sizes and method.yaml say so."""
    from loosefit.animate import load_run
    from loosefit.models.jointnet_psd import project_psd

    shutil.copytree(run, out, ignore=shutil.ignore_patterns("tensorboard", "last.pt"))
    meta, model, _ = load_run(run)
    return _rewritten(out, meta, {**meta["sizes"], "psd_modes": modes}, project_psd(model, modes), "psd_modes", modes)


def _rewritten(out: Path, meta: dict, sizes: dict, model, setting: str, value) -> Path:
    """The run folder ``out`` with ``model``'s weights in its best checkpoint, ``sizes`` in its model.json and the
    model ``setting`` at ``value`` in its method.yaml. Returns ``out``."""
    import torch
    import yaml

    from loosefit.train.run import RunDir, load_checkpoint

    (out / "model.json").write_text(json.dumps({**meta, "sizes": sizes}, indent=1))
    config = yaml.safe_load((out / "method.yaml").read_text())
    config["model"][setting] = value
    (out / "method.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    checkpoint = RunDir(out).best_checkpoint
    state = load_checkpoint(checkpoint)
    state["model"] = model.state_dict()
    torch.save(state, checkpoint)
    return out


def pinned_run(run: Path, out: Path, radius: float, garment=None, body=None) -> Path:
    """A copy of the run folder ``run`` in ``out`` (or ``run`` itself when it is already there) whose best checkpoint
    keeps its garment's pins over ``radius`` metres (:func:`loosefit.models.pins.with_pins`: ``garment`` and ``body``,
    by default those of its training store); its model.json sizes and method.yaml say so."""
    from loosefit.animate import load_run
    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.data import DatasetStore
    from loosefit.models.pins import with_pins

    if run != out:
        shutil.copytree(run, out, ignore=shutil.ignore_patterns("tensorboard", "last.pt"))
    meta, model, _ = load_run(out)
    if garment is None:
        with DatasetStore.open(meta["data"]) as store:
            first = store.sequence(meta["train_sequences"][0])
            body = AnnyBody(AnnyShape.from_array(store.body(first.body)), rig=store.motion(first.motion).rig)
            garment = store.garment(meta["garment"])
    pinned = with_pins(model, garment, body, radius)
    return _rewritten(out, meta, pinned.sizes(), pinned, "pin_radius", radius)


def pin_shipped(folder: Path, garment_file: Path, radius: float) -> None:
    """Give the shipped garment ``folder`` (``src/loosefit/pretrained/<name>-<method>``) its garment's pins in place,
    from the garment file it was trained on (``Garment.save``: an OBJ and its sidecar; the body: the file's shape, or
    the average one), for a garment whose store is not here. Its weights stay as shipped; the storage check of the
    former pinless files is dropped (it needs the store)."""
    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.garment import Garment

    garment = Garment.load(garment_file)
    body = AnnyBody(AnnyShape(**garment.body_shape) if garment.body_shape else AnnyShape())
    scratch = Path(tempfile.mkdtemp(prefix="loosefit-pins-")) / folder.name
    shutil.copytree(folder, scratch)
    pinned_run(scratch, scratch, radius, garment, body)
    info = json.loads((folder / "pretrained.json").read_text())
    info = {k: v for k, v in info.items() if k not in ("checkpoint", "checkpoint_bytes", "int8", "storage_check")}
    info["trained_on"]["pins_added_with_radius"] = radius
    info["trained_on"]["pins_garment_file"] = garment_file.name
    ship(scratch, folder, info)
    print(f"{folder}: pins over {radius} m from {garment_file}")


def storage_check(run: Path, shipped: Path, data: Path, sequences: list[str]) -> dict:
    """How far the shipped checkpoint (float16 or int8, a projected PSD) moves the animation of ``sequences`` from
    the run's float32 one: the largest vertex distance (mm), the pooled RMSE of each against the simulation (mm) and
    their bend ratios (:func:`loosefit.metrics.surface.bend_ratio` over every frame of the sequences)."""
    from loosefit.animate import Animator
    from loosefit.data import DatasetStore
    from loosefit.metrics.surface import bend_ratio

    store = DatasetStore.open(data)
    motions = [store.motion(store.sequence(name).motion) for name in sequences]
    gt = [np.asarray(store.sequence(name).verts[:], np.float64) for name in sequences]
    run_pred, shipped_pred = (Animator(folder, threads=2).animate_batch(motions) for folder in (run, shipped))
    rmse = [1000 * np.sqrt(np.mean(np.concatenate([np.sum((p - g) ** 2, -1).ravel() for p, g in zip(preds, gt)])))
            for preds in (run_pred, shipped_pred)]
    largest = max(float(np.abs(np.linalg.norm(a - b, axis=-1)).max()) for a, b in zip(run_pred, shipped_pred))
    faces = np.asarray(store.garment(store.sequence(sequences[0]).garment).faces)
    bend = [bend_ratio(np.concatenate(preds), np.concatenate(gt), faces) for preds in (run_pred, shipped_pred)]
    return {"sequences": len(sequences), "max_vertex_distance_mm": 1000 * largest,
            "run_rmse_mm": rmse[0], "shipped_rmse_mm": rmse[1], "run_bend_ratio": bend[0], "shipped_bend_ratio": bend[1]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--accuracy", help="the accuracy.py results JSON that trained and scored the runs")
    ap.add_argument("--runs", help="accuracy.py's --runs folder")
    ap.add_argument("--garment", help="the store's garment entry, e.g. skirt+average")
    ap.add_argument("--name", required=True, help="the shipped name: pretrained:<name>[/<method>]")
    ap.add_argument("--methods", nargs="+", default=["virtualbones", "jointnet"])
    ap.add_argument("--psd-modes", type=int, default=0, help="JointNet: its free PSD basis projected onto this many "
                    "smoothest modes (0: as trained)")
    ap.add_argument("--pin-radius", type=float, default=None, help="keep the garment's pins over this many metres "
                    "(loosefit.models.pins) in a run trained without them (default: as trained)")
    ap.add_argument("--pin-shipped", type=Path, default=None, metavar="GARMENT.obj", help="give the already shipped "
                    "<name>-<method> garments pins (--pin-radius) from this garment file, without runs or store")
    a = ap.parse_args()
    if a.pin_shipped is not None:
        for method in a.methods:
            pin_shipped(ROOT / f"{a.name}-{method}", a.pin_shipped, a.pin_radius)
        return
    if not (a.accuracy and a.runs and a.garment):
        ap.error("--accuracy, --runs and --garment are needed to ship runs")
    scratch = Path(tempfile.mkdtemp(prefix="loosefit-ship-"))
    results = json.loads(Path(a.accuracy).read_text())["results"]
    garment = results["garments"][a.garment]
    for method in a.methods:
        overall = garment["metrics"][method]["overall"]
        info = {
            "trained_on": {"data": results["data"], "garment": a.garment, "sequences": garment["sequences"]["train"],
                           "validated_on": garment["sequences"]["val"], "preset": results["preset"],
                           "overrides": results["overrides"][method]},
            "test": {"sequences": garment["sequences"]["test"],
                     **{k: overall.get(k) for k in ("rmse_mm", "rmse_vs_mean_mm", "rmse_vs_mean_corrected_mm",
                                                    "floor_mm", "collision_pct")},
                     "body_lbs_rmse_mm": garment["metrics"]["body-lbs"]["overall"]["rmse_mm"]},
            "results": Path(a.accuracy).name,
        }
        run = Path(a.runs) / a.garment / method
        if method == "jointnet" and a.psd_modes:
            run = projected_run(run, scratch / method, a.psd_modes)
            info["trained_on"]["psd_projected_onto_modes"] = a.psd_modes
        if a.pin_radius is not None:
            run = pinned_run(run, scratch / method, a.pin_radius)
            info["trained_on"]["pins_added_with_radius"] = a.pin_radius
        out = ship(run, ROOT / f"{a.name}-{method}", info)
        if Path(results["data"]).is_dir():  # the shipped garment against the float32 run it was made from
            meta = json.loads((out / "pretrained.json").read_text())
            meta["storage_check"] = storage_check(run, out, Path(results["data"]), garment["sequences"]["test"])
            (out / "pretrained.json").write_text(json.dumps(meta, indent=1))
            print(f"{out}: int8 {meta['int8'] or 'nothing'}, float16 the rest; it moves the test animations by at most "
                  f"{meta['storage_check']['max_vertex_distance_mm']:.2f} mm")
        print(f"{out}: {info['test']['rmse_mm']:.1f} mm RMSE on the test split "
              f"(body-LBS {info['test']['body_lbs_rmse_mm']:.1f})")


if __name__ == "__main__":
    main()
