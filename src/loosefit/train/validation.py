"""Which sequences validate a training run, so that model selection never sees a test motion.

The validation set selects ``checkpoints/best.pt`` (and shows the training curve on unseen motions): a
run that validated on the test motions would pick the epoch that flatters its own test score. So:

- a store with a ``val`` split (the plan's ``split: {val: ...}``) validates on it;
- a store without one trains without validation and says so, unless validation motions are carved out
  of the training sequences: named (``motions``) or a ``fraction`` of the training motions, chosen by a
  hash of their names (the same choice on every machine and in every run, whatever the order of the
  store). Every sequence of a carved motion validates (all its body shapes and parameter sets), every
  other sequence of the garment stays in training; a motion that any test sequence of the store uses is
  never carved;
- the ``test`` split validates only when it is named explicitly, with a warning.

For a learning curve, :func:`train_on_fraction` then keeps a share of the training motions: the same
ranking by name within each motion kind, so the shares are nested (25 % within 50 % within 100 %) and
every kind keeps at least one motion.

The garment rig of a prepared store was fitted on every training sequence, carved ones too: carving
changes what the networks train on, not the rig they drive.
"""

from __future__ import annotations

import hashlib
import logging
import math
from dataclasses import dataclass, field
from typing import Callable, Optional

from loosefit.errors import InputError

log = logging.getLogger(__name__)

#: ``val_split`` values: the store's own validation split, the test split (explicitly), or none.
SPLITS = ("val", "test", "none")


@dataclass(frozen=True)
class Validation:
    """How a run validates.

    Attributes:
        source: ``"val"`` (the store's split), ``"carved"`` (training motions set aside), ``"test"``
            (named explicitly) or ``"none"``.
        train: the sequence names that train; val: those that validate (empty for ``"none"``).
        motions: the validation motions (store motion names), sorted.
        note: one line saying what was chosen (logged, and kept in the run's ``model.json``).
    """

    source: str
    train: list[str]
    val: list[str] = field(default_factory=list)
    motions: list[str] = field(default_factory=list)
    note: str = ""

    def to_json(self) -> dict:
        return {"source": self.source, "motions": list(self.motions), "note": self.note}


def held_out_motions(store) -> set[str]:
    """The motions that any usable test sequence of ``store`` uses (every garment, shape and parameter set)."""
    return {store.sequence(n).motion for n in store.sequence_names(split="test")}


def motion_rank(name: str) -> str:
    """The key that orders motions for a carved fraction: a digest of the name alone."""
    return hashlib.sha1(name.encode("utf-8")).hexdigest()


def carve_motions(train_motions: list[str], forbidden: set[str], motions: Optional[list[str]] = None,
                  fraction: Optional[float] = None, path=None) -> list[str]:
    """The training motions that become validation motions.

    Args:
        train_motions: the motions of the training sequences.
        forbidden: motions that must not validate (those of test sequences).
        motions: named validation motions; or ``fraction`` in (0, 1): that share of ``train_motions``
            (rounded, at least one), the candidates not in ``forbidden`` taken in :func:`motion_rank` order.

    Raises:
        InputError: a named motion that is not a training motion or is a test motion; a fraction out of
            range, or one that would leave no training motion or finds no candidate.
    """
    available = sorted(set(train_motions))
    if motions is not None and fraction is not None:
        raise InputError("give validation motions or a validation fraction, not both", path)
    if motions is not None:
        chosen = sorted(set(motions))
        if not chosen:
            raise InputError("no validation motion named", path)
        test = sorted(set(chosen) & forbidden)
        if test:
            raise InputError(f"validation motions {test} are test motions: model selection must not see them", path)
        unknown = sorted(set(chosen) - set(available))
        if unknown:
            raise InputError(f"validation motions {unknown} are not training motions of this garment "
                             f"(they are {available})", path)
    else:
        if fraction is None or not 0 < fraction < 1 or not math.isfinite(fraction):
            raise InputError(f"the validation fraction must be in (0, 1), got {fraction}", path)
        candidates = sorted((m for m in available if m not in forbidden), key=motion_rank)
        if not candidates:
            raise InputError(f"no training motion can validate: all of them ({available}) are test motions too", path)
        count = min(max(1, round(fraction * len(available))), len(candidates))
        chosen = sorted(candidates[:count])
    if len(chosen) >= len(available):
        raise InputError(f"validating on every training motion ({available}) would leave none to train on", path)
    return chosen


