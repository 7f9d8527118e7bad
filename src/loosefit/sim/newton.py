"""NVIDIA Newton (``newton``, on ``warp``) as the simulation backend, with :class:`SolverVBD`.

``newton`` and ``warp`` are imported inside :func:`run_cloth` only, so ``import loosefit.sim``
stays light.

Scene. One particle system holds the garment and the body collider. Body vertices and the pinned
garment vertices have zero mass: VBD leaves them where they are put, and they are put, before
every substep, on the straight line between the two frames around it (``garment_frames`` for the
pins, ``collider_frames`` for the body). Cloth-body contact is VBD's particle self-contact
(vertex-triangle and edge-edge pairs), so the body is a true deforming triangle mesh. Which pairs
may touch is chosen with VBD's rest-shape exclusion: the distance between two primitives in a
*reference* configuration decides whether they are considered at all. The reference puts all
body vertices on one point far away from the garment, so body-body pairs never count and every
garment-body pair does; with ``self_collision`` off all garment vertices share one point too, so
garment-garment pairs never count either. (The reference is used for nothing else: rest shapes
of the triangles and hinges come from ``garment_frames[0]``.)

Why VBD and not ``SolverStyle3D`` (measured on the CPU, warm kernel cache,
``benchmarks/experiments/newton_style3d_box.py``): with the body built the same way, Style3D let a cloth fall
through a box collider that was standing still (70 mm inside, with 8 or 24 substeps) and took
473 ms/frame at 8 substeps for 121 cloth particles; VBD kept every vertex outside the box while
it rose and slid (``tests/sim/test_backends.py``) at 77 ms/frame with 10 substeps, and repeats
bit-identically across processes.

Unit mapping (:func:`material`), with ``rho`` the areal density, ``A_v = A / V`` the garment
area per vertex and ``h`` its mean edge length:

- mass: ``rho`` times one third of the area of each incident triangle (lumped).
- membrane: VBD's stable Neo-Hookean membrane is isotropic, with Lamé parameters ``mu``,
  ``lambda`` in N/m (energy per rest area). Its uniaxial (plane-stress) stiffness is
  ``E = 4 mu (mu + lambda) / (2 mu + lambda)``, which is set to ``tension``: a hanging strip
  stretches as ``rho g L^2 / (2 tension)``, as with Blender's springs. Poisson's ratio is
  ``nu = clip(tension / (2 shear) - 1, 0, NU_MAX)``: an isotropic sheet has shear stiffness
  ``E / (2 (1 + nu))``, so a ``shear`` below ``tension / (2 (1 + NU_MAX))`` (stiff woven
  fabric) cannot be honoured and the sheet shears at ``E / (2 (1 + NU_MAX))``.
  ``compression`` is not used: the membrane resists compression with the same modulus at
  small strain (cloth buckles out of plane long before, which bending decides).
- bending: each hinge stores ``ke`` with energy ``ke * l * theta^2 / 2`` (``l`` its length,
  ``theta`` the fold angle). A sheet of rigidity ``B`` bent to radius ``R`` stores
  ``B / (2 R^2)`` per area; hinges ``d`` apart fold by ``d / R`` each, so ``ke = B / d`` with
  ``d = (A_1 + A_2) / l`` (the two incident triangle areas over the hinge length), exact for a
  regular right-triangle grid bent about a grid line.
- stretch damping: VBD's membrane damping ``kd`` resists the rate of the Green strain, a stress
  of about ``4 kd`` times the strain rate. Two vertices one edge apart whose relative velocity
  should decay at ``stretch_damping`` per second need ``kd = stretch_damping * rho * A_v / 8``.
- bending damping: a hinge's damping torque is ``kd * l * dtheta/dt``; a vertex at lever ``h``
  slows at ``bending_damping`` per second with ``kd = bending_damping * rho * A_v * h^2 / l``.
- air drag: a force ``-air_drag * A_i * v_i`` on each free vertex (``A_i`` its lumped area, still
  air), applied explicitly at the start of each substep.
- gravity: ``-gravity`` along Z; time: a substep lasts ``time_scale / (fps * quality)`` s.
- contact: the contact distance (VBD's self-contact margin) is ``collision_distance``, contacts
  are searched within twice that, before each substep and after its inertial prediction. VBD has
  one contact distance for all pairs, so ``self_collision_distance`` is not used. Stiffness :data:`CONTACT_KE` (N/m; with VBD's default of 1e3 a
  cloth sank 70 mm into a body, 1e5 kept it out). Friction coefficient ``friction / 100``
  (Blender's cloth collision multiplies its 0-80 setting by 0.01). The body's own velocity does
  not enter friction (its vertices are placed, not integrated), so a sliding body drags cloth a
  little less than in Blender.
- ``quality``: substeps per frame; :data:`ITERATIONS` VBD iterations per substep;
  ``collision_quality`` is unused (contacts are searched once per substep and kept while iterating).

Determinism: warp's CPU backend runs kernels on one thread, and the scene is built in a fixed
order, so two runs (and two processes) with the same inputs give identical results. On CUDA the
solver is asked for warp's deterministic mode.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from loosefit.errors import InputError
from loosefit.geometry.laplacian import edges
from loosefit.geometry.normals import face_areas
from loosefit.sim.params import SimParams

#: Largest Poisson's ratio used to approach fabric's weak shear with an isotropic membrane.
NU_MAX = 0.3
#: Contact stiffness, N/m.
CONTACT_KE = 1.0e5
#: VBD iterations per substep.
ITERATIONS = 10
#: Where the reference configuration puts body vertices (far from any garment), m.
_FAR = 1.0e4


def _edge_table(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Interior edges of a triangle mesh: ``(H, 2)`` vertex pairs (sorted) and ``(H, 2)`` the two faces."""
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), 1)
    face = np.tile(np.arange(len(faces)), 3)
    order = np.lexsort((e[:, 1], e[:, 0]))
    e, face = e[order], face[order]
    shared = np.flatnonzero((e[1:] == e[:-1]).all(1))
    return e[shared], np.stack([face[shared], face[shared + 1]], 1)


