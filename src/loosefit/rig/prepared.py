"""Readers of what the ``prepare`` stage (:mod:`loosefit.rig.prepare`) stores with a dataset: the virtual bone rig,
the bone transforms of the training frames, the spectral descriptor, the fit attribute and the normalisation
statistics (the layout is in :mod:`loosefit.rig.prepare`'s docstring). Each reader takes a
:class:`~loosefit.data.store.DatasetStore` or its path, and refuses a group that was not finished
(``status`` other than ``"done"``) with an :class:`~loosefit.errors.InputError` that says to run ``loosefit prepare``.
"""

from __future__ import annotations

import numpy as np

from loosefit.data.mirror import MIRRORED
from loosefit.data.store import DatasetStore
from loosefit.errors import InputError
from loosefit.rig.fit_attribute import FitAttributeModel
from loosefit.rig.normalization import NormalizationStats
from loosefit.rig.virtual_bones import VirtualBoneRig

#: The status of a finished group.
DONE = "done"



def _open(store) -> DatasetStore:
    return store if isinstance(store, DatasetStore) else DatasetStore.open(store, mode="r")


def _require_done(store: DatasetStore, group: str, what: str) -> dict:
    try:
        attrs = store.read_attrs(group)
    except InputError:
        attrs = {}
    if attrs.get("status") != DONE:
        status = attrs.get("status", "missing")
        raise InputError(f"{what} is not prepared (status {status!r}): run `loosefit prepare`", store.path)
    return attrs


def load_rig(store, garment: str) -> VirtualBoneRig:
    """The virtual bone rig of a prepared garment (``store``: a :class:`DatasetStore` or its path)."""
    store = _open(store)
    group = f"garments/{garment}/rig"
    attrs = _require_done(store, group, f"the rig of garment {garment!r}")
    names = ("rest_verts", "weight_indices", "weight_values", "bone_rest_positions")
    arrays = {k: store.read_array(group, k) for k in names}
    arrays["faces"] = store.garment(garment).faces
    rig = VirtualBoneRig.from_arrays(arrays)
    rig.rmse = attrs["rmse_lf_mm"] / 1e3
    rig.settings = attrs.get("solver", {})
    return rig


def prepared_split(store: DatasetStore, garment: str) -> tuple[dict, str, np.ndarray | None]:
    """How ``garment``'s rig was prepared: its settings (``{}`` when it was not), and the low/high-frequency split
    it used, as :func:`loosefit.geometry.smoothing.frequency_split`'s smoothing preset and ``fixed (V,)`` vertices
    (None: none; stores prepared before ``keep_pinned`` existed smoothed the pinned vertices too)."""
    try:
        settings = dict(store.read_attrs(f"garments/{garment}/rig").get("settings", {}))
    except InputError:
        settings = {}  # not prepared (yet): the default split
    fixed = store.garment(garment).pinned if settings.get("keep_pinned", False) else None
    return settings, settings.get("smoothing", "virtualbones"), fixed


def load_bone_transforms(store, garment: str, sequence: str) -> tuple[np.ndarray, np.ndarray]:
    """``rotations (T, B, 3, 3)`` and ``translations (T, B, 3)`` float32 of a training sequence's frames (or of its
    mirror's, ``<sequence>=mirrored``, in a store prepared with ``mirror``)."""
    store = _open(store)
    group = f"garments/{garment}/rig"
    attrs = _require_done(store, group, f"the rig of garment {garment!r}")
    base = sequence.removesuffix(MIRRORED)
    if base not in attrs["sequences"]:
        raise InputError(f"sequence {base!r} is not a training sequence of garment {garment!r}", store.path)
    if base != sequence and not attrs.get("settings", {}).get("mirror", False):
        raise InputError(f"the rig of garment {garment!r} has no mirrored sequences: prepare the store with the "
                         "setting mirror=true to train on them", store.path)
    frames = f"{group}/frames/{sequence}"
    return store.read_array(frames, "rotations"), store.read_array(frames, "translations")


def load_descriptor(store, garment: str) -> np.ndarray:
    """The spectral descriptor ``(z,)`` float32 of a garment."""
    store = _open(store)
    _require_done(store, f"garments/{garment}/descriptor", f"the descriptor of garment {garment!r}")
    return store.read_array(f"garments/{garment}/descriptor", "spectral")


def load_fit_attribute(store) -> tuple[FitAttributeModel, dict[tuple[str, str], np.ndarray]]:
    """The fitted factor analysis and the fit attribute ``alpha (F,)`` of every ``(garment, body)`` pair."""
    store = _open(store)
    group = "prepare/fit_attribute"
    attrs = _require_done(store, group, "the fit attribute")
    names = ("mean", "components", "noise_variance", "meta")
    model = FitAttributeModel.from_arrays({k: store.read_array(group, k) for k in names})
    alpha = store.read_array(group, "alpha")
    return model, {(g, b): alpha[i] for i, (g, b, _) in enumerate(attrs["pairs"])}


def read_stats(store, garment: str | None = None) -> NormalizationStats:
    """Normalisation statistics: the dataset's (``garment=None``) or those of one garment's rig."""
    store = _open(store)
    if garment is None:
        _require_done(store, "prepare", "the dataset")
        group = "prepare/stats"
    else:
        _require_done(store, f"garments/{garment}/rig", f"the rig of garment {garment!r}")
        group = f"garments/{garment}/rig/stats"
    keys = [f"{n}.{k}" for n in store.read_attrs(group)["names"] for k in ("count", "mean", "m2")]
    arrays = {key: store.read_array(group, key) for key in keys}
    return NormalizationStats.from_arrays(arrays)
