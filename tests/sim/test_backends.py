"""Both cloth backends against closed forms: a hanging strip's stretch, a box collider, repeatability,
a 10-micrometre start perturbation. Where Blender misses a bound the test is a strict expected
failure stating the measured number, so that fixing it shows up."""

import importlib.util

import numpy as np
import pytest

from loosefit.sim.collider import steps_per_frame, travel_per_step
from loosefit.sim.params import SimParams
from loosefit.sim.sequence import backend_run_cloth

FAR_COLLIDER = np.array([[50.0, 0, 0], [51, 0, 0], [50, 1, 0]], np.float32)
NEWTON = pytest.param(
    "newton", marks=pytest.mark.skipif(importlib.util.find_spec("newton") is None, reason="newton is not installed")
)


def blender_fails(reason: str):
    return pytest.param("blender", marks=pytest.mark.xfail(strict=True, reason=reason))


def strip(nx: int = 3, ny: int = 11, width: float = 0.04, length: float = 0.2, top: float = 1.0):
    """A vertical strip in the XZ plane hanging from its top row: ``(verts (nx*ny, 3), faces, pinned)``; edges 2 cm."""
    x, s = np.meshgrid(np.linspace(0, width, nx), np.linspace(0, length, ny))
    verts = np.stack([x.ravel(), np.zeros(nx * ny), top - s.ravel()], 1).astype(np.float32)
    faces = []
    for i in range(ny - 1):
        for j in range(nx - 1):
            a, c = i * nx + j, (i + 1) * nx + j
            faces += [(a, c, a + 1), (a + 1, c, c + 1)]
    pinned = np.zeros(nx * ny, bool)
    pinned[:nx] = True
    return verts, np.array(faces, np.int64), pinned


def hang(backend, verts, faces, pinned, params, frames, start=None):
    """``(frames, V, 3)``: simulate at 30 fps with the pins still and the collider far away."""
    garment = np.repeat(verts[None], frames, 0)
    if start is not None:
        garment[0] = start
    collider = np.repeat(FAR_COLLIDER[None], frames, 0)
    return backend_run_cloth(backend)(faces, pinned, garment, collider, np.array([[0, 1, 2]]), params, 30.0)[0]


@pytest.mark.parametrize("backend", [blender_fails("measured 0.97 mm against 1.47 mm at 20 N/m: 34% too stiff"), NEWTON])
def test_hanging_strip_stretches_as_the_closed_form(backend):
    # A strip of length L, areal density rho and stretch stiffness k (N/m) hanging from its top edge
    # carries at height s the weight of what is below, rho*g*w*(L - s), so its strain there is
    # rho*g*(L - s)/k and its bottom drops by the integral, rho*g*L^2/(2k). The lumped-mass chain of
    # the mesh has exactly the same sum (row j carries the rows below plus half its own), so what
    # is left is the solver's error: Newton's VBD iterates 10 times per substep and does not
    # converge fully (measured 8% too soft at k = 50 N/m with 20 substeps). Tolerance 15%; the two
    # stiffnesses must also give the 2:1 ratio of the closed form within 10%.
    verts, faces, pinned = strip()
    length, rho, g = 0.2, 0.15, 9.81
    drops = {}
    for k in (20.0, 40.0):
        params = SimParams(tension=k, compression=k, density=rho, gravity=g, quality=20, bending=1e-8,
                           air_drag=0.0, stretch_damping=50.0)
        out = hang(backend, verts, faces, pinned, params, 46)
        bottom = verts[-3:, 2].mean() - out[-10:, -3:, 2].mean(axis=1)  # the last third of a second
        assert np.ptp(bottom) < 0.05 * bottom.mean()  # settled
        drops[k] = float(bottom.mean())
        assert drops[k] == pytest.approx(rho * g * length**2 / (2 * k), rel=0.15)
    assert drops[20.0] / drops[40.0] == pytest.approx(2.0, rel=0.1)


def box(half: float = 0.1):
    """A closed cube of side ``2 * half`` centred at the origin, triangles facing out."""
    corners = np.array([[x, y, z] for x in (-half, half) for y in (-half, half) for z in (-half, half)], np.float32)
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    return corners, np.array(faces, np.int64)


def box_signed_distance(points: np.ndarray, centre: np.ndarray, half: float = 0.1) -> np.ndarray:
    """Exact signed distance of ``points (P, 3)`` to the cube at ``centre``, negative inside, m."""
    q = np.abs(points - centre) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(-1), 0.0)


def patch(n: int = 11, size: float = 0.3, height: float = 0.25):
    """A horizontal ``n x n`` cloth square at ``height``: ``(verts (n*n, 3), faces)``."""
    x, y = np.meshgrid(np.linspace(-size / 2, size / 2, n), np.linspace(-size / 2, size / 2, n))
    verts = np.stack([x.ravel(), y.ravel(), np.full(n * n, height)], 1).astype(np.float32)
    faces = [(i * n + j, i * n + j + 1, (i + 1) * n + j + 1) for i in range(n - 1) for j in range(n - 1)]
    faces += [(i * n + j, (i + 1) * n + j + 1, (i + 1) * n + j) for i in range(n - 1) for j in range(n - 1)]
    return verts, np.array(faces, np.int64)


