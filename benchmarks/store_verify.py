"""The cost of verifying a dataset store: ``loosefit info`` reads every chunk file.

A store of ``--sequences`` sequences of ``--frames`` frames of a ``--vertices``-vertex garment
(smooth random motion, so Blosc-zstd compresses it about as much as cloth) is written once; then,
best of ``--repeat`` runs each, warm file cache:

- ``write_s``: writing one sequence, of which ``checksum_s`` is the CRC-32 of its files;
- ``info_metadata_s``: ``info(verify=False)`` (metadata and directory listings only);
- ``info_verify_s``: ``info()``, every chunk compared with the checksum recorded at commit;
- ``info_decode_s``: ``info()`` on the same store with the checksums removed (the path for stores
  written before checksums existed: every chunk is decoded instead);
- ``read_all_s``: reading every sequence's vertices (``seq.verts[:]``), for scale.

Run: .venv/bin/python benchmarks/store_verify.py [--sequences 16] [--frames 180] [--vertices 3000] [--repeat 3]
(writes benchmarks/results/store_verify.json)
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import save_results  # noqa: E402

from loosefit.data.chunks import file_checksums  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.motion.motion import Motion  # noqa: E402


class Grid:
    """A garment-like object: V vertices, no faces needed for the store's checks beyond shape."""

    def __init__(self, num_verts: int):
        self.verts = np.random.default_rng(0).normal(0, 0.2, (num_verts, 3)).astype(np.float32)
        self.faces = np.stack([np.arange(num_verts - 2), np.arange(1, num_verts - 1), np.arange(2, num_verts)], 1)
        self.pinned = np.zeros(num_verts, bool)
        self.kind, self.params, self.name = "skirt", {}, "bench"


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequences", type=int, default=16)
    ap.add_argument("--frames", type=int, default=180)
    ap.add_argument("--vertices", type=int, default=3000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rng = np.random.default_rng(1)
    with tempfile.TemporaryDirectory() as tmp:
        store = DatasetStore.create(Path(tmp) / "bench.zarr")
        store.add_garment("g", Grid(args.vertices))
        store.add_body("b", np.full(6, 0.5, np.float32))
        T = args.frames
        store.add_motion("m", Motion(np.zeros((T, 31, 3)), np.zeros((T, 3)), 30.0, "cmu_mb", [f"j{i}" for i in range(31)], "m"))
        write = []
        for i in range(args.sequences):
            # cloth-like: a smooth path per vertex (cumulative small steps), millimetre noise
            verts = (np.cumsum(rng.normal(0, 0.002, (T, args.vertices, 3)), 0) + store.garment("g").verts).astype(np.float32)
            t = time.perf_counter()
            store.write_sequence(f"s{i:03d}", verts, "g", "b", "m", {}, {}, "train")
            write.append(time.perf_counter() - t)
        seq_dir = store.path / "sequences" / "s000"
        checksum_s = best(lambda: file_checksums(seq_dir, ("verts",)), args.repeat)
        raw = args.sequences * T * args.vertices * 3 * 4
        info = store.info()
        assert info["problems"] == {}, info["problems"]
        result = {
            "sequences": args.sequences, "frames": T, "vertices": args.vertices,
            "raw_mb": raw / 1e6, "stored_mb": info["size_bytes"] / 1e6,
            "write_s": float(np.median(write)), "checksum_s": checksum_s,
            "info_metadata_s": best(lambda: store.info(verify=False), args.repeat),
            "info_verify_s": best(store.info, args.repeat),
            "read_all_s": best(lambda: [store.sequence(n).verts[:] for n in store.sequence_names()], args.repeat),
        }
        for name in store.sequence_names():  # as if written before checksums existed
            attrs_file = store.path / "sequences" / name / ".zattrs"
            attrs = json.loads(attrs_file.read_text())
            del attrs["checksums"]
            attrs_file.write_text(json.dumps(attrs))
        result["info_decode_s"] = best(store.info, args.repeat)
        result["verify_mb_per_s"] = info["size_bytes"] / 1e6 / result["info_verify_s"]
        result["decode_mb_per_s"] = raw / 1e6 / result["info_decode_s"]
        store.close()
    save_results("store_verify", result)


if __name__ == "__main__":
    main()
