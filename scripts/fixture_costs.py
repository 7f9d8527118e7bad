"""A pytest plugin that records what each test costs on its own and what its fixtures cost, for
``scripts/mark_fast_tests.py``: ``pytest -p fixture_costs`` (with ``scripts/`` on ``sys.path``) writes the JSON
named by ``$FIXTURE_COSTS_JSON`` at the end of the session.

A test's time in a run depends on which tests ran before it: an expensive session fixture (a simulated store,
the body model) is paid by the first test that asks for it. So the plugin keeps the two apart:

- per fixture instance (its name, where it is defined, its scope's node and its parameter): the seconds of its
  own setup (its dependencies are set up before pytest calls the setup hook, so they are not counted twice);
- per test: the seconds of its call and teardown, its setup less the fixture setups measured inside it, and the
  fixture instances it needs (its whole closure).

A subset of the tests then costs the sum of its tests' own seconds plus the seconds of every fixture instance
any of them needs, once.
"""

from __future__ import annotations

import json
import os
import time

import pytest

_fixtures: dict[str, float] = {}
_tests: dict[str, dict] = {}
_inside: list[float] = [0.0]  # fixture seconds measured during the current test's setup or call


def instance_key(fixturedef, item) -> str:
    """Names one instance of a fixture as ``item`` uses it: name, definition place, scope node, parameter."""
    scope = fixturedef.scope
    if scope == "session":
        node = ""
    elif scope == "package":
        node = os.path.dirname(item.nodeid.split("::")[0])
    elif scope == "module":
        node = item.nodeid.split("::")[0]
    elif scope == "class":
        node = "::".join(item.nodeid.split("::")[:2])
    else:
        node = item.nodeid
    callspec = getattr(item, "callspec", None)
    param = ""
    if callspec is not None and fixturedef.argname in callspec.params:
        param = repr(callspec.params[fixturedef.argname])
    return f"{fixturedef.argname}@{fixturedef.baseid}|{scope}:{node}|{param}"


@pytest.hookimpl(hookwrapper=True)
def pytest_fixture_setup(fixturedef, request):
    start = time.perf_counter()
    yield
    seconds = time.perf_counter() - start
    _inside[0] += seconds
    item = request._pyfuncitem
    _fixtures[instance_key(fixturedef, item)] = _fixtures.get(instance_key(fixturedef, item), 0.0) + seconds


def closure_keys(item) -> list[str]:
    info = getattr(item, "_fixtureinfo", None)
    if info is None:
        return []
    keys = []
    for name in item.fixturenames:
        defs = info.name2fixturedefs.get(name)
        if defs:
            keys.append(instance_key(defs[-1], item))
    return keys


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    _inside[0] = 0.0


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_call(item):
    _inside[0] = 0.0  # a fixture asked for inside the test body (getfixturevalue) is counted as a fixture


def pytest_runtest_logreport(report):
    row = _tests.setdefault(report.nodeid, {"own": 0.0, "fixtures": []})
    own = report.duration
    if report.when in ("setup", "call"):
        own = max(own - _inside[0], 0.0)
    row["own"] += own


def pytest_collection_modifyitems(items):
    for item in items:
        _tests.setdefault(item.nodeid, {"own": 0.0, "fixtures": []})["fixtures"] = closure_keys(item)


def pytest_sessionfinish(session):
    path = os.environ.get("FIXTURE_COSTS_JSON")
    if path:
        ran = {k: v for k, v in _tests.items() if v["own"] > 0.0}
        with open(path, "w") as f:
            json.dump({"tests": ran, "fixtures": _fixtures}, f)
