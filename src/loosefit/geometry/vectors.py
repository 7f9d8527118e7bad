"""Unit vectors (numpy)."""

from __future__ import annotations

import numpy as np


def unit(v: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """``v (..., 3)`` scaled to unit length along the last axis; a vector shorter than ``eps`` is
    divided by ``eps`` (it stays near zero instead of becoming NaN)."""
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), eps)
