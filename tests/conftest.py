"""Shared fixtures. The Anny body is built once per test session (its cache once per machine)."""

from __future__ import annotations

from pathlib import Path

import pytest

#: The fast subset, chosen by measurement (scripts/mark_fast_tests.py): every other test is marked ``slow``, so
#: ``pytest -m "not slow"`` runs the list; ``pytest`` runs everything.
FAST_TESTS = Path(__file__).with_name("fast_tests.txt")


def pytest_collection_modifyitems(config, items):
    if not FAST_TESTS.is_file():
        return
    fast = {line.strip() for line in FAST_TESTS.read_text().splitlines() if line.strip() and not line.startswith("#")}
    for item in items:
        if item.nodeid not in fast:
            item.add_marker(pytest.mark.slow)


#: Real motion capture the tests read, in the repository: the first 62 frames (1 s at 60 fps, after the T-pose some
#: files put first) of seven CMU clips on a Character Creator skeleton, one per subject and one marked "Imported",
#: with the collection's ``clips.csv`` (tests/data/cmu-cc/README.md). The whole collection lies beside the repository
#: in ``../shared/mocap/cmu-cc``, where the dataset plans point.
TEST_MOCAP = Path(__file__).resolve().parent / "data" / "cmu-cc"


@pytest.fixture(scope="session")
def body():
    """The default Anny body (13,718 vertices, rig cmu_mb, average shape)."""
    from loosefit.body import AnnyBody

    return AnnyBody()


@pytest.fixture(scope="session")
def proxy_body(body):
    """The low-resolution collision proxy of the default body (1,229 vertices)."""
    return body.collision_proxy()


# Small real datasets for the model, training and animation tests: simulated by Blender and prepared
# by the real ``prepare`` stage, once per session (about 15-30 s in all on 2 cores).

TINY_PLAN = """
name: tiny
garments:
  skirt: {template: skirt, seed: 0, edge_length: 0.05, params: {length: 0.45, flare: 25}}
motions:
  walk: {procedural: walk, seconds: 1.5, seed: 0}
  spin: {procedural: spin, seconds: 1.5, seed: 1}
  sway: {procedural: sway, seconds: 1.5, seed: 2}
sim_params:
  default: {preroll: 0.5}
split:
  test: {motions: [sway]}
"""

SECOND_PLAN = """
name: second
garments:
  dress: {template: dress, seed: 1, edge_length: 0.06, params: {length: 0.5}}
motions:
  walk: {procedural: walk, seconds: 1.0, seed: 3}
sim_params:
  default: {preroll: 0.5}
"""


def _build(tmp_root, name: str, plan_text: str, bones: int):
    from loosefit.rig.prepare import prepare
    from loosefit.simulate import run_plan

    plan = tmp_root / f"{name}.yaml"
    plan.write_text(plan_text)
    store = tmp_root / f"{name}.zarr"
    summary = run_plan(plan, store, progress=False)
    assert summary["failed"] == 0 and summary["crashed"] == 0, summary
    prepare(store, bones=bones, progress=False)
    return store


@pytest.fixture(scope="session")
def tiny_store(tmp_path_factory):
    """A prepared store: one skirt (a few hundred vertices), walk + spin for training, sway for test, 8 bones."""
    return _build(tmp_path_factory.mktemp("models"), "tiny", TINY_PLAN, bones=8)


@pytest.fixture(scope="session")
def second_store(tmp_path_factory):
    """A prepared store with a dress of a different vertex count (training sequences only), 6 bones."""
    return _build(tmp_path_factory.mktemp("models2"), "second", SECOND_PLAN, bones=6)


@pytest.fixture(scope="session")
def tiny_train(tiny_store):
    from loosefit.models.dataset import GarmentSequences

    return GarmentSequences(tiny_store, "skirt+average", "train")


@pytest.fixture(scope="session")
def tiny_test(tiny_store):
    from loosefit.models.dataset import GarmentSequences

    return GarmentSequences(tiny_store, "skirt+average", "test", bones=False)


#: Debian's Chromium, which ``make test`` installs, and the flags it runs headless with on these machines (no
#: background networking: the closed network refuses its connections; WebGL in software, SwiftShader).
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run", "--use-gl=swiftshader",
                 "--enable-unsafe-swiftshader"]


@pytest.fixture(scope="module")
def browser():
    """A headless Chromium through Playwright (no browser download); absent: the test fails, naming the fix."""
    if not Path(CHROMIUM).is_file():
        pytest.fail(f"{CHROMIUM} is missing: `make test` installs it (apt-get install chromium)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        launched = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield launched
        launched.close()
