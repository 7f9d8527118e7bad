"""Reference runs stored with a sequence: round trip, status, replacement, damage, repair, info."""

import numpy as np
import pytest

from loosefit.data import DatasetStore, format_info
from loosefit.data.run_spread import floor_m
from loosefit.errors import InputError
from tests.data.conftest import random_verts


def base_and_runs(store, count=3):
    """Sequence "s" (test split, 70 frames) with ``count`` ok runs: base + small offsets."""
    base = random_verts(70, 25)
    store.write_sequence("s", base, "g", "b", "m70", {}, {}, "test")
    rng = np.random.default_rng(5)
    runs = [base + rng.normal(0, 0.01, base.shape).astype(np.float32) for _ in range(count)]
    for k, run in enumerate(runs, start=1):
        store.write_reference("s", k, run, info={"noise_seed": k, "noise_m": 1e-5, "stats": {"quality": np.int64(7)}})
    return base, np.stack(runs)


def test_round_trip_in_index_order_with_status(store):
    base, runs = base_and_runs(store)
    store.write_reference("s", 4, runs[0][:20] * np.nan, status="failed", reason="NaN vertices")
    reopened = DatasetStore.open(store.path)
    meta = reopened.reference_runs("s")
    assert list(meta) == [1, 2, 3, 4]
    assert meta[2]["status"] == "ok" and meta[2]["noise_seed"] == 2 and meta[2]["stats"] == {"quality": 7}
    assert meta[2]["frames"] == 70 and meta[4]["frames"] == 20
    assert (meta[4]["status"], meta[4]["reason"]) == ("failed", "NaN vertices")
    got = reopened.references("s")  # the failed run is left out
    assert got.shape == (3, 70, 25, 3) and got.dtype == np.float32
    np.testing.assert_array_equal(got, runs)
    assert reopened.reference("s", 4).shape == (20, 25, 3)
    # the sequence itself reads as before; its arrays do not include the runs
    seq = reopened.sequence("s")
    np.testing.assert_array_equal(seq.verts[:], base) and seq.extra == {}
    assert reopened.problems() == {}


def test_store_without_runs_reads_as_before(store):
    store.write_sequence("s", random_verts(70, 25), "g", "b", "m70", {}, {}, "test")
    assert store.reference_runs("s") == {}
    assert store.references("s").shape == (0, 70, 25, 3)
    info = store.info()
    assert info["references"] == {} and "reference runs" not in format_info(info)


def test_replacing_a_run_and_the_sequence(store):
    base, runs = base_and_runs(store, count=2)
    store.write_reference("s", 2, runs[0])
    np.testing.assert_array_equal(store.references("s"), runs[[0, 0]])
    store.delete_reference("s", 2)
    store.delete_reference("s", 9)  # none: nothing to do
    assert list(store.reference_runs("s")) == [1]
    # a new base run drops the runs made beside the old one
    store.write_sequence("s", random_verts(70, 25, seed=9), "g", "b", "m70", {}, {}, "test")
    assert store.reference_runs("s") == {}


@pytest.mark.parametrize("args, message", [
    ((0, np.zeros((70, 25, 3))), "index must be an integer >= 1"),
    ((1, np.zeros((69, 25, 3))), r"must have shape \(70, 25, 3\)"),
    ((1, np.zeros((70, 24, 3))), r"must have shape \(70, 25, 3\)"),
    ((1, np.full((70, 25, 3), np.nan)), "NaN or infinite"),
])
def test_bad_runs_are_refused(store, args, message):
    store.write_sequence("s", random_verts(70, 25), "g", "b", "m70", {}, {}, "test")
    with pytest.raises(InputError, match=message):
        store.write_reference("s", *args)
    with pytest.raises(InputError, match="no sequence named 'other'"):
        store.write_reference("other", 1, np.zeros((70, 25, 3)))
    with pytest.raises(InputError, match="status must be one of"):
        store.write_reference("s", 1, np.zeros((3, 25, 3)), status="failed")  # no reason
    assert store.reference_runs("s") == {}


def test_info_gives_the_floor_of_base_and_runs(store, capsys):
    from loosefit.cli import main

    base, runs = base_and_runs(store)
    store.write_reference("s", 4, runs[0][:5], status="failed", reason="crashed: x")
    store.close()
    info = DatasetStore.open(store.path).info()
    r = info["references"]["s"]
    assert (r["ok"], r["failed"]) == (3, 1)
    assert r["floor_mm"] == pytest.approx(1000 * floor_m(np.concatenate([base[None], runs])), rel=1e-6)
    line = f"s: 3 ok, 1 failed, floor {r['floor_mm']:.2f} mm"
    assert line in format_info(info)
    assert main(["info", str(store.path)]) == 0 and line in capsys.readouterr().out


def test_damaged_run_is_named_listed_and_repaired(store):
    base_and_runs(store, count=2)
    chunk = store.path / "sequences" / "s" / "references" / "2" / "1.0.0"
    chunk.write_bytes(chunk.read_bytes()[:-7] + b"garbage")
    reopened = DatasetStore.open(store.path, mode="a")
    with pytest.raises(InputError, match="checksum") as err:
        reopened.references("s")
    assert err.value.path == chunk
    problems = reopened.problems()
    assert list(problems) == ["sequences/s/references/2"] and "checksum" in problems["sequences/s/references/2"]
    assert reopened.info()["references"]["s"]["damaged"]
    dropped = reopened.repair()  # the runs go as one group; the base sequence stays
    assert list(dropped) == ["sequences/s/references"]
    assert reopened.sequence_names() == ["s"] and reopened.reference_runs("s") == {}
