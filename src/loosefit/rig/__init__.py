"""Garment preparation: virtual bones (SSDR), the spectral descriptor, the fit attribute, normalisation
statistics, the ``prepare`` stage that stores them with a dataset (:func:`loosefit.rig.prepare.prepare`;
the function is not re-exported here, where its name would hide its module) and the readers of what it
stored (:mod:`loosefit.rig.prepared`)."""

from loosefit.rig.fit_attribute import FitAttributeModel, distance_vector
from loosefit.rig.normalization import NormalizationStats, RunningStats
from loosefit.rig.prepare import PrepareSettings
from loosefit.rig.prepared import (
    load_bone_transforms,
    load_descriptor,
    load_fit_attribute,
    load_rig,
    read_stats,
)
from loosefit.rig.spectral import spectral_decomposition, spectral_descriptor
from loosefit.rig.virtual_bones import VirtualBoneRig, fit_virtual_bones, skin_bones, solve_bone_transforms, sparse_weights

__all__ = [
    "FitAttributeModel",
    "NormalizationStats",
    "PrepareSettings",
    "RunningStats",
    "VirtualBoneRig",
    "distance_vector",
    "fit_virtual_bones",
    "load_bone_transforms",
    "load_descriptor",
    "load_fit_attribute",
    "load_rig",
    "read_stats",
    "skin_bones",
    "sparse_weights",
    "solve_bone_transforms",
    "spectral_decomposition",
    "spectral_descriptor",
]
