"""Training data of many garments for the multi-garment method (SwinGar).

A store garment (``skirt-0+average``...) is one garment fitted to one body shape. Everything a
multi-garment network needs of it at rest is a :class:`GarmentGraph`: rest mesh, vertex normals, the
per-vertex fit to the body, the spectral descriptor, vertex masses, the body shape and the body's rest
joints. :class:`MultiGarmentData` loads every garment of a split (its sequences through
:class:`~loosefit.models.dataset.GarmentSequences`, canonical as there), and :class:`MultiWindowDataset`
cuts all sequences into windows that carry the motion history before their first frame, so a window
is predicted exactly as the same frames of a whole sequence (no burn-in).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch.utils.data import Dataset

from loosefit.body import AnnyBody, AnnyShape
from loosefit.body.base import BodyModel
from loosefit.data.store import DatasetStore
from loosefit.errors import InputError
from loosefit.geometry.garment_batch import GarmentBatch
from loosefit.geometry.laplacian import mass_matrix
from loosefit.geometry.normals import vertex_normals
from loosefit.models.dataset import STD_FLOOR, GarmentSequences
from loosefit.models.layers.gat_ln import attention_table
from loosefit.rig.fit_attribute import body_distances
from loosefit.rig.spectral import check_distance, spectral_descriptor
from loosefit.sim.attach import garment_weights

#: The per-vertex arrays of a :class:`GarmentGraph` (besides its rest positions).
VERTEX_KEYS = ("normals", "fit", "mass", "skin_prior")
#: Areal density of the garment fabric, kg/m^2, for the gravity term (silk-like; not in the paper).
DEFAULT_DENSITY = 0.1


def face_pairs(faces: np.ndarray) -> np.ndarray:
    """``(P, 2)`` int64 pairs of faces sharing an edge (the dual graph of the mesh)."""
    faces = np.asarray(faces, np.int64)
    e = np.sort(np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], 1).reshape(-1, 2), 1)
    owner = np.repeat(np.arange(len(faces)), 3)
    order = np.lexsort((e[:, 1], e[:, 0]))
    e, owner = e[order], owner[order]
    same = (e[1:] == e[:-1]).all(1)
    return np.stack([owner[:-1][same], owner[1:][same]], 1).astype(np.int64)


@dataclass
class GarmentGraph:
    """One garment on one body, at rest. Shapes for ``V`` vertices, ``J`` joints, ``S`` shape values.

    Attributes:
        name: label (the store garment name).
        rest ``(V, 3)``: rest positions, metres (the body's rest frame, soles on z = 0).
        faces ``(F, 3)`` int64. normals ``(V, 3)``: unit vertex normals at rest.
        fit ``(V,)``: distance from each vertex to the closest body vertex at rest, metres (the fit attribute
            ``a_i`` of SwinGar Sec. III-C, see :mod:`loosefit.models.swingar`).
        descriptor ``(z,)``: spectral descriptor (:func:`loosefit.rig.spectral.spectral_descriptor`) with the
            distance the model asks for; ``(0,)`` for a model without one (SwinGar's ``none`` and ``pooling``).
        mass ``(V,)``: vertex masses, kg (lumped Voronoi area times the fabric density).
        body_shape ``(S,)``: the body's shape values. rest_joints ``(J, 3)``: its rest joint positions, metres.
        skin_prior ``(V, J)``: the skinning weights of each vertex's nearest rest body vertex (body-LBS,
            :func:`loosefit.sim.attach.garment_weights`), which :class:`~loosefit.models.swingar.SwinGar` may
            start its dynamic weights from (``skinning_prior``).
        descriptor_distance: the distance ``descriptor`` was computed with (``"geodesic"``, ``"euclidean"``), or
            None when there is none.
    """

    name: str
    rest: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    fit: np.ndarray
    descriptor: np.ndarray
    mass: np.ndarray
    body_shape: np.ndarray
    rest_joints: np.ndarray
    skin_prior: np.ndarray
    descriptor_distance: str | None = "geodesic"

    @property
    def num_verts(self) -> int:
        return len(self.rest)

    def garment(self) -> GarmentBatch:
        """The garment as a one-garment :class:`~loosefit.geometry.garment_batch.GarmentBatch`: ``rest``, ``faces``,
        its mesh edges both ways and the per-vertex features ``normals``, ``fit``, ``mass``, ``skin_prior`` (an
        :class:`InputError` when they disagree on the vertex count or a face names a vertex it does not have)."""
        return GarmentBatch.from_list([self.rest], [self.faces], features={k: [getattr(self, k)] for k in VERTEX_KEYS},
                                      names=[self.name])

    def tensors(self) -> dict[str, torch.Tensor]:
        """The graph as tensors (those of :meth:`garment`, then the per-garment ``descriptor``, ``body_shape`` and
        ``rest_joints``), with the attention table (``table``, ``valid`` ``(V, D)``: each vertex's neighbourhood),
        the mesh ``edges (E, 2)`` (each undirected edge once, ``i < j``) and the ``face_pairs (P, 2)`` the losses
        use."""
        garment = self.garment()
        table, valid = attention_table(self.faces, self.num_verts)
        out = {"rest": garment.verts, "faces": garment.faces, **garment.features}
        out.update({k: torch.from_numpy(np.ascontiguousarray(getattr(self, k)))
                    for k in ("descriptor", "body_shape", "rest_joints")})
        # directed_edges lists each undirected edge (i < j, sorted) first, then the same edges reversed
        undirected = garment.edge_index[:, : garment.edge_index.shape[1] // 2]
        out.update(table=torch.from_numpy(table), valid=torch.from_numpy(valid), edges=undirected.T.contiguous(),
                   face_pairs=torch.from_numpy(face_pairs(self.faces)))
        return out


def garment_graph(name: str, verts: np.ndarray, faces: np.ndarray, body: BodyModel, body_shape: np.ndarray,
                  descriptor_samples: int, density: float = DEFAULT_DENSITY,
                  descriptor_distance: str | None = "geodesic") -> GarmentGraph:
    """Build the :class:`GarmentGraph` of a rest garment ``verts (V, 3)``, ``faces (F, 3)`` on ``body`` (posed in
    its own shape; ``body_shape (S,)`` its shape values as the network sees them).

    ``descriptor_distance``: the distance of the spectral descriptor's affinity, ``"geodesic"`` or
    ``"euclidean"`` (:func:`loosefit.rig.spectral.spectral_descriptor`), or None for no descriptor (an empty
    vector; the vertex count then need not reach ``descriptor_samples``). A model reads it from its config
    (:meth:`loosefit.models.swingar.SwinGarConfig.graph_settings`), in training and animation alike."""
    verts = np.asarray(verts, np.float32)
    faces = np.asarray(faces, np.int64)
    if not density > 0:
        raise InputError(f"fabric density must be positive, got {density}")
    if descriptor_distance is None:
        descriptor = np.zeros(0, np.float32)
    else:
        check_distance(descriptor_distance)
        if len(verts) < descriptor_samples:
            raise InputError(f"garment {name!r} has {len(verts)} vertices, fewer than the spectral descriptor's "
                             f"{descriptor_samples} samples: lower model.descriptor_samples")
        descriptor = spectral_descriptor(verts, faces, descriptor_samples, distance=descriptor_distance)
    mass = np.asarray(mass_matrix(verts, faces).diagonal(), np.float32) * density
    return GarmentGraph(name, verts, faces, vertex_normals(verts[None], faces)[0].astype(np.float32),
                        body_distances(verts, body.rest_verts()), descriptor,
                        mass, np.asarray(body_shape, np.float32), body.rest_joints().astype(np.float32),
                        np.asarray(garment_weights(verts, body), np.float32), descriptor_distance)


class MultiGarmentData:
    """Every garment of a split of a store, with its sequences (canonical, as :class:`GarmentSequences`).

    Args:
        store: a :class:`DatasetStore` or its path.
        split: ``"train"``, ``"val"``, ``"test"`` or None (all).
        garments: store garment names to use (None: every garment with sequences in the split).
        descriptor_samples: ``z`` of the spectral descriptor. density: fabric density, kg/m^2.
        body: load the canonical collision proxy of the posed body (for the collision loss).
        descriptor_distance: the descriptor's distance, ``"geodesic"``, ``"euclidean"`` or None (no
            descriptor), as :func:`garment_graph` takes it.
    """

    def __init__(self, store, split: str | None = "train", garments: list[str] | None = None,
                 descriptor_samples: int = 256, density: float = DEFAULT_DENSITY, body: bool = True,
                 descriptor_distance: str | None = "geodesic"):
        self.store = store if isinstance(store, DatasetStore) else DatasetStore.open(store, mode="r")
        names = self.store.garment_names() if garments is None else list(garments)
        unknown = sorted(set(names) - set(self.store.garment_names()))
        if unknown:
            raise InputError(f"no garments {unknown} in the store (has {self.store.garment_names()})", self.store.path)
        in_split = {self.store.sequence(n).garment for n in self.store.sequence_names(split=split)}
        names = [g for g in names if g in in_split]
        if not names:
            raise InputError(f"no {split or 'usable'} sequences of the garments asked for", self.store.path)
        self.sequences: list[GarmentSequences] = []
        self.graphs: list[GarmentGraph] = []
        for g in names:
            data = GarmentSequences(self.store, g, split, bones=False, body=body, history=None)
            bodies = {s.body_name for s in data.sequences}
            if len(bodies) != 1:
                raise InputError(f"garment {g!r} is simulated on several bodies {sorted(bodies)}", self.store.path)
            values = np.asarray(self.store.body(bodies.pop()), np.float32)
            proxy = AnnyBody(AnnyShape.from_array(values), resolution="low")
            garment = data.garment
            self.graphs.append(garment_graph(g, garment.verts, garment.faces, proxy, values, descriptor_samples, density,
                                             descriptor_distance))
            self.sequences.append(data)

    @property
    def num_joints(self) -> int:
        return int(self.sequences[0].sequences[0].joints.shape[1] + 1)

    def feature_stats(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Mean and floored std of ``root (11,)``, ``joints (J-1, 6)`` over every frame of every garment."""
        out = {}
        for key in ("root", "joints"):
            x = np.concatenate([getattr(s, key) for d in self.sequences for s in d.sequences]).astype(np.float64)
            out[key] = (x.mean(0).astype(np.float32), np.maximum(x.std(0), STD_FLOOR[key]).astype(np.float32))
        return out


def history_frames(x: np.ndarray, start: int, count: int) -> np.ndarray:
    """The ``count`` frames of ``x (T, ...)`` before frame ``start``; frames before 0 repeat frame 0 (the body
    stood in its first pose before the motion began)."""
    idx = np.clip(np.arange(start - count, start), 0, None)
    return x[idx]


class MultiWindowDataset(Dataset):
    """Windows of ``window`` frames every ``stride`` frames over all sequences of all garments.

    Each item: ``root (w, 11)``, ``joints (w, J-1, 6)``, ``verts (w, V, 3)``, optional ``body (w, Vb, 3)``,
    ``body_normals``, ``body_nearest (w, V)``; ``history_root (h, 11)`` and ``history_joints (h, J-1, 6)``,
    the ``h`` frames before the window (:func:`history_frames`); ``graph`` (index into ``data.graphs``),
    ``graph_tensors`` (:meth:`GarmentGraph.tensors`, shared by the items of a garment), ``burn_in`` 0,
    ``sequence``, ``start``.
    """

    def __init__(self, data: MultiGarmentData, window: int, stride: int, history: int):
        if window < 1 or stride < 1 or history < 0:
            raise InputError(f"window and stride must be >= 1 and history >= 0, got {window}, {stride}, {history}")
        self.data, self.window, self.history = data, window, history
        self.graph_tensors = [g.tensors() for g in data.graphs]
        self.index = []
        for gi, seqs in enumerate(data.sequences):
            for si, s in enumerate(seqs.sequences):
                starts = list(range(0, max(s.num_frames - window, 0) + 1, stride))
                if starts[-1] + window < s.num_frames:
                    starts.append(s.num_frames - window)
                self.index += [(gi, si, a) for a in starts]

    def __len__(self) -> int:
        return len(self.index)

    def __getitem__(self, k: int) -> dict:
        gi, si, a = self.index[k]
        s = self.data.sequences[gi].sequences[si]
        b = min(a + self.window, s.num_frames)
        item = {"graph": gi, "sequence": si, "start": a, "burn_in": 0, "graph_tensors": self.graph_tensors[gi],
                "history_root": torch.from_numpy(history_frames(s.root, a, self.history)),
                "history_joints": torch.from_numpy(history_frames(s.joints, a, self.history))}
        for key in ("root", "joints", "verts", "body", "body_normals", "body_nearest"):
            value = getattr(s, key)
            if value is not None:
                item[key] = torch.from_numpy(np.ascontiguousarray(value[a:b]))
        return item


def collate_by_graph(items: list[dict]) -> list[dict]:
    """Group items by garment (``graph``) and stack each group's tensors (windows of one length per group,
    as a dataset's ``window`` makes them; shorter end windows get a group of their own)."""
    groups: dict[tuple, list[dict]] = {}
    for item in items:
        groups.setdefault((item["graph"], item["root"].shape[0]), []).append(item)
    out = []
    for (gi, _), group in groups.items():
        batch = {"graph": gi, "graph_tensors": group[0]["graph_tensors"]}
        for key in group[0]:
            if key in ("graph", "graph_tensors"):
                continue
            values = [it[key] for it in group]
            batch[key] = torch.stack(values) if isinstance(values[0], torch.Tensor) else torch.tensor(values)
        out.append(batch)
    return out
