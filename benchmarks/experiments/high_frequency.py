"""What VirtualBones' high-frequency module adds on held-out motions, and the most it could add.

For each trained VirtualBones run (``--runs/<garment>/virtualbones``, as :mod:`accuracy` leaves them) and
the sequences of ``--split`` (the held-out motions by default; ``--split train`` for how well the module
fits what it saw), in the canonical frame (RMSE does not change under the rigid heading frame):

- ``b``: the low-frequency mesh the network predicts; ``c``: its high-frequency offsets (the output is
  ``b + c``); ``y``: the simulation; ``h = y - y_LF``: the simulation's own high-frequency part, with the
  low/high split the run's rig was prepared with.
- :class:`loosefit.metrics.correction.CorrectionStats` then gives the RMSE without and with the offsets,
  with the ideal offsets ``c = h`` (the ceiling of any high-frequency module on this low-frequency
  result), the part of ``h`` the offsets explain, and the split of the error change into what the offsets
  share with ``h`` and with the low-frequency module's own error.

Run: .venv/bin/python benchmarks/experiments/high_frequency.py --data DATA.zarr --runs RUNS [--garments skirt+average,...]
         [--split test] [--sequences 0] [--name high-frequency]
(writes benchmarks/results/<name>.json)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts
from _common import save_results  # noqa: E402

from loosefit.animate import Animator  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.errors import InputError  # noqa: E402
from loosefit.metrics.correction import CorrectionStats  # noqa: E402
from loosefit.models.dataset import GarmentSequences  # noqa: E402
from loosefit.models.ensemble import predict_outputs  # noqa: E402


def garment_analysis(store: DatasetStore, garment: str, run: Path, split: str, limit: int) -> dict:
    """Per sequence and pooled :meth:`CorrectionStats.summary` of one garment's VirtualBones run."""
    model = Animator(run, checkpoint="last").model
    data = GarmentSequences(store, garment, split, bones=False, body=False)
    sequences = data.sequences[:limit] if limit else data.sequences
    pooled, rows = CorrectionStats(), {}
    with torch.no_grad():
        for seq in sequences:
            out = predict_outputs(model, seq, ("verts", "lf"))
            lf, offsets = out["lf"], out["verts"] - out["lf"]
            one = CorrectionStats()
            for stats in (one, pooled):
                stats.add(seq.verts, lf, offsets, seq.verts - seq.lf)
            rows[seq.name] = one.summary()
            print(f"  {seq.name}: {rows[seq.name]['base_rmse_mm']:.2f} -> {rows[seq.name]['corrected_rmse_mm']:.2f} mm "
                  f"(ideal offsets {rows[seq.name]['ideal_rmse_mm']:.2f})", flush=True)
    return {"run": str(run), "split": split, "rig": data.rig_settings, "sequences": rows, "overall": pooled.summary()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, required=True, help="the prepared dataset the runs were trained on")
    parser.add_argument("--runs", type=Path, required=True, help="folder of <garment>/virtualbones runs")
    parser.add_argument("--garments", default="", help="comma-separated garments (default: every garment with a run)")
    parser.add_argument("--split", default="test", help="sequences to analyse")
    parser.add_argument("--sequences", type=int, default=0, help="at most this many sequences per garment (0: all)")
    parser.add_argument("--name", default="high-frequency", help="results/<name>.json")
    args = parser.parse_args()
    torch.set_num_threads(1)
    store = DatasetStore.open(args.data)
    garments = args.garments.split(",") if args.garments else [
        g for g in store.garment_names() if (args.runs / g / "virtualbones").is_dir()]
    if not garments:
        raise InputError("no VirtualBones run of any garment of the store", args.runs)
    results = {"data": str(args.data), "garments": {}}
    for garment in garments:
        print(f"== {garment}", flush=True)
        results["garments"][garment] = garment_analysis(store, garment, args.runs / garment / "virtualbones",
                                                        args.split, args.sequences)
    save_results(args.name, results)


if __name__ == "__main__":
    main()