def material(params: SimParams, verts: np.ndarray, faces: np.ndarray, fps: float) -> dict:
    """Newton/VBD material values for ``params`` on the garment ``verts (V, 3)``, ``faces (F, 3)``.

    Returns:
        ``mu``, ``lmbd`` (membrane Lamé parameters, N/m), ``tri_kd`` (membrane damping), ``nu``,
        ``hinges (H, 2)`` vertex pairs of interior edges, ``hinge_ke (H,)`` and ``hinge_kd (H,)``,
        ``vertex_area (V,)`` lumped areas (m^2), ``dt`` substep (s).
    """
    verts = np.asarray(verts, np.float64)
    area = face_areas(verts, faces)
    vertex_area = np.zeros(len(verts))
    np.add.at(vertex_area, faces.ravel(), np.repeat(area / 3.0, 3))
    e, f = _edge_table(faces)
    length = np.linalg.norm(verts[e[:, 0]] - verts[e[:, 1]], axis=1)
    every = edges(faces)
    mean_edge = float(np.linalg.norm(verts[every[:, 0]] - verts[every[:, 1]], axis=1).mean())
    area_per_vertex = float(area.sum()) / len(verts)

    E = params.tension
    nu = float(np.clip(E / (2.0 * max(params.shear, 1e-12)) - 1.0, 0.0, NU_MAX))
    mu = E / (2.0 * (1.0 + nu))
    lmbd = E * nu / (1.0 - nu * nu)  # plane stress
    spacing = (area[f[:, 0]] + area[f[:, 1]]) / np.maximum(length, 1e-12)
    return {
        "mu": mu,
        "lmbd": lmbd,
        "nu": nu,
        "tri_kd": params.stretch_damping * params.density * area_per_vertex / 8.0,
        "hinges": e,
        "hinge_ke": params.bending / np.maximum(spacing, 1e-12),
        "hinge_kd": params.bending_damping * params.density * area_per_vertex * mean_edge**2 / np.maximum(length, 1e-12),
        "vertex_area": vertex_area,
        "dt": params.time_scale / (fps * params.quality),
    }


