"""Shared inputs of the robustness cases (from the session's tiny store), and the cases the collected
tests ask for, run once on a pool of two subprocesses."""

from __future__ import annotations

import sys

import pytest

from tests.robustness.cases_pipeline import GARMENT, TINY_TRAIN
from tests.robustness.catalog import all_cases
from tests.robustness.forkserver import ForkServers
from tests.robustness.harness import Shared, run_cases

CASES = all_cases()


@pytest.fixture(scope="session")
def robustness_shared(tiny_store, tmp_path_factory):
    """The tiny store, a virtualbones run trained on it in seconds, its training motion ``walk``, that
    motion animated (a mesh sequence with the body) and a coarse skirt with its sidecar; the session's pool of
    fork servers that runs the commands."""
    from loosefit.cli import main
    from loosefit.training import train_model

    root = tmp_path_factory.mktemp("robustness-shared")
    run, motion, seq, garment = root / "run", root / "walk.npz", root / "walk-anim.npz", root / "skirt.obj"
    train_model("virtualbones", tiny_store, GARMENT, run, overrides=TINY_TRAIN[1::2])
    for argv in (["motion", "generate", "--kind", "walk", "--seconds", "1.5", "--seed", "0", "--out", str(motion)],
                 ["animate", str(run), "--motion", str(motion), "--out", str(seq)],
                 ["garment", "make", "--kind", "skirt", "--seed", "0", "--edge-length", "0.05", "--param",
                  "length=0.45", "--param", "flare=25", "--out", str(garment)]):
        assert main(argv) == 0, argv
    shared = Shared(root=root, store=tiny_store, run=run, motion=motion, seq=seq, garment=garment,
                    plan=tiny_store.parent / "tiny.yaml", python=sys.executable)
    shared.forks = ForkServers(shared.python, shared.env())  # one pool for every module's cases
    yield shared
    shared.forks.close()


@pytest.fixture(scope="module")
def robustness_results(request, robustness_shared, tmp_path_factory) -> dict:
    """Result name -> :class:`~tests.robustness.harness.Result` of every case a collected test of this module
    names (its ``case`` parameter), run once for the module, two at a time. Per module, so that parallel test
    workers (pytest-xdist, one module each) never run the same cases twice."""
    wanted = {item.callspec.params["case"] for item in request.session.items
              if item.module is request.module and hasattr(item, "callspec") and "case" in item.callspec.params}
    cases = [c for c in CASES if wanted & set(c.results or (c.name,))]
    results = run_cases(cases, tmp_path_factory.mktemp("robustness-cases"), robustness_shared, workers=2)
    return {r.name: r for r in results}

