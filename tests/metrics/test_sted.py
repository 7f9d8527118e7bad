"""STED against a loop-based reference, hand-computed values and its invariances."""

from collections import deque

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from loosefit.errors import InputError
from loosefit.metrics.sted import combine, sted, sted_spatial_per_frame, sted_temporal


def reference_spatial(pred, gt, faces, rings):
    """Direct transcription of the definition: BFS neighbourhoods and weighted deviations, with loops."""
    V = gt.shape[1]
    nbrs = [set() for _ in range(V)]
    edge_set = set()
    for f in faces:
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            nbrs[a].add(b)
            nbrs[b].add(a)
            edge_set.add((min(a, b), max(a, b)))
    per_frame = []
    for t in range(len(gt)):
        devs = []
        for v in range(V):
            depth = {v: 0}
            queue = deque([v])
            while queue:
                u = queue.popleft()
                if depth[u] < rings:
                    for w in nbrs[u]:
                        if w not in depth:
                            depth[w] = depth[u] + 1
                            queue.append(w)
            hood = [(a, b) for a, b in edge_set if a in depth and b in depth]
            lengths = np.array([np.linalg.norm(gt[t, a] - gt[t, b]) for a, b in hood])
            ed = np.array([abs(np.linalg.norm(pred[t, a] - pred[t, b]) - l) / l for (a, b), l in zip(hood, lengths)])
            avg = (lengths * ed).sum() / lengths.sum()
            devs.append(np.sqrt((lengths * (ed - avg) ** 2).sum() / lengths.sum()))
        per_frame.append(np.mean(devs))
    return np.array(per_frame)


def sphere_sequence(T=3, seed=0, noise=0.01):
    m = trimesh.creation.icosphere(1, radius=0.5)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    rng = np.random.default_rng(seed)
    gt = v[None] + np.linspace(0, 0.2, T)[:, None, None] * np.array([1.0, 0.5, 0.0])
    return gt + rng.normal(0, 0.02, gt.shape), gt + rng.normal(0, noise, gt.shape), f


@pytest.mark.parametrize("rings", [1, 2])
def test_spatial_part_matches_loop_reference(rings):
    gt, pred, faces = sphere_sequence()
    got = sted_spatial_per_frame(pred, gt, faces, rings)
    assert np.abs(got - reference_spatial(pred, gt, faces, rings)).max() < 1e-12


def test_hand_computed_right_triangle():
    gt = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=np.float64)
    pred = gt.copy()
    pred[0, 1, 0] = 1.1  # edges 01: 1 -> 1.1, 12: sqrt(2) -> sqrt(2.21), 02 unchanged
    l = np.array([1.0, np.sqrt(2), 1.0])
    ed = np.array([0.1, (np.sqrt(2.21) - np.sqrt(2)) / np.sqrt(2), 0.0])
    avg = (l * ed).sum() / l.sum()
    dev = np.sqrt((l * (ed - avg) ** 2).sum() / l.sum())  # every vertex sees all three edges
    assert dev == pytest.approx(0.038272, abs=1e-6)
    assert sted_spatial_per_frame(pred, gt, [[0, 1, 2]])[0] == pytest.approx(dev, rel=1e-12)


def test_rigid_motion_of_the_whole_sequence_scores_zero():
    gt, _, faces = sphere_sequence(T=5)
    R = Rotation.from_rotvec([0.3, -1.1, 0.7]).as_matrix()
    pred = gt @ R.T + [2.0, -1.0, 0.5]
    result = sted(pred, gt, faces)
    assert result.spatial < 1e-7 and result.temporal < 1e-7 and result.combined < 1e-7


def test_uniform_scaling_costs_only_in_time():
    gt, _, faces = sphere_sequence(T=4)
    s, dt, c = 1.2, 0.3, 0.5
    result = sted(s * gt, gt, faces, dt=dt, c=c)
    assert result.spatial < 1e-9  # every edge stretched alike: no local deviation
    step = np.linalg.norm(gt[1:] - gt[:-1], axis=-1) / np.linalg.norm(gt[0].max(0) - gt[0].min(0))
    ted = (np.sqrt(dt**2 + (s * step) ** 2) - np.sqrt(dt**2 + step**2)) / np.sqrt(dt**2 + step**2)
    assert result.temporal == pytest.approx(ted.mean(), rel=1e-9)
    assert result.combined == pytest.approx(c * ted.mean(), rel=1e-9)


def test_temporal_part_of_a_jittering_vertex():
    gt = np.zeros((3, 3, 3))
    gt[:, 1, 0] = 1.0
    gt[:, 2, 1] = 1.0  # a still triangle, bounding-box diagonal sqrt(2)
    pred = gt.copy()
    pred[1, 0, 2] = 0.1  # vertex 0 jumps up in frame 1 and back
    dt = 0.3
    one = np.sqrt(dt**2 + (0.1 / np.sqrt(2)) ** 2) / dt - 1  # relative length change of each of its 2 moves
    assert sted_temporal(pred, gt, dt) == pytest.approx(2 * one / 6, rel=1e-12)  # 2 of 2x3 temporal edges
    assert combine(0.3, 0.8, 0.5) == pytest.approx(0.5)


def test_invalid_inputs():
    gt, pred, faces = sphere_sequence(T=1)
    with pytest.raises(InputError, match="2 frames"):
        sted(pred, gt, faces)
    with pytest.raises(InputError, match="rings"):
        sted_spatial_per_frame(pred, gt, faces, rings=0)
    with pytest.raises(InputError, match="shape"):
        sted_spatial_per_frame(pred[:, :5], gt, faces)
