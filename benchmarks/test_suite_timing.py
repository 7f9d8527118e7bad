"""Time ``make test``'s pytest command and add the run to ``benchmarks/results/test-suite-timing.json``.

The suite must stay under 15 minutes on 2 cores with the first install; run this on an idle machine (the load
average before and after is recorded, so a loaded run reads as one)::

    .venv/bin/python benchmarks/test_suite_timing.py --label "whole, make test, idle"
    .venv/bin/python benchmarks/test_suite_timing.py --fast --label "fast subset, make test-fast, idle"

Each run is kept under its label, with pytest's counts, its own seconds, the wall time and the load.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

from _common import RESULTS, save_results

ROOT = Path(__file__).resolve().parents[1]
COMMAND = [sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "loadscope"]
_SUMMARY = re.compile(r"=*\s*(?P<counts>(?:\d+ \w+(?:, )?)+) in (?P<seconds>[\d.]+)s")


def summary(output: str) -> dict:
    """pytest's last summary line as ``{"passed": n, ..., "pytest_s": s}`` (empty if there is none)."""
    found = list(_SUMMARY.finditer(output))
    if not found:
        return {}
    last = found[-1]
    counts = {word: int(n) for n, word in re.findall(r"(\d+) (\w+)", last.group("counts"))}
    return {**counts, "pytest_s": float(last.group("seconds"))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--label", required=True, help="the run's name in the JSON")
    ap.add_argument("--fast", action="store_true", help="the fast subset (-m 'not slow') instead of everything")
    args = ap.parse_args()
    command = COMMAND + (["-m", "not slow"] if args.fast else []) + ["tests"]
    load_before = os.getloadavg()[0]
    start = time.perf_counter()
    proc = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - start
    print(proc.stdout[-2000:])
    run = {"command": " ".join(["pytest", *command[3:]]), "date": time.strftime("%Y-%m-%d %H:%M"), "exit": proc.returncode,
           **summary(proc.stdout), "wall_s": round(wall, 1), "load_average_before": round(load_before, 2),
           "load_average_after": round(os.getloadavg()[0], 2)}
    path = RESULTS / "test-suite-timing.json"
    old = json.loads(path.read_text()) if path.exists() else {}
    runs = dict(old["results"]["runs"]) if old else {}
    runs[args.label] = run
    save_results("test-suite-timing", {"runs": runs})


if __name__ == "__main__":
    main()
