"""Animated garment export and import, one entry point for every format, chosen by the path.

=====================  ====================================================================
path                   format
=====================  ====================================================================
``*.npz``              loosefit mesh sequence (:class:`~loosefit.io.mesh_sequence.MeshSequence`), bit-exact
``*.usdc`` ``*.usda``  USD stage (``*.usd``: crate), time-sampled points (:mod:`loosefit.io.usd`), bit-exact
``*.glb``              glTF morph-target animation (:mod:`loosefit.io.gltf`), within one float32 step
``*.abc``              Alembic through Blender (:mod:`loosefit.io.alembic`), bit-exact
``*.pc2``              Point Cache 2 plus ``<stem>.obj`` (first frame, faces, fps), bit-exact
no suffix, or ``/``    folder of ``frame_00000.obj`` ... (:mod:`loosefit.io.obj_sequence`), 7 digits
=====================  ====================================================================

The body under the garment, when given, travels with it in every format (``.pc2``: as
``<stem>_body.pc2`` / ``<stem>_body.obj``) and comes back in ``MeshSequence.extra["body_verts"]``
and ``["body_faces"]``. Every file (and the OBJ folder) appears complete or not at all.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.io.alembic import read_alembic, write_alembic
from loosefit.io.gltf import read_glb, write_glb
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.io.obj import read_obj, write_obj
from loosefit.io.obj_sequence import read_fps, read_obj_sequence, write_obj_sequence
from loosefit.io.usd import read_usd, write_usd
from loosefit.io.pc2 import read_pc2, write_pc2

SUFFIXES = (".npz", ".usdc", ".usda", ".usd", ".glb", ".abc", ".pc2")


def export_animation(
    path: str | Path,
    verts: np.ndarray,
    faces: np.ndarray,
    fps: float = 30.0,
    body_verts: np.ndarray | None = None,
    body_faces: np.ndarray | None = None,
) -> Path:
    """Write an animated garment to ``path`` in the format its suffix names (see the module table).

    Args:
        path: output file; no suffix or a trailing ``/`` means a folder of OBJ frames (``out/take.1/``).
        verts: ``(T, V, 3)`` garment positions per frame, Z-up metres.
        faces: ``(F, 3)`` garment triangles, 0-based.
        fps: frames per second.
        body_verts: optional ``(T, Vb, 3)`` body positions per frame.
        body_faces: ``(Fb, 3)`` body triangles, required with ``body_verts``.

    Returns:
        The path written (for OBJ folders, without the trailing slash).
    """
    folder = str(path).endswith(("/", "\\"))
    path = Path(path)
    kind = "obj" if folder or path.suffix == "" else path.suffix.lower()
    if kind != "obj" and kind not in SUFFIXES:
        raise InputError(f"unknown animation format {path.suffix!r}; use one of {', '.join(SUFFIXES)}, "
                         "or a folder (no suffix, or end the path with /)", path)
    seq = _checked(path, verts, faces, fps, body_verts, body_faces)
    if kind == "obj":
        write_obj_sequence(path, seq)
    elif kind == ".npz":
        seq.save(path)
    elif kind in (".usdc", ".usda", ".usd"):
        write_usd(path, seq)
    elif kind == ".glb":
        write_glb(path, seq)
    elif kind == ".abc":
        write_alembic(path, seq)
    else:
        _write_pc2_pair(path, seq.verts, seq.faces, seq.fps)
        if body_verts is not None:
            _write_pc2_pair(_body_path(path), seq.extra["body_verts"], seq.extra["body_faces"], seq.fps)
    return path


def export_files(path: str | Path, body: bool = False) -> list[Path]:
    """The files (or OBJ folder) :func:`export_animation` writes for ``path``: the path itself, and for ``.pc2``
    its ``<stem>.obj`` too (with ``body``, the body's ``.pc2`` and ``.obj`` as well), so that a caller can check
    them all before the work starts."""
    path = Path(path)
    if path.suffix.lower() != ".pc2":
        return [path]
    pairs = [path, _body_path(path)] if body else [path]
    return [p for pc2 in pairs for p in (pc2, pc2.with_suffix(".obj"))]


def read_animation(path: str | Path) -> MeshSequence:
    """Read any file :func:`export_animation` writes back into a :class:`MeshSequence` (Z-up metres)."""
    path = Path(path)
    if path.is_dir():
        return read_obj_sequence(path)
    if not path.is_file():
        raise InputError("no such animation file or folder", path)
    kind = path.suffix.lower()
    if kind == ".npz":
        return MeshSequence.load(path)
    if kind in (".usdc", ".usda", ".usd"):
        return read_usd(path)
    if kind == ".glb":
        return read_glb(path)
    if kind == ".abc":
        return read_alembic(path)
    if kind == ".pc2":
        verts, faces, fps = _read_pc2_pair(path)
        extra = {}
        if _body_path(path).is_file():
            extra["body_verts"], extra["body_faces"], _ = _read_pc2_pair(_body_path(path))
        return MeshSequence(verts, faces, fps, extra)
    raise InputError(f"unknown animation format {path.suffix!r}; use one of {', '.join(SUFFIXES)} or an OBJ-sequence folder",
                     path)


def _checked(path: Path, verts, faces, fps, body_verts, body_faces) -> MeshSequence:
    """The arrays as a :class:`MeshSequence`, or an :class:`InputError` naming ``path`` and the problem."""
    if not np.isfinite(fps) or fps <= 0:
        raise InputError(f"fps must be a positive number, got {fps}", path)
    if (body_verts is None) != (body_faces is None):
        raise InputError("body_verts and body_faces go together: give both or neither", path)
    meshes = {"garment": (verts, faces)}
    if body_verts is not None:
        meshes["body"] = (body_verts, body_faces)
    checked = {}
    for name, (mesh_verts, mesh_faces) in meshes.items():
        mesh_verts = np.asarray(mesh_verts, dtype=np.float32)
        mesh_faces = np.asarray(mesh_faces)
        if mesh_verts.ndim != 3 or mesh_verts.shape[0] == 0 or mesh_verts.shape[1] == 0 or mesh_verts.shape[2] != 3:
            raise InputError(f"{name} verts must have shape (T, V, 3) with T, V > 0, got {mesh_verts.shape}", path)
        if not np.isfinite(mesh_verts).all():
            bad = np.argwhere(~np.isfinite(mesh_verts))[0]
            raise InputError(f"{name} verts are not finite (NaN or inf) at frame {bad[0]}, vertex {bad[1]}", path)
        if mesh_faces.ndim != 2 or len(mesh_faces) == 0 or mesh_faces.shape[1] != 3 or not np.issubdtype(mesh_faces.dtype, np.integer):
            raise InputError(f"{name} faces must be integer triangles (F, 3) with F > 0, got {mesh_faces.dtype} {mesh_faces.shape}", path)
        if mesh_faces.min() < 0 or mesh_faces.max() >= mesh_verts.shape[1]:
            low, high = mesh_faces.min(), mesh_faces.max()
            raise InputError(f"{name} faces index vertices outside [0, {mesh_verts.shape[1]}): min {low}, max {high}", path)
        checked[name] = mesh_verts, mesh_faces
    extra = {}
    if "body" in checked:
        if len(checked["body"][0]) != len(checked["garment"][0]):
            raise InputError(f"body has {len(checked['body'][0])} frames, garment {len(checked['garment'][0])}", path)
        extra = {"body_verts": checked["body"][0], "body_faces": checked["body"][1].astype(np.int64)}
    return MeshSequence(*checked["garment"], fps=float(fps), extra=extra)


def _body_path(path: Path) -> Path:
    """Where a ``.pc2`` export keeps the body: ``<stem>_body.pc2`` beside it."""
    return path.with_name(f"{path.stem}_body{path.suffix}")


def _write_pc2_pair(path: Path, verts: np.ndarray, faces: np.ndarray, fps: float) -> None:
    """``path`` (.pc2, every frame) and ``<stem>.obj`` beside it (first frame, faces, ``# fps`` comment)."""
    write_obj(path.with_suffix(".obj"), verts[0], faces, f"loosefit rest mesh for {path.name}\nfps {float(fps)!r}")
    write_pc2(path, verts)


def _read_pc2_pair(path: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """``(verts (T, V, 3), faces (F, 3), fps)`` from a ``.pc2`` file and its ``<stem>.obj``."""
    frames, _, _ = read_pc2(path)
    obj = path.with_suffix(".obj")
    if not obj.is_file():
        raise InputError(f"a .pc2 file holds no triangles; expected them in {obj.name} beside it", path)
    rest, faces = read_obj(obj)
    if len(rest) != frames.shape[1]:
        raise InputError(f"{obj.name} has {len(rest)} vertices, the cache {frames.shape[1]}", path)
    return frames, faces, read_fps(obj)
