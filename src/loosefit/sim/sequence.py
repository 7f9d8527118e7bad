"""Simulate one garment on one body motion: pre-roll, cloth simulation (Blender or Newton), quality measures and gate."""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from loosefit.body.base import BodyModel
from loosefit.errors import InputError
from loosefit.extras import require, require_installed
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.motion.motion import Motion
from loosefit.sim.attach import garment_weights, skin_garment
from loosefit.sim.collider import collider_frames, steps_per_frame, travel_per_step
from loosefit.sim.params import BACKENDS, SimParams
from loosefit.sim.preroll import preroll_frames, with_preroll
from loosefit.sim.quality import QualityGate, measure


@dataclass
class SimResult:
    """A simulated sequence.

    Attributes:
        verts: ``(T, V, 3)`` float32 garment vertices, metres, one per motion frame (pre-roll dropped).
        stats: timing (``ms_per_frame``, ``wall_s``, ``frames``, ``preroll_frames``), the solver
            steps per frame used (``quality``) and the quality measures of
            :func:`loosefit.sim.quality.measure`.
        status: ``"ok"`` or ``"failed"`` (by the quality gate).
        reason: why it failed, empty when ok.
        body_verts: ``(T, Vb, 3)`` float32 full-resolution posed body at the same frames.
    """

    verts: np.ndarray
    stats: dict[str, Any]
    status: str = "ok"
    reason: str = ""
    body_verts: np.ndarray = field(default=None, repr=False)


#: backend -> the module that simulates
BACKEND_MODULES = {"blender": ("bpy", "simulation backend 'blender' (Blender cloth)"),
                   "newton": ("newton", "simulation backend 'newton'")}


def _backend_module(backend: str) -> tuple[str, str]:
    if backend not in BACKEND_MODULES:
        raise InputError(f"unknown simulation backend {backend!r}; known: {list(BACKENDS)}")
    return BACKEND_MODULES[backend]


def check_backend(backend: str) -> None:
    """That a backend's simulator is installed, without importing it (for a process whose workers simulate)."""
    require_installed(*_backend_module(backend))


def backend_run_cloth(backend: str):
    """The ``run_cloth`` function of a backend (``"blender"`` or ``"newton"``); each imports its simulator lazily."""
    require(*_backend_module(backend))
    if backend == "newton":
        from loosefit.sim.newton import run_cloth
    else:
        from loosefit.sim.blender import run_cloth
    return run_cloth


def simulate_sequence(
    garment,
    body: BodyModel,
    motion: Motion,
    params: SimParams | None = None,
    shape=None,
    gate: QualityGate | None = None,
) -> SimResult:
    """Simulate ``garment`` on ``body`` moving along ``motion``.

    Args:
        garment: a :class:`loosefit.garment.Garment` (``verts (V, 3)`` in the rest pose of ``body``
            with ``shape``, ``faces (F, 3)``, ``pinned (V,)`` bool).
        body: the full-resolution body; its inflated collision proxy is the collider unless
            ``params.collider == "full"`` (:mod:`loosefit.sim.collider`). Penetration is always
            measured on the full body.
        motion: ``T`` frames on the body's rig.
        params: simulation parameters (defaults when ``None``).
        shape: body shape (``None`` for the body's own).
        gate: quality limits (defaults when ``None``).

    Returns:
        :class:`SimResult` with ``T`` frames.
    """
    params = params or SimParams()
    gate = gate or QualityGate()
    body.check_motion(motion)
    rest = np.asarray(garment.verts, np.float32)
    faces = np.asarray(garment.faces, np.int64)
    pinned = np.asarray(garment.pinned, bool)
    if rest.ndim != 2 or rest.shape[1] != 3 or pinned.shape != (len(rest),):
        raise InputError(
            f"garment {getattr(garment, 'name', '')!r} needs verts (V, 3) and pinned (V,), "
            f"got {rest.shape} and {pinned.shape}"
        )

    start = time.perf_counter()
    lead = preroll_frames(params.preroll, motion.fps)
    full = with_preroll(body, motion, lead, shape)
    collider, collider_faces = collider_frames(body, full, shape, params.collider)
    garment_frames = skin_garment(rest, garment_weights(rest, body, shape), body, full, shape)
    if params.adaptive_quality:
        # Newton's contact needs smaller body steps than Blender's (loosefit.sim.collider).
        steps = steps_per_frame(collider, garment_frames[0], params.collision_distance, params.quality,
                                travel_per_step=travel_per_step(params.backend))
        params = dataclasses.replace(params, quality=steps)
    body_verts = body.pose(motion, shape).verts
    floor = float(min(body_verts[..., 2].min(), body.rest_verts(shape)[:, 2].min()))  # the soles on the ground
    verts, seconds = backend_run_cloth(params.backend)(
        faces, pinned, garment_frames, collider, collider_faces, params, motion.fps, floor=floor
    )
    verts = verts[lead:]
    stats = measure(verts, rest, faces, pinned, body_verts, body.faces, body.rest_verts(shape), motion.fps)
    stats.update(
        ms_per_frame=float(1000.0 * seconds.mean()),
        frames=int(motion.num_frames),
        preroll_frames=int(lead),
        quality=int(params.quality),
        garment_verts=int(len(rest)),
        wall_s=float(time.perf_counter() - start),
    )
    status, reason = gate.check(stats)
    return SimResult(verts=verts, stats=stats, status=status, reason=reason, body_verts=body_verts)


def save_result(path: str | Path, result: SimResult, faces: np.ndarray, body_faces: np.ndarray, fps: float) -> None:
    """Write a result as a loosefit mesh-sequence ``.npz``: garment and body vertices and faces,
    ``stats`` (JSON text), ``status`` and ``reason``."""
    extra = {
        "body_verts": result.body_verts,
        "body_faces": np.asarray(body_faces, np.int64),
        "stats": np.str_(json.dumps(result.stats)),
        "status": np.str_(result.status),
        "reason": np.str_(result.reason),
    }
    MeshSequence(result.verts, faces, fps, extra).save(path)