def box_scene(frames: int = 40):
    """The cloth falls 5 cm onto a 20 cm box, which then rises 20 cm (0.4 m/s) while sliding sideways
    (0.2 m/s). Returns ``verts, faces, collider (frames, 8, 3), box faces, centre (frames, 3)``."""
    verts, faces = patch()
    corners, box_faces = box()
    t = np.arange(frames) / 30.0
    centre = np.stack([0.2 * np.clip(t - 0.5, 0, None), 0 * t, 0.1 + 0.4 * np.clip(t - 0.5, 0, 0.5)], 1)
    return verts, faces, (corners[None] + centre[:, None]).astype(np.float32), box_faces, centre


def run_box(backend, quality):
    """``(cloth (frames, V, 3), signed distance of each vertex to the box (frames, V))``."""
    verts, faces, collider, box_faces, centre = box_scene()
    garment = np.repeat(verts[None], len(collider), 0)
    free = np.zeros(len(verts), bool)
    out = backend_run_cloth(backend)(faces, free, garment, collider, box_faces, SimParams(quality=quality), 30.0)[0]
    return out, np.array([box_signed_distance(out[k], centre[k]) for k in range(len(out))])


@pytest.mark.parametrize("backend", ["blender", NEWTON])
def test_cloth_dropped_on_a_moving_box_stays_outside(backend):
    verts, _, collider, _, centre = box_scene()
    params = SimParams()
    steps = steps_per_frame(collider, verts, params.collision_distance, params.quality,
                            travel_per_step=travel_per_step(backend))
    # The box moves hypot(0.4, 0.2) / 30 = 14.9 mm per frame: 5 steps of at most 3 mm for Newton;
    # Blender's 2 steps of 8 mm are raised to the minimum, quality = 5.
    assert steps == 5
    out, sd = run_box(backend, steps)
    assert sd.min() > -0.001  # no vertex more than 1 mm inside, in any frame
    assert sd[15:30].min(1).max() < 2 * params.collision_distance  # lying on it while it rises
    # Carried up: at the end of the rise (frame 29, the lid 0.19 m higher than at landing) the cloth
    # over the lid lies on it, about one contact distance above. (Later the box slides out from under it.)
    rel = out[29] - centre[29]
    over = (np.abs(rel[:, :2]) < 0.09).all(1)
    assert over.sum() > 20
    assert np.median(rel[over, 2]) == pytest.approx(0.1 + params.collision_distance, abs=0.002)


@pytest.mark.parametrize("backend", ["blender", NEWTON])
def test_two_runs_are_bit_identical(backend):
    verts, faces, pinned = strip()
    params = SimParams(tension=50.0, quality=4)
    a = hang(backend, verts, faces, pinned, params, 10)
    b = hang(backend, verts, faces, pinned, params, 10)
    assert np.abs(a[-1] - verts).max() > 1e-4  # it moved
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("backend", ["blender", NEWTON])
def test_a_10_micrometre_start_perturbation_stays_small(backend):
    # The perturbed start is also the perturbed rest shape (frame 0 is both). For a stable, damped
    # system the motion is a smooth function of the rest shape: moving the vertices by at most
    # `noise` changes edge directions and lengths by a fraction at most 2 * noise / h (h the
    # shortest edge), so the motion (at most D away from the start) changes by about that fraction
    # of D, twice that for the overshoot of a suddenly changed equilibrium, plus the start offset
    # itself (at most sqrt(3) * noise per vertex). A chaotic system exceeds this by orders of
    # magnitude: Blender with the fabric loosefit shipped before (compression equal to tension, air
    # drag 0.05) gave 507 um here, and a 10 um change grew to 115 mm within 4 s on the bench skirt. The bound assumes a stable equilibrium: with bending 1e-5 N*m, Newton's strip
    # buckles out of its plane in the compression phases of its first stretch oscillation (a flat
    # sheet has no out-of-plane stiffness but bending) and the 10 um grew to 260 um there
    # (measured); at 1e-4 N*m it stays at the noise level.
    verts, faces, pinned = strip()
    params = SimParams(tension=50.0, quality=8, bending=1e-4)
    frames = 30
    noise = np.random.default_rng(0).normal(0.0, 1e-5, verts.shape).astype(np.float32)
    noise[pinned] = 0.0  # the pins are driven; perturb the cloth
    a = hang(backend, verts, faces, pinned, params, frames)
    b = hang(backend, verts, faces, pinned, params, frames, start=verts + noise)
    max_noise = float(np.abs(noise).max())
    h = 0.02
    travel = float(np.linalg.norm(a - verts[None], axis=-1).max())
    bound = np.sqrt(3) * max_noise + 2 * (2 * max_noise / h) * travel
    diff = float(np.linalg.norm(a - b, axis=-1).max())
    assert 0 < diff < bound, (diff, bound, travel)
