"""Every robustness case, and what each result name stands for (its kind, the brief owning its defect
family, whether the pytest suite runs it)."""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass

from tests.robustness.cases_files import body_cases, garment_cases, motion_cases
from tests.robustness.cases_hostile import hostile_brief_cases
from tests.robustness.cases_outputs import (REQUESTS, animate_cases, evaluate_cases, other_cases, render_cases,
                                            report_cases, view_cases)
from tests.robustness.cases_pipeline import simulate_cases, store_cases, train_cases
from tests.robustness.harness import Case, Result, error_line


def all_cases() -> list[Case]:
    cases = [*body_cases(), *motion_cases(), *garment_cases(), *store_cases(), *simulate_cases(), *train_cases(),
             *animate_cases(), *evaluate_cases(), *render_cases(), *report_cases(), *view_cases(), *other_cases(),
             *hostile_brief_cases()]
    names = [n for c in cases for n in (c.results or (c.name,))]
    duplicated = {n for n in names if names.count(n) > 1}
    assert not duplicated, f"case names used twice: {sorted(duplicated)}"
    return cases


@dataclass(frozen=True)
class Meta:
    """What one result name stands for."""

    kind: str  # "bad", "control" or "extreme"
    brief: str  # "store", "inputs", "viewer", "hostile" or ""
    defect: bool  # a defect family of one of the briefs: the pytest suite runs it


def result_meta(cases: list[Case]) -> dict[str, Meta]:
    """Each result name's :class:`Meta` (a server case gives one per request)."""
    meta = {}
    requests = {r.name: r for r in REQUESTS}
    for case in cases:
        for name in case.results or (case.name,):
            req = requests.get(name)
            if req is not None:
                meta[name] = Meta("control" if req.control else "bad", case.brief, req.defect)
            else:
                meta[name] = Meta(case.kind, case.brief, case.defect)
    return meta


def select(cases: list[Case], pattern: str | None) -> list[Case]:
    """The cases with a result name matching ``pattern``: comma-separated globs (a plain word: containing it)."""
    if not pattern:
        return cases
    globs = [p if any(ch in p for ch in "*?[") else f"*{p}*" for p in pattern.split(",") if p]
    return [c for c in cases if any(fnmatch.fnmatch(n, g) for n in c.results or (c.name,) for g in globs)]


def good_outcomes(cases: list[Case]) -> dict[str, tuple[str, ...]]:
    """Each result name's acceptable outcomes (a server request: ``ok`` for a valid one, else ``clear_errors``)."""
    requests = {r.name: r for r in REQUESTS}
    good = {}
    for case in cases:
        for name in case.results or (case.name,):
            req = requests.get(name)
            good[name] = case.good() if req is None else ("ok",) if req.control else ("clear_errors",)
    return good


def defect_names(brief: str) -> list[str]:
    """The result names of one brief's defect families, in the catalogue's order."""
    return [name for name, meta in result_meta(all_cases()).items() if meta.defect and meta.brief == brief]


def assert_handled(result: Result, good: tuple[str, ...]) -> None:
    """The documented behaviour: an acceptable outcome; a refusal is exit 2 with exactly one error line,
    naming the file or argument (no traceback, nothing written, nothing changed: those are outcomes)."""
    assert result.outcome in good, result.describe()
    if result.outcome == "clear_errors" and result.returncode == 2:
        assert not result.problem, result.describe()
        lines = [ln for ln in result.stderr.splitlines() if ": error: " in ln]
        assert len(lines) == 1 and lines[0].strip().endswith(error_line(result.stderr)), result.describe()
