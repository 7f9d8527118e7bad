"""``loosefit export-rig``: a trained garment as an engine-ready skinned rig, no network needed to play it.

The garment is skinned to its virtual bones (the SSDR rig of the run, VirtualBones Eq. 1) and the bones'
motion predicted by the run's network (the VirtualBones low-frequency module, Sec. 4.2, or JointNet's bone
transforms) is baked per frame; the body is skinned to its own skeleton, posed by the motion. Both keep at
most ``influences`` weights per vertex (4 or 8, what engines take), renormalised. Written as a skinned
glTF (:mod:`loosefit.io.skinned_gltf`) or a UsdSkel stage (:mod:`loosefit.io.skinned_usd`).

What plays back is the *low-frequency* garment: the high-frequency module of VirtualBones and the
pose-space deformation of JointNet need the network and are not part of a rig.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from loosefit.animate import Animator
from loosefit.errors import InputError
from loosefit.io.skinned_mesh import SkinnedMesh, dense_to_sparse
from loosefit.models.motion_features import motion_features
from loosefit.motion.heading import motion_frames
from loosefit.motion.motion import Motion
from loosefit.threads import torch_threads

#: Influences per vertex engines take (glTF: 4 per JOINTS_n / WEIGHTS_n set).
INFLUENCES = (4, 8)
SUFFIXES = (".glb", ".usdc", ".usda", ".usd")
#: Frames skinned at once when measuring the truncation error (bounds memory).
TRUNCATION_CHUNK = 32


def _rig_buffers(model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(rest (V, 3), dense weights (V, B), bone rest centroids (B, 3))`` of a virtual-bone model."""
    rest = getattr(model, "rest_verts", None)
    rest = model.rig_rest if rest is None else rest  # VirtualBones: rest_verts; JointNet: rig_rest
    return rest.numpy(), model.skin_weights.numpy(), model.bone_rest.numpy()


