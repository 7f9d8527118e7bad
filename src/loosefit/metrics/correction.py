"""How much a correction added to a base prediction helps, and why (e.g. VirtualBones' high-frequency
offsets added to its low-frequency mesh).

With the ground truth ``y``, a base prediction ``b``, a correction ``c`` (the prediction is ``b + c``)
and the part ``h`` of ``y`` that the correction is meant to supply (for VirtualBones the simulation's
own high-frequency part ``y - y_LF``), the squared error changes by::

    |y - b - c|^2 - |y - b|^2 = |c|^2 - 2 <c, h> - 2 <c, y - b - h>

summed over frames and vertices: the correction pays its own size, earns what it shares with ``h`` and
what it shares with the rest of the base's error ``y - b - h`` (for VirtualBones, the low-frequency
module's own error; a correction that sharpens the predicted mesh can push against it). The best
scaling of the correction, ``s* = <c, y - b> / |c|^2``, says how much of it is worth keeping.

:class:`CorrectionStats` keeps these sums, so they pool over sequences of any length.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from loosefit.errors import InputError


@dataclass
class CorrectionStats:
    """Sums over vertex samples (frames x vertices) of squared lengths and dot products, metres^2.

    Attributes:
        count: vertex samples added.
        base_error: ``sum |y - b|^2``. corrected_error: ``sum |y - b - c|^2``.
        correction: ``sum |c|^2``. part: ``sum |h|^2``. part_miss: ``sum |c - h|^2``.
        with_part: ``sum <c, h>``. with_rest: ``sum <c, y - b - h>``. base_with_part: ``sum <y - b, h>``.
    """

    count: int = 0
    base_error: float = 0.0
    corrected_error: float = 0.0
    correction: float = 0.0
    part: float = 0.0
    part_miss: float = 0.0
    with_part: float = 0.0
    with_rest: float = 0.0
    base_with_part: float = 0.0

    def add(self, gt: np.ndarray, base: np.ndarray, correction: np.ndarray, part: np.ndarray) -> None:
        """Add one sequence: ``gt``, ``base``, ``correction``, ``part`` all ``(T, V, 3)`` metres."""
        arrays = [np.asarray(a, np.float64) for a in (gt, base, correction, part)]
        if any(a.shape != arrays[0].shape for a in arrays) or arrays[0].ndim != 3 or arrays[0].shape[-1] != 3:
            raise InputError(f"gt, base, correction and part must share one (T, V, 3) shape, got "
                             f"{[a.shape for a in arrays]}")
        y, b, c, h = arrays
        if not all(np.isfinite(a).all() for a in arrays):
            raise InputError("gt, base, correction or part contains NaN or infinite positions")
        error = y - b
        self.count += y.shape[0] * y.shape[1]
        self.base_error += float((error**2).sum())
        self.corrected_error += float(((error - c) ** 2).sum())
        self.correction += float((c**2).sum())
        self.part += float((h**2).sum())
        self.part_miss += float(((c - h) ** 2).sum())
        self.with_part += float((c * h).sum())
        self.with_rest += float((c * (error - h)).sum())
        self.base_with_part += float((error * h).sum())

    def summary(self) -> dict[str, float]:
        """RMS values in mm (``base_rmse_mm``, ``corrected_rmse_mm``, ``correction_rms_mm``, ``part_rms_mm``,
        ``ideal_rmse_mm``: with ``c = h``), mean dot products in mm^2 (``with_part_mm2``, ``with_rest_mm2``),
        ``part_explained``: ``1 - |c - h|^2 / |h|^2``, ``best_scale``: ``s*``, ``best_scale_rmse_mm``: with
        ``s* c``."""
        if self.count == 0:
            raise InputError("no vertex samples were added")
        n = self.count
        gain = self.with_part + self.with_rest  # <c, y - b>
        scale = gain / self.correction if self.correction > 0 else 0.0
        rms = {"base_rmse_mm": self.base_error, "corrected_rmse_mm": self.corrected_error,
               "correction_rms_mm": self.correction, "part_rms_mm": self.part,
               # y - b - h is what remains with the ideal correction c = h
               "ideal_rmse_mm": self.base_error - 2 * self.base_with_part + self.part,
               "best_scale_rmse_mm": self.base_error - scale * gain}
        out = {k: 1e3 * math.sqrt(max(v, 0.0) / n) for k, v in rms.items()}
        out.update(with_part_mm2=1e6 * self.with_part / n, with_rest_mm2=1e6 * self.with_rest / n,
                   part_explained=1.0 - self.part_miss / self.part if self.part > 0 else 0.0, best_scale=scale,
                   samples=n)
        return out
