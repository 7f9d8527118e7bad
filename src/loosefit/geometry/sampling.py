"""Furthest point sampling of mesh vertices (Euclidean or geodesic), as in SwinGar's spectral descriptor.

Start from one vertex (given, or drawn from ``seed``), then repeatedly add the vertex whose distance to
the already chosen set is largest. Each step updates the running minimum distance with the distances
from the newest sample only: ``O(k V)`` Euclidean, ``k`` Dijkstra runs for geodesic.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import dijkstra

from loosefit.errors import InputError
from loosefit.geometry.geodesic import edge_graph


def furthest_point_sampling(
    points: np.ndarray, count: int, faces: np.ndarray | None = None, start: int | None = None, seed: int = 0
) -> np.ndarray:
    """Indices ``(count,)`` int64 of ``count`` furthest-point samples of ``points (N, 3)``.

    Args:
        points: ``(N, 3)`` positions, metres.
        count: number of samples, ``1 <= count <= N``.
        faces: ``(F, 3)`` triangles: when given, distances are edge geodesics (Dijkstra on the mesh
            graph); otherwise Euclidean. Vertices unreachable from the samples (other components)
            count as infinitely far and are picked first.
        start: the first sample; ``None`` draws it uniformly with ``seed``.
        seed: random seed for the first sample.

    Returns:
        Distinct vertex indices in the order they were chosen.
    """
    points = np.asarray(points, np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or not np.isfinite(points).all():
        raise InputError(f"furthest point sampling needs finite points (N, 3), got shape {points.shape}")
    n = len(points)
    if int(count) != count or not 1 <= count <= n:
        raise InputError(f"sample count must be an integer in [1, {n}], got {count}")
    if start is None:
        start = int(np.random.default_rng(seed).integers(n))
    elif not 0 <= start < n:
        raise InputError(f"start vertex {start} outside [0, {n})")
    graph = edge_graph(points, faces) if faces is not None else None

    def dist_from(i: int) -> np.ndarray:
        if graph is None:
            return np.linalg.norm(points - points[i], axis=1)
        return dijkstra(graph, directed=False, indices=i)

    chosen = np.empty(int(count), dtype=np.int64)
    chosen[0] = start
    nearest = dist_from(start)
    for k in range(1, int(count)):
        nearest[chosen[:k]] = -1.0  # never pick a sample twice, even among coincident points
        chosen[k] = int(np.argmax(nearest))
        nearest = np.minimum(nearest, dist_from(chosen[k]))
    return chosen
