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
    """Sums over vertex samples (frames x vertices), metres^2, with ``e = y - b`` the base's error: every
    figure of :meth:`summary` follows from these seven.

    Attributes:
        count: vertex samples added.
        error: ``sum |e|^2``. correction: ``sum |c|^2``. part: ``sum |h|^2``.
        error_correction: ``sum <e, c>``. error_part: ``sum <e, h>``. correction_part: ``sum <c, h>``.
    """

    count: int = 0
    error: float = 0.0
    correction: float = 0.0
    part: float = 0.0
    error_correction: float = 0.0
    error_part: float = 0.0
    correction_part: float = 0.0

    def add(self, gt: np.ndarray, base: np.ndarray, correction: np.ndarray, part: np.ndarray) -> None:
        """Add one sequence: ``gt``, ``base``, ``correction``, ``part`` all ``(T, V, 3)`` metres."""
        arrays = [np.asarray(a, np.float64) for a in (gt, base, correction, part)]
        if any(a.shape != arrays[0].shape for a in arrays) or arrays[0].ndim != 3 or arrays[0].shape[-1] != 3:
            raise InputError(f"gt, base, correction and part must share one (T, V, 3) shape, got "
                             f"{[a.shape for a in arrays]}")
        y, b, c, h = arrays
        if not all(np.isfinite(a).all() for a in arrays):
            raise InputError("gt, base, correction or part contains NaN or infinite positions")
        e = y - b
        self.count += y.shape[0] * y.shape[1]
        for name, u, v in (("error", e, e), ("correction", c, c), ("part", h, h), ("error_correction", e, c),
                           ("error_part", e, h), ("correction_part", c, h)):
            setattr(self, name, getattr(self, name) + float((u * v).sum()))

    def summary(self) -> dict[str, float]:
        """RMS values in mm (``base_rmse_mm``, ``corrected_rmse_mm``, ``correction_rms_mm``, ``part_rms_mm``,
        ``ideal_rmse_mm``: with ``c = h``), mean dot products in mm^2 (``with_part_mm2``: ``<c, h>``,
        ``with_rest_mm2``: ``<c, e - h>``), ``part_explained``: ``1 - |c - h|^2 / |h|^2``, ``best_scale``:
        ``s*``, ``best_scale_rmse_mm``: with ``s* c``."""
        if self.count == 0:
            raise InputError("no vertex samples were added")
        n = self.count
        scale = self.error_correction / self.correction if self.correction > 0 else 0.0
        squares = {"base_rmse_mm": self.error,
                   "corrected_rmse_mm": self.error - 2 * self.error_correction + self.correction,
                   "correction_rms_mm": self.correction, "part_rms_mm": self.part,
                   "ideal_rmse_mm": self.error - 2 * self.error_part + self.part,
                   "best_scale_rmse_mm": self.error - scale * self.error_correction}
        out = {k: 1e3 * math.sqrt(max(v, 0.0) / n) for k, v in squares.items()}
        part_miss = self.correction - 2 * self.correction_part + self.part  # |c - h|^2
        out.update(with_part_mm2=1e6 * self.correction_part / n,
                   with_rest_mm2=1e6 * (self.error_correction - self.correction_part) / n,
                   part_explained=1.0 - part_miss / self.part if self.part > 0 else 0.0, best_scale=scale,
                   samples=n)
        return out
