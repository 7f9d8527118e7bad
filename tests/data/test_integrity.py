"""Damaged stores: real Zarr files damaged on disk (a truncated chunk, a flipped byte, garbage
attributes, a pickle codec). Every reader raises InputError naming the damaged file, ``info`` lists
the damage, plan resume simulates a damaged sequence again, and repair drops exactly what is damaged
and leaves every other file bit-identical."""

from __future__ import annotations

import hashlib
import json
import os

import numcodecs
import numpy as np
import pytest
import zarr

from loosefit.cli import main
from loosefit.data import DatasetStore, format_info, format_repair
from loosefit.errors import InputError
from tests.data.conftest import random_verts


def truncate(path):
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def flip_byte(path):
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def digests(root, skip=()):
    """SHA-256 of every file of the store by relative path, leaving out ``skip`` prefixes and the lock."""
    out = {}
    for dirpath, _, files in os.walk(root):
        for name in files:
            rel = os.path.relpath(os.path.join(dirpath, name), root)
            if rel != ".lock" and not rel.startswith(".staging") and not any(rel.startswith(p + "/") for p in skip):
                out[rel] = hashlib.sha256((root / rel).read_bytes()).hexdigest()
    return out


def write_pickled(path, dtype):
    """A real Zarr array whose chunks are pickles: object dtype with a Pickle object codec, or a
    numeric dtype with a Pickle filter."""
    if dtype == object:
        array = zarr.open_array(str(path), mode="w", shape=(2,), chunks=(2,), dtype=object, object_codec=numcodecs.Pickle())
        array[:] = np.array([{"a": 1}, "b"], dtype=object)
    else:
        array = zarr.open_array(str(path), mode="w", shape=(4,), chunks=(4,), dtype=dtype, filters=[numcodecs.Pickle()])
        array[:] = np.arange(4)


@pytest.fixture
def three(store):
    """Sequences a, b, c (70 frames, three chunks each) in the store; returns their vertices."""
    verts = {name: random_verts(70, 25, seed=i) for i, name in enumerate("abc")}
    for name, v in verts.items():
        store.write_sequence(name, v, "g", "b", "m70", {}, {"job_hash": "h"}, "train",
                             extra={"contact": v[..., 2] > 0})
    return verts


@pytest.mark.parametrize("damage", [truncate, flip_byte])
def test_damaged_chunk_raises_naming_the_file_and_info_lists_it(store, three, damage):
    chunk = store.path / "sequences" / "b" / "verts" / "1.0.0"
    damage(chunk)
    reader = DatasetStore.open(store.path)
    seq = reader.sequence("b")  # lazily opened: the damage shows when the chunk is read
    np.testing.assert_array_equal(seq.verts[:32], three["b"][:32])  # chunks before it read fine
    for read in (lambda: seq.verts[:], lambda: seq.verts[40:45], lambda: seq.verts.oindex[[0, 40]]):
        with pytest.raises(InputError, match="checksum mismatch: the file changed after it was written") as err:
            read()
        assert err.value.path == chunk
        assert f"loosefit info {store.path} --repair" in str(err.value)

    info = reader.info()
    assert info["problems"] == {"sequences/b": "verts/1.0.0: checksum mismatch: the file changed after it was written (corrupt)"}
    assert info["sequences"]["count"] == 2  # the damaged one is not counted
    text = format_info(info)
    assert "sequences/b: verts/1.0.0: checksum mismatch" in text and "--repair" in text
    assert reader.verify_sequence("b").startswith("verts/1.0.0: checksum mismatch")
    assert reader.verify_sequence("a") is None and reader.verify_sequence("nope") == "no sequence named 'nope'"


def test_chunk_without_checksum_is_decoded_to_verify(store, three):
    """Arrays written before checksums were recorded: a truncated Blosc chunk does not decode."""
    attrs_file = store.path / "sequences" / "b" / ".zattrs"
    attrs = json.loads(attrs_file.read_text())
    del attrs["checksums"]
    attrs_file.write_text(json.dumps(attrs))
    chunk = store.path / "sequences" / "b" / "verts" / "2.0.0"
    truncate(chunk)
    with pytest.raises(InputError, match=r"chunk cannot be decoded \(RuntimeError: .*blosc") as err:
        DatasetStore.open(store.path).sequence("b").verts[:]
    assert err.value.path == chunk
    problems = DatasetStore.open(store.path).problems()
    assert list(problems) == ["sequences/b"] and problems["sequences/b"].startswith("verts/2.0.0: chunk cannot be decoded")
    assert DatasetStore.open(store.path).problems(verify=False) == {}  # only reading the chunk finds it


def test_garbage_attributes_are_refused_not_skipped(store, three):
    attrs_file = store.path / "sequences" / "c" / ".zattrs"
    attrs_file.write_text('{"garment": "g", "split": ')  # cut short
    reader = DatasetStore.open(store.path)
    for read in (reader.sequence_names, lambda: reader.sequence_names(split="train"), lambda: reader.sequence("c")):
        with pytest.raises(InputError, match="corrupt sequence 'c': .zattrs is not valid JSON") as err:
            read()
        assert err.value.path == attrs_file
    assert not reader.has_sequence("c")
    assert reader.problems() == {"sequences/c": ".zattrs is not valid JSON (corrupt)"}
    attrs_file.write_text(json.dumps({"complete": True, "garment": "g"}))  # JSON, attributes missing
    with pytest.raises(InputError, match="corrupt sequence 'c': .zattrs attribute 'body' is missing or malformed"):
        reader.sequence_names()


