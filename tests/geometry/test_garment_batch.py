"""GarmentBatch: padded <-> packed round trips, edge offsets against a brute-force union, splits, edge cases."""

import numpy as np
import pytest
import torch
import trimesh

from loosefit.errors import InputError
from loosefit.geometry.garment_batch import GarmentBatch, directed_edges
from loosefit.geometry.laplacian import edges as mesh_edges


def garments(sizes=(0, 1, 2)):
    """Icospheres of different subdivisions (12, 42, 162 vertices) with a random per-vertex feature each."""
    rng = np.random.default_rng(3)
    out = []
    for s in sizes:
        m = trimesh.creation.icosphere(s, radius=0.5)
        V = len(m.vertices)
        out.append({"verts": np.asarray(m.vertices, np.float32), "faces": np.asarray(m.faces, np.int64),
                    "normal": rng.normal(size=(V, 3)).astype(np.float32),
                    "weights": rng.random((V, 4, 2)).astype(np.float32)})
    return out


def batch_of(items, **kw):
    return GarmentBatch.from_list([g["verts"] for g in items], [g["faces"] for g in items],
                                  features={k: [g[k] for g in items] for k in ("normal", "weights")}, **kw)


def test_packed_padded_round_trip_is_exact_on_garments_of_different_sizes():
    items = garments()
    b = batch_of(items)
    assert b.num_verts.tolist() == [12, 42, 162] and b.max_verts == 162 and b.total_verts == 216
    padded, valid = b.features_padded("weights")
    assert padded.shape == (3, 162, 4, 2) and valid.shape == (3, 162)
    for i, g in enumerate(items):  # each garment's rows first, then zeros, marked by valid
        V = len(g["verts"])
        assert torch.equal(padded[i, :V], torch.from_numpy(g["weights"]))
        assert not padded[i, V:].any() and valid[i, :V].all() and not valid[i, V:].any()
    assert torch.equal(b.packed(padded), b.features["weights"])
    verts, _ = b.verts_padded()
    assert torch.equal(b.padded(b.packed(verts)), verts)
    assert torch.equal(b.padded(b.verts, fill=7.0)[0, 12:], torch.full((150, 3), 7.0))
    # from the padded form back to a batch: the same packed arrays, faces and edges
    again = GarmentBatch.from_padded(valid, verts, {"weights": padded}, faces=[g["faces"] for g in items])
    assert torch.equal(again.verts, b.verts) and torch.equal(again.features["weights"], b.features["weights"])
    assert torch.equal(again.faces, b.faces) and torch.equal(again.edge_index, b.edge_index)


def test_edge_index_and_faces_offsets_match_a_brute_force_disjoint_union():
    items = garments((1, 0, 1))
    b = batch_of(items)
    # brute force: rename every garment's vertices by a global dictionary, garment after garment
    name, faces, edges = {}, [], []
    for i, g in enumerate(items):
        for v in range(len(g["verts"])):
            name[(i, v)] = len(name)
        faces += [[name[(i, int(v))] for v in f] for f in g["faces"]]
        und = {tuple(sorted((int(f[a]), int(f[(a + 1) % 3])))) for f in g["faces"] for a in range(3)}
        edges += [(name[(i, s)], name[(i, t)]) for s, t in und] + [(name[(i, t)], name[(i, s)]) for s, t in und]
    assert b.faces.tolist() == faces
    assert sorted(map(tuple, b.edge_index.T.tolist())) == sorted(edges)
    assert b.num_edges.tolist() == [2 * len(mesh_edges(g["faces"])) for g in items]
    assert b.batch.tolist() == [i for i, g in enumerate(items) for _ in g["verts"]]
    assert b.vert_offsets.tolist() == [0, 42, 54]
    # edges given explicitly are shifted as they are (not recomputed)
    own = [np.array([[0, 1], [1, 0]]), np.array([[2], [0]]), np.zeros((2, 0), np.int64)]
    e = GarmentBatch.from_list([g["verts"] for g in items], edges=own).edge_index
    assert e.tolist() == [[0, 1, 44], [1, 0, 42]]


def test_directed_edges_are_both_directions_of_the_mesh_edges():
    faces = np.array([[0, 1, 2], [2, 1, 3]])
    e = directed_edges(faces)
    assert e.T.tolist() == [[0, 1], [0, 2], [1, 2], [1, 3], [2, 3], [1, 0], [2, 0], [2, 1], [3, 1], [3, 2]]


