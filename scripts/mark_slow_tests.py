"""Measure the test suite and write ``tests/slow_tests.txt``: the tests ``pytest -m "not slow"`` leaves out.

A test is slow when its setup, call and teardown take more than ``--seconds`` (default 1.5 s) on this machine.
A session or module fixture's cost lands on the first test that uses it, so leaving that test out moves the
cost to the next one: after the whole suite, the script runs the fast subset again and adds what is still slow,
until the fast subset holds no slow test (at most ``--rounds`` times). The list is plain node ids, one a line;
``tests/conftest.py`` marks them ``slow``. Run it on an idle machine after adding slow tests::

    .venv/bin/python scripts/mark_slow_tests.py              # the whole suite, then the fast subset
    .venv/bin/python scripts/mark_slow_tests.py --fast-only  # keep the list, re-measure the fast subset only
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIST = ROOT / "tests" / "slow_tests.txt"
HEADER = ("# Tests left out of the fast subset (pytest -m 'not slow'): each took more than {seconds:g} s "
          "(setup + call + teardown)\n# when measured by scripts/mark_slow_tests.py; regenerate it there, "
          "do not edit it by hand.\n")


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


def write_list(slow: set[str], seconds: float) -> None:
    LIST.write_text(HEADER.format(seconds=seconds) + "".join(f"{n}\n" for n in sorted(slow)))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seconds", type=float, default=1.5, help="a test slower than this is slow")
    p.add_argument("--rounds", type=int, default=4, help="fast-subset re-measurements at most")
    p.add_argument("--fast-only", action="store_true", help="keep the current list and re-measure the fast subset")
    a = p.parse_args()
    existing = {line.strip() for line in LIST.read_text().splitlines() if line.strip() and not line.startswith("#")} \
        if LIST.is_file() else set()
    slow = set(existing) if a.fast_only else set()
    if not a.fast_only:
        times, wall, rc = measure(["tests"])
        slow = {n for n, t in times.items() if t > a.seconds}
        print(f"whole suite: {len(times)} tests in {wall:.0f} s (exit {rc}); {len(slow)} slower than {a.seconds:g} s")
        write_list(slow, a.seconds)
    for _ in range(a.rounds):
        times, wall, rc = measure(["tests", "-m", "not slow"])
        more = {n for n, t in times.items() if t > a.seconds}
        print(f"fast subset: {len(times)} tests in {wall:.0f} s (exit {rc}); {len(more)} still slower than {a.seconds:g} s")
        if not more:
            break
        slow |= more
        write_list(slow, a.seconds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
