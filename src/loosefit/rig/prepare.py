"""The ``prepare`` stage: virtual bones, spectral descriptors, fit attributes and normalisation statistics.

``loosefit prepare DATA.zarr`` runs :func:`prepare` on a simulated dataset. For every garment:

1. the spectral descriptor of its rest mesh (:mod:`loosefit.rig.spectral`), garments without
   training sequences included (methods that generalise to new garments need theirs);
2. when it has training sequences: their low-frequency meshes (diffusion smoothing,
   :func:`loosefit.geometry.smoothing.frequency_split`), SSDR virtual bones fitted on frames drawn
   evenly from all of them (test sequences are never read), and the bone transforms of every
   training frame (:mod:`loosefit.rig.virtual_bones`), with the statistics of the rig's targets.

Then, over the whole dataset: the fit attribute of every garment-body pair from a factor analysis
fitted on the training pairs (:mod:`loosefit.rig.fit_attribute`), and the statistics of the
network inputs (:mod:`loosefit.rig.normalization`).

What it writes (``<g>`` a garment, ``<s>`` a training sequence)::

    garments/<g>/rig/            attrs: status ("writing" | "done"), settings, sequences, bones,
                                 rmse_lf_mm, rmse_full_mm (bones against the low-frequency and the
                                 full meshes, all training frames), seconds, fit_seconds, solver
        rest_verts (V,3), weight_indices (V,K), weight_values (V,K), bone_rest_positions (B,3)
        frames/<s>/rotations (T,B,3,3) float32, frames/<s>/translations (T,B,3) float32
        frames/<s>=mirrored/...  the same for the sequence's left-right mirror (setting ``mirror``)
        stats/                   bone_rotation (B,3) axis-angle, bone_translation (B,3),
                                 garment_verts (3,), lf_verts (3,), hf_offset (3,), hf_offset_vertex (V,3)
    garments/<g>/descriptor/     spectral (z,) float32; attrs: status, settings
    prepare/fit_attribute/       mean, components, noise_variance, meta (the model), alpha (P,F);
                                 attrs: status ("done" | "skipped"), reason, pairs [[garment, body, split]], settings
    prepare/stats/               body_rotation (J,3), body_translation (3,), body_velocity (3,) (m per frame),
                                 body_shape (S,), garment_verts (3,), hf_offset (3,), spectral_descriptor (z,),
                                 fit_attribute (F,)

Each statistic is stored as ``<name>.count``, ``.mean``, ``.m2`` and ``.std`` (population). Every
array is written atomically by the store. Resuming: a garment whose rig (or descriptor) is
``"done"`` with the same settings and training sequences is skipped; an interrupted one is redone
from the start. Frame ``i`` of ``frames/<s>`` is frame ``i`` of sequence ``<s>`` and of its motion.
The later stages read all this through :mod:`loosefit.rig.prepared`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from loosefit.config import config_from_dict
from loosefit.data.mirror import GarmentMirror, MirroredSequence
from loosefit.data.store import DatasetStore
from loosefit.errors import InputError
from loosefit.geometry.rotations import matrix_to_axis_angle
from loosefit.geometry.smoothing import frequency_split, get_preset
from loosefit.rig.fit_attribute import DEFAULT_FACTORS, FitAttributeModel, distance_vector
from loosefit.rig.normalization import NormalizationStats, RunningStats
from loosefit.rig.prepared import DONE, read_stats
from loosefit.rig.spectral import DEFAULT_SAMPLES, DEFAULT_SIGMA, spectral_descriptor
from loosefit.rig.virtual_bones import (
    DEFAULT_BONES,
    DEFAULT_MAX_SOLVE_FRAMES,
    DEFAULT_THREADS,
    DEFAULT_TRANS_AFFINE,
    TRANSFORM_CHUNK,
    fit_virtual_bones,
    frame_errors,
    solve_bone_transforms,
    solve_frames,
)

@dataclass(frozen=True)
class PrepareSettings:
    """Settings of :func:`prepare` (a :mod:`loosefit.config` dataclass: from a mapping or YAML, with overrides).

    Attributes:
        bones: virtual bones per garment (VirtualBones uses 80).
        influences: non-zero skinning weights per vertex at most.
        iterations: SSDR alternating iterations of the weight solve.
        transform_iterations: bone sweeps per frame when solving every frame's transforms.
        max_solve_frames: frames (from all training sequences together) the weight solve sees.
        trans_affine: Dem Bones' translation-affinity weight.
        smoothing: smoothing preset of the low/high-frequency split.
        keep_pinned: the split leaves the garment's pinned vertices where they are (its high
            frequency is zero there): smoothing along the pinned waist ring would shrink it into the
            body, and the low-frequency module would learn a waist inside the body.
        descriptor_samples: ``z`` of the spectral descriptor.
        descriptor_sigma: its affinity kernel width, metres.
        fit_factors: factors of the fit attribute.
        seed: seeds the descriptor's first sample and the fit attribute's vertex selection.
        threads: OpenMP threads of the SSDR solver (1 is fastest on shared 2-core machines).
        mirror: rig the left-right mirror of every training sequence too (:mod:`loosefit.data.mirror`): its
            frames join the weight solve and its bone transforms are stored as ``frames/<s>=mirrored``, for
            training with ``data.mirror``.
    """

    bones: int = DEFAULT_BONES
    influences: int = 8
    iterations: int = 20
    transform_iterations: int = 30
    max_solve_frames: int = DEFAULT_MAX_SOLVE_FRAMES
    trans_affine: float = DEFAULT_TRANS_AFFINE
    smoothing: str = "virtualbones"
    keep_pinned: bool = True
    descriptor_samples: int = DEFAULT_SAMPLES
    descriptor_sigma: float = DEFAULT_SIGMA
    fit_factors: int = DEFAULT_FACTORS
    seed: int = 0
    threads: int = DEFAULT_THREADS
    mirror: bool = False

    def rig(self) -> dict:
        """The settings a rig depends on (``mirror`` only when set: rigs prepared before it existed stay done)."""
        keys = ("bones", "influences", "iterations", "transform_iterations", "max_solve_frames", "trans_affine")
        rig = {k: getattr(self, k) for k in (*keys, "smoothing", "keep_pinned")}
        return {**rig, "mirror": True} if self.mirror else rig

    def descriptor(self) -> dict:
        """The settings a spectral descriptor depends on."""
        return {"samples": self.descriptor_samples, "sigma": self.descriptor_sigma, "seed": self.seed}

    def fit_attribute(self) -> dict:
        """The settings the fit attribute depends on."""
        return {"factors": self.fit_factors, "seed": self.seed}


def prepare_settings(values: dict | None = None, source: str | Path | None = None) -> PrepareSettings:
    """:class:`PrepareSettings` from a mapping (:func:`loosefit.config.config_from_dict`; missing keys keep
    their defaults); an unknown key raises :class:`InputError` listing the allowed ones."""
    names = [f.name for f in dataclasses.fields(PrepareSettings)]
    unknown = sorted(set(values or {}) - set(names))
    if unknown:
        raise InputError(f"unknown prepare settings {unknown}; known: {names}", source)
    s = config_from_dict(PrepareSettings, values, source)
    get_preset(s.smoothing)  # an unknown preset names the known ones
    bad = [f"{k}={getattr(s, k)!r} (must be {rule})" for k, ok, rule in (
        ("influences", s.influences >= 1, "at least 1"), ("iterations", s.iterations >= 0, ">= 0"),
        ("transform_iterations", s.transform_iterations >= 0, ">= 0"),
        ("max_solve_frames", s.max_solve_frames >= 1, "at least 1"),
        ("trans_affine", math.isfinite(s.trans_affine) and s.trans_affine >= 0, "a finite number >= 0"),
        ("descriptor_samples", s.descriptor_samples >= 1, "at least 1"),
        ("descriptor_sigma", math.isfinite(s.descriptor_sigma) and s.descriptor_sigma > 0, "a finite number > 0"),
        ("threads", s.threads >= 1, "at least 1")) if not ok]
    if bad:
        raise InputError(f"bad prepare settings: {'; '.join(bad)}", source)
    return s


def prepare(
    store_path: str | Path, bones: int | None = None, body=None, force: bool = False, progress: bool = True,
    **settings
) -> dict:
    """Prepare a simulated dataset for training (see the module docstring for what is stored).

    Args:
        store_path: the dataset (opened for appending).
        bones: virtual bones per garment (None: :attr:`PrepareSettings.bones`).
        body: the body model the dataset's body shapes belong to, for the fit attribute (default: Anny,
            loaded only when there is a factor analysis to fit).
        force: redo garments that are already done.
        progress: show progress bars.
        **settings: any other field of :class:`PrepareSettings`.

    Returns:
        A summary: per garment the rig's bone count, errors and time, the fit attribute's status,
        and the names of the dataset statistics.
    """
    s = prepare_settings({**settings, **({} if bones is None else {"bones": int(bones)})})
    with DatasetStore.open(store_path, mode="a") as store:  # the write lock is let go on return (the demo's
        # held-out simulation writes the store next)
        sequences = {name: store.sequence(name) for name in store.sequence_names(status="ok")}
        train = {g: [] for g in store.garment_names()}
        for name, q in sequences.items():
            if q.split == "train":
                train[q.garment].append(name)
        _check_before_writing(store, s, train, force)
        store.write_attrs("prepare", {"status": "writing"})
        summary: dict = {"garments": {}}
        for g in tqdm(store.garment_names(), desc="garments", disable=not progress):
            garment = store.garment(g)
            _prepare_descriptor(store, g, garment, s, force)
            entry = {"descriptor": s.descriptor(), "training_sequences": len(train[g])}
            if train[g]:
                entry.update(_prepare_rig(store, g, garment, train[g], s, force, progress))
            summary["garments"][g] = entry
        summary["fit_attribute"] = _prepare_fit_attribute(store, sequences, body, s, force)
        summary["stats"] = sorted(_prepare_dataset_stats(store, sequences, train))
        store.write_attrs("prepare", {"status": DONE, "settings": dataclasses.asdict(s)})
        return summary


# ---------------------------------------------------------------- per garment


def _is_done(store: DatasetStore, group: str, expected: dict) -> bool:
    """Whether ``group`` was finished with attributes equal to ``expected``."""
    try:
        attrs = store.read_attrs(group)
    except InputError:
        return False
    return attrs.get("status") == DONE and all(attrs.get(k) == v for k, v in expected.items())


def _rig_expected(s: PrepareSettings, names: list[str]) -> dict:
    """The attributes a finished rig of these settings and training sequences has."""
    return {"settings": s.rig(), "sequences": names}


def _check_before_writing(store: DatasetStore, s: PrepareSettings, train: dict[str, list[str]], force: bool) -> None:
    """Refuse, before anything in the store changes, what would stop prepare half-way: a garment with fewer
    vertices than the descriptor's samples, a bone count its rig cannot have, a damaged training sequence
    that its rig would read (every chunk is read: the time of reading those sequences once). A refused
    prepare leaves a prepared store as it was; a rig interrupted half-way is marked ``"writing"``."""
    for g, names in train.items():
        num_verts = store.garment_num_verts(g)
        if num_verts < s.descriptor_samples:
            raise InputError(
                f"garment {g!r} has {num_verts} vertices, fewer than the spectral descriptor's "
                f"{s.descriptor_samples} samples: lower descriptor_samples (all garments need the same)",
                store.path,
            )
        if not names or (not force and _is_done(store, f"garments/{g}/rig", _rig_expected(s, names))):
            continue
        if not 1 <= s.bones <= num_verts:
            raise InputError(f"bones={s.bones}: garment {g!r} has {num_verts} vertices, so its rig can have "
                             f"1 to {num_verts} bones", store.path)
        for name in names:
            problem = store.verify_sequence(name)
            if problem:
                raise InputError(f"training sequence {name!r} is damaged ({problem}); nothing was changed: "
                                 f"`loosefit info {store.path} --repair` drops it", store.path / "sequences" / name)


def _prepare_descriptor(store: DatasetStore, g: str, garment, s: PrepareSettings, force: bool) -> None:
    group = f"garments/{g}/descriptor"
    if not force and _is_done(store, group, {"settings": s.descriptor()}):
        return
    store.write_attrs(group, {"status": "writing"})
    d = spectral_descriptor(garment.verts, garment.faces, s.descriptor_samples, s.descriptor_sigma, s.seed)
    store.write_array(group, "spectral", d)
    store.write_attrs(group, {"status": DONE, "settings": s.descriptor()})


def _solve_counts(lengths: list[int], budget: int) -> list[int]:
    """Weight-solve frames per sequence: proportional to its length, at least one each."""
    total = sum(lengths)
    return [max(1, min(n, int(round(budget * n / total)))) for n in lengths]


def _prepare_rig(
    store: DatasetStore, g: str, garment, names: list[str], s: PrepareSettings, force: bool, progress: bool
) -> dict:
    group = f"garments/{g}/rig"
    expected = _rig_expected(s, names)
    if not force and _is_done(store, group, expected):
        attrs = store.read_attrs(group)
        kept = ("bones", "rmse_lf_mm", "rmse_full_mm", "seconds", "fit_seconds")
        return {k: attrs[k] for k in kept} | {"skipped": True}
    started = time.perf_counter()
    store.write_attrs(group, {"status": "writing"})
    faces = garment.faces
    fixed = garment.pinned if s.keep_pinned else None
    rest_lf = frequency_split(garment.verts, faces, s.smoothing, fixed=fixed)[0]
    seqs = [store.sequence(n) for n in names]
    if s.mirror:
        mirror = GarmentMirror.build(garment.verts, faces)
        seqs += [MirroredSequence(q, mirror) for q in seqs]
    lengths = [q.num_frames for q in seqs]
    picks = [solve_frames(n, k) for n, k in zip(lengths, _solve_counts(lengths, s.max_solve_frames))]
    sample = np.concatenate([frequency_split(q.verts.oindex[p], faces, s.smoothing, fixed=fixed)[0]
                             for q, p in zip(seqs, picks)])
    if progress:
        tqdm.write(f"{g}: SSDR weights of {s.bones} bones on {len(sample)} of {sum(lengths)} training frames")
    fit_started = time.perf_counter()
    rig, R0, T0 = fit_virtual_bones(
        sample, rest_lf, faces, bones=s.bones, influences=s.influences, iterations=s.iterations,
        trans_affine=s.trans_affine, max_solve_frames=len(sample), threads=s.threads,
    )
    fit_seconds = time.perf_counter() - fit_started
    B = rig.num_bones
    stats = NormalizationStats()
    err_lf, err_full = [], []
    bar = tqdm(total=sum(lengths), desc=f"{g} bone transforms", unit="frame", leave=False, disable=not progress)
    offset = 0
    for q, pick in zip(seqs, picks):
        # Every frame starts from the weight-solve frame of its own sequence nearest in time.
        nearest = offset + np.abs(np.arange(q.num_frames)[:, None] - pick[None]).argmin(1)
        rotations = np.empty((q.num_frames, B, 3, 3), np.float32)
        translations = np.empty((q.num_frames, B, 3), np.float32)
        for a in range(0, q.num_frames, TRANSFORM_CHUNK):
            b = min(a + TRANSFORM_CHUNK, q.num_frames)
            full = np.asarray(q.verts[a:b], np.float32)
            lf, hf = frequency_split(full, faces, s.smoothing, fixed=fixed)
            R, T = solve_bone_transforms(rig, lf, R0[nearest[a:b]], T0[nearest[a:b]], iterations=s.transform_iterations,
                                         threads=s.threads)
            rotations[a:b], translations[a:b] = R, T
            err_lf.append(frame_errors(rig, lf, R, T))
            err_full.append(frame_errors(rig, full, R, T))
            stats.add("bone_rotation", matrix_to_axis_angle(R.astype(np.float64)).numpy(), (B, 3))
            stats.add("bone_translation", T, (B, 3))
            stats.add("garment_verts", full, (3,))
            stats.add("lf_verts", lf, (3,))
            stats.add("hf_offset", hf, (3,))
            stats.add("hf_offset_vertex", hf, (rig.num_verts, 3))
            bar.update(b - a)
        store.write_array(f"{group}/frames/{q.name}", "rotations", rotations)
        store.write_array(f"{group}/frames/{q.name}", "translations", translations)
        offset += len(pick)
    bar.close()
    for key, value in rig.to_arrays().items():
        if key not in ("faces", "rmse", "settings"):
            store.write_array(group, key, value)
    _write_stats(store, f"{group}/stats", stats)
    result = {
        "bones": B,
        "rmse_lf_mm": float(np.sqrt(np.concatenate(err_lf).mean()) * 1e3),
        "rmse_full_mm": float(np.sqrt(np.concatenate(err_full).mean()) * 1e3),
        "seconds": time.perf_counter() - started,
        "fit_seconds": fit_seconds,
    }
    store.write_attrs(group, {"status": DONE, **expected, **result, "solver": rig.settings})
    return result


# ---------------------------------------------------------------- dataset level


def _prepare_fit_attribute(store: DatasetStore, sequences: dict, body, s: PrepareSettings, force: bool) -> dict:
    group = "prepare/fit_attribute"
    split_of: dict[tuple[str, str], str] = {}
    for q in sequences.values():
        # A pair with any training sequence is a training pair.
        key = (q.garment, q.body)
        split_of[key] = "train" if q.split == "train" or split_of.get(key) == "train" else q.split
    pairs = [[g, b, split_of[(g, b)]] for g, b in sorted(split_of)]
    expected = {"pairs": pairs, "settings": s.fit_attribute()}
    if not force and _is_done(store, group, expected):
        return {"status": DONE, "pairs": len(pairs), "skipped": True}
    train = [i for i, p in enumerate(pairs) if p[2] == "train"]
    if len(train) < 2:
        reason = f"factor analysis needs at least 2 training garment-body pairs, the dataset has {len(train)}"
        store.write_attrs(group, {"status": "skipped", "reason": reason, **expected})
        return {"status": "skipped", "reason": reason}
    if body is None:
        from loosefit.body.anny_body import AnnyBody

        body = AnnyBody()
    garments = {g: store.garment(g) for g, _, _ in pairs}
    bodies = {b: _body_verts(store, body, b) for _, b, _ in pairs}
    length = min(len(garments[pairs[i][0]].verts) for i in train)
    vectors = np.stack(
        [distance_vector(garments[g].verts, garments[g].faces, bodies[b], length, s.seed) for g, b, _ in pairs]
    )
    model = FitAttributeModel.fit(vectors[train], s.fit_factors, s.seed)
    store.write_attrs(group, {"status": "writing"})
    for key, value in model.to_arrays().items():
        store.write_array(group, key, value)
    store.write_array(group, "alpha", model.transform(vectors))
    store.write_attrs(group, {"status": DONE, "reason": "", "length": length, **expected})
    return {"status": DONE, "pairs": len(pairs), "training_pairs": len(train), "factors": model.num_factors,
            "length": length}


def _body_verts(store: DatasetStore, body, name: str) -> np.ndarray:
    """Rest vertices of the store's body ``name`` on ``body``, whose model must be the one it was stored for."""
    model = store.read_attrs(f"bodies/{name}").get("model", "")
    if not str(getattr(body, "name", "")).startswith(str(model)):
        raise InputError(f"body {name!r} is a {model!r} shape but prepare was given the body {body.name!r}", store.path)
    return body.rest_verts(store.body(name))