def test_split_lists_and_indexing_give_back_the_inputs():
    items = garments()
    b = batch_of(items)
    for name in ("normal", "weights"):
        for part, g in zip(b.split(b.features[name]), items):
            assert torch.equal(part, torch.from_numpy(g[name]))
    for f, e, v, g in zip(b.faces_list(), b.edges_list(), b.verts_list(), items):
        assert torch.equal(f, torch.from_numpy(g["faces"]))
        assert torch.equal(e, torch.from_numpy(directed_edges(g["faces"])))
        assert torch.equal(v, torch.from_numpy(g["verts"]))
    fp = b.faces_padded()
    assert fp.shape == (3, 320, 3) and (fp[0, 20:] == -1).all() and torch.equal(fp[1, :80], b.faces_list()[1])
    sub = b[[2, 0]]  # a sub-batch, renumbered from 0
    assert sub.num_verts.tolist() == [162, 12]
    assert torch.equal(sub.faces, torch.cat([torch.from_numpy(items[2]["faces"]),
                                             torch.from_numpy(items[0]["faces"]) + 162]))
    assert torch.equal(sub.features["normal"], torch.cat([torch.from_numpy(items[2]["normal"]),
                                                          torch.from_numpy(items[0]["normal"])]))
    assert torch.equal(b[1:].verts, b.verts[12:]) and torch.equal(b[-1].verts, b.verts[54:])
    assert torch.equal(b[torch.tensor([False, True, False])].edge_index, b[1].edge_index)
    assert [g.num_verts.item() for g in b.unbind()] == [12, 42, 162]
    per_garment = torch.tensor([10.0, 20.0, 30.0])
    assert b.gather_per_garment(per_garment).tolist() == [10.0] * 12 + [20.0] * 42 + [30.0] * 162
    with pytest.raises(IndexError):
        b[3]


def test_empty_and_single_garment_batches():
    empty = GarmentBatch.from_list([], [], features={"normal": []})
    assert len(empty) == 0 and empty.total_verts == 0 and empty.max_verts == 0
    assert empty.valid.shape == (0, 0) and empty.edge_index.shape == (2, 0) and empty.faces.shape == (0, 3)
    assert empty.batch.shape == (0,) and empty.split(torch.zeros(0, 3)) == []
    assert empty.padded(torch.zeros(0, 3)).shape == (0, 0, 3) and empty.packed(torch.zeros(0, 0, 3)).shape == (0, 3)
    (g,) = garments((0,))
    one = batch_of([g])
    padded, valid = one.verts_padded()
    assert torch.equal(padded[0], torch.from_numpy(g["verts"])) and bool(valid.all())
    assert torch.equal(one.packed(padded), one.verts)
    assert torch.equal(one.edge_index, torch.from_numpy(directed_edges(g["faces"])))
    assert one.batch.tolist() == [0] * 12
    counted = GarmentBatch.from_list(num_verts=[3, 1], edges=[np.array([[0], [2]]), np.zeros((2, 0), np.int64)])
    assert counted.valid.tolist() == [[True, True, True], [True, False, False]] and counted.features == {}


def test_bad_garments_raise_a_clear_input_error():
    a, b = garments((0, 1))
    with pytest.raises(InputError, match="garment 1: normal has 12 vertices, its verts has 42"):
        GarmentBatch.from_list([a["verts"], b["verts"]], features={"normal": [a["normal"], a["normal"]]})
    with pytest.raises(InputError, match="garment 'dress': faces name vertices"):
        GarmentBatch.from_list([a["verts"]], [b["faces"]], names=["dress"])
    with pytest.raises(InputError, match="garment 0: normal has a scalar, its verts has 12"):
        GarmentBatch.from_list([a["verts"]], features={"normal": [np.float32(1.0)]})
    with pytest.raises(InputError, match="lists of different lengths"):
        GarmentBatch.from_list([a["verts"], b["verts"]], [a["faces"]])
    with pytest.raises(InputError, match="garment 0: faces name vertices 0..41, the garment has 12"):
        GarmentBatch.from_list([a["verts"]], [b["faces"]])
    with pytest.raises(InputError, match=r"garment 0: edges must be \(2xn\)"):
        GarmentBatch.from_list([a["verts"]], edges=[np.zeros((3, 2), np.int64)])
    with pytest.raises(InputError, match="num_verts"):
        GarmentBatch.from_list([a["verts"]], num_verts=[5])
    batch = batch_of([a, b])
    with pytest.raises(InputError, match="must have 54 rows"):
        batch.padded(torch.zeros(53, 3))
    with pytest.raises(InputError, match=r"must be \(2, >= 42"):
        batch.packed(torch.zeros(2, 41, 3))
    with pytest.raises(InputError, match="first rows"):
        GarmentBatch.from_padded(torch.tensor([[False, True]]), torch.zeros(1, 2, 3))


def test_to_moves_every_tensor_and_keeps_the_topology():
    b = batch_of(garments((0, 0)))
    moved = b.to("cpu")
    assert moved.same_topology(b) and torch.equal(moved.features["normal"], b.features["normal"])
    other = batch_of(garments((0, 1)))
    assert not other.same_topology(b)
    if torch.cuda.is_available():
        gpu = b.to("cuda")
        assert gpu.batch.device.type == "cuda" and torch.equal(gpu.padded(gpu.verts).cpu(), b.padded(b.verts))
