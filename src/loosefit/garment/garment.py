"""The Garment type: a triangle mesh in the body's rest pose with a mask of pinned vertices.

On disk a garment is a Wavefront OBJ (vertices and triangles) plus a JSON sidecar
``<stem>.json`` beside it holding the kind, name, parameters, pinned vertex ids and, when it was made on
an Anny body, that body's shape (``body_shape``), so that simulating it on another shape drapes it there
(:func:`loosefit.garment.body_fit.refit`).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.garment.obj_io import read_obj
from loosefit.paths import atomic_path

SIDECAR_FORMAT = 1


def shape_record(shape) -> dict[str, float] | None:
    """The JSON record of an :class:`~loosefit.body.anny_body.AnnyShape` (``None`` for anything else, such as
    SMPL betas): its six values by key."""
    from loosefit.body.anny_body import AnnyShape

    return {k: float(v) for k, v in dataclasses.asdict(shape).items()} if isinstance(shape, AnnyShape) else None


@dataclass
class Garment:
    """A garment mesh in the rest pose of the body it was fitted to.

    Attributes:
        verts: ``(V, 3)`` float32 rest-pose positions, metres (Z up, front -Y).
        faces: ``(F, 3)`` int64 triangles, normals pointing away from the body.
        pinned: ``(V,)`` bool, vertices attached to the body (waistband, shoulders, strap tops).
        kind: template kind (``"skirt"``, ``"dress"``, ``"long_shirt"``, ``"jumpsuit"``) or ``"imported"``.
        params: the parameters it was made with (JSON-serialisable).
        name: a label.
        body_shape: the Anny shape values (:class:`~loosefit.body.anny_body.AnnyShape` keys) of the body it
            was made on or fitted to; ``None`` when unknown (another body model, or a sidecar of an older
            version).
    """

    verts: np.ndarray
    faces: np.ndarray
    pinned: np.ndarray
    kind: str
    params: dict = field(default_factory=dict)
    name: str = ""
    body_shape: dict | None = None

    def __post_init__(self):
        self.verts = np.ascontiguousarray(self.verts, dtype=np.float32)
        self.faces = np.ascontiguousarray(self.faces, dtype=np.int64)
        self.pinned = np.ascontiguousarray(self.pinned, dtype=bool)
        if self.verts.ndim != 2 or self.verts.shape[1] != 3:
            raise InputError(f"garment {self.name!r}: verts must be (V, 3), got {self.verts.shape}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise InputError(f"garment {self.name!r}: faces must be (F, 3), got {self.faces.shape}")
        if self.pinned.shape != (len(self.verts),):
            raise InputError(f"garment {self.name!r}: pinned must be ({len(self.verts)},), got {self.pinned.shape}")
        if len(self.faces) and (self.faces.min() < 0 or self.faces.max() >= len(self.verts)):
            raise InputError(f"garment {self.name!r}: a face index is out of range 0..{len(self.verts) - 1}")

    @property
    def num_verts(self) -> int:
        return len(self.verts)

    @staticmethod
    def sidecar_path(path: str | Path) -> Path:
        """The JSON sidecar of an OBJ path: ``<stem>.json`` in the same folder."""
        path = Path(path)
        return path.with_name(path.stem + ".json")

    def save(self, path: str | Path) -> None:
        """Write ``path`` (.obj) and its sidecar ``<stem>.json``, each atomically."""
        path = Path(path)
        if path.suffix.lower() != ".obj":
            raise InputError("a garment is saved as .obj", path)
        lines = [f"# loosefit garment {self.name} ({self.kind}): {self.num_verts} vertices, {len(self.faces)} faces"]
        lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in self.verts.tolist()]
        lines += [f"f {a} {b} {c}" for a, b, c in (self.faces + 1).tolist()]
        meta = {
            "format": SIDECAR_FORMAT,
            "kind": self.kind,
            "name": self.name,
            "num_verts": self.num_verts,
            "params": self.params,
            "pinned": np.nonzero(self.pinned)[0].tolist(),
        }
        if self.body_shape is not None:
            meta["body_shape"] = self.body_shape
        with atomic_path(path) as tmp:
            tmp.write_text("\n".join(lines) + "\n")
        with atomic_path(self.sidecar_path(path)) as tmp:
            tmp.write_text(json.dumps(meta, indent=1) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> "Garment":
        """Read a garment written by :meth:`save` (an OBJ of triangles and its JSON sidecar)."""
        path = Path(path)
        side = cls.sidecar_path(path)
        if not path.is_file():
            raise InputError("no such garment file", path)
        if not side.is_file():
            raise InputError(f"garment sidecar {side.name} is missing (use import_garment for other meshes)", path)
        verts, faces = read_obj(path)
        if len(verts) == 0 or len(faces) == 0:
            raise InputError("no vertices or faces", path)
        try:
            meta = json.loads(side.read_text())
            pinned_ids = np.asarray(meta["pinned"], dtype=np.int64)
            kind, name, params = str(meta["kind"]), str(meta["name"]), dict(meta["params"])
            body_shape = meta.get("body_shape")
            if body_shape is not None:
                from loosefit.body.anny_body import AnnyShape

                body_shape = shape_record(AnnyShape(**body_shape))
        except (ValueError, KeyError, TypeError, InputError) as err:
            raise InputError(f"unreadable garment sidecar: {getattr(err, 'problem', err)}", side) from None
        if meta.get("num_verts", len(verts)) != len(verts):
            raise InputError(f"sidecar says {meta['num_verts']} vertices, the OBJ has {len(verts)}", side)
        if len(pinned_ids) and (pinned_ids.min() < 0 or pinned_ids.max() >= len(verts)):
            raise InputError("a pinned vertex id is out of range", side)
        pinned = np.zeros(len(verts), bool)
        pinned[pinned_ids] = True
        return cls(verts=verts, faces=faces, pinned=pinned, kind=kind, params=params, name=name, body_shape=body_shape)

