"""Mesh sequences as USD stages (``.usdc`` binary crate or ``.usda`` text), through ``usd-core``.

Layout written: ``/loosefit`` (an Xform, the default prim) holding ``garment`` (and ``body`` when the
sequence has one), each a ``UsdGeom.Mesh`` with constant ``faceVertexCounts`` / ``faceVertexIndices``,
``subdivisionScheme = none`` (USD's default would smooth the triangles), and ``points`` and
``extent`` time-sampled at time codes ``0 .. T-1``. The stage has ``timeCodesPerSecond = fps``,
start and end time codes, up axis Z and ``metersPerUnit = 1``. Points are float32, so positions
round-trip bit-exactly.

The reader takes one frame per time sample of the mesh's ``points``, applies the prim's world
transform, and converts Y-up stages and other units to loosefit's Z-up metres, so a mesh sequence
written by another tool reads too (triangles only).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.paths import atomic_path

ROOT = "/loosefit"


def write_usd(path: str | Path, seq: MeshSequence) -> None:
    """Write ``seq`` (garment, and body if ``seq.extra`` has ``body_verts``/``body_faces``) to a ``.usdc``/``.usda`` stage."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(seq.fps)
    stage.SetFramesPerSecond(seq.fps)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(len(seq.verts) - 1)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, ROOT).GetPrim())
    _define_mesh(stage, f"{ROOT}/garment", seq.verts, seq.faces)
    if "body_verts" in seq.extra:
        _define_mesh(stage, f"{ROOT}/body", seq.extra["body_verts"], seq.extra["body_faces"])
    with atomic_path(path) as tmp:  # the temporary name keeps the suffix, which picks crate or text
        if not stage.GetRootLayer().Export(str(tmp)):
            raise InputError("USD could not write the stage", path)


def _define_mesh(stage, prim_path: str, verts: np.ndarray, faces: np.ndarray) -> None:
    """A triangle ``UsdGeom.Mesh`` at ``prim_path`` whose points follow ``verts (T, V, 3)`` at time codes 0..T-1."""
    from pxr import Usd, UsdGeom, Vt

    mesh = UsdGeom.Mesh.Define(stage, prim_path)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(faces, np.int32).ravel()))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateDoubleSidedAttr(True)  # cloth is seen from both sides
    points, extent = mesh.CreatePointsAttr(), mesh.CreateExtentAttr()
    for t, frame in enumerate(np.asarray(verts, np.float32)):
        time = Usd.TimeCode(t)
        points.Set(Vt.Vec3fArray.FromNumpy(frame), time)
        extent.Set(Vt.Vec3fArray.FromNumpy(np.stack([frame.min(0), frame.max(0)])), time)


def read_usd(path: str | Path) -> MeshSequence:
    """Read a USD mesh sequence: the mesh named ``garment`` (else the first mesh) and ``body`` if present.

    Returns a :class:`MeshSequence` with ``verts (T, V, 3)`` in Z-up metres, one frame per time
    sample of the garment's points, ``fps`` = the stage's time codes per second, and the body (read
    at the same times) in ``extra["body_verts"]`` / ``extra["body_faces"]``.
    """
    from pxr import Sdf, Usd, UsdGeom

    path = Path(path)
    if not path.is_file():
        raise InputError("no such USD file", path)
    layer = Sdf.Layer.Find(str(path))
    if layer is not None:  # a layer cached by this process may be older than the file
        layer.Reload()
    try:
        stage = Usd.Stage.Open(str(path))
    except Exception as e:  # pxr raises its own Tf.ErrorException on unreadable files
        raise InputError(f"cannot open USD stage: {str(e).strip()}", path) from None
    meshes = [prim for prim in stage.Traverse() if prim.IsA(UsdGeom.Mesh)]
    if not meshes:
        raise InputError("the stage has no mesh", path)
    named = {prim.GetName(): prim for prim in meshes}
    garment = named.get("garment", meshes[0])
    times = garment.GetAttribute("points").GetTimeSamples() or [Usd.TimeCode.Default()]
    verts, faces = _read_mesh(stage, garment, times, path)
    extra = {}
    if "garment" in named and "body" in named:
        extra["body_verts"], extra["body_faces"] = _read_mesh(stage, named["body"], times, path)
    return MeshSequence(verts, faces, stage.GetTimeCodesPerSecond(), extra)


def _read_mesh(stage, prim, times: list, path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``(verts (T, V, 3) float32 Z-up metres at ``times``, faces (F, 3) int64)`` of a mesh prim."""
    from pxr import UsdGeom

    mesh = UsdGeom.Mesh(prim)
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(), dtype=np.int64)
    if counts.size and (counts != 3).any():
        corners = counts[counts != 3][0]
        raise InputError(f"mesh {prim.GetPath()} has polygons with {corners} corners; only triangles are read", path)
    faces = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int64).reshape(-1, 3)
    if mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
        faces = faces[:, ::-1].copy()
    frames = []
    for time in times:
        points = mesh.GetPointsAttr().Get(time)
        if points is None:
            raise InputError(f"mesh {prim.GetPath()} has no points", path)
        world = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(time))  # row vectors: p @ M
        points = np.asarray(points, dtype=np.float64) @ world[:3, :3] + world[3, :3]
        if frames and len(points) != len(frames[0]):
            raise InputError(f"mesh {prim.GetPath()} changes vertex count over time ({len(frames[0])} -> {len(points)})", path)
        frames.append(points)
    verts = np.stack(frames) * UsdGeom.GetStageMetersPerUnit(stage)
    if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y:
        verts = np.stack([verts[..., 0], -verts[..., 2], verts[..., 1]], axis=-1)
    if faces.size and (faces.min() < 0 or faces.max() >= verts.shape[1]):
        raise InputError(f"mesh {prim.GetPath()} has face indices outside [0, {verts.shape[1]})", path)
    return verts.astype(np.float32), faces
