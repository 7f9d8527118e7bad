"""The mesh-sequence ``.npz``: loosefit's plain interchange file for animated meshes.

Arrays: ``verts (T, V, 3)`` float32 metres, ``faces (F, 3)`` int64, ``fps`` scalar; optionally
``body_verts (T, Vb, 3)`` and ``body_faces (Fb, 3)`` for the body under a garment, and any other
named arrays (``joints (T, J, 3)``...).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.io.npz import load_npz, save_npz


@dataclass
class MeshSequence:
    """An animated triangle mesh: ``verts (T, V, 3)`` float32, ``faces (F, 3)`` int64, ``fps``; ``extra`` arrays."""

    verts: np.ndarray
    faces: np.ndarray
    fps: float = 30.0
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self):
        self.verts = np.asarray(self.verts, dtype=np.float32)
        self.faces = np.asarray(self.faces, dtype=np.int64)
        if self.verts.ndim == 2:
            self.verts = self.verts[None]
        if self.verts.ndim != 3 or self.verts.shape[2] != 3:
            raise InputError(f"verts must have shape (T, V, 3), got {self.verts.shape}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise InputError(f"faces must have shape (F, 3), got {self.faces.shape}")
        if self.faces.size and (self.faces.min() < 0 or self.faces.max() >= self.verts.shape[1]):
            raise InputError(f"faces index vertices outside [0, {self.verts.shape[1]})")

    def save(self, path: str | Path) -> None:
        save_npz(path, {"verts": self.verts, "faces": self.faces, "fps": np.float64(self.fps), **self.extra}, compressed=True)

    @classmethod
    def load(cls, path: str | Path) -> "MeshSequence":
        path = Path(path)
        arrays = load_npz(path, "mesh sequence")
        missing = {"verts", "faces"} - set(arrays)
        if missing:
            raise InputError(f"not a mesh sequence, missing arrays {sorted(missing)}", path)
        fps = float(arrays.pop("fps", 30.0))
        try:
            return cls(arrays.pop("verts"), arrays.pop("faces"), fps, arrays)
        except InputError as e:
            raise InputError(e.problem, path) from None
