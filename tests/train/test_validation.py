"""Which sequences validate a run: the store's val split, carved training motions or none; never a test
motion unless the test split is named, and then with a warning."""

from __future__ import annotations

import itertools
import logging

import pytest

from loosefit.data.store import DatasetStore
from loosefit.errors import InputError
from loosefit.train.validation import (carve_motions, choose_validation, held_out_motions, keep_fraction, motion_kind,
                                       motion_rank, train_on_fraction)

MOTIONS = [f"{kind}-{seed}" for kind in ("walk", "run", "spin", "jump", "kick", "sway") for seed in range(3)]


@pytest.mark.parametrize("fraction", [0.05, 0.2, 0.34, 0.5, 0.9])
@pytest.mark.parametrize("held", [set(), {"walk-1", "spin-2", "kick-0"}, set(MOTIONS[:12])])
def test_a_carved_fraction_never_holds_a_test_motion(fraction, held):
    """Every fraction and set of test motions: no test motion validates, at least one motion still trains,
    and the share is the rounded fraction of the training motions while enough candidates remain."""
    chosen = carve_motions(MOTIONS, held, fraction=fraction)
    assert chosen and not set(chosen) & held
    assert len(chosen) < len(MOTIONS) and set(chosen) <= set(MOTIONS)
    candidates = len(set(MOTIONS) - held)
    assert len(chosen) == min(max(1, round(fraction * len(MOTIONS))), candidates)


def test_a_carved_fraction_depends_on_the_names_alone():
    """The same motions in any order give the same choice: the candidates in the order of a digest of each
    name, so adding a motion never swaps out the others (it only enters, or not, by its own rank)."""
    first = carve_motions(MOTIONS, set(), fraction=0.2)
    for shuffled in itertools.islice(itertools.permutations(MOTIONS[:6]), 50):
        assert carve_motions(list(shuffled) + MOTIONS[6:], set(), fraction=0.2) == first
    assert first == sorted(sorted(MOTIONS, key=motion_rank)[:4])  # round(0.2 * 18) = 4
    grown = carve_motions(MOTIONS + ["mix-0"], set(), fraction=4 / 19)
    assert len(set(grown) & set(first)) >= 3


def test_named_validation_motions_are_checked():
    assert carve_motions(MOTIONS, {"sway-0"}, motions=["walk-0", "run-1"]) == ["run-1", "walk-0"]
    with pytest.raises(InputError, match=r"\['sway-0'\] are test motions"):
        carve_motions(MOTIONS, {"sway-0"}, motions=["walk-0", "sway-0"])
    with pytest.raises(InputError, match=r"\['dance'\] are not training motions"):
        carve_motions(MOTIONS, set(), motions=["dance"])
    with pytest.raises(InputError, match="leave none to train on"):
        carve_motions(["walk", "spin"], set(), motions=["walk", "spin"])
    with pytest.raises(InputError, match="not both"):
        carve_motions(MOTIONS, set(), motions=["walk-0"], fraction=0.5)
    for bad in (0.0, 1.0, -0.5, float("nan")):
        with pytest.raises(InputError, match=r"fraction must be in \(0, 1\)"):
            carve_motions(MOTIONS, set(), fraction=bad)
    with pytest.raises(InputError, match="all of them .* are test motions too"):
        carve_motions(["walk", "spin"], {"walk", "spin"}, fraction=0.5)


# ---------------------------------------------------------------- on a simulated store


def _skirt(store):
    return lambda name: store.sequence(name).garment == "skirt+average"


def test_a_store_without_val_trains_without_validation_and_says_so(tiny_store, caplog):
    """The tiny store has walk and spin for training, sway for test and no val split."""
    store = DatasetStore.open(tiny_store)
    assert held_out_motions(store) == {"sway"}
    with caplog.at_level(logging.WARNING, logger="loosefit.train.validation"):
        chosen = choose_validation(store, _skirt(store), "val", what="garment 'skirt+average'")
    assert chosen.source == "none" and chosen.val == [] and len(chosen.train) == 2
    assert "no validation sequences of garment 'skirt+average'" in caplog.text and "without validation" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="loosefit.train.validation"):  # asked for none: not a warning
        assert choose_validation(store, _skirt(store), "none").val == []
    assert caplog.text == ""


