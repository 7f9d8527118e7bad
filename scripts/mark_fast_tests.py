"""Measure the test suite and choose its fast subset: ``tests/fast_tests.txt``, the tests that
``pytest -m "not slow"`` runs (``tests/conftest.py`` marks every other test ``slow``).

The subset is chosen by measurement, on a budget of seconds, with the fixtures counted once. A test's time in a
run depends on what ran before it (an expensive session fixture, such as a simulated store, is paid by the first
test asking for it), so the whole suite is measured with ``scripts/fixture_costs.py``: each test's own seconds
and each fixture instance's setup seconds, apart. A subset costs its tests' own seconds plus, once, the fixtures
any of them needs. The choice is greedy on that cost: first every test file's cheapest test (so that every
module stays covered; a file whose cheapest test costs more than ``--cap`` is left out), then the test that adds
the least, again and again, while the subset's cost stays within ``--budget``. The subset is then run alone and
its wall time saved with the times in ``benchmarks/results/test-durations.json``. Run it on an idle machine after
adding tests::

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
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIST = ROOT / "tests" / "fast_tests.txt"
RESULTS = ROOT / "benchmarks" / "results" / "test-durations.json"
HEADER = ("# The fast subset (pytest -m 'not slow'): chosen by scripts/mark_fast_tests.py from measured times;\n"
          "# every test not listed here is marked slow. Regenerate it there, do not edit it by hand.\n")


def measure(args: list[str]) -> tuple[dict, float, int]:
    """Run pytest with ``args`` and the fixture-cost plugin; return its record (``tests``: each test's own
    seconds and fixture instances; ``fixtures``: each instance's seconds), the wall time and the exit status."""
    with tempfile.TemporaryDirectory() as tmp:
        record = Path(tmp, "costs.json")
        env = dict(os.environ, FIXTURE_COSTS_JSON=str(record),
                   PYTHONPATH=os.pathsep.join([str(ROOT / "scripts"), os.environ.get("PYTHONPATH", "")]))
        start = time.perf_counter()
        rc = subprocess.call([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "fixture_costs",
                              *args], cwd=ROOT, env=env)
        wall = time.perf_counter() - start
        costs = json.loads(record.read_text())
    return costs, wall, rc


def subset_cost(chosen, costs: dict) -> float:
    """Seconds of ``chosen`` tests run alone: their own seconds plus every fixture instance they need, once."""
    tests, fixtures = costs["tests"], costs["fixtures"]
    needed = {k for n in chosen for k in tests[n]["fixtures"]}
    return sum(tests[n]["own"] for n in chosen) + sum(fixtures.get(k, 0.0) for k in needed)


def choose(costs: dict, budget: float, cap: float) -> set[str]:
    """Each file's cheapest test (if it adds at most ``cap``), then the cheapest additions within ``budget``."""
    tests, fixtures = costs["tests"], costs["fixtures"]
    have: set[str] = set()  # fixture instances the chosen tests already pay for

    def adds(node: str) -> float:
        return tests[node]["own"] + sum(fixtures.get(k, 0.0) for k in set(tests[node]["fixtures"]) - have)

    chosen: set[str] = set()
    spent = 0.0
    by_file: dict[str, list[str]] = defaultdict(list)
    for node in tests:
        by_file[node.split("::")[0]].append(node)
    # files in order of their cheapest test alone, so that cheap files share fixtures first
    for nodes in sorted(by_file.values(), key=lambda ns: min(map(adds, ns))):
        best = min(nodes, key=adds)
        if adds(best) <= cap:
            spent += adds(best)
            chosen.add(best)
            have.update(tests[best]["fixtures"])
    rest = set(tests) - chosen
    while rest:
        best = min(rest, key=adds)
        if spent + adds(best) > budget:
            break
        spent += adds(best)
        chosen.add(best)
        have.update(tests[best]["fixtures"])
        rest.discard(best)
    return chosen


def write_list(fast: set[str]) -> None:
    LIST.write_text(HEADER + "".join(f"{n}\n" for n in sorted(fast)))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--budget", type=float, default=120.0, help="seconds the chosen tests cost, fixtures once, at most")
    p.add_argument("--cap", type=float, default=15.0, help="a file whose cheapest test adds more is left out")
    p.add_argument("--from-json", action="store_true", help="choose from the times saved by the last measurement")
    a = p.parse_args()
    if a.from_json:
        saved = json.loads(RESULTS.read_text())
        costs, suite = saved["costs"], saved["suite"]
    else:
        LIST.unlink(missing_ok=True)  # no list: nothing is marked slow, the whole suite runs
        costs, wall, rc = measure(["tests"])
        suite = {"tests": len(costs["tests"]), "wall_s": round(wall, 1), "exit": rc}
        print(f"whole suite: {suite['tests']} tests in {wall:.0f} s (exit {rc})")
        save(costs, suite, {}, a)  # kept at once: choosing again (--from-json) needs no second whole run
    fast = choose(costs, a.budget, a.cap)
    write_list(fast)
    predicted = subset_cost(fast, costs)
    fast_costs, wall, rc = measure(["tests", "-m", "not slow"])
    files = {n.split("::")[0] for n in fast_costs["tests"]}
    subset = {"tests": len(fast_costs["tests"]), "test_files": len(files),
              "test_files_in_suite": len({n.split("::")[0] for n in costs["tests"]}),
              "predicted_s": round(predicted, 1), "wall_s": round(wall, 1), "exit": rc}
    print(f"fast subset: {subset['tests']} tests from {len(files)} files, predicted {predicted:.0f} s, "
          f"ran in {wall:.0f} s (exit {rc})")
    save(costs, suite, subset, a)
    return rc


def save(costs: dict, suite: dict, subset: dict, a: argparse.Namespace) -> None:
    RESULTS.write_text(json.dumps({
        "machine": {"platform": platform.platform(), "python": platform.python_version(), "cpus": os.cpu_count(),
                    "load_average": os.getloadavg(), "date": time.strftime("%Y-%m-%d %H:%M:%S")},
        "settings": {"budget_s": a.budget, "cap_s": a.cap}, "suite": suite, "fast_subset": subset,
        "costs": costs}, indent=1) + "\n")


if __name__ == "__main__":
    sys.exit(main())
