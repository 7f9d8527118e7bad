"""Skinned meshes with baked joint animation as a UsdSkel stage (``.usdc`` / ``.usda``), through ``usd-core``.

Layout written under ``/loosefit`` (an Xform, the default prim), per
:class:`~loosefit.io.skinned_mesh.SkinnedMesh` named ``<name>``:

- ``/loosefit/<name>`` a ``SkelRoot`` holding
- ``skeleton`` (``UsdSkel.Skeleton``): ``joints`` as paths of the hierarchy (``Hips/LHipJoint/...``; free
  virtual bones are roots ``bone_000``...), ``bindTransforms`` (world, ``translate(b_j)``: joint frames are
  world-aligned in the bind pose) and ``restTransforms`` (the bind pose's local transforms); its
  ``skel:animationSource`` is
- ``skeleton/animation`` (``UsdSkel.Animation``): local ``translations`` and ``rotations`` (quatf)
  time-sampled at time codes ``0 .. T-1``, ``scales`` 1;
- ``mesh`` (``UsdGeom.Mesh``, ``subdivisionScheme = none``): the bind-pose points and the
  ``SkelBindingAPI`` with ``primvars:skel:jointIndices`` / ``jointWeights`` (vertex interpolation,
  ``elementSize`` = influences) and an identity ``geomBindTransform``.

The stage is Z-up, ``metersPerUnit = 1``, ``timeCodesPerSecond = fps``. USD's skinning (``UsdSkel``,
e.g. ``UsdSkel.BakeSkinning``) then gives :meth:`SkinnedMesh.skin` at every time code.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import torch

from loosefit.errors import InputError
from loosefit.geometry.rotations import matrix_to_quaternion
from loosefit.io.skinned_mesh import SkinnedMesh, common_timing
from loosefit.paths import atomic_path

ROOT = "/loosefit"


def usd_name(name: str) -> str:
    """``name`` as a USD prim / joint name: characters outside ``[A-Za-z0-9_]`` become ``_``, no leading digit."""
    name = re.sub(r"\W", "_", name, flags=re.ASCII) or "_"
    return f"_{name}" if name[0].isdigit() else name


def joint_paths(mesh: SkinnedMesh) -> list[str]:
    """UsdSkel joint paths of the mesh's joints (``parent/child``), names made unique among siblings."""
    paths: list[str] = []
    taken: set[str] = set()
    for j, name in enumerate(mesh.joint_names):
        prefix = "" if mesh.parents[j] < 0 else paths[mesh.parents[j]] + "/"
        path, n = prefix + usd_name(name), 1
        while path in taken:
            path, n = f"{prefix}{usd_name(name)}_{n}", n + 1
        taken.add(path)
        paths.append(path)
    return paths


def _translation_matrices(points: np.ndarray):
    """``(J, 3)`` -> ``Vt.Matrix4dArray`` of translations (USD matrices act on row vectors: translation in row 3)."""
    from pxr import Vt

    M = np.tile(np.eye(4), (len(points), 1, 1))
    M[:, 3, :3] = points
    return Vt.Matrix4dArray.FromNumpy(M)


def write_skinned_usd(path: str | Path, meshes: list[SkinnedMesh]) -> None:
    """Write skinned meshes with their joint animation to a UsdSkel stage (layout in the module docstring).

    All meshes must share the frame count and rate.
    """
    from pxr import Usd, UsdGeom, UsdSkel, Vt

    frames, fps = common_timing(meshes, path)
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(frames - 1)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, ROOT).GetPrim())
    for mesh in meshes:
        root = f"{ROOT}/{usd_name(mesh.name)}"
        UsdSkel.Root.Define(stage, root)
        joints = Vt.TokenArray(joint_paths(mesh))
        skeleton = UsdSkel.Skeleton.Define(stage, f"{root}/skeleton")
        skeleton.CreateJointsAttr(joints)
        skeleton.CreateBindTransformsAttr(_translation_matrices(mesh.bind_positions.astype(np.float64)))
        skeleton.CreateRestTransformsAttr(_translation_matrices(mesh.bind_local()))

        animation = UsdSkel.Animation.Define(stage, f"{root}/skeleton/animation")
        animation.CreateJointsAttr(joints)
        quats = matrix_to_quaternion(torch.from_numpy(mesh.rotations)).numpy()[..., [1, 2, 3, 0]]  # -> (x, y, z, w)
        quats, trans = quats.astype(np.float32), mesh.translations.astype(np.float32)
        rotations, translations = animation.CreateRotationsAttr(), animation.CreateTranslationsAttr()
        for t in range(frames):
            rotations.Set(Vt.QuatfArray.FromNumpy(np.ascontiguousarray(quats[t])), t)
            translations.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(trans[t])), t)
        animation.CreateScalesAttr(Vt.Vec3hArray.FromNumpy(np.ones((mesh.num_joints, 3), np.float16)))
        UsdSkel.BindingAPI.Apply(skeleton.GetPrim()).CreateAnimationSourceRel().SetTargets([animation.GetPath()])

        geom = UsdGeom.Mesh.Define(stage, f"{root}/mesh")
        geom.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(mesh.rest_verts))
        geom.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([mesh.rest_verts.min(0), mesh.rest_verts.max(0)])))
        geom.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(mesh.faces), 3, np.int32)))
        geom.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(mesh.faces.astype(np.int32).ravel()))
        geom.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        geom.CreateDoubleSidedAttr(True)  # cloth is seen from both sides
        binding = UsdSkel.BindingAPI.Apply(geom.GetPrim())
        binding.CreateSkeletonRel().SetTargets([skeleton.GetPath()])
        K = mesh.influences
        binding.CreateJointIndicesPrimvar(False, K).Set(Vt.IntArray.FromNumpy(mesh.weight_indices.astype(np.int32).ravel()))
        binding.CreateJointWeightsPrimvar(False, K).Set(Vt.FloatArray.FromNumpy(mesh.weight_values.ravel()))
        binding.CreateGeomBindTransformAttr().Set(_translation_matrices(np.zeros((1, 3)))[0])
    with atomic_path(path) as tmp:  # the temporary name keeps the suffix, which picks crate or text
        if not stage.GetRootLayer().Export(str(tmp)):
            raise InputError("USD could not write the stage", path)