def test_carved_motions_validate_and_the_rest_trains(tiny_store):
    store = DatasetStore.open(tiny_store)
    named = choose_validation(store, _skirt(store), "val", val_motions=["spin"])
    assert named.source == "carved" and named.val == ["skirt+average+spin+default"]
    assert named.train == ["skirt+average+walk+default"] and named.motions == ["spin"]
    by_fraction = choose_validation(store, _skirt(store), "none", val_fraction=0.5)
    assert by_fraction.motions == [sorted(["spin", "walk"], key=motion_rank)[0]]
    assert set(by_fraction.val).isdisjoint(by_fraction.train)
    assert set(by_fraction.val) | set(by_fraction.train) == set(named.val) | set(named.train)
    with pytest.raises(InputError, match=r"\['sway'\] are test motions"):
        choose_validation(store, _skirt(store), "val", val_motions=["sway"])
    with pytest.raises(InputError, match="not both"):
        choose_validation(store, _skirt(store), "test", val_motions=["spin"])
    with pytest.raises(InputError, match="validation split must be one of"):
        choose_validation(store, _skirt(store), "train")


def test_the_test_split_validates_only_when_named_and_is_warned(tiny_store, caplog):
    store = DatasetStore.open(tiny_store)
    with caplog.at_level(logging.WARNING, logger="loosefit.train.validation"):
        chosen = choose_validation(store, _skirt(store), "test")
    assert chosen.source == "test" and chosen.val == ["skirt+average+sway+default"]
    assert "TEST split" in caplog.text and "flattered" in caplog.text


def test_a_training_fraction_keeps_every_kind_and_nests():
    """8 walks, 4 spins, 1 jump: a quarter keeps 2, 1 and 1 (at least one of each kind, rounded up); the
    shares are nested; the choice depends on the names alone."""
    kind_of = {**{f"walk-{i}": "walk" for i in range(8)}, **{f"spin-{i}": "spin" for i in range(4)}, "jump-0": "jump"}
    quarter, half, whole = (keep_fraction(kind_of, f) for f in (0.25, 0.5, 1.0))
    count = lambda chosen, kind: sum(kind_of[m] == kind for m in chosen)  # noqa: E731
    assert [count(quarter, k) for k in ("walk", "spin", "jump")] == [2, 1, 1]
    assert [count(half, k) for k in ("walk", "spin", "jump")] == [4, 2, 1]
    assert set(quarter) < set(half) < set(whole) == set(kind_of)
    assert keep_fraction(dict(reversed(list(kind_of.items()))), 0.25) == quarter


def test_a_training_fraction_on_a_store(tiny_store):
    """The tiny store trains on one walk and one spin: any fraction keeps both (every kind); validation is
    untouched; a fraction outside (0, 1] names the store."""
    store = DatasetStore.open(tiny_store)
    chosen = choose_validation(store, _skirt(store), "none")
    assert train_on_fraction(store, chosen, 0.1).train == chosen.train and train_on_fraction(store, chosen, 1.0) == chosen
    assert "training on 2 of 2 training motions" in train_on_fraction(store, chosen, 0.1).note
    with pytest.raises(InputError, match=r"training fraction must be in \(0, 1\], got 1.5") as err:
        train_on_fraction(store, chosen, 1.5)
    assert str(tiny_store) in str(err.value)
    assert motion_kind("walk:seed=3") == "walk" and motion_kind("clip") == "file"
    assert motion_kind("walk:seed=3", "spin-2") == "walk"  # a procedural motion is its generator's, whatever its key
    assert motion_kind("005_02", "ballet-005_02-1") == "ballet" and motion_kind("005_02", "clip") == "file"
    assert motion_kind("x", "-odd-") == "file" and motion_kind("x", "-") == "file"
