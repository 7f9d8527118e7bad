"""A mesh sequence as a folder of OBJ files: ``frame_00000.obj``, ``frame_00001.obj`` ...

Every frame is a complete OBJ (vertices and triangles), so any mesh tool opens any frame. The body
under the garment, when the sequence has one (``extra["body_verts"]``, ``extra["body_faces"]``),
goes to ``body_00000.obj`` ... beside it. Each file starts with a ``# fps 30.0`` comment, which the
reader takes the frame rate from (30 when absent). Coordinates are text with 7 significant digits
(:func:`~loosefit.io.obj.write_obj`): positions round-trip to within 6e-7 of their magnitude
(< 1e-6 m for a garment within 1.6 m of the origin), not bit-exactly.

The folder appears complete or not at all: it is written under a temporary name beside the target
and renamed; an existing OBJ-sequence folder at the target is replaced, any other folder is refused.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.io.obj import read_obj, write_obj
from loosefit.paths import atomic_folder

_FILE = re.compile(r"(frame|body)_(\d+)\.obj")


def write_obj_sequence(folder: str | Path, seq: MeshSequence) -> None:
    """Write ``seq.verts (T, V, 3)`` as ``folder/frame_%05d.obj`` (and the body as ``body_%05d.obj``)."""
    folder = Path(folder)
    if folder.exists():
        if not folder.is_dir():
            raise InputError("exists and is not a folder; cannot write an OBJ sequence there", folder)
        foreign = [p.name for p in folder.iterdir() if not _FILE.fullmatch(p.name)]
        if foreign:
            raise InputError(f"folder holds files that are not OBJ-sequence frames ({foreign[0]} ...); refusing to replace it", folder)
    body_verts, body_faces = seq.extra.get("body_verts"), seq.extra.get("body_faces")
    with atomic_folder(folder) as tmp:
        for t, verts in enumerate(seq.verts):
            header = f"loosefit mesh sequence frame {t}\nfps {float(seq.fps)!r}"  # repr: the float reads back exactly
            write_obj(tmp / f"frame_{t:05d}.obj", verts, seq.faces, header)
            if body_verts is not None:
                write_obj(tmp / f"body_{t:05d}.obj", body_verts[t], body_faces, header)


def read_obj_sequence(folder: str | Path) -> MeshSequence:
    """Read a folder of ``frame_%05d.obj`` files (and ``body_%05d.obj`` if present) into a :class:`MeshSequence`.

    All frames must share one triangle list and vertex count; frames are numbered 0..T-1 without gaps.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError("not a folder of OBJ frames", folder)
    frames = _numbered(folder, "frame")
    if not frames:
        raise InputError("no frame_*.obj files in the folder", folder)
    verts, faces = _read_frames(frames)
    extra = {}
    bodies = _numbered(folder, "body")
    if bodies:
        if len(bodies) != len(frames):
            raise InputError(f"{len(frames)} garment frames but {len(bodies)} body frames", folder)
        extra["body_verts"], extra["body_faces"] = _read_frames(bodies)
    return MeshSequence(verts, faces, read_fps(frames[0]), extra)


def _numbered(folder: Path, kind: str) -> list[Path]:
    """``folder/<kind>_<n>.obj`` files sorted by ``n``; the numbers must be 0..N-1."""
    found = {}
    for path in folder.iterdir():
        match = _FILE.fullmatch(path.name)
        if match and match.group(1) == kind:
            found[int(match.group(2))] = path
    missing = sorted(set(range(len(found))) - set(found))
    if missing:
        raise InputError(f"{kind} files are not numbered 0..{len(found) - 1}: {kind}_{missing[0]:05d}.obj is missing", folder)
    return [found[i] for i in range(len(found))]


def _read_frames(paths: list[Path]) -> tuple[np.ndarray, np.ndarray]:
    """Stack the OBJ files ``paths`` into ``(verts (T, V, 3), faces (F, 3))``; topology must not change."""
    verts0, faces0 = read_obj(paths[0])
    verts = np.empty((len(paths),) + verts0.shape, np.float32)
    verts[0] = verts0
    for t, path in enumerate(paths[1:], 1):
        frame_verts, frame_faces = read_obj(path)
        if frame_verts.shape != verts0.shape or not np.array_equal(frame_faces, faces0):
            raise InputError(f"topology differs from {paths[0].name} ({len(frame_verts)} vs {len(verts0)} vertices, or other faces)",
                             path)
        verts[t] = frame_verts
    return verts, faces0


def read_fps(path: str | Path) -> float:
    """The frame rate from the ``# fps <value>`` comment at the top of OBJ file ``path`` (30 when absent)."""
    path = Path(path)
    with open(path) as f:
        for line in f:
            if not line.startswith("#"):
                break
            if line.startswith("# fps "):
                try:
                    return float(line.split()[2])
                except (IndexError, ValueError):
                    raise InputError(f"malformed frame-rate comment {line.strip()!r}", path) from None
    return 30.0


