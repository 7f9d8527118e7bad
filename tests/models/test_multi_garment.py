"""GarmentGraph: its garment as a GarmentBatch, the tensors built from it, and a clear error on a bad garment."""

import numpy as np
import pytest
import torch
import trimesh

from loosefit.errors import InputError
from loosefit.geometry.laplacian import edges
from loosefit.models.multi_garment import GarmentGraph


def graph(fit_count=None):
    m = trimesh.creation.icosphere(1, radius=0.4)
    V = len(m.vertices)
    rng = np.random.default_rng(5)
    return GarmentGraph("sphere", np.asarray(m.vertices, np.float32), np.asarray(m.faces, np.int64),
                        rng.normal(size=(V, 3)).astype(np.float32), rng.random(fit_count or V).astype(np.float32),
                        rng.random(8).astype(np.float32), rng.random(V).astype(np.float32),
                        rng.random(6).astype(np.float32), rng.random((4, 3)).astype(np.float32),
                        rng.random((V, 4)).astype(np.float32))


def test_tensors_are_the_garments_arrays_and_its_unique_edges():
    g = graph()
    t = g.tensors()
    for key in ("rest", "faces", "normals", "fit", "mass", "skin_prior", "descriptor", "body_shape", "rest_joints"):
        assert torch.equal(t[key], torch.from_numpy(getattr(g, key))), key
    assert torch.equal(t["edges"], torch.from_numpy(edges(g.faces)))  # each undirected edge once, i < j
    garment = g.garment()
    assert len(garment) == 1 and garment.num_verts.tolist() == [42] and garment.edge_index.shape == (2, 2 * 120)


def test_a_per_vertex_array_of_another_length_names_the_garment():
    with pytest.raises(InputError, match="garment 'sphere': fit has 41 vertices, its verts has 42"):
        graph(fit_count=41).tensors()
