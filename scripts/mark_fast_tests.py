"""Measure the test suite and choose its fast subset: ``tests/fast_tests.txt``, the tests that
``pytest -m "not slow"`` runs (``tests/conftest.py`` marks every other test ``slow``).

The subset is chosen by measurement, on a budget: every test file keeps its quickest test (so that every
module stays covered), then the quickest of the rest join until their measured seconds (setup, call and
teardown) reach ``--budget``. A test that needs an expensive fixture is never quick: the fixture's cost lands
on the first test using it. The script then runs the chosen subset alone, drops what measured slower than
``--cap`` there (a fixture's cost moved to it), and saves the times and the subset's wall time in
``benchmarks/results/test-durations.json``. Run it on an idle machine after adding tests::

    .venv/bin/python scripts/mark_fast_tests.py                 # measure everything, choose, check
    .venv/bin/python scripts/mark_fast_tests.py --from-json     # choose again from the saved times, check
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIST = ROOT / "tests" / "fast_tests.txt"
RESULTS = ROOT / "benchmarks" / "results" / "test-durations.json"
HEADER = ("# The fast subset (pytest -m 'not slow'): chosen by scripts/mark_fast_tests.py from measured times;\n"
          "# every test not listed here is marked slow. Regenerate it there, do not edit it by hand.\n")


def node_id(case: ET.Element) -> str:
    """The pytest node id of a JUnit ``testcase`` (``classname`` is the dotted file path, then any class)."""
    parts = case.get("classname", "").split(".")
    for k in range(len(parts), 0, -1):  # the longest prefix that is a file
        path = Path(ROOT, *parts[:k]).with_suffix(".py")
        if path.is_file():
            return "::".join([path.relative_to(ROOT).as_posix(), *parts[k:], case.get("name", "")])
    raise ValueError(f"cannot find the file of test {case.get('classname')}::{case.get('name')}")


def measure(args: list[str]) -> tuple[dict[str, float], float, int]:
    """Run pytest with ``args``; return each test's seconds, the wall time and pytest's exit status."""
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp, "junit.xml")
        start = time.perf_counter()
        rc = subprocess.call([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                              "-o", "junit_duration_report=total", f"--junitxml={report}", *args], cwd=ROOT)
        wall = time.perf_counter() - start
        times = {node_id(c): float(c.get("time", 0.0)) for c in ET.parse(report).getroot().iter("testcase")}
    return times, wall, rc


def choose(times: dict[str, float], budget: float, cap: float) -> set[str]:
    """Each file's quickest test (if under ``cap``), then the quickest others until ``budget`` seconds."""
    by_file: dict[str, list[str]] = defaultdict(list)
    for node in times:
        by_file[node.split("::")[0]].append(node)
    chosen = {min(nodes, key=times.get) for nodes in by_file.values()}
    chosen = {n for n in chosen if times[n] <= cap}
    spent = sum(times[n] for n in chosen)
    for node in sorted(set(times) - chosen, key=times.get):
        if spent + times[node] > budget or times[node] > cap:
            break
        chosen.add(node)
        spent += times[node]
    return chosen


def write_list(fast: set[str]) -> None:
    LIST.write_text(HEADER + "".join(f"{n}\n" for n in sorted(fast)))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--budget", type=float, default=90.0, help="measured seconds of the chosen tests, at most")
    p.add_argument("--cap", type=float, default=2.0, help="no test slower than this is fast")
    p.add_argument("--from-json", action="store_true", help="choose from the times saved by the last measurement")
    a = p.parse_args()
    if a.from_json:
        saved = json.loads(RESULTS.read_text())
        times, suite = saved["times"], saved["suite"]
    else:
        LIST.unlink(missing_ok=True)  # no list: nothing is marked slow, the whole suite runs
        times, wall, rc = measure(["tests"])
        suite = {"tests": len(times), "wall_s": round(wall, 1), "exit": rc}
        print(f"whole suite: {len(times)} tests in {wall:.0f} s (exit {rc})")
        save(times, suite, {}, a)  # kept at once: choosing again (--from-json) needs no second whole run
    fast = choose(times, a.budget, a.cap)
    write_list(fast)
    fast_times, wall, rc = measure(["tests", "-m", "not slow"])
    moved = {n for n, t in fast_times.items() if t > a.cap}
    if moved:  # a fixture's cost landed on them: leave them out, measure once more
        write_list(fast - moved)
        fast_times, wall, rc = measure(["tests", "-m", "not slow"])
    files = {n.split("::")[0] for n in fast_times}
    subset = {"tests": len(fast_times), "test_files": len(files), "wall_s": round(wall, 1), "exit": rc,
              "measured_s": round(sum(fast_times.values()), 1), "dropped_after_check": sorted(moved)}
    print(f"fast subset: {subset['tests']} tests from {len(files)} files in {wall:.0f} s (exit {rc})")
    save(times, suite, subset, a)
    return rc


def save(times: dict[str, float], suite: dict, subset: dict, a: argparse.Namespace) -> None:
    RESULTS.write_text(json.dumps({
        "machine": {"platform": platform.platform(), "python": platform.python_version(), "cpus": os.cpu_count(),
                    "date": time.strftime("%Y-%m-%d %H:%M:%S")},
        "settings": {"budget_s": a.budget, "cap_s": a.cap}, "suite": suite, "fast_subset": subset,
        "times": times}, indent=1) + "\n")


if __name__ == "__main__":
    sys.exit(main())