def choose_validation(store, keep: Callable[[str], bool], val_split: Optional[str] = "val",
                      val_motions: Optional[list[str]] = None, val_fraction: Optional[float] = None,
                      what: str = "") -> Validation:
    """The training and validation sequences of a run (see the module doc).

    Args:
        store: an open :class:`~loosefit.data.store.DatasetStore`.
        keep: which sequence names the run may use at all (its garment, its simulation parameters).
        val_split: ``"val"`` (default), ``"test"`` (explicitly: warned), ``"none"`` or None.
        val_motions, val_fraction: carve validation motions out of the training sequences instead.
        what: words naming the run's data in messages (``"garment 'skirt+average'"``).

    Raises:
        InputError: an unknown split; carving together with the store's own ``val`` split (or with
            ``test``); the carving errors of :func:`carve_motions`.
    """
    split = "none" if val_split is None else val_split
    if split not in SPLITS:
        raise InputError(f"the validation split must be one of {list(SPLITS)}, got {val_split!r}", store.path)
    train = [n for n in store.sequence_names(split="train") if keep(n)]
    what = f" of {what}" if what else ""
    carving = val_motions is not None or val_fraction is not None
    if carving:
        if split == "test":
            raise InputError("validate on the test split or on carved training motions, not both", store.path)
        own = [n for n in store.sequence_names(split="val") if keep(n)]
        if split == "val" and own:
            raise InputError(f"the store has validation sequences{what} ({len(own)}): validate on them, or give "
                             "the validation split 'none' to carve training motions instead", store.path)
        motion_of = {n: store.sequence(n).motion for n in train}
        chosen = carve_motions(list(motion_of.values()), held_out_motions(store), val_motions, val_fraction, store.path)
        val = [n for n in train if motion_of[n] in chosen]
        note = (f"validating on training motions set aside{what}: {', '.join(chosen)} ({len(val)} sequences); "
                f"{len(train) - len(val)} sequences train")
        result = Validation("carved", [n for n in train if n not in val], val, chosen, note)
    elif split == "none":
        result = Validation("none", train, note=f"training{what} without validation (none asked for)")
    else:
        val = [n for n in store.sequence_names(split=split) if keep(n)]
        motions = sorted({store.sequence(n).motion for n in val})
        if not val and split == "val":
            note = (f"the store has no validation sequences{what}: training without validation (the last "
                    "checkpoint is the model); carve some with --val-motions or --val-fraction")
            result = Validation("none", train, note=note)
        elif not val:
            result = Validation("none", train, note=f"no test sequences{what} to validate on: training without validation")
        else:
            note = f"validating on the store's {split} split{what}: {len(val)} sequences of {', '.join(motions)}"
            if split == "test":
                note = ("validating on the TEST split: the best checkpoint is chosen by the test motions, so any "
                        f"accuracy measured on them is flattered ({len(val)} sequences of {', '.join(motions)})")
            else:
                seen = sorted(set(motions) & held_out_motions(store))
                if seen:
                    note += f"; note: test sequences use {', '.join(seen)} too"
            result = Validation(split, train, val, motions, note)
    # shown by default: validating on the test motions, and a run that asked for validation but gets none
    if result.source == "test" or (result.source == "none" and split != "none"):
        log.warning(result.note)
    else:
        log.info(result.note)
    return result


def motion_kind(name: str, key: str | None = None) -> str:
    """The family of a motion from its name (:attr:`Motion.name`): the procedural generator's (``walk`` for
    ``walk:seed=3``); for any other motion the part of its store ``key`` (the plan's motion name) before the first
    ``-`` (``ballet`` for ``ballet-005_02-1``: plans name capture pieces ``<kind>-<clip>-<piece>``), else
    ``"file"``."""
    if ":seed=" in name:
        return name.split(":")[0]
    return key.split("-")[0] if key and "-" in key.strip("-") else "file"


def keep_fraction(kind_of: dict[str, str], fraction: float) -> list[str]:
    """The motions kept by a training ``fraction`` in (0, 1]: of each kind's ``n`` motions (``kind_of``: motion
    -> kind), the first ``ceil(fraction * n)`` (at least one) in :func:`motion_rank` order; sorted. Nested:
    what a smaller fraction keeps, a larger one keeps too."""
    by_kind: dict[str, list[str]] = {}
    for motion, kind in kind_of.items():
        by_kind.setdefault(kind, []).append(motion)
    return sorted(m for motions in by_kind.values()
                  for m in sorted(motions, key=motion_rank)[:max(1, math.ceil(fraction * len(motions)))])


def train_on_fraction(store, validation: Validation, fraction: float) -> Validation:
    """``validation`` with only a ``fraction`` in (0, 1] of its training motions training (a learning curve):
    :func:`keep_fraction` of the training motions by :func:`motion_kind` of the stored motion. Every sequence
    of a kept motion trains; the validation sequences are unchanged.

    Raises:
        InputError: a fraction outside (0, 1].
    """
    if not 0 < fraction <= 1 or not math.isfinite(fraction):
        raise InputError(f"the training fraction must be in (0, 1], got {fraction}", store.path)
    if fraction == 1:
        return validation
    motion_of = {n: store.sequence(n).motion for n in validation.train}
    kept = set(keep_fraction({m: motion_kind(store.motion(m).name, m) for m in set(motion_of.values())}, fraction))
    train = [n for n in validation.train if motion_of[n] in kept]
    note = (f"{validation.note}; training on {len(kept)} of {len(set(motion_of.values()))} training motions "
            f"(fraction {fraction:g} of each kind: {len(train)} sequences)")
    log.info(note)
    return Validation(validation.source, train, validation.val, validation.motions, note)
