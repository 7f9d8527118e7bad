import dataclasses
import json

import numpy as np
import pytest

from loosefit.geometry.signed_distance import BodySDF
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.sim import SimParams, simulate_sequence
from loosefit.sim.sequence import save_result
from tests.sim.conftest import jump, walk

SHORT = SimParams(preroll=0.5)


def mean_dihedral(frames: np.ndarray, faces: np.ndarray) -> float:
    """Mean angle (degrees) between the normals of triangles sharing an edge, over all frames: a fold measure."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), 1)
    face = np.tile(np.arange(len(faces)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, face = edges[order], face[order]
    shared = (edges[1:] == edges[:-1]).all(1)
    a, b = face[:-1][shared], face[1:][shared]
    n = np.cross(frames[:, faces[:, 1]] - frames[:, faces[:, 0]], frames[:, faces[:, 2]] - frames[:, faces[:, 0]])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return float(np.degrees(np.arccos(np.clip((n[:, a] * n[:, b]).sum(-1), -1, 1))).mean())


def test_mean_dihedral_closed_form():
    verts = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1]]], np.float64)  # second triangle tilted up
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    n2 = np.cross([0, 1, 1], [-1, 1, 0])  # (v3 - v1) x (v2 - v1)
    expected = np.degrees(np.arccos(n2[2] / np.linalg.norm(n2)))
    assert mean_dihedral(verts, faces) == pytest.approx(expected)


@pytest.fixture(scope="module")
def walked(body, skirt):
    motion = walk(body, 30)
    return motion, simulate_sequence(skirt, body, motion, SHORT)


def test_skirt_on_a_walking_body(body, skirt, walked):
    motion, result = walked
    assert result.status == "ok", result.reason
    assert result.verts.shape == (30, len(skirt.verts), 3) and result.verts.dtype == np.float32
    assert np.isfinite(result.verts).all() and not result.stats["nan"]
    assert result.stats["penetration"] < 0.01 and result.stats["preroll_frames"] == 15
    assert result.stats["pinned_drift"] < 0.01
    assert result.stats["ms_per_frame"] > 0
    # Frame 0 is settled on the body: the cloth barely moves relative to the still-standing body.
    settle = np.linalg.norm(result.verts[1] - result.verts[0], axis=1).max()
    assert settle < 0.02
    # The hem swings: it moves, and while the body accelerates forward (-Y) it trails behind the hips.
    hem = result.verts[:, -32:]
    speed = np.linalg.norm(np.diff(hem, axis=0), axis=-1).mean() * 30
    assert speed > 0.1
    behind = hem[:, :, 1].mean(1) - motion.translation[:, 1]
    waist = result.verts[:, skirt.pinned, 1].mean(1) - motion.translation[:, 1]
    assert behind[8] - behind[0] > 0.01  # the hem lags by more than a centimetre...
    assert abs(waist[8] - waist[0]) < 0.005  # ...while the waistband moves with the body
    # The waistband stays on the body (exact distances on every fifth frame).
    for t in range(0, 30, 5):
        gap = np.abs(BodySDF(result.body_verts[t], body.faces).query(result.verts[t, skirt.pinned]))
        assert gap.max() < 0.02
        assert gap.max() <= result.stats["pinned_distance"] + 1e-6  # the stored statistic is an upper bound


def test_waistband_holds_on_a_jumping_body(body, skirt):
    motion = jump(body, 30)
    root = motion.translation[:, 2]
    pinned = simulate_sequence(skirt, body, motion, SHORT)
    free = simulate_sequence(dataclasses.replace(skirt, pinned=np.zeros_like(skirt.pinned)), body, motion, SHORT)
    assert pinned.status == "ok", pinned.reason
    waist = pinned.verts[:, :32, 2].mean(1) - root  # the waistband ring, relative to the hips
    below = pinned.verts[:, 32:64, 2].mean(1) - root  # the ring under it, not pinned
    assert np.ptp(waist) < 0.005 and np.ptp(below) < 0.01  # it does not slide down
    # Measured, not assumed: without the pins the same skirt slides down the jumping body.
    slid = waist - (free.verts[:, :32, 2].mean(1) - root)
    assert slid[0] > 0.05 and slid[-1] > slid[0] + 0.05


def test_stiffness_and_density_change_the_result_as_expected(body, skirt):
    motion = walk(body, 30)
    runs = {
        name: simulate_sequence(skirt, body, motion, SHORT.with_overrides(over)).verts
        for name, over in {"soft": {"bending": 1e-7}, "stiff": {"bending": 1e-4},
                           "light": {"density": 0.05}, "heavy": {"density": 0.4}}.items()
    }
    folds = {name: mean_dihedral(v, skirt.faces) for name, v in runs.items()}
    assert folds["stiff"] < folds["soft"] - 1.0  # degrees: fewer, smoother folds
    # gravity wins over the same bending stiffness: 15.8 against 15.0 degrees with the default damping
    # (bending damping 20/s smooths the folds of a walk; at 5/s the gap was larger)
    assert folds["heavy"] > folds["light"] + 0.5
    assert runs["heavy"][:, -32:, 2].mean() < runs["light"][:, -32:, 2].mean()  # and it hangs lower


def test_save_result(tmp_path, body, skirt, walked):
    motion, result = walked
    save_result(tmp_path / "seq.npz", result, skirt.faces, body.faces, motion.fps)
    seq = MeshSequence.load(tmp_path / "seq.npz")
    np.testing.assert_array_equal(seq.verts, result.verts)
    assert seq.extra["body_verts"].shape == (30, body.num_verts, 3)
    assert json.loads(str(seq.extra["stats"])) == result.stats and str(seq.extra["status"]) == "ok"
