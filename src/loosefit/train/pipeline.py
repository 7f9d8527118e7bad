"""The old import path of :mod:`loosefit.training` (``train_model``, ``MODEL_META``, ``METHOD_CONFIG``...).

:mod:`loosefit.training` sits above both :mod:`loosefit.models` and :mod:`loosefit.train`; this module
forwards names to it on first use, so importing the ``train`` package never imports the models.
"""

from __future__ import annotations

from typing import Any


def __getattr__(name: str) -> Any:
    from loosefit import training

    return getattr(training, name)
