"""DatasetStore: exact round trips, splits, validation, format checks, corruption reports."""

from __future__ import annotations

import json
import os
import shutil

import numpy as np
import pytest
import zarr

from loosefit.data import DatasetStore, format_info
from loosefit.data.store import FORMAT_VERSION, FRAMES_PER_CHUNK
from loosefit.errors import InputError
from tests.data.conftest import grid_garment, random_motion, random_verts


def test_garment_body_motion_round_trip(store):
    g = grid_garment()
    back = store.garment("g")
    np.testing.assert_array_equal(back.verts, g.verts)
    np.testing.assert_array_equal(back.faces, g.faces)
    np.testing.assert_array_equal(back.pinned, g.pinned)
    assert back.verts.dtype == np.float32 and back.faces.dtype == np.int64 and back.pinned.dtype == bool
    assert (back.kind, back.params, back.name) == ("skirt", {"length": 0.4, "flare": [1, 2]}, "grid")
    assert store.garment_num_verts("g") == 25

    np.testing.assert_array_equal(store.body("b"), np.array([0.5, 0.4, 0.6, 0.5, 0.5, 0.3], np.float32))
    assert store.read_attrs("bodies/b")["model"] == "anny"

    m, back = random_motion(70, seed=1, name="walk"), store.motion("m70")
    np.testing.assert_array_equal(back.rotations, m.rotations)
    np.testing.assert_array_equal(back.translation, m.translation)
    assert (back.fps, back.rig, back.joint_names, back.name) == (m.fps, m.rig, m.joint_names, m.name)
    assert (store.garment_names(), store.body_names(), store.motion_names()) == (["g"], ["b"], ["m45", "m70"])


def test_sequence_round_trip_with_extras(store):
    verts = random_verts(70, 25)
    contact = np.random.default_rng(3).random((70, 25)) > 0.5
    stats = {"ms_per_frame": np.float32(41.5), "penetration": 0.0025, "flags": {"nan": False}}
    store.write_sequence(
        "s", verts, "g", "b", "m70", {"bending": 0.5, "steps": np.int64(10)}, stats, "train", extra={"contact": contact}
    )
    seq = DatasetStore.open(store.path).sequence("s")
    np.testing.assert_array_equal(seq.verts[:], verts)
    np.testing.assert_array_equal(seq.verts[33:40], verts[33:40])
    np.testing.assert_array_equal(seq.extra["contact"][:], contact)
    assert seq.verts.chunks == (FRAMES_PER_CHUNK, 25, 3)
    assert (seq.garment, seq.body, seq.motion) == ("g", "b", "m70")
    assert (seq.split, seq.status, seq.reason) == ("train", "ok", "")
    assert seq.sim_params == {"bending": 0.5, "steps": 10}
    assert seq.stats == {"ms_per_frame": 41.5, "penetration": 0.0025, "flags": {"nan": False}}
    assert (seq.num_frames, seq.num_verts) == (70, 25)


def test_rewrite_replaces_sequence(store):
    store.write_sequence("s", random_verts(70, 25, seed=1), "g", "b", "m70", {}, {}, "train", extra={"x": np.ones(3)})
    second = random_verts(45, 25, seed=2)
    store.write_sequence("s", second, "g", "b", "m45", {}, {"v": 2}, "test")
    seq = store.sequence("s")
    np.testing.assert_array_equal(seq.verts[:], second)
    assert (seq.motion, seq.split, seq.stats, seq.extra) == ("m45", "test", {"v": 2}, {})
    assert not (store.path / "sequences" / "s" / "x").exists()
    assert os.listdir(store.path / ".staging") == []


