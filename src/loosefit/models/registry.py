"""Method names (as on the command line) to model classes, imported on first use."""

from __future__ import annotations

import importlib

from loosefit.errors import InputError

METHODS = {
    "virtualbones": "loosefit.models.virtualbones:VirtualBones",
    "jointnet": "loosefit.models.jointnet:JointNet",
    "body-lbs": "loosefit.models.body_lbs:BodyLBS",
    "fitgar": "loosefit.models.fitgar:FitGar",
    "swingar": "loosefit.models.swingar:SwinGar",
}


def model_class(method: str):
    """The model class of ``method``: a :class:`~loosefit.models.base.GarmentModel` subclass, or a
    multi-garment model (class attribute ``multi_garment``, e.g. FitGar)."""
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; available: {sorted(METHODS)}")
    module, name = METHODS[method].split(":")
    return getattr(importlib.import_module(module), name)


def run_config_class(method: str):
    """The dataclass of a method's whole run config (its module's ``Config``: ``model`` and, for trained
    methods, ``train`` and ``data`` sections), as read from ``configs/models/<method>.yaml``."""
    return importlib.import_module(model_class(method).__module__).Config
