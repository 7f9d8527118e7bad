"""The benchmarks' documentation stays navigable: ``benchmarks/README.md`` holds at most 600 lines, every link
of the top-level README, ``docs/``, ``benchmarks/README.md`` and ``benchmarks/experiments/LOG.md`` to a file or
to a section resolves (sections by GitHub's heading anchors), every row of the top-level numbers table links to
the section that measured it, and every file in ``benchmarks/results/`` is cited where a reader or the code looks
(the docs above, ``src/``, ``tests/``, ``scripts/``)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BENCH_README = REPO / "benchmarks" / "README.md"
LOG = REPO / "benchmarks" / "experiments" / "LOG.md"
RESULTS = REPO / "benchmarks" / "results"
MAX_LINES = 600
#: Text files whose mention of a result's name counts as citing it.
CITING_DIRS = ("docs", "src", "tests", "scripts")
CITING_SUFFIXES = {".md", ".py", ".yaml", ".yml", ".txt", ".sh", ".j2", ".html", ".js", ".toml"}

LINK = re.compile(r"\[[^\]]*\]\(([^()\s]+)\)")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
RESULT_NAME = re.compile(r"`([\w.+-]+\.(?:json|png))`")


def documents() -> list[Path]:
    """The Markdown files whose links are checked."""
    return [REPO / "README.md", *sorted((REPO / "docs").glob("**/*.md")), BENCH_README, LOG]


def prose_lines(path: Path) -> list[str]:
    """The lines of a Markdown file outside fenced code blocks (``# comment`` in a shell block is no heading)."""
    lines, fenced = [], False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        lines.append("" if fenced else line)
    return lines


def github_anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, every character but letters, digits, ``_``, ``-`` and spaces
    dropped (backticks, dots, commas, colons, apostrophes ...), spaces turned into ``-``."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a Markdown file, repeated headings numbered ``-1``, ``-2`` as GitHub does."""
    seen: dict[str, int] = {}
    out = set()
    for line in prose_lines(path):
        match = HEADING.match(line)
        if not match:
            continue
        anchor = github_anchor(match.group(2))
        if anchor in seen:
            seen[anchor] += 1
            anchor = f"{anchor}-{seen[anchor]}"
        else:
            seen[anchor] = 0
        out.add(anchor)
    return out


def broken_links(path: Path) -> list[str]:
    """``line: target (why)`` for each relative link of ``path`` whose file or section does not exist."""
    broken = []
    for number, line in enumerate(prose_lines(path), 1):
        for target in LINK.findall(line):
            if re.match(r"^[a-z]+:", target):  # https:, mailto:
                continue
            file_part, _, anchor = target.partition("#")
            linked = (path.parent / file_part).resolve() if file_part else path
            if not linked.exists():
                broken.append(f"{number}: {target} (no such file)")
            elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
                broken.append(f"{number}: {target} (no such section in {linked.name})")
    return broken


def test_github_anchor_matches_the_headings_the_readme_links_to():
    assert github_anchor("Real capture, held-out subjects (`bench-real`, `accuracy-real-skirt.json`)") == \
        "real-capture-held-out-subjects-bench-real-accuracy-real-skirtjson"
    assert github_anchor("On an H100: the paper's SwinGar at 0.64x body-LBS on unseen garments") == \
        "on-an-h100-the-papers-swingar-at-064x-body-lbs-on-unseen-garments"
    assert github_anchor("Garments made for other bodies, fitted (`garment_fit.py`)") == \
        "garments-made-for-other-bodies-fitted-garment_fitpy"


def test_link_check_finds_a_missing_file_and_a_missing_section(tmp_path):
    doc = tmp_path / "doc.md"
    doc.write_text("# Title\n\n## A section (`x.py`)\n\n[ok](#a-section-xpy) [gone](#nowhere) [file](missing.json)\n"
                   "```\n# not a heading\n[in code](nothing.md)\n```\n[self](doc.md#title)\n", encoding="utf-8")
    assert anchors(doc) == {"title", "a-section-xpy"}
    assert broken_links(doc) == ["5: #nowhere (no such section in doc.md)", "5: missing.json (no such file)"]


def test_benchmarks_readme_is_at_most_600_lines():
    lines = BENCH_README.read_text(encoding="utf-8").count("\n")
    assert lines <= MAX_LINES, f"benchmarks/README.md has {lines} lines (at most {MAX_LINES}): move finished " \
                               "investigations to benchmarks/experiments/LOG.md"


@pytest.mark.parametrize("doc", documents(), ids=lambda p: str(p.relative_to(REPO)))
def test_every_link_to_a_file_or_section_resolves(doc):
    assert broken_links(doc) == []


@pytest.mark.parametrize("doc", [BENCH_README, LOG], ids=lambda p: str(p.relative_to(REPO)))
def test_every_result_named_in_the_benchmark_docs_exists(doc):
    present = {p.name for p in RESULTS.rglob("*") if p.is_file()}
    named = {name for line in prose_lines(doc) for name in RESULT_NAME.findall(line)}
    assert sorted(named - present) == []


def test_every_row_of_the_numbers_table_links_to_its_benchmark_section():
    lines = prose_lines(REPO / "README.md")
    start = lines.index("## The numbers")
    rows = [line for line in lines[start:] if line.startswith("| ") and not line.startswith("| what was measured")]
    assert len(rows) >= 5
    for row in rows:
        first_cell = row.split("|")[1]
        assert re.search(r"\]\(benchmarks/README\.md#[\w-]+\)", first_cell), row


def citing_text() -> str:
    """Everything a result can be cited from, as one string."""
    files = [REPO / "README.md", BENCH_README, LOG]
    for folder in CITING_DIRS:
        files += [p for p in (REPO / folder).rglob("*") if p.is_file() and p.suffix in CITING_SUFFIXES]
    return "\n".join(p.read_text(encoding="utf-8", errors="replace") for p in files)


def test_every_result_file_is_cited():
    text = citing_text()
    uncited = []
    for path in sorted(p for p in RESULTS.rglob("*") if p.is_file()):
        # by file name anywhere, or (the claims table, the report tests) by its stem as a quoted string
        if path.name not in text and f'"{path.stem}"' not in text and f"'{path.stem}'" not in text:
            uncited.append(str(path.relative_to(RESULTS)))
    assert uncited == [], "cited nowhere (cite them in benchmarks/README.md or experiments/LOG.md, or git rm them)"
