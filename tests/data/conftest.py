"""Small synthetic dataset objects shared by the data tests (no body model needed)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from loosefit.data import DatasetStore
from loosefit.motion import Motion


def grid_garment(n: int = 5, name: str = "grid", kind: str = "skirt"):
    """A flat ``n x n`` grid garment (n*n vertices, 2 (n-1)^2 triangles), top row pinned."""
    from loosefit.garment import Garment

    u, v = np.meshgrid(np.linspace(-0.2, 0.2, n), np.linspace(0.5, 0.9, n))
    verts = np.stack([u.ravel(), np.full(n * n, -0.15), v.ravel()], axis=1).astype(np.float32)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + n], 1), np.stack([a + 1, a + n + 1, a + n], 1)]).astype(np.int64)
    pinned = verts[:, 2] > 0.89
    params = {"length": 0.4, "flare": [1, 2]}
    return Garment(verts=verts, faces=faces, pinned=pinned, kind=kind, params=params, name=name)


def random_motion(frames: int, seed: int = 0, name: str = "m") -> Motion:
    rng = np.random.default_rng(seed)
    return Motion(
        rotations=rng.normal(0, 0.3, (frames, 31, 3)),
        translation=rng.normal(0, 0.1, (frames, 3)) + [0, 0, 0.86],
        fps=30.0,
        rig="cmu_mb",
        joint_names=[f"j{k}" for k in range(31)],
        name=name,
    )


def random_verts(frames: int, num_verts: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(0, 0.3, (frames, num_verts, 3)).astype(np.float32)


@pytest.fixture(scope="session")
def template_store(tmp_path_factory):
    """Built once: garment "g" (25 vertices), body "b", motions "m70" and "m45" (70 and 45 frames)."""
    s = DatasetStore.create(tmp_path_factory.mktemp("template") / "data.zarr")
    s.add_garment("g", grid_garment())
    s.add_body("b", np.array([0.5, 0.4, 0.6, 0.5, 0.5, 0.3], np.float32))
    s.add_motion("m70", random_motion(70, seed=1, name="walk"))
    s.add_motion("m45", random_motion(45, seed=2, name="spin"))
    return s.path


@pytest.fixture
def store(template_store, tmp_path):
    """A fresh copy of the template store, open in mode "a" (copying skips the writes' fsyncs)."""
    shutil.copytree(template_store, tmp_path / "data.zarr")
    return DatasetStore.open(tmp_path / "data.zarr", mode="a")
