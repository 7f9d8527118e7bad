"""A batch of garment meshes of different vertex counts, in packed and padded form.

Garments travel through the models in two layouts, and this module is the one place that converts between them:

- **packed**: every garment's rows one after the other, ``(N, D)`` with ``N = sum_i V_i``; ``batch (N,)`` names each
  row's garment, the mesh ``faces (sum F_i, 3)`` and the graph ``edge_index (2, sum E_i)`` are shifted into that
  numbering (garment ``i``'s vertex ``v`` is row ``vert_offsets[i] + v``). Graph layers (PyG's ``GATConv``,
  FitGar's generators) read this disjoint union of graphs.
- **padded**: ``(B, Vmax, D)`` with ``valid (B, Vmax)`` bool, True on a garment's own ``V_i`` rows (the first ones);
  the rows after them are filler. A model's dense outputs ``(B, V, ...)`` over frames of one garment are this form
  without filler.

A :class:`GarmentBatch` holds the packed form (tensors; the padded one is computed on demand) of: rest vertices
``verts (N, 3)`` metres (optional: frames of a garment carry per-vertex features instead), faces, directed edges
(``source -> target`` columns, as PyG), and named per-vertex ``features`` ``(N, ...)`` of any trailing shape.
Conversions (:meth:`GarmentBatch.padded`, :meth:`GarmentBatch.packed`, :meth:`GarmentBatch.split`), per-garment
lists, indexing (a sub-batch renumbered from 0) and :meth:`GarmentBatch.to` are methods of the class.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import torch

from loosefit.errors import InputError
from loosefit.geometry.laplacian import edges as mesh_edges


def directed_edges(faces: np.ndarray) -> np.ndarray:
    """``(2, E)`` int64 directed edges of a triangle mesh ``faces (F, 3)``: each undirected edge ``(i, j)``,
    ``i < j``, sorted, then the same edges reversed (both directions, as a graph layer reads a mesh)."""
    e = mesh_edges(np.asarray(faces, np.int64).reshape(-1, 3))
    return np.ascontiguousarray(np.concatenate([e, e[:, ::-1]]).T)


def _tensor(x, dtype: torch.dtype | None = None) -> torch.Tensor:
    t = x if isinstance(x, torch.Tensor) else torch.from_numpy(np.ascontiguousarray(x))
    return t if dtype is None else t.to(dtype)


def _offsets(counts: torch.Tensor) -> torch.Tensor:
    """``(B,)`` first packed row of each of ``counts (B,)`` runs."""
    return torch.cumsum(counts, 0) - counts


class GarmentBatch:
    """``B`` garments of ``V_i`` vertices, ``F_i`` faces and ``E_i`` directed edges each (see the module doc).

    Build one with :meth:`from_list` (per-garment arrays) or :meth:`from_padded`; the constructor takes the packed
    form as it is stored. Shapes (``N = sum V_i``, ``F = sum F_i``, ``E = sum E_i``):

    Attributes:
        num_verts ``(B,)`` int64: ``V_i``. num_faces ``(B,)``, num_edges ``(B,)`` int64: ``F_i``, ``E_i``.
        verts ``(N, 3)`` float: rest vertices, metres, or None.
        faces ``(F, 3)`` int64, in the packed numbering. edge_index ``(2, E)`` int64, in the packed numbering.
        features: name -> ``(N, ...)`` per-vertex tensor.
    """

    def __init__(self, num_verts: torch.Tensor, verts: torch.Tensor | None = None, faces: torch.Tensor | None = None,
                 num_faces: torch.Tensor | None = None, edge_index: torch.Tensor | None = None,
                 num_edges: torch.Tensor | None = None, features: Mapping[str, torch.Tensor] | None = None):
        self.num_verts = _tensor(num_verts, torch.int64).reshape(-1)
        B, device = len(self.num_verts), self.num_verts.device
        self.verts = verts
        self.faces = faces if faces is not None else torch.zeros(0, 3, dtype=torch.int64, device=device)
        self.num_faces = num_faces if num_faces is not None else torch.zeros(B, dtype=torch.int64, device=device)
        self.edge_index = edge_index if edge_index is not None else torch.zeros(2, 0, dtype=torch.int64, device=device)
        self.num_edges = num_edges if num_edges is not None else torch.zeros(B, dtype=torch.int64, device=device)
        self.features = dict(features or {})
        self._batch: torch.Tensor | None = None

    # ------------------------------------------------------------------ building

    @classmethod
    def from_list(cls, verts: Sequence | None = None, faces: Sequence | None = None, edges: Sequence | None = None,
                  features: Mapping[str, Sequence] | None = None, feature_dtype: torch.dtype | None = None,
                  num_verts: Sequence[int] | None = None, names: Sequence[str] | None = None) -> "GarmentBatch":
        """The batch of per-garment arrays (numpy or torch), each list one entry per garment:

        Args:
            verts: ``V_i x 3`` rest vertices, metres; None: no rest vertices (the counts come from ``features``).
            faces: ``F_i x 3`` int faces in the garment's own numbering; None: no faces.
            edges: ``2 x E_i`` int directed edges (row 0 sources, row 1 targets) in the garment's own numbering;
                None: :func:`directed_edges` of the faces (no edges without faces).
            features: name -> ``V_i x ...`` per-vertex arrays.
            feature_dtype: cast ``verts`` and the features to this dtype (None: keep theirs).
            num_verts: ``V_i`` of each garment, for a batch of neither rest vertices nor features (else checked).
            names: garment names the errors quote (default: their positions in the lists).

        Raises:
            InputError: lists of different lengths, a garment whose arrays disagree on its vertex count, faces
                or edges of the wrong shape or naming a vertex the garment does not have.
        """
        features = dict(features or {})

        def label(i: int) -> str:
            return str(i) if names is None else repr(names[i])

        lengths = {name: len(v) for name, v in [("verts", verts), ("faces", faces), ("edges", edges),
                                                 ("num_verts", num_verts), ("names", names), *features.items()]
                   if v is not None}
        if len(set(lengths.values())) > 1:
            raise InputError(f"garment lists of different lengths: {lengths}")
        B = next(iter(lengths.values()), 0)
        if verts is None and not features and num_verts is None:
            raise InputError("a garment batch needs rest vertices, a per-vertex feature or num_verts to count the "
                             "vertices")
        first = "verts" if verts is not None else next(iter(features), "num_verts")
        sizes = ([len(x) if np.ndim(x) else 0 for x in (verts if verts is not None else features[first])]
                 if first != "num_verts" else [int(V) for V in num_verts])
        arrays_of = ([("verts", verts)] if verts is not None else []) + list(features.items())
        if num_verts is not None and [int(V) for V in num_verts] != sizes:
            raise InputError(f"num_verts {[int(V) for V in num_verts]} disagree with the garments' {first} ({sizes})")
        for name, arrays in arrays_of:
            for i, (x, V) in enumerate(zip(arrays, sizes)):
                if np.ndim(x) == 0 or len(x) != V:
                    got = "a scalar" if np.ndim(x) == 0 else f"{len(x)} vertices"
                    raise InputError(f"garment {label(i)}: {name} has {got}, its {first} has {V}")
                if name == "verts" and tuple(np.shape(x)[1:]) != (3,):
                    raise InputError(f"garment {label(i)}: verts must be (V, 3), got {tuple(np.shape(x))}")
        num_verts = torch.tensor(sizes, dtype=torch.int64).reshape(B)
        offsets = _offsets(num_verts)
        if edges is None and faces is not None:
            edges = [directed_edges(_tensor(f).cpu().numpy()) for f in faces]
        num_faces = num_edges = None
        packed_faces = packed_edges = None
        if faces is not None:
            parts = [_check_indices(_tensor(f, torch.int64), (-1, 3), V, f"garment {label(i)}: faces")
                     for i, (f, V) in enumerate(zip(faces, sizes))]
            num_faces = torch.tensor([len(f) for f in parts], dtype=torch.int64).reshape(B)
            packed_faces = torch.cat([f + int(s) for f, s in zip(parts, offsets)]) if parts else None
        if edges is not None:
            parts = [_check_indices(_tensor(e, torch.int64), (2, -1), V, f"garment {label(i)}: edges")
                     for i, (e, V) in enumerate(zip(edges, sizes))]
            num_edges = torch.tensor([e.shape[1] for e in parts], dtype=torch.int64).reshape(B)
            packed_edges = torch.cat([e + int(s) for e, s in zip(parts, offsets)], 1) if parts else None

        def cat(arrays):
            parts = [_tensor(x, feature_dtype) for x in arrays]
            return torch.cat(parts) if parts else None

        packed = {name: cat(arrays) for name, arrays in features.items()}
        return cls(num_verts, None if verts is None else cat(verts), packed_faces, num_faces, packed_edges, num_edges,
                   {k: v for k, v in packed.items() if v is not None})

    @classmethod
    def from_padded(cls, valid: torch.Tensor, verts: torch.Tensor | None = None,
                    features: Mapping[str, torch.Tensor] | None = None, faces: Sequence | None = None,
                    edges: Sequence | None = None) -> "GarmentBatch":
        """The batch of padded per-vertex arrays ``(B, Vmax, ...)`` whose garments hold the rows ``valid (B, Vmax)``
        marks (the first ``V_i`` of each: a garment's rows come first); ``faces``/``edges``: as :meth:`from_list`."""
        valid = _tensor(valid, torch.bool)
        if valid.dim() != 2:
            raise InputError(f"valid must be (B, Vmax), got {tuple(valid.shape)}")
        counts = valid.sum(1)
        if not bool((torch.arange(valid.shape[1], device=valid.device)[None] < counts[:, None]).eq(valid).all()):
            raise InputError("valid must mark the first rows of each garment (a garment's vertices come first)")
        features = dict(features or {})
        for name, x in [("verts", verts), *features.items()]:
            if x is not None and (x.dim() < 2 or tuple(x.shape[:2]) != tuple(valid.shape)):
                raise InputError(f"padded {name} must be {tuple(valid.shape)} + (...), got {tuple(x.shape)}")
        lists = {name: [x[i, :int(V)] for i, V in enumerate(counts)] for name, x in features.items()}
        vlist = None if verts is None else [v[:int(V)] for v, V in zip(verts, counts)]
        return cls.from_list(vlist, faces, edges, lists, num_verts=counts.tolist())

    # ------------------------------------------------------------------ sizes and indices

    def __len__(self) -> int:
        return len(self.num_verts)

    @property
    def num_garments(self) -> int:
        return len(self.num_verts)

    @property
    def total_verts(self) -> int:
        """``N = sum V_i``."""
        return int(self.num_verts.sum()) if len(self) else 0

    @property
    def max_verts(self) -> int:
        """``Vmax = max V_i`` (0 for an empty batch)."""
        return int(self.num_verts.max()) if len(self) else 0

    @property
    def device(self) -> torch.device:
        return self.num_verts.device

    @property
    def vert_offsets(self) -> torch.Tensor:
        """``(B,)`` int64 packed row of each garment's vertex 0."""
        return _offsets(self.num_verts)

    @property
    def batch(self) -> torch.Tensor:
        """``(N,)`` int64: the garment of each packed row (PyG's ``batch`` vector)."""
        if self._batch is None or self._batch.device != self.device:
            self._batch = torch.repeat_interleave(torch.arange(len(self), device=self.device), self.num_verts)
        return self._batch

    @property
    def valid(self) -> torch.Tensor:
        """``(B, Vmax)`` bool: True on each garment's own rows of the padded form."""
        return torch.arange(self.max_verts, device=self.device)[None] < self.num_verts[:, None]

    def slot(self) -> torch.Tensor:
        """``(N,)`` int64: each packed row's vertex number within its garment (its column of the padded form)."""
        return torch.arange(self.total_verts, device=self.device) - self.vert_offsets[self.batch]

    # ------------------------------------------------------------------ conversions

    def padded(self, x: torch.Tensor, fill: float = 0.0) -> torch.Tensor:
        """Packed per-vertex ``x (N, ...)`` -> padded ``(B, Vmax, ...)``, rows past a garment's own ``fill``."""
        self._check_packed(x)
        out = x.new_full((len(self), self.max_verts, *x.shape[1:]), fill)
        out[self.batch, self.slot()] = x
        return out

    def packed(self, x: torch.Tensor) -> torch.Tensor:
        """Padded per-vertex ``x (B, Vmax, ...)`` (or wider: ``(B, V >= Vmax, ...)``) -> packed ``(N, ...)``; the
        filler rows are dropped."""
        if x.dim() < 2 or x.shape[0] != len(self) or x.shape[1] < self.max_verts:
            raise InputError(f"a padded array of this batch must be ({len(self)}, >= {self.max_verts}, ...), "
                             f"got {tuple(x.shape)}")
        return x[self.batch, self.slot()]

    def split(self, x: torch.Tensor) -> list[torch.Tensor]:
        """Packed per-vertex ``x (N, ...)`` -> one ``(V_i, ...)`` view per garment."""
        self._check_packed(x)
        return list(x.split(self.num_verts.tolist()))

    def gather_per_garment(self, x: torch.Tensor) -> torch.Tensor:
        """Per-garment ``x (B, ...)`` -> ``(N, ...)``: each vertex gets its garment's row."""
        if x.shape[0] != len(self):
            raise InputError(f"a per-garment array of this batch must have {len(self)} rows, got {tuple(x.shape)}")
        return x[self.batch]

    def verts_padded(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Rest vertices ``(B, Vmax, 3)`` metres (zeros past each garment) and ``valid (B, Vmax)``."""
        if self.verts is None:
            raise InputError("this garment batch holds no rest vertices")
        return self.padded(self.verts), self.valid

    def features_padded(self, name: str, fill: float = 0.0) -> tuple[torch.Tensor, torch.Tensor]:
        """Feature ``name`` padded ``(B, Vmax, ...)`` and ``valid (B, Vmax)``."""
        return self.padded(self.feature(name), fill), self.valid

    def feature(self, name: str) -> torch.Tensor:
        """The packed per-vertex feature ``name (N, ...)``."""
        if name not in self.features:
            raise InputError(f"this garment batch has no per-vertex feature {name!r} (it has {sorted(self.features)})")
        return self.features[name]

    def faces_list(self) -> list[torch.Tensor]:
        """Each garment's faces ``(F_i, 3)`` in its own numbering."""
        return [f - o for f, o in zip(self.faces.split(self.num_faces.tolist()), self.vert_offsets.tolist())]

    def edges_list(self) -> list[torch.Tensor]:
        """Each garment's directed edges ``(2, E_i)`` in its own numbering."""
        return [e - o for e, o in zip(self.edge_index.split(self.num_edges.tolist(), 1), self.vert_offsets.tolist())]

    def verts_list(self) -> list[torch.Tensor]:
        """Each garment's rest vertices ``(V_i, 3)``."""
        if self.verts is None:
            raise InputError("this garment batch holds no rest vertices")
        return self.split(self.verts)

    def faces_padded(self, fill: int = -1) -> torch.Tensor:
        """Faces ``(B, Fmax, 3)`` int64 in each garment's own numbering, rows past ``F_i`` all ``fill``."""
        Fmax = int(self.num_faces.max()) if len(self) else 0
        out = torch.full((len(self), Fmax, 3), fill, dtype=torch.int64, device=self.device)
        for i, f in enumerate(self.faces_list()):
            out[i, :len(f)] = f
        return out

    # ------------------------------------------------------------------ garments, devices

    def __getitem__(self, index) -> "GarmentBatch":
        """The sub-batch of garments ``index`` (an int, a slice, or a sequence of ints / a bool mask), renumbered."""
        if isinstance(index, (int, np.integer)):
            if not -len(self) <= index < len(self):
                raise IndexError(f"garment {index} of a batch of {len(self)}")
            picks = [int(index) % len(self)]
        elif isinstance(index, slice):
            picks = list(range(len(self)))[index]
        else:
            index = _tensor(index) if not isinstance(index, list) else torch.tensor(index, dtype=torch.int64)
            if index.dtype == torch.bool:
                index = index.nonzero()[:, 0]
            picks = [int(i) % len(self) for i in index.tolist()] if len(self) else index.tolist()
        if any(not 0 <= i < len(self) for i in picks):
            raise IndexError(f"garments {picks} of a batch of {len(self)}")
        split = {name: self.split(x) for name, x in self.features.items()}
        faces, edges = self.faces_list(), self.edges_list()
        return GarmentBatch.from_list(
            None if self.verts is None else [self.verts_list()[i] for i in picks], [faces[i] for i in picks],
            [edges[i] for i in picks], {name: [parts[i] for i in picks] for name, parts in split.items()},
            num_verts=[int(self.num_verts[i]) for i in picks])

    def unbind(self) -> list["GarmentBatch"]:
        """One single-garment batch per garment, in order."""
        return [self[i] for i in range(len(self))]

    def to(self, device) -> "GarmentBatch":
        """A copy with every tensor on ``device``."""
        move = lambda t: None if t is None else t.to(device)  # noqa: E731
        return GarmentBatch(move(self.num_verts), move(self.verts), move(self.faces), move(self.num_faces),
                            move(self.edge_index), move(self.num_edges),
                            {k: move(v) for k, v in self.features.items()})

    def cuda(self) -> "GarmentBatch":
        return self.to("cuda")

    def same_topology(self, other: "GarmentBatch") -> bool:
        """Whether ``other`` has the same garments' counts, faces and edges (compares tensors: a host
        synchronisation on a GPU)."""
        mine = (self.num_verts, self.num_faces, self.num_edges, self.faces, self.edge_index)
        theirs = (other.num_verts, other.num_faces, other.num_edges, other.faces, other.edge_index)
        return all(a.shape == b.shape and a.device == b.device and bool(torch.equal(a, b))
                   for a, b in zip(mine, theirs))

    def graph(self) -> dict[str, torch.Tensor]:
        """The packed graph as PyG-style tensors: ``edge_index (2, E)``, ``faces (F, 3)``, ``batch (N,)`` and
        ``counts (B,)`` (``V_i``)."""
        return {"edge_index": self.edge_index, "faces": self.faces, "batch": self.batch, "counts": self.num_verts}

    def __repr__(self) -> str:
        return (f"GarmentBatch({len(self)} garments, vertices {self.num_verts.tolist()}, faces "
                f"{int(self.num_faces.sum()) if len(self) else 0}, edges {self.edge_index.shape[1]}, features "
                f"{sorted(self.features)})")

    # ------------------------------------------------------------------ checks

    def _check_packed(self, x: torch.Tensor) -> None:
        if x.dim() < 1 or x.shape[0] != self.total_verts:
            raise InputError(f"a packed per-vertex array of this batch must have {self.total_verts} rows "
                             f"(vertices {self.num_verts.tolist()}), got {tuple(x.shape)}")


def _check_indices(x: torch.Tensor, shape: tuple[int, int], num_verts: int, what: str) -> torch.Tensor:
    """``x`` if it has ``shape`` (-1: any size) and its entries name vertices ``0 .. num_verts - 1``."""
    if x.dim() != 2 or any(s != -1 and s != n for s, n in zip(shape, x.shape)):
        wanted = "x".join("n" if s == -1 else str(s) for s in shape)
        raise InputError(f"{what} must be ({wanted}), got {tuple(x.shape)}")
    if x.numel() and (int(x.min()) < 0 or int(x.max()) >= num_verts):
        raise InputError(f"{what} name vertices {int(x.min())}..{int(x.max())}, the garment has {num_verts}")
    return x

