"""FrameWindows: every window equals direct slicing of the stored arrays, also through DataLoader workers."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from loosefit.data.windows import FrameWindows, collate_windows
from loosefit.errors import InputError
from tests.data.conftest import grid_garment, random_motion, random_verts

WINDOW, STRIDE = 16, 5


@pytest.fixture
def filled(store):
    """Sequences "a" (70 frames, motion m70, with a per-frame extra), "b" (45 frames), "short" (failed)."""
    store.write_sequence(
        "a", random_verts(70, 25, 1), "g", "b", "m70", {}, {}, "train",
        extra={"speed": np.arange(70.0, dtype=np.float32)},
    )
    store.write_sequence("b", random_verts(45, 25, 2), "g", "b", "m45", {}, {}, "train")
    store.write_sequence("bad", random_verts(10, 25, 3), "g", "b", "m45", {}, {}, "test", status="failed", reason="x")
    return store


def _expected(store, names, fields):
    """All windows by brute force, in FrameWindows' order."""
    out = []
    for name in names:
        seq = store.sequence(name)
        motion = store.motion(seq.motion)
        full = {
            "verts": seq.verts[:],
            "rotations": motion.rotations,
            "translation": motion.translation,
            **{k: v[:] for k, v in seq.extra.items()},
        }
        for start in range(0, seq.num_frames - WINDOW + 1, STRIDE):
            out.append((name, start, {f: full[f][start : start + WINDOW] for f in fields}))
    return out


def test_windows_match_direct_slicing(filled):
    ds = FrameWindows(filled, ["a", "b"], WINDOW, STRIDE)
    expected = _expected(filled, ["a", "b"], ("verts", "rotations", "translation"))
    assert len(ds) == len(expected) == 11 + 6
    for k, (name, start, arrays) in enumerate(expected):
        item = ds[k]
        assert (item["name"], item["garment"], item["body"], item["start"]) == (name, "g", "b", start)
        for field, value in arrays.items():
            assert item[field].dtype == torch.float32
            np.testing.assert_array_equal(item[field].numpy(), value)
    assert ds[-1]["start"] == expected[-1][1]
    with pytest.raises(IndexError):
        ds[len(ds)]


def test_extra_fields_only(filled):
    ds = FrameWindows(filled.path, ["a"], WINDOW, STRIDE, fields=["speed"])
    assert set(ds[3]) == {"name", "garment", "body", "start", "speed"}
    np.testing.assert_array_equal(ds[3]["speed"].numpy(), np.arange(15.0, 15.0 + WINDOW))


@pytest.mark.parametrize("workers", [0, 2])
def test_dataloader(filled, workers):
    ds = FrameWindows(filled, ["a", "b"], WINDOW, STRIDE)
    loader = DataLoader(ds, batch_size=4, shuffle=False, num_workers=workers, collate_fn=collate_windows)
    batches = list(loader)
    expected = _expected(filled, ["a", "b"], ("verts", "rotations", "translation"))
    assert [len(b["name"]) for b in batches] == [4, 4, 4, 4, 1]
    assert batches[0]["verts"].shape == (4, WINDOW, 25, 3) and batches[0]["rotations"].shape == (4, WINDOW, 31, 3)
    got = [(n, int(s), {f: b[f][i].numpy() for f in ("verts", "rotations", "translation")})
           for b in batches for i, (n, s) in enumerate(zip(b["name"], b["start"]))]
    assert [(n, s) for n, s, _ in got] == [(n, s) for n, s, _ in expected]
    for (_, _, a), (_, _, e) in zip(got, expected):
        for field in e:
            np.testing.assert_array_equal(a[field], e[field])


def test_bad_requests(filled):
    with pytest.raises(InputError, match="status 'failed'"):
        FrameWindows(filled, ["a", "bad"], WINDOW)
    with pytest.raises(InputError, match="no per-frame array 'speed'"):
        FrameWindows(filled, ["b"], WINDOW, fields=["speed"])
    with pytest.raises(InputError, match="no sequence has 80 frames"):
        FrameWindows(filled, ["a", "b"], 80)
    with pytest.raises(InputError, match="no sequence named 'zzz'"):
        FrameWindows(filled, ["zzz"], WINDOW)
    with pytest.raises(InputError, match="window and stride must be >= 1"):
        FrameWindows(filled, ["a"], 0)


def test_collate_refuses_mixed_vertex_counts(filled):
    filled.add_garment("g36", grid_garment(n=6, name="g36"))
    filled.add_motion("m20", random_motion(20))
    filled.write_sequence("c", random_verts(20, 36), "g36", "b", "m20", {}, {}, "train")
    ds = FrameWindows(filled, ["b", "c"], WINDOW, STRIDE)
    with pytest.raises(InputError, match=r"cannot batch 'verts' of shapes \[\(16, 25, 3\), \(16, 36, 3\)\]"):
        collate_windows([ds[0], ds[len(ds) - 1]])
