"""The robustness matrix: every verb and every format loosefit reads, fed bad input, crafted payloads,
numerical extremes and valid controls, each through the command line in a subprocess.

The cases live in ``tests/robustness/`` (shared with the pytest suite there, which runs the defect
families of the fixes); their classification is in :mod:`tests.robustness.harness`. This script makes
the expensive shared inputs once through the command line under test (a tiny simulated and prepared
store, a tiny trained virtualbones run, a motion, its animation and a garment: about 2 minutes), runs
every case on a pool of ``--workers`` subprocesses, and writes ``benchmarks/results/robustness.json``
(``robustness-<label>.json`` with ``--label``): counts per outcome, per kind of input, per family, the
defect cases that still fail grouped by the fix that owns them, and one record per case.

    .venv/bin/python benchmarks/robustness.py                                   # the working tree
    .venv/bin/python benchmarks/robustness.py --src /tmp/before/src --label before   # another tree
    .venv/bin/python benchmarks/robustness.py --only smpl --label smpl           # cases matching a pattern

The whole matrix takes 20-40 minutes on 2 shared cores (most cases load the body model: 5-10 s each).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _common import RESULTS, machine  # noqa: E402
from tests.conftest import TINY_PLAN  # noqa: E402
from tests.robustness.cases_pipeline import GARMENT, TINY_TRAIN  # noqa: E402
from tests.robustness.catalog import all_cases, good_outcomes, result_meta, select  # noqa: E402
from tests.robustness.harness import CONTROL_OUTCOMES, OUTCOMES, Result, Shared, counts, run_cases  # noqa: E402


def build_shared(root: Path, python: str, src: str | None, reuse: bool = False) -> Shared:
    """The shared inputs, made through the command line under test (two chains on two workers); with
    ``reuse``, those an earlier run left in ``root`` (when complete)."""
    sh = Shared(root=root, store=root / "tiny.zarr", run=root / "run", motion=root / "walk.npz",
                seq=root / "walk-anim.npz", garment=root / "garment" / "skirt.obj", plan=root / "tiny.yaml",
                python=python, src=src)
    if reuse and sh.seq.is_file() and sh.garment.is_file():
        return sh
    if root.exists():
        shutil.rmtree(root)  # made again from scratch: an earlier run's store and run folder would be refused
    root.mkdir(parents=True)
    sh.plan.write_text(TINY_PLAN)
    chains = [
        [["simulate", str(sh.plan), "--out", str(sh.store)],
         ["prepare", str(sh.store), "--bones", "6"],
         ["train", "--method", "virtualbones", "--data", str(sh.store), "--garment", GARMENT, "--out", str(sh.run),
          *TINY_TRAIN]],
        [["motion", "generate", "--kind", "walk", "--seconds", "1.5", "--seed", "0", "--out", str(sh.motion)],
         ["garment", "make", "--kind", "skirt", "--seed", "0", "--edge-length", "0.05", "--param", "length=0.45",
          "--param", "flare=25", "--out", str(sh.garment)]],
    ]

    def run_chain(chain):
        for argv in chain:
            t0 = time.perf_counter()
            proc = subprocess.run(sh.command(argv), cwd=root, env=sh.env(), capture_output=True, text=True)
            print(f"  shared: loosefit {argv[0]} {argv[1]}: exit {proc.returncode}, {time.perf_counter() - t0:.0f} s",
                  flush=True)
            if proc.returncode != 0:
                raise RuntimeError(f"making the shared inputs failed: loosefit {' '.join(argv)}\n{proc.stderr[-3000:]}")

    with ThreadPoolExecutor(2) as pool:
        for f in [pool.submit(run_chain, c) for c in chains]:
            f.result()
    run_chain([["animate", str(sh.run), "--motion", str(sh.motion), "--out", str(sh.seq)]])
    return sh


def revision(src: str | None) -> str:
    tree = Path(src).parent if src else ROOT
    try:
        rev = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(tree), "status", "--porcelain", "--", "src"], capture_output=True,
                               text=True).stdout.strip()
        return rev + (" + uncommitted changes in src/" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def summarise(results: list[Result], cases, seconds: float, src: str | None) -> dict:
    meta = result_meta(cases)
    good = good_outcomes(cases)
    by_kind, by_family = {}, {}
    for r in results:
        m = meta[r.name]
        by_kind.setdefault(m.kind, []).append(r)
        by_family.setdefault(r.name.split("/", 1)[0], []).append(r)
    failing = {}
    for r in results:
        m = meta[r.name]
        if r.outcome not in good[r.name]:
            failing.setdefault(m.brief or "none", []).append(
                {"name": r.name, "outcome": r.outcome, "defect": m.defect, "problem": r.problem,
                 "first_stderr_line": r.first_stderr_line()[:300]})
    return {
        "source": src or "working tree",
        "revision": revision(src),
        "cases": len(results),
        "counts": counts(results),
        "counts_by_kind": {k: counts(v) for k, v in sorted(by_kind.items())},
        "counts_by_family": {k: {o: n for o, n in counts(v).items() if n} for k, v in sorted(by_family.items())},
        "not_handled_well": {k: failing[k] for k in sorted(failing)},
        "seconds": round(seconds),
        "list": [r.record() for r in results],
    }


def write_results(name: str, results: dict) -> Path:
    path = RESULTS / f"{name}.json"
    payload = {"benchmark": name, "machine": machine(), "results": results}
    fd, tmp = tempfile.mkstemp(dir=RESULTS, prefix=f".{name}.", suffix=".json")
    with os.fdopen(fd, "w") as f:
        json.dump(payload, f, indent=1)
    os.chmod(tmp, 0o644)
    os.replace(tmp, path)
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--label", default=None, help="results file robustness-LABEL.json (default robustness.json)")
    ap.add_argument("--only", default=None, metavar="PATTERN",
                    help="cases whose name matches (comma-separated globs or words)")
    ap.add_argument("--src", default=None, metavar="PATH", help="run the command line with PYTHONPATH=PATH (an older tree)")
    ap.add_argument("--workers", type=int, default=2, help="cases run at once (each a subprocess)")
    ap.add_argument("--work", default=None, help="scratch folder (default: a temporary one, removed afterwards)")
    ap.add_argument("--reuse-shared", action="store_true", help="with --work: reuse the shared inputs an earlier "
                    "run left there (made with the same --src)")
    args = ap.parse_args()
    if args.workers < 1:
        ap.error("--workers must be >= 1")
    src = str(Path(args.src).resolve()) if args.src else None
    cases = select(all_cases(), args.only)
    if not cases:
        ap.error(f"no case matches {args.only!r}")
    name = "robustness" + (f"-{args.label}" if args.label else "")
    with tempfile.TemporaryDirectory(prefix="robustness-") as tmp:
        work = Path(args.work).resolve() if args.work else Path(tmp)
        t0 = time.perf_counter()
        print(f"making the shared inputs with {src or 'the working tree'} ...", flush=True)
        shared = build_shared(work / "shared", sys.executable, src, reuse=args.reuse_shared and bool(args.work))
        print(f"running {len(cases)} cases on {args.workers} workers ...", flush=True)
        lock = threading.Lock()

        def progress(r: Result) -> None:
            with lock:
                print(f"  {r.outcome:15s} {r.seconds:5.0f} s  {r.name}" + (f"  ({r.problem})" if r.problem else ""),
                      flush=True)

        results = run_cases(cases, work / "cases", shared, workers=args.workers, progress=progress)
        summary = summarise(results, cases, time.perf_counter() - t0, src)
    path = write_results(name, summary)
    print(json.dumps({k: summary[k] for k in ("source", "revision", "cases", "counts", "counts_by_kind")}, indent=1))
    for brief, items in summary["not_handled_well"].items():
        print(f"not handled well ({brief}): " + ", ".join(f"{i['name']} [{i['outcome']}]" for i in items))
    print(f"wrote {path}")
    assert set(OUTCOMES) | set(CONTROL_OUTCOMES) <= set(summary["counts"])


if __name__ == "__main__":
    main()
