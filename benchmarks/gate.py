"""The current quality gate on every sequence of a simulated store: which pass, which fail and why.

The gate (:mod:`loosefit.sim.quality`) runs when a sequence is simulated and its verdict is stored with
it. When the gate changes, this script measures the stored sequences again (the body posed along each
stored motion, the garment's rest state from the store) and compares the new verdicts with the stored
ones, so that a stricter gate can be checked against simulations that passed before.

Run: .venv/bin/python benchmarks/gate.py DATA.zarr [--name gate-bench]
(writes benchmarks/results/<name>.json: per sequence the stored and the current status, the reason, and
every statistic of the gate)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import save_results  # noqa: E402

from loosefit.data import DatasetStore  # noqa: E402
from loosefit.sim.quality import QualityGate, measure  # noqa: E402
from loosefit.simulate import plan_body  # noqa: E402


def gate_sequence(store: DatasetStore, name: str, gate: QualityGate) -> dict:
    """The gate's statistics and verdict for the stored sequence ``name``, beside its stored verdict."""
    seq = store.sequence(name)
    body = plan_body(tuple(float(v) for v in store.body(seq.body)))
    garment, motion = store.garment(seq.garment), store.motion(seq.motion)
    stats = measure(seq.verts[:], garment.verts, garment.faces, garment.pinned, body.pose(motion).verts,
                    body.faces, body.rest_verts(), motion.fps)
    status, reason = gate.check(stats)
    return {"stored_status": seq.status, "stored_reason": seq.reason, "status": status, "reason": reason,
            "stats": {k: float(v) for k, v in stats.items()}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", help="a simulated store (DATA.zarr)")
    parser.add_argument("--name", default="gate", help="results name: benchmarks/results/<name>.json")
    args = parser.parse_args()
    store, gate = DatasetStore.open(args.data), QualityGate()
    sequences = {}
    for name in sorted(store.sequence_names(status=None)):
        sequences[name] = row = gate_sequence(store, name, gate)
        print(f"{name}: stored {row['stored_status']}, now {row['status']} {row['reason']}".rstrip(), flush=True)
    count = {kind: sum(r[key] == "ok" for r in sequences.values()) for kind, key in (("stored", "stored_status"),
                                                                                     ("now", "status"))}
    print(f"{count['now']} of {len(sequences)} pass the current gate ({count['stored']} passed the stored one)")
    save_results(args.name, {"data": args.data, "gate": vars(gate), "sequences": len(sequences),
                             "ok_stored": count["stored"], "ok_now": count["now"], "per_sequence": sequences})


if __name__ == "__main__":
    main()