def predict_bones(animator: Animator, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """World bone transforms of a virtual-bone run along ``motion``: rotations ``(T, B, 3, 3)`` and
    translations ``(T, B, 3)`` float64 mapping rest-mesh points ``p`` to ``R p + T`` in the world.

    The network predicts them in the frame ``[Rh | o]`` of each frame (the model's
    :attr:`~loosefit.models.base.GarmentModel.frame`: :mod:`loosefit.motion.heading`); in the world they are
    ``[Rh R | Rh T + o]``. Frames run :attr:`Animator.chunk_frames` at a time with the recurrent state carried, as
    :meth:`Animator.animate_batch`.
    """
    model = animator.model
    if not hasattr(model, "skin_weights") or not hasattr(model, "bone_rest"):
        raise InputError(f"{animator.method} has no virtual bones: export-rig needs a virtualbones or jointnet run")
    feats = motion_features(motion, animator.history)
    root, joints = torch.from_numpy(feats["root"])[None], torch.from_numpy(feats["joints"])[None]
    rotations, translations, state = [], [], None
    with torch_threads(animator.threads), torch.no_grad():
        for start in range(0, motion.num_frames, animator.chunk_frames):
            stop = start + animator.chunk_frames
            out = model(root[:, start:stop], joints[:, start:stop], state)
            rotations.append(out["bones"][0][0].double().numpy())
            translations.append(out["bones"][1][0].double().numpy())
            state = out["state"]
    R, T = np.concatenate(rotations), np.concatenate(translations)
    Rh, origin = motion_frames(motion, animator.frame)
    return Rh[:, None] @ R, (Rh[:, None] @ T[..., None])[..., 0] + origin[:, None]


def garment_rig(run_dir: str | Path, motion: Motion, checkpoint: str = "last", threads: int | None = 1) -> SkinnedMesh:
    """The run's garment skinned to its virtual bones, the bones' predicted motion baked (all SSDR weights).

    Bones are root joints ``bone_000`` ... at their rest centroids ``c_j``; frame ``t`` gives bone ``j``
    the rotation ``R_j(t)`` and the position ``R_j(t) c_j + T_j(t)`` (module docstring of
    :mod:`loosefit.io.skinned_mesh`), so skinning reproduces the low-frequency prediction.
    """
    animator = Animator(run_dir, checkpoint=checkpoint, threads=threads)
    if motion.num_joints != animator.num_joints:
        raise InputError(f"motion {motion.name!r} has {motion.num_joints} joints, the run was trained on "
                         f"{animator.num_joints}", run_dir)
    R, T = predict_bones(animator, motion)
    rest, weights, centres = _rig_buffers(animator.model)
    idx, val = dense_to_sparse(weights)
    B = len(centres)
    position = (R @ centres.astype(np.float64)[:, :, None])[..., 0] + T
    return SkinnedMesh("garment", rest, animator.faces, [f"bone_{j:03d}" for j in range(B)], np.full(B, -1),
                       centres, R, position, idx, val, motion.fps)


def body_rig(body, motion: Motion, shape=None) -> SkinnedMesh:
    """The body skinned to its own skeleton, posed by ``motion`` (all of its weights).

    Joints are the body rig's (``body.joint_names``, bind positions its rest joints); the root's local
    translation is ``motion.translation``, every other joint's its rest offset from its parent, as in
    :func:`loosefit.geometry.lbs.forward_kinematics`.
    """
    from loosefit.geometry.rotations import axis_angle_to_matrix

    body.check_motion(motion)
    rest_joints = body.rest_joints(shape).astype(np.float64)
    parents = np.asarray(body.parents)
    if any(not p < j for j, p in enumerate(parents)):
        raise InputError(f"body rig {body.rig!r}: joint parents must come before their children")
    R = axis_angle_to_matrix(torch.from_numpy(motion.rotations).double()).numpy()
    offsets = rest_joints - np.where(parents[:, None] >= 0, rest_joints[np.maximum(parents, 0)], 0.0)
    trans = np.repeat(offsets[None], motion.num_frames, 0)
    trans[:, 0] = motion.translation
    idx, val = dense_to_sparse(body.skinning_weights())
    return SkinnedMesh("body", body.rest_verts(shape), body.faces, body.joint_names, parents, rest_joints, R, trans,
                       idx, val, motion.fps)


def truncation_error(mesh: SkinnedMesh, influences: int) -> dict:
    """How far keeping ``influences`` weights moves the skinned vertices from all of them, over every frame:
    ``{"max_mm", "rms_mm", "vertices_truncated"}`` (vertices with more non-zero weights than kept)."""
    delta = mesh.limited(influences).dense_weights() - mesh.dense_weights()  # skinning is linear in the weights
    worst, squares = 0.0, 0.0
    for start in range(0, mesh.num_frames, TRUNCATION_CHUNK):
        frames = slice(start, start + TRUNCATION_CHUNK)
        dist = np.linalg.norm(mesh.skin(frames, weights=delta), axis=-1)
        worst, squares = max(worst, float(dist.max())), squares + float((dist**2).sum())
    rms = np.sqrt(squares / (mesh.num_frames * len(mesh.rest_verts)))
    return {"max_mm": worst * 1e3, "rms_mm": float(rms) * 1e3,
            "vertices_truncated": int(((mesh.weight_values > 0).sum(1) > influences).sum())}


def export_rig(run_dir: str | Path, motion: Motion, out: str | Path, body=None, influences: int = 4,
               checkpoint: str = "last", threads: int | None = 1) -> dict:
    """Write the garment (and ``body`` unless None) as skinned meshes animated along ``motion``.

    Args:
        run_dir: a trained virtualbones or jointnet run folder.
        motion: the motion, on the run's (and the body's) rig.
        out: ``.glb`` (skinned glTF) or ``.usdc`` / ``.usda`` / ``.usd`` (UsdSkel).
        body: the body model posed by the motion (its shape), or None for the garment alone.
        influences: weights kept per vertex, 4 or 8.

    Returns:
        ``{"path", "bytes", "frames", "garment": {...}, "body": {...}}`` with per mesh the vertex, joint and
        influence counts and the :func:`truncation_error` of the influence limit.
    """
    out = Path(out)
    if out.suffix.lower() not in SUFFIXES:
        raise InputError(f"unknown rig format {out.suffix!r}; use one of {', '.join(SUFFIXES)}", out)
    if influences not in INFLUENCES:
        raise InputError(f"influences per vertex must be one of {INFLUENCES}, got {influences}", out)
    meshes = [garment_rig(run_dir, motion, checkpoint, threads)]
    if body is not None:
        meshes.append(body_rig(body, motion))
    summary = {"frames": motion.num_frames, "fps": motion.fps, "influences": influences}
    for mesh in meshes:
        summary[mesh.name] = {"vertices": len(mesh.rest_verts), "joints": mesh.num_joints,
                              "influences_in_rig": mesh.influences, **truncation_error(mesh, influences)}
    limited = [m.limited(influences) for m in meshes]
    if out.suffix.lower() == ".glb":
        from loosefit.io.skinned_gltf import write_skinned_glb

        write_skinned_glb(out, limited)
    else:
        from loosefit.io.skinned_usd import write_skinned_usd

        write_skinned_usd(out, limited)
    return {"path": str(out), "bytes": out.stat().st_size, **summary}
