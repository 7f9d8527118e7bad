"""The Newton backend's own checks: the material mapping, identical results across processes, the
substep rule, and its errors. The physics shared with Blender is in ``test_backends.py``."""

import importlib.util
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.sim.params import SimParams
from loosefit.sim.plan import load_plan
from loosefit.sim.sequence import backend_run_cloth
from tests.sim.test_backends import FAR_COLLIDER, hang, run_box, strip

needs_newton = pytest.mark.skipif(importlib.util.find_spec("newton") is None, reason="newton is not installed")


def test_material_closed_form():
    from loosefit.sim.newton import NU_MAX, material

    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    p = SimParams(density=0.2, tension=1000.0, shear=400.0, bending=2e-5, stretch_damping=80.0,
                  bending_damping=4.0, quality=4, time_scale=0.5)
    m = material(p, verts, faces, fps=25.0)
    nu = 1000 / 800 - 1  # 0.25: an isotropic sheet with E = 1000 N/m and G = 400 N/m
    assert m["nu"] == pytest.approx(nu)
    assert 4 * m["mu"] * (m["mu"] + m["lmbd"]) / (2 * m["mu"] + m["lmbd"]) == pytest.approx(1000.0)  # uniaxial E
    assert m["mu"] == pytest.approx(400.0)
    np.testing.assert_array_equal(m["hinges"], [[1, 2]])  # the one interior edge
    length = np.sqrt(2)
    assert m["hinge_ke"] == pytest.approx([2e-5 / (1.0 / length)])  # B / ((A1 + A2) / l)
    mean_edge = (4 + np.sqrt(2)) / 5
    assert m["hinge_kd"] == pytest.approx([4.0 * 0.2 * 0.25 * mean_edge**2 / length])
    assert m["tri_kd"] == pytest.approx(80.0 * 0.2 * 0.25 / 8)
    np.testing.assert_allclose(m["vertex_area"], [1 / 6, 1 / 3, 1 / 3, 1 / 6])
    assert m["dt"] == pytest.approx(0.5 / (25 * 4))
    # Woven fabric's weak shear cannot be met by an isotropic sheet: Poisson's ratio stops at NU_MAX.
    assert material(SimParams(tension=3000.0, shear=100.0), verts, faces, 30.0)["nu"] == NU_MAX


@needs_newton
def test_identical_across_processes(tmp_path):
    verts, faces, pinned = strip()
    params = SimParams(tension=50.0, quality=4)
    here = hang("newton", verts, faces, pinned, params, 10)
    script = textwrap.dedent(f"""
        import numpy as np
        from loosefit.sim.params import SimParams
        from tests.sim.test_backends import hang, strip
        verts, faces, pinned = strip()
        np.save({str(tmp_path / "other.npy")!r}, hang("newton", verts, faces, pinned, SimParams(tension=50.0, quality=4), 10))
    """)
    subprocess.run([sys.executable, "-c", script], check=True, capture_output=True)
    np.testing.assert_array_equal(np.load(tmp_path / "other.npy"), here)


@needs_newton
def test_too_few_substeps_let_the_box_through():
    # Why NEWTON_TRAVEL_PER_STEP is below one collision distance: with 3 substeps the box's lid moves
    # 4.4 mm per substep while rising, more than the 4 mm gap the contact keeps, and passes through
    # the cloth (test_backends: with the rule's 5 substeps no vertex gets in).
    _, sd = run_box("newton", 3)
    assert sd[:15].min() > -0.001  # lying still on the box is fine...
    assert sd.min() < -0.01  # ...the rising lid goes through


def test_unknown_backend_is_an_input_error():
    with pytest.raises(InputError, match=r"backend='bullet'.*\['blender', 'newton'\]"):
        SimParams(backend="bullet")
    with pytest.raises(InputError, match="backend"):
        SimParams().with_overrides(["backend=mujoco"])
    with pytest.raises(InputError, match="unknown simulation backend"):
        backend_run_cloth("mujoco")


def test_newton_missing_is_an_input_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "newton", None)  # `import newton` now fails as if not installed
    with pytest.raises(InputError, match=r"pip install .loosefit\[sim\]."):
        SimParams(backend="newton")
    verts, faces, pinned = strip()
    garment = np.repeat(verts[None], 2, 0)
    collider = np.repeat(FAR_COLLIDER[None], 2, 0)
    with pytest.raises(InputError, match=r"pip install .loosefit\[sim\]."):
        backend_run_cloth("newton")(faces, pinned, garment, collider, np.array([[0, 1, 2]]), SimParams(), 30.0)


def test_plan_hash_names_the_backend_only_when_it_is_not_blender(tmp_path):
    # Stores simulated before SimParams had a backend keep their hashes (no re-simulation on
    # resume); a Newton parameter set is another sequence.
    from tests.sim.test_plan import PLAN, _write

    def hashes(params):
        plan = load_plan(_write(tmp_path, {**PLAN, "sim_params": {"default": params, "stiff": {"bending": 1e-4}}}))
        return {job.id: job.hash for job in plan.jobs}["skirt+tall+walk+default"]

    assert hashes({}) == hashes({"backend": "blender"})
    if importlib.util.find_spec("newton") is not None:
        assert hashes({}) != hashes({"backend": "newton"})


def test_simulate_sequence_dispatches_to_the_backend_with_its_step_rule(monkeypatch, body, skirt):
    # The one code path (pre-roll, collider, gate) hands the backend its own substep count.
    import loosefit.sim.blender
    import loosefit.sim.newton
    from loosefit.sim import simulate_sequence
    from loosefit.sim.collider import NEWTON_TRAVEL_PER_STEP, TRAVEL_PER_STEP
    from tests.sim.conftest import walk

    calls = {}

    def fake(name):
        def run_cloth(faces, pinned, garment_frames, collider, collider_faces, params, fps, workdir=None, floor=None):
            calls[name] = params.quality
            return garment_frames.copy(), np.full(len(garment_frames), 0.001)
        return run_cloth

    monkeypatch.setattr(loosefit.sim.newton, "run_cloth", fake("newton"))
    monkeypatch.setattr(loosefit.sim.blender, "run_cloth", fake("blender"))
    motion = walk(body, 20)
    for backend in ("blender", "newton"):
        params = SimParams(preroll=0.3, quality=1, backend=backend)
        result = simulate_sequence(skirt, body, motion, params)
        assert result.stats["quality"] == calls[backend]
    # Same body travel, so the step counts are in the ratio of the allowed travel per step (up to rounding).
    ratio = TRAVEL_PER_STEP / NEWTON_TRAVEL_PER_STEP
    assert calls["newton"] == pytest.approx(ratio * calls["blender"], abs=ratio + 1)
    assert calls["blender"] > 1