@pytest.mark.parametrize("dtype, message", [(object, "dtype '|O' is an object dtype"), ("<f4", "filter 'pickle'")])
def test_pickle_codec_is_never_decoded(store, three, monkeypatch, dtype, message):
    decoded = []
    monkeypatch.setattr(numcodecs.Pickle, "decode", lambda self, buf, out=None: decoded.append(buf))
    contact = store.path / "sequences" / "a" / "contact"
    write_pickled(contact, dtype)
    store.write_array("normalisation/g", "mean", np.zeros(3))
    stage = store.path / "normalisation" / "g" / "mean"
    write_pickled(stage, dtype)

    reader = DatasetStore.open(store.path)
    with pytest.raises(InputError, match=message) as err:
        reader.sequence("a")
    assert err.value.path == contact / ".zarray"
    with pytest.raises(InputError, match=message) as err:
        reader.read_array("normalisation/g", "mean")
    assert err.value.path == stage / ".zarray"
    problems = reader.problems()
    assert sorted(problems) == ["normalisation/g/mean", "sequences/a"]
    assert problems["sequences/a"].startswith("contact/.zarray: its ") and message in problems["sequences/a"]
    assert problems["normalisation/g/mean"].startswith(".zarray: its ") and message in problems["normalisation/g/mean"]
    assert store.repair() == {  # a later stage's array goes with its stage's group
        "sequences/a": problems["sequences/a"],
        "normalisation/g": f"normalisation/g/mean: {problems['normalisation/g/mean']}",
    }
    assert decoded == []


def test_repair_drops_exactly_the_damaged_and_keeps_the_rest_bit_identical(store, three):
    store.write_sequence("failed", np.full((5, 25, 3), np.nan, np.float32), "g", "b", "m70", {}, {}, "val",
                         status="failed", reason="exploded")
    store.write_array("garments/g/rig", "weights", np.eye(25, 4, dtype=np.float32))
    store.write_array("garments/g/rig/frames/a", "rotations", np.ones((70, 4, 3), np.float32))
    store.write_attrs("garments/g/rig", {"status": "done"})
    store.write_array("normalisation/g", "mean", np.arange(3.0))
    truncate(store.path / "sequences" / "b" / "verts" / "0.0.0")
    (store.path / "sequences" / "c" / ".zattrs").write_text("garbage")
    flip_byte(store.path / "garments" / "g" / "rig" / "frames" / "a" / "rotations" / "0.0.0")
    dropped_paths = ("sequences/b", "sequences/c", "garments/g/rig")
    before = digests(store.path, skip=dropped_paths)

    dropped = store.repair()
    assert list(dropped) == list(dropped_paths)
    assert dropped["garments/g/rig"].startswith("garments/g/rig/frames/a/rotations: 0.0.0: checksum mismatch")
    assert digests(store.path) == before  # every other file as it was, byte for byte
    assert store.problems() == {} and store.sequence_names(status=None) == ["a", "failed"]
    np.testing.assert_array_equal(store.read_array("normalisation/g", "mean"), np.arange(3.0))
    text = format_repair(store.path, dropped)
    assert "dropped 3 damaged item(s)" in text and f"loosefit simulate PLAN --out {store.path}" in text
    assert f"loosefit prepare {store.path}" in text
    assert store.repair() == {}


def test_repair_of_a_damaged_garment_drops_the_sequences_made_from_it(store, three):
    truncate(store.path / "garments" / "g" / "verts" / "0.0")
    with pytest.raises(InputError, match="checksum mismatch") as err:
        DatasetStore.open(store.path).garment("g")
    assert err.value.path == store.path / "garments" / "g" / "verts" / "0.0"
    before = digests(store.path, skip=("garments/g", "sequences/a", "sequences/b", "sequences/c"))
    dropped = store.repair()
    assert dropped == {
        "garments/g": "verts/0.0: checksum mismatch: the file changed after it was written (corrupt)",
        **{f"sequences/{n}": "made from the damaged garment 'g'" for n in "abc"},
    }
    assert digests(store.path) == before and store.motion_names() == ["m45", "m70"]


def test_resume_simulates_damaged_sequences_again(store, three):
    from loosefit.sim.plan import SequenceJob
    from loosefit.simulate import _done

    def job(name):
        return SequenceJob(id=name, garment="g", shape="b", motion="m70", sim_params="p", split="train", hash="h")

    truncate(store.path / "sequences" / "b" / "contact" / "1.0")
    (store.path / "sequences" / "c" / "verts" / "2.0.0").unlink()
    assert [_done(store, job(n)) for n in "abc"] == [True, False, False]
    assert not _done(store, SequenceJob("a", "g", "b", "m70", "p", "train", "other hash"))


def test_cli_info_lists_damage_and_repair_drops_it(store, three, capsys):
    truncate(store.path / "sequences" / "a" / "verts" / "0.0.0")
    store.close()
    assert main(["info", str(store.path)]) == 0
    out = capsys.readouterr().out
    assert "sequences/a: verts/0.0.0: checksum mismatch" in out and "sequences (2, 140 frames ok)" in out
    assert main(["info", str(store.path), "--repair"]) == 0
    out = capsys.readouterr().out
    assert f"{store.path}: dropped 1 damaged item(s)" in out and "  sequences/a: verts/0.0.0: checksum mismatch" in out
    assert f"`loosefit simulate PLAN --out {store.path}`" in out
    assert main(["info", str(store.path), "--repair", "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == {"dropped": {}}
    assert main(["info", str(store.path)]) == 0
    assert "problems: none" in capsys.readouterr().out