def check_installed() -> None:
    """Raise :class:`InputError` when ``newton`` or ``warp`` cannot be imported (a cheap look-up, no import)."""
    import importlib.util

    missing = [name for name in ("newton", "warp") if importlib.util.find_spec(name) is None]
    if missing:
        raise InputError(
            f"simulation backend 'newton' needs the packages {missing}, which cannot be imported; "
            "install them with `pip install 'loosefit[sim]'` (newton brings warp-lang), or use backend=blender"
        )


def run_cloth(
    faces: np.ndarray,
    pinned: np.ndarray,
    garment_frames: np.ndarray,
    collider_frames: np.ndarray,
    collider_faces: np.ndarray,
    params: SimParams,
    fps: float,
    workdir: str | Path | None = None,
    floor: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Simulate a garment on a moving collider with Newton's VBD solver.

    ``floor`` is accepted for the common interface but not modelled yet: Newton's cloth has no ground
    (Blender's has a collision plane there); hems that reach the ground go through it.

    Args:
        faces: ``(F, 3)`` garment triangles.
        pinned: ``(V,)`` bool, vertices that follow ``garment_frames`` exactly.
        garment_frames: ``(N, V, 3)`` garment skinned to the body; frame 0 is the start state and
            rest shape of the cloth, later frames are targets for the pinned vertices only.
        collider_frames: ``(N, Vc, 3)`` body collider vertices per frame.
        collider_faces: ``(Fc, 3)`` collider triangles.
        params: simulation parameters.
        fps: frames per second of the animation.
        workdir: unused (the same signature as :func:`loosefit.sim.blender.run_cloth`).

    Returns:
        ``(verts (N, V, 3) float32 cloth positions per frame, seconds (N,) wall time per frame)``.
    """
    check_installed()
    try:
        import warp as wp
    except ImportError as e:
        raise InputError(f"simulation backend 'newton' cannot import warp ({e}); pip install 'loosefit[sim]'") from None

    wp.config.quiet = True
    try:
        import newton
    except ImportError as e:
        raise InputError(f"simulation backend 'newton' cannot import newton ({e}); pip install 'loosefit[sim]'") from None

    faces = np.asarray(faces, np.int64)
    collider_faces = np.asarray(collider_faces, np.int64)
    pinned = np.asarray(pinned, bool)
    garment_frames = np.asarray(garment_frames, np.float32)
    collider_frames = np.asarray(collider_frames, np.float32)
    num_frames, num_verts = garment_frames.shape[:2]
    if collider_frames.shape[0] != num_frames or pinned.shape != (num_verts,):
        raise InputError(
            f"garment frames {garment_frames.shape}, collider frames {collider_frames.shape} and "
            f"pinned {pinned.shape} do not match"
        )
    num_body = collider_frames.shape[1]
    rest = garment_frames[0]
    mat = material(params, rest, faces, fps)

    wp.init()
    device = wp.get_preferred_device()

    builder = newton.ModelBuilder(gravity=(0.0, 0.0, -params.gravity))
    cloth_args = dict(pos=wp.vec3(0.0), rot=wp.quat_identity(), scale=1.0, vel=wp.vec3(0.0))
    builder.add_cloth_mesh(
        **cloth_args, vertices=rest.tolist(), indices=faces.ravel().tolist(), density=params.density,
        tri_ke=mat["mu"], tri_ka=mat["lmbd"], tri_kd=mat["tri_kd"], edge_ke=0.0, edge_kd=0.0,
        particle_radius=params.collision_distance,
    )
    builder.add_cloth_mesh(
        **cloth_args, vertices=collider_frames[0].tolist(), indices=collider_faces.ravel().tolist(),
        density=0.0, tri_ke=0.0, tri_ka=0.0, tri_kd=0.0, edge_ke=0.0, edge_kd=0.0,
        particle_radius=params.collision_distance,
    )
    for i in np.flatnonzero(pinned):
        builder.particle_mass[i] = 0.0
    builder.color(include_bending=True)
    model = builder.finalize(device=device)

    # Per-hinge bending: Newton's edges are (opposite 0, opposite 1, v0, v1); match them to ours.
    edge_idx = model.edge_indices.numpy()
    props = np.zeros((len(edge_idx), 2), np.float32)
    ours = {(int(a), int(b)): k for k, (a, b) in enumerate(mat["hinges"])}
    for k, (o0, o1, a, b) in enumerate(edge_idx):
        if o0 < 0 or o1 < 0 or a >= num_verts:
            continue
        h = ours.get((min(a, b), max(a, b)))
        if h is not None:
            props[k] = (mat["hinge_ke"][h], mat["hinge_kd"][h])
    model.edge_bending_properties.assign(props)
    model.soft_contact_ke = CONTACT_KE
    model.soft_contact_kd = 0.0
    model.soft_contact_mu = params.friction * 0.01

    state_in, state_out = model.state(), model.state()
    control = model.control()

    # The reference configuration for contact filtering (see the module docstring).
    reference = model.particle_q.numpy().copy()
    reference[num_verts:] = _FAR
    if not params.self_collision:
        reference[:num_verts] = 0.0
    model.particle_q.assign(reference)

    kwargs = {"deterministic": wp.DeterministicMode.RUN_TO_RUN} if device.is_cuda else {}
    solver = newton.solvers.SolverVBD(
        model,
        iterations=ITERATIONS,
        particle_enable_self_contact=True,
        particle_self_contact_margin=params.collision_distance,
        particle_self_contact_gap=params.collision_distance,
        # Pairs closer than this in the reference are skipped: body-body always, garment-garment
        # without self-collision (their reference distance is 0), garment-body never (_FAR).
        particle_rest_shape_contact_exclusion_radius=1.0 if not params.self_collision else 1e-6,
        # Search contacts before each substep and again after the inertial prediction: with the
        # first search only, a box rising 0.93 collision distances per substep went through the
        # cloth; with both it did not (measured).
        collision_frequency_type={
            newton.solvers.SolverBase.CollisionSlot.SOFT_SELF_CONTACT:
                newton.solvers.SolverBase.CollisionFrequencyType.PRE_POST_INIT
        },
        **kwargs,
    )

    driven = np.concatenate([np.flatnonzero(pinned), num_verts + np.arange(num_body)])
    targets = np.concatenate([garment_frames[:, pinned], collider_frames], axis=1)  # (N, D, 3)
    free = np.ones(num_verts + num_body, bool)
    free[driven] = False
    drag = np.zeros((num_verts + num_body, 1), np.float32)
    drag[:num_verts, 0] = params.air_drag * mat["vertex_area"]
    drag[~free] = 0.0
    dt = mat["dt"]

    out = np.empty((num_frames, num_verts, 3), np.float32)
    seconds = np.zeros(num_frames)
    out[0] = rest
    for frame in tqdm(range(1, num_frames), desc="newton cloth", unit="frame", mininterval=10.0, leave=False):
        start = time.perf_counter()
        for sub in range(params.quality):
            w = (sub + 1) / params.quality
            q = state_in.particle_q.numpy()
            q[driven] = (1.0 - w) * targets[frame - 1] + w * targets[frame]
            state_in.particle_q.assign(q)
            if params.air_drag > 0:
                state_in.particle_f.assign(-drag * state_in.particle_qd.numpy())
            solver.step(state_in, state_out, control, None, dt)
            state_in, state_out = state_out, state_in
        out[frame] = state_in.particle_q.numpy()[:num_verts]
        seconds[frame] = time.perf_counter() - start
    seconds[0] = seconds[1:].mean() if num_frames > 1 else 0.0
    return out, seconds