def _prepare_dataset_stats(store: DatasetStore, sequences: dict, train: dict) -> list[str]:
    stats = NormalizationStats()
    for q in sequences.values():
        if q.split != "train":
            continue
        motion = store.motion(q.motion)
        n = q.num_frames
        stats.add("body_rotation", motion.rotations[:n], motion.rotations.shape[1:])
        stats.add("body_translation", motion.translation[:n], (3,))
        stats.add("body_velocity", np.diff(motion.translation[:n], axis=0, prepend=motion.translation[:1]), (3,))
        shape = store.body(q.body)
        stats.add("body_shape", shape, shape.shape)  # one sample per training sequence
    for g, names in train.items():
        if names:
            descriptor = store.read_array(f"garments/{g}/descriptor", "spectral")
            stats.add("spectral_descriptor", descriptor, descriptor.shape)
            rig_stats = read_stats(store, g)
            # Pooled over garments: the merge of each garment's statistics.
            for key in ("garment_verts", "hf_offset"):
                stats.setdefault(key, RunningStats.empty(rig_stats[key].shape)).merge(rig_stats[key])
    attrs = store.read_attrs("prepare/fit_attribute")
    if attrs.get("status") == DONE:
        alpha = store.read_array("prepare/fit_attribute", "alpha")
        rows = [i for i, p in enumerate(attrs["pairs"]) if p[2] == "train"]
        stats.add("fit_attribute", alpha[rows], alpha.shape[1:])
    _write_stats(store, "prepare/stats", stats)
    return list(stats)


def _write_stats(store: DatasetStore, group: str, stats: NormalizationStats) -> None:
    for key, value in stats.to_arrays().items():
        store.write_array(group, key, np.asarray(value))
    # The list read back, so that statistics of an earlier run that this one did not make are ignored.
    store.write_attrs(group, {"names": sorted(stats)})