def test_splits_and_status(store):
    for name, split in [("c", "test"), ("a", "train"), ("b", "train"), ("d", "val")]:
        store.write_sequence(name, random_verts(45, 25), "g", "b", "m45", {}, {}, split)
    nan = np.full((12, 25, 3), np.nan, np.float32)
    store.write_sequence(
        "e", nan, "g", "b", "m70", {}, {"exploded": True}, "train", status="failed", reason="NaN at frame 12"
    )
    assert store.sequence_names() == ["a", "b", "c", "d"]
    assert store.sequence_names(split="train") == ["a", "b"]
    assert store.sequence_names(split="test") == ["c"]
    assert store.sequence_names(split="val") == ["d"]
    assert store.sequence_names(split="train", status="failed") == ["e"]
    assert store.sequence_names(status=None) == ["a", "b", "c", "d", "e"]
    failed = store.sequence("e")
    assert (failed.status, failed.reason, failed.num_frames) == ("failed", "NaN at frame 12", 12)
    assert np.isnan(failed.verts[:]).all()
    info = store.info()
    assert info["sequences"] == {
        "count": 5,
        "frames": 4 * 45,
        "by_split": {
            "train": {"ok": 2, "failed": 1, "frames": 90},
            "test": {"ok": 1, "failed": 0, "frames": 45},
            "val": {"ok": 1, "failed": 0, "frames": 45},
        },
    }
    assert info["garments"] == {"g": {"kind": "skirt", "verts": 25, "faces": 32, "pinned": 5}}
    assert info["motions"]["m70"] == {"frames": 70, "joints": 31, "fps": 30.0, "rig": "cmu_mb"}
    assert info["problems"] == {}
    text = format_info(info)
    assert "train: 2 ok (90 frames), 1 failed" in text and "g: skirt, 25 vertices, 32 faces, 5 pinned" in text
    with pytest.raises(InputError, match="split must be one of"):
        store.sequence_names(split="training")


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"verts": random_verts(70, 24)}, r"shape \(T, 25, 3\)"),
        ({"verts": random_verts(69, 25)}, "69 frames but motion 'm70' has 70"),
        ({"garment": "nope"}, "no garment named 'nope'"),
        ({"motion": "nope"}, "no motion named 'nope'"),
        ({"body": "nope"}, "no body named 'nope'"),
        ({"split": "training"}, "split must be one of"),
        ({"status": "failed"}, "needs a reason"),
        ({"status": "maybe"}, "status must be one of"),
        ({"name": "../escape"}, "bad sequence name"),
        ({"name": ".hidden"}, "bad sequence name"),
        ({"stats": {"t": object()}}, "cannot be stored as JSON"),
        ({"extra": {"verts": np.ones(3)}}, "taken by the vertices"),
    ],
)
def test_write_sequence_refuses_bad_input(store, kwargs, message):
    args = dict(name="s", verts=random_verts(70, 25), garment="g", body="b", motion="m70")
    args.update(sim_params={}, stats={}, split="train")
    args.update(kwargs)
    with pytest.raises(InputError, match=message) as err:
        store.write_sequence(**args)
    assert str(store.path) in str(err.value)
    assert store.sequence_names(status=None) == [] and os.listdir(store.path / ".staging") == []


def test_nan_refused_unless_failed(store):
    verts = random_verts(70, 25)
    verts[50, 3, 1] = np.nan
    with pytest.raises(InputError, match="frames 32-63 contain NaN"):
        store.write_sequence("s", verts, "g", "b", "m70", {}, {}, "train")
    assert not store.has_sequence("s") and os.listdir(store.path / ".staging") == []
    store.write_sequence("s", verts, "g", "b", "m70", {}, {}, "train", status="failed", reason="exploded")
    np.testing.assert_array_equal(store.sequence("s").verts[:], verts)


def test_read_only_mode_refuses_writes(store):
    ro = DatasetStore.open(store.path)
    with pytest.raises(InputError, match="read-only"):
        ro.write_sequence("s", random_verts(70, 25), "g", "b", "m70", {}, {}, "train")
    with pytest.raises(InputError, match="read-only"):
        ro.add_garment("h", grid_garment())


