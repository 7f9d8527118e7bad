"""Every paper equation loosefit implements is tagged at its code line: a comment naming the paper and the number."""

from __future__ import annotations

import re
import tokenize
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "loosefit"

#: The numbered equations of each paper (../shared/papers) that loosefit computes. Left out: SwinGar Eq. 1 (the
#: problem statement), Eqs. 3 and 5 (bounds, not computed); FitGar Eqs. 1-2 (the SMPL body, smplx's own code).
IMPLEMENTED = {
    "SwinGar": [2, 4, 6, 7, 8, 9, 10, 11, 12, 13, 14],
    "VirtualBones": [1, 2, 3, 4],
    "JointNet": [1, 2, 3, 4, 5, 6, 7, 8],
    "FitGar": [3, 4, 5, 6, 7, 8, 9],
}
TAG = re.compile(r"\b(SwinGar|VirtualBones|JointNet|FitGar)(?:'s)? Eqs?\. (\d+)(?:-(\d+))?")


def comment_tags() -> dict[str, set[int]]:
    """``paper -> equation numbers`` named in the package's comments (not docstrings); ``Eqs. 3-4`` counts both."""
    tags: dict[str, set[int]] = {}
    for path in SRC.rglob("*.py"):
        with path.open() as f:
            for tok in tokenize.generate_tokens(f.readline):
                if tok.type == tokenize.COMMENT:
                    for paper, first, last in TAG.findall(tok.string):
                        tags.setdefault(paper, set()).update(range(int(first), int(last or first) + 1))
    return tags


def test_every_implemented_equation_has_a_tagged_code_line():
    tags = comment_tags()
    missing = {paper: sorted(set(numbers) - tags.get(paper, set())) for paper, numbers in IMPLEMENTED.items()}
    assert not any(missing.values()), missing


def test_tags_name_equations_the_papers_have():
    """A tag of an equation number its paper does not have is a typo (VirtualBones has 4 numbered equations,
    JointNet 8, FitGar 9, SwinGar 14)."""
    last = {"VirtualBones": 4, "JointNet": 8, "FitGar": 9, "SwinGar": 14}
    bad = {paper: sorted(n for n in numbers if not 1 <= n <= last[paper]) for paper, numbers in comment_tags().items()}
    assert not any(bad.values()), bad
