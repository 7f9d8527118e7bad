"""The report's inputs: the held-out sequences of a dataset store and every run's animation of them.

A run is a folder written by ``loosefit train``; each animates the sequences of the garment(s) it was
trained for (per-garment methods: its garment; SwinGar: any garment; FitGar: any garment, frame by
frame). The ground truth is the simulation stored in the dataset; the body is posed on the
sequence's own shape and motion (for the collision ratio and the error maps).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from loosefit.errors import InputError


@dataclass
class Sequence:
    """One held-out sequence: ``gt (T, V, 3)`` metres on ``faces (F, 3)``, the posed body
    ``body_verts (T, Vb, 3)`` / ``body_faces (Fb, 3)``, its stored reference runs ``references (K, T, V, 3)``
    (K = 0 when it has none) and the inputs the animators need."""

    name: str
    garment: str
    gt: np.ndarray
    faces: np.ndarray
    body_verts: np.ndarray
    body_faces: np.ndarray
    fps: float
    motion: object = field(repr=False)
    body: object = field(repr=False)
    garment_mesh: object = field(repr=False)
    references: np.ndarray = field(default=None, repr=False)


@dataclass
class Method:
    """One run: its ``label`` in the report, ``method`` name, folder, predictions ``{sequence: (T, V, 3)}``
    and a line per sequence motion outside the run's training range (:mod:`loosefit.motion_range`)."""

    label: str
    method: str
    run: Path
    predictions: dict[str, np.ndarray]
    warnings: list[str] = field(default_factory=list)


def load_sequences(data: str | Path, names: list[str] | None = None, split: str | None = "test") -> list[Sequence]:
    """The sequences ``names`` of store ``data`` (default: every ``"ok"`` sequence of ``split``)."""
    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.data import DatasetStore

    store = DatasetStore.open(data, "r")
    available = store.sequence_names(split=None)
    names = store.sequence_names(split=split) if names is None else list(names)
    unknown = [n for n in names if n not in available]
    if unknown:
        raise InputError(f"no sequence {unknown} in the dataset (it has {available[:8]}...)", Path(data))
    if not names:
        raise InputError(f"the dataset has no sequence in split {split!r} to report on", Path(data))
    out = []
    for name in names:
        seq = store.sequence(name)
        motion = store.motion(seq.motion)
        body = AnnyBody(AnnyShape.from_array(store.body(seq.body)), rig=motion.rig)
        garment = store.garment(seq.garment)
        out.append(Sequence(name, seq.garment, np.asarray(seq.verts[:], np.float32), np.asarray(garment.faces),
                            body.pose(motion).verts, np.asarray(body.faces), float(motion.fps), motion, body, garment,
                            store.references(name)))
    return out


def animate_run(run: str | Path, sequences: list[Sequence], device: str = "cpu") -> tuple[str, dict[str, np.ndarray]]:
    """The method name of ``run`` and its predictions ``{sequence name: (T, V, 3)}`` of the sequences it
    can animate (a per-garment run: those of its garment).

    Raises:
        InputError: not a run folder, or a run for a garment none of ``sequences`` wears.
    """
    from loosefit.animate import Animator, read_run_meta
    from loosefit.animate_any import AnyGarmentAnimator, is_static_run

    run = Path(run)
    meta = read_run_meta(run)
    if is_static_run(run):
        animator = AnyGarmentAnimator(run, device=device)
        out = {s.name: animator.animate(animator.pair(s.garment_mesh.verts, s.faces, s.body), s.motion) for s in sequences}
        return meta["method"], out
    if meta.get("garment") is None and "garments" in meta:  # a multi-garment dynamic method (SwinGar)
        out = {}
        for s in sequences:
            out[s.name] = Animator(run, garment=s.garment_mesh, body=s.body, device=device).animate(s.motion)
        return meta["method"], out
    mine = [s for s in sequences if s.garment == meta.get("garment")]
    if not mine:
        worn = sorted({s.garment for s in sequences})
        raise InputError(f"this {meta.get('method')} run is for garment {meta.get('garment')!r}; the reported "
                         f"sequences wear {worn}", run)
    animator = Animator(run, device=device)
    if len(animator.faces) != len(mine[0].faces) or not np.array_equal(animator.faces, mine[0].faces):
        raise InputError(f"the run's garment mesh differs from the dataset's {mine[0].garment!r} "
                         "(the store was simulated again)", run)
    predictions = animator.animate_batch([s.motion for s in mine])
    return meta["method"], {s.name: p for s, p in zip(mine, predictions)}


def load_methods(runs: list[str | Path], sequences: list[Sequence], device: str = "cpu",
                 handling: str = "exact") -> list[Method]:
    """Every run animated on ``sequences``, with collision handling ``handling``
    (:func:`loosefit.models.collision.post_process`); labels are method names, with the run folder's name when
    two runs share a method."""
    if not runs:
        raise InputError("give at least one run folder to report on")
    from loosefit.models.collision import check_post_process, post_process

    check_post_process(handling)  # before any run is animated
    from loosefit.animate import read_run_meta
    from loosefit.motion_range import range_warnings

    loaded = []
    for run in runs:
        method, predictions = animate_run(run, sequences, device)
        by_name = {s.name: s for s in sequences}
        predictions = {name: post_process(p, by_name[name].faces, by_name[name].body, by_name[name].motion, handling,
                                          by_name[name].garment_mesh.verts)
                       for name, p in predictions.items()}
        meta = read_run_meta(run)
        warnings = [line for s in sequences if s.name in predictions
                    for line in range_warnings(meta, s.motion, f"of sequence {s.name}")]
        loaded.append((method, Path(run), predictions, warnings))
    counts = {m: sum(1 for x, *_ in loaded if x == m) for m, *_ in loaded}
    return [Method(m if counts[m] == 1 else f"{m} ({r.name})", m, r, p, w) for m, r, p, w in loaded]
