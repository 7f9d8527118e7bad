"""Why the Newton backend uses SolverVBD: SolverStyle3D on the collider scene of the tests.

A measurement, not a test. The scene of ``tests/sim/test_backends.py::test_cloth_dropped_on_a_moving_box_stays_outside``
(an 11 x 11 cloth dropped 5 cm onto a 20 cm box that then rises and slides), with the box as
zero-mass particles and triangles as in :mod:`loosefit.sim.newton`, stepped by Style3D instead.
Run from the project root: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/experiments/newton_style3d_box.py [substeps]``.

Measured (CPU, warm kernel cache): with 8 or 24 substeps the cloth falls through the box lid while
the box is still at rest (70 mm inside at frame 6), then keeps falling; 473 ms/frame at 8 substeps,
against 77 ms/frame for VBD at 10 substeps, which keeps every vertex outside.
"""

import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

wp.config.quiet = True
import newton  # noqa: E402
from newton.solvers import style3d  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: tests.sim
from tests.sim.test_backends import box, box_signed_distance, patch  # noqa: E402


def main(substeps: int = 8, frames: int = 40) -> None:
    verts, faces = patch()
    corners, box_faces = box()
    t = np.arange(frames) / 30.0
    centre = np.stack([0.2 * np.clip(t - 0.5, 0, None), 0 * t, 0.1 + 0.4 * np.clip(t - 0.5, 0, 0.5)], 1)
    collider = (corners[None] + centre[:, None]).astype(np.float32)
    builder = newton.ModelBuilder()
    newton.solvers.SolverStyle3D.register_custom_attributes(builder)
    common = dict(pos=wp.vec3(0.0), rot=wp.quat_identity(), vel=wp.vec3(0.0))
    style3d.add_cloth_mesh(builder, **common, vertices=verts.tolist(), indices=faces.ravel().tolist(), density=0.15,
                           tri_aniso_ke=wp.vec3(3.0e3, 3.0e3, 1.0e2), edge_aniso_ke=wp.vec3(1e-5, 1e-5, 1e-5))
    style3d.add_cloth_mesh(builder, **common, vertices=collider[0].tolist(), indices=box_faces.ravel().tolist(),
                           density=0.0, tri_aniso_ke=wp.vec3(0.0), edge_aniso_ke=wp.vec3(0.0))
    model = builder.finalize(device="cpu")
    model.soft_contact_mu = 0.05
    solver = newton.solvers.SolverStyle3D(model, config=newton.solvers.SolverStyle3D.Config(iterations=10))
    state_in, state_out = model.state(), model.state()
    control = model.control()
    pipeline = newton.CollisionPipeline(model)
    contacts = pipeline.contacts()
    n = len(verts)
    out = np.empty((frames, n, 3), np.float32)
    out[0] = verts
    dt = 1.0 / 30.0 / substeps
    start = time.perf_counter()
    for f in range(1, frames):
        for s in range(substeps):
            w = (s + 1) / substeps
            q = state_in.particle_q.numpy()
            q[n:] = (1 - w) * collider[f - 1] + w * collider[f]
            state_in.particle_q.assign(q)
            pipeline.collide(state_in, contacts)
            solver.step(state_in, state_out, control, contacts, dt)
            state_in, state_out = state_out, state_in
        out[f] = state_in.particle_q.numpy()[:n]
    print(f"substeps {substeps}: {1000 * (time.perf_counter() - start) / (frames - 1):.0f} ms/frame")
    sd = np.array([box_signed_distance(out[k], centre[k]) for k in range(frames)])
    print("deepest cloth vertex inside the box per frame, mm:", np.round(-np.minimum(sd.min(1), 0) * 1000, 1))


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 8)
