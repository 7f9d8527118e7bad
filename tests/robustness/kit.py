"""Short constructors for the case tables, and the checks they share."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from tests.robustness.harness import Case, Ctx, tree_hash


def bad(name: str, argv: list[str], setup=None, **kw) -> Case:
    """A bad input: must be refused clearly (or repaired, when ``report`` / ``fixes`` say so)."""
    return Case(name, argv, setup, kind="bad", **kw)


def ext(name: str, argv: list[str], setup=None, **kw) -> Case:
    """A numerical extreme (NaN, inf, a huge or tiny size): handled like a bad input."""
    return Case(name, argv, setup, kind="extreme", **kw)


def ok(name: str, argv: list[str], setup=None, **kw) -> Case:
    """A valid control: must succeed (and pass its check)."""
    return Case(name, argv, setup, kind="control", **kw)


def also(*setups):
    """Several setup steps in order."""
    def setup(tmp, sh):
        for step in setups:
            step(tmp, sh)
    return setup


# ---------------------------------------------------------------------------------------------- checks


def wrote(*paths: str):
    """The command wrote each of ``paths`` (``{tmp}``-style templates), non-empty."""
    def check(c: Ctx):
        missing = [p for p in (q.format(**c.shared.tokens(c.tmp)) for q in paths)
                   if not Path(p).exists() or (Path(p).is_file() and Path(p).stat().st_size == 0)]
        return f"did not write {', '.join(missing)}" if missing else None
    return check


def no_warning(c: Ctx):
    """Nothing on stderr says ``warning`` (a valid input must not raise a false alarm)."""
    hits = [ln for ln in c.result.stderr.splitlines() if "warning" in ln.lower() and "warp" not in ln.lower()]
    return f"a false alarm: {hits[0].strip()}" if hits else None


def both(*checks):
    def check(c: Ctx):
        for one in checks:
            problem = one(c)
            if problem:
                return problem
        return None
    return check


def lists_problem(store: str = "d.zarr", split: str = "train"):
    """``info`` output names the damaged sequence of ``split`` among its problems (after the word
    ``problems``), not ``problems: none``."""
    def check(c: Ctx):
        from tests.robustness.craft import sequence_named

        seq = sequence_named(c.shared.store, split)
        text = c.result.output
        if c.result.returncode == 0 and ("problems: none" in text or seq not in text.split("problems", 1)[-1]):
            return f"the damaged sequence {seq} is not among the problems"
        return None
    return check


def reads_back(store: str = "d.zarr", split: str = "train"):
    """Every chunk of the ``split`` sequence's ``verts`` decodes to finite numbers of the recorded shape
    (a resumed plan re-simulated the damaged sequence)."""
    def check(c: Ctx):
        import zarr

        from tests.robustness.craft import sequence_named

        seq = sequence_named(c.shared.store, split)
        path = c.tmp / store / "sequences" / seq / "verts"
        try:
            verts = zarr.open_array(str(path), mode="r")[:]
        except Exception as e:  # noqa: BLE001 - any decoding failure is the finding
            return f"sequence {seq} still does not read back ({type(e).__name__}: {e})"
        if verts.dtype == object or not np.isfinite(verts).all():
            return f"sequence {seq} still holds unreadable or non-finite vertices"
        return None
    return check


def repaired_store(store: str = "d.zarr", split: str = "train"):
    """The damaged ``split`` sequence is gone and every other sequence is bit-identical to the shared
    store's."""
    def check(c: Ctx):
        from tests.robustness.craft import sequence_named, sequences

        bad = sequence_named(c.shared.store, split)
        root = c.tmp / store / "sequences"
        if (root / bad).exists() and (root / bad / ".zattrs").exists():
            return f"the damaged sequence {bad} is still in the store"
        for name in sequences(c.shared.store):
            if name != bad and tree_hash(root / name) != tree_hash(c.shared.store / "sequences" / name):
                return f"sequence {name} changed"
        if bad not in c.result.output:
            return f"the output does not say that {bad} was dropped"
        return None
    return check


def gone(*patterns: str):
    """No file matches the glob ``patterns`` (relative to the scratch folder) after the command."""
    def check(c: Ctx):
        left = [str(p.relative_to(c.tmp)) for pat in patterns for p in c.tmp.glob(pat)]
        return f"left behind: {', '.join(left)}" if left else None
    return check


def json_at(path: Path) -> dict:
    return json.loads(path.read_text())