def test_readding_identical_entry_keeps_later_arrays(store):
    store.write_array("garments/g/rig", "weights", np.eye(4, dtype=np.float32))
    store.add_garment("g", grid_garment())
    np.testing.assert_array_equal(store.read_array("garments/g/rig", "weights"), np.eye(4))
    store.add_garment("g", grid_garment(kind="dress"))  # same vertex count, different garment: replaced
    assert store.garment("g").kind == "dress"
    with pytest.raises(InputError, match="no group 'rig'|no array"):
        store.read_array("garments/g/rig", "weights")


def test_replacing_used_garment_or_motion_with_other_size_is_refused(store):
    store.write_sequence("s", random_verts(45, 25), "g", "b", "m45", {}, {}, "train")
    with pytest.raises(InputError, match=r"used by sequences \['s'\]"):
        store.add_garment("g", grid_garment(n=6))
    with pytest.raises(InputError, match=r"used by sequences \['s'\]"):
        store.add_motion("m45", random_motion(46))
    store.add_motion("m45", random_motion(45, seed=9))  # same frame count: allowed
    np.testing.assert_array_equal(store.motion("m45").rotations, random_motion(45, seed=9).rotations)


def test_a_plan_run_replaces_a_used_entry_only_if_it_rewrites_every_user(store):
    """A second plan defining motion ``m45`` (or garment ``g``) otherwise would leave the first plan's sequences
    with vertices simulated on the old one: refused unless the run writes every sequence using it again."""
    store.write_sequence("s", random_verts(45, 25), "g", "b", "m45", {}, {}, "train")
    store.write_sequence("t", random_verts(45, 25), "g", "b", "m45", {}, {}, "train")
    stored = store.motion("m45").rotations
    with pytest.raises(InputError, match=r"motion 'm45' differs .* \['t'\]"):
        store.add_motion("m45", random_motion(45, seed=9), rewritten={"s"})
    with pytest.raises(InputError, match=r"garment 'g' differs .* \['s', 't'\]"):
        store.add_garment("g", grid_garment(kind="dress"), rewritten=set())
    np.testing.assert_array_equal(store.motion("m45").rotations, stored)  # nothing replaced
    assert store.garment("g").kind == "skirt"
    store.add_motion("m45", random_motion(45, seed=2, name="spin"), rewritten=set())  # identical: nothing to do
    store.add_motion("m45", random_motion(45, seed=9), rewritten={"s", "t"})
    np.testing.assert_array_equal(store.motion("m45").rotations, random_motion(45, seed=9).rotations)


def test_write_array_and_attrs(store):
    w = np.random.default_rng(0).random((25, 8)).astype(np.float32)
    store.write_array("garments/g/rig", "weights", w)
    store.write_array("garments/g/rig", "weights", 2 * w)  # replaced atomically
    np.testing.assert_array_equal(store.read_array("garments/g/rig", "weights"), 2 * w)
    store.write_array("normalisation/g", "mean", np.arange(3.0))
    np.testing.assert_array_equal(store.read_array("normalisation/g", "mean"), np.arange(3.0))
    store.write_attrs("garments/g/rig", {"bones": 8})
    store.write_attrs("garments/g/rig", {"rmse_mm": 3.2})
    assert store.read_attrs("garments/g/rig") == {"bones": 8, "rmse_mm": 3.2}
    # Zarr itself sees the arrays (the store stays a plain Zarr hierarchy).
    np.testing.assert_array_equal(zarr.open_group(str(store.path), mode="r")["garments/g/rig/weights"][:], 2 * w)
    with pytest.raises(InputError, match="entry's own array"):
        store.write_array("garments/g", "verts", np.zeros((25, 3)))
    with pytest.raises(InputError, match="no garment named 'h'"):
        store.write_array("garments/h/rig", "weights", w)
    with pytest.raises(InputError, match="reserved"):
        store.write_attrs("garments/g", {"complete": False})
    assert os.listdir(store.path / ".staging") == []


