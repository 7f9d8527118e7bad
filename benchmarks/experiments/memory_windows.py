"""How the recurrent models' training windows set their memory: held-out RMSE per motion kind of VirtualBones
and JointNet trained three ways, with the same networks and epochs.

- ``windows``: windows every ``stride`` frames from a zero state with a burn-in (VirtualBones 64 frames every
  48, burn-in 16; JointNet 60 every 50, burn-in 10: the paper's 50 frames of loss);
- ``long``: windows of 176 frames every 88 with a burn-in of 48 (both models);
- ``carried``: stateful truncated back-propagation through time (``data.carry_state``: consecutive windows
  of 64 frames for VirtualBones, 50 for JointNet, the GRU state carried across them; :mod:`loosefit.models.streams`).

Each variant is one ``benchmarks/accuracy.py`` run (``--preset cpu``, 32 bones, the demo's JointNet sizes; epochs:
VirtualBones 40 + 15 as in the demo, JointNet 20 + 8, fewer than the demo's for the loaded machine) into
``--runs/<variant>``, writing ``benchmarks/results/memory-<variant>.json`` (``--only-virtualbones``: VirtualBones
alone, as the long windows were measured); ``--summarise`` collects the RMSE per motion kind and split
(train / val / test) and the training steps and times of every variant into
``benchmarks/results/memory-comparison.json``.

Run: .venv/bin/python benchmarks/experiments/memory_windows.py --data /work/stores/memory.zarr --runs RUNS --variant windows
     .venv/bin/python benchmarks/experiments/memory_windows.py --summarise
(the store: `loosefit simulate configs/datasets/memory.yaml --out memory.zarr`)
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts
from _common import RESULTS, save_results  # noqa: E402

HERE = Path(__file__).resolve().parents[1]  # benchmarks/, where accuracy.py is
#: The same networks and epochs for every variant: the CPU preset's VirtualBones, the demo's JointNet sizes,
#: the demo's epochs.
COMMON = [
    "virtualbones:train.stages.low.epochs=40", "virtualbones:train.stages.high.epochs=15",
    "jointnet:model.gru_hidden=128", "jointnet:model.features=128", "jointnet:model.bone_mlp=[256,256]",
    "jointnet:model.psd_mlp=[128]", "jointnet:model.psd_shapes=16",
    "jointnet:train.stages.stage1.epochs=20", "jointnet:train.stages.stage2.epochs=8",
]
VARIANTS = {
    "windows": ["virtualbones:data.carry_state=false", "jointnet:data.carry_state=false",
                "virtualbones:data.window=64", "virtualbones:data.stride=48", "virtualbones:data.burn_in=16",
                "jointnet:data.window=60", "jointnet:data.stride=50", "jointnet:data.burn_in=10"],
    "long": ["virtualbones:data.carry_state=false", "jointnet:data.carry_state=false",
             "virtualbones:data.window=176", "virtualbones:data.stride=88", "virtualbones:data.burn_in=48",
             "jointnet:data.window=176", "jointnet:data.stride=88", "jointnet:data.burn_in=48"],
    "carried": ["virtualbones:data.carry_state=true", "virtualbones:data.window=64",
                "jointnet:data.carry_state=true", "jointnet:data.window=50"],
}
METHODS = ("body-lbs", "virtualbones", "jointnet")


def run_variant(data: str, runs: Path, variant: str, bones: int) -> None:
    sets = [a for s in COMMON + VARIANTS[variant] for a in ("--set", s)]
    subprocess.run([sys.executable, str(HERE / "accuracy.py"), "--data", data, "--runs", str(runs / variant),
                    "--bones", str(bones), "--name", f"memory-{variant}", *sets], check=True)


def run_virtualbones(data: str, runs: Path, variant: str) -> None:
    """VirtualBones alone (train or resume as accuracy.py does, then RMSE per motion kind and split of its
    output and of its low-frequency mesh), for a variant whose JointNet did not fit in the time at hand."""
    import accuracy
    from loosefit.animate import Animator
    from loosefit.data.store import DatasetStore

    sets = accuracy.parse_sets(COMMON + VARIANTS[variant], "cpu")
    store = DatasetStore.open(data, mode="r")
    garments = {}
    for garment in accuracy.garments_with_test(store):
        run = runs / variant / garment / "virtualbones"
        validation = accuracy.garment_validation(store, garment, 0.2)
        training = accuracy.train_run("virtualbones", Path(data), garment, run, sets["virtualbones"],
                                       validation=validation)
        animator = Animator(run)
        meta = animator.meta
        splits = {"train": meta["train_sequences"], "val": meta["val_sequences"],
                  "test": accuracy.held_out_sequences(store, garment)}
        garments[garment] = {"training": {"virtualbones": training},
                             "virtualbones": {"errors_by_kind": accuracy.errors_by_kind(store, animator, splits)},
                             "virtualbones-lf": {"errors_by_kind": accuracy.errors_by_kind(store, animator, splits, "lf")}}
    save_results(f"memory-{variant}", {"overrides": sets, "garments": garments})


def summarise() -> dict:
    out = {"common_overrides": COMMON, "variants": {}}
    for variant, overrides in VARIANTS.items():
        path = RESULTS / f"memory-{variant}.json"
        if not path.is_file():
            continue
        results = json.loads(path.read_text())["results"]
        entry = {"overrides": overrides, "garments": {}}
        for garment, g in results["garments"].items():
            entry["garments"][garment] = {
                method: {"errors_by_kind": g[method]["errors_by_kind"],
                         "train_wall_s": g["training"].get(method, {}).get("train_wall_s"),
                         "train_steps": g["training"].get(method, {}).get("global_step")}
                for method in METHODS + ("virtualbones-lf",) if method in g
            }
        out["variants"][variant] = entry
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", help="the simulated store")
    parser.add_argument("--runs", type=Path, help="folder of the variants' run folders")
    parser.add_argument("--variant", choices=sorted(VARIANTS), action="append", default=[])
    parser.add_argument("--bones", type=int, default=32)
    parser.add_argument("--only-virtualbones", action="store_true", help="train and evaluate VirtualBones alone")
    parser.add_argument("--summarise", action="store_true", help="collect the variants' results")
    args = parser.parse_args()
    for variant in args.variant:
        if not (args.data and args.runs):
            parser.error("--variant needs --data and --runs")
        if args.only_virtualbones:
            run_virtualbones(args.data, args.runs, variant)
        else:
            run_variant(args.data, args.runs, variant, args.bones)
    if args.summarise:
        save_results("memory-comparison", summarise())


if __name__ == "__main__":
    main()
