"""Shared fixtures. The Anny body is built once per test session (its cache once per machine)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def body():
    """The default Anny body (13,718 vertices, rig cmu_mb, average shape)."""
    from loosefit.body import AnnyBody

    return AnnyBody()


@pytest.fixture(scope="session")
def proxy_body(body):
    """The low-resolution collision proxy of the default body (1,229 vertices)."""
    return body.collision_proxy()