def test_open_checks_format(tmp_path, store):
    with pytest.raises(InputError, match="no such dataset store"):
        DatasetStore.open(tmp_path / "missing.zarr")
    (tmp_path / "file.zarr").write_text("x")
    with pytest.raises(InputError, match="not a directory"):
        DatasetStore.open(tmp_path / "file.zarr")
    (tmp_path / "empty.zarr").mkdir()
    with pytest.raises(InputError, match="no readable .zgroup") as err:
        DatasetStore.open(tmp_path / "empty.zarr")
    assert "empty.zarr" in str(err.value)
    zarr.open_array(str(tmp_path / "array.zarr"), mode="w", shape=(3,))
    with pytest.raises(InputError, match="single Zarr array"):
        DatasetStore.open(tmp_path / "array.zarr")
    zarr.open_group(str(tmp_path / "other.zarr"), mode="w")
    with pytest.raises(InputError, match="not a loosefit dataset"):
        DatasetStore.open(tmp_path / "other.zarr")
    with pytest.raises(InputError, match="already exists"):
        DatasetStore.create(store.path)

    attrs_file = store.path / ".zattrs"
    attrs = json.loads(attrs_file.read_text())
    attrs_file.write_text(json.dumps({**attrs, "format_version": FORMAT_VERSION + 1}))
    with pytest.raises(InputError, match=f"format version {FORMAT_VERSION + 1} was written by a newer loosefit") as err:
        DatasetStore.open(store.path)
    assert str(store.path) in str(err.value)
    attrs_file.write_text(json.dumps(attrs))
    shutil.rmtree(store.path / "motions")
    with pytest.raises(InputError, match="group 'motions' is missing"):
        DatasetStore.open(store.path)


def test_corrupt_sequence_is_reported_by_name(store):
    verts = random_verts(70, 25)
    store.write_sequence("good", verts, "g", "b", "m70", {}, {}, "train")
    store.write_sequence("broken", verts, "g", "b", "m70", {}, {}, "train")
    store.write_sequence("holed", verts, "g", "b", "m70", {}, {}, "train")
    (store.path / "sequences" / "broken" / "verts" / ".zarray").unlink()
    (store.path / "sequences" / "holed" / "verts" / "1.0.0").unlink()
    reopened = DatasetStore.open(store.path)
    with pytest.raises(InputError, match="corrupt sequence 'broken': array 'verts': no readable .zarray") as err:
        reopened.sequence("broken")
    assert err.value.path == store.path / "sequences" / "broken" / "verts" / ".zarray"
    with pytest.raises(InputError, match=r"corrupt sequence 'holed': array 'verts': chunk file is missing \(2 of") as err:
        reopened.sequence("holed")
    assert err.value.path == store.path / "sequences" / "holed" / "verts" / "1.0.0"
    np.testing.assert_array_equal(reopened.sequence("good").verts[:], verts)
    assert reopened.problems() == {
        "sequences/broken": "verts/.zarray: no readable .zarray (missing or not JSON)",
        "sequences/holed": "verts/1.0.0: chunk file is missing (2 of the array's 3 are there)",
    }
    assert "sequences/broken: verts/.zarray: no readable .zarray" in format_info(reopened.info())
    store.delete_sequence("broken")
    store.write_sequence("holed", verts, "g", "b", "m70", {}, {}, "train")
    assert store.problems() == {} and store.sequence_names() == ["good", "holed"]


def test_sequence_without_marker_is_refused_by_name(store):
    """An entry without completion marker is not a sequence (has_sequence), but listing the store
    names it rather than leaving it out silently."""
    store.write_sequence("s", random_verts(45, 25), "g", "b", "m45", {}, {}, "train")
    attrs_file = store.path / "sequences" / "s" / ".zattrs"
    attrs_file.write_text(json.dumps({k: v for k, v in json.loads(attrs_file.read_text()).items() if k != "complete"}))
    assert not store.has_sequence("s")
    assert store.problems() == {
        "sequences/s": "no completion marker in its .zattrs (corrupt or not written by loosefit)"
    }
    for read in (store.sequence_names, lambda: store.sequence("s")):
        with pytest.raises(InputError, match="corrupt sequence 's': no completion marker") as err:
            read()
        assert err.value.path == attrs_file
