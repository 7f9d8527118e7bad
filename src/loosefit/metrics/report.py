"""Evaluate predicted garment sequences against ground truth: per-sequence and overall metrics,
a text table, and CSV / JSON files (written atomically).

Metrics per sequence (see each module for the formula): ``rmse_mm``, ``mean_vertex_error_mm``,
``hausdorff_mm`` (:mod:`~loosefit.metrics.errors`); ``sted_spatial``, ``sted_temporal``, ``sted``
(:mod:`~loosefit.metrics.sted`); ``e_dist_cm``, ``e_norm_deg`` (:mod:`~loosefit.metrics.surface`);
``collision_pct`` when a posed body is known (:mod:`~loosefit.metrics.collision`), and with it
``surface_inside_pct`` (the share of the surface samples, edge midpoints and triangle centroids, deeper inside
the body than ``EvaluationSettings.surface_depth``, 5 mm by default: a limb passing between vertices) and
``deepest_mm`` (the deepest point inside the body, vertices and samples, 0 when none is):
:func:`~loosefit.metrics.collision.penetration`; ``collapsed_pct`` (triangles under 20 % of their simulated area
or flipped) and ``roughness_deg`` (mean dihedral-angle difference over interior edges), the bounded surface
quality of :mod:`~loosefit.metrics.surface` (``None`` for a mesh without interior edges), and ``bend_ratio`` (the
prediction's mean unsigned dihedral angle over the simulation's, ``sim_bend_deg``: above 1, more folded than cloth);
``laplacian_consistency``: SwinGar's Laplacian consistency deviation ``|diag(L_pred) - diag(L_gt)|``
(:func:`~loosefit.metrics.surface.laplacian_consistency`, half-cotangent weights, dimensionless) of the
prediction against the simulation, over every vertex and frame: how far the prediction's local surface
structure is from the simulated one. With reference runs of a sequence (perturbed simulations, stored
with it: :meth:`loosefit.data.store.DatasetStore.references`), ``rmse_vs_mean_mm`` (against the mean of the
base and its reference runs), ``rmse_vs_mean_corrected_mm`` (the same with the mean's own spread removed,
``sqrt(max(0, e^2 - floor^2 / K))`` for K reference runs) and ``floor_mm`` (their spread around that mean, below
which no deterministic model scores against one run): :mod:`~loosefit.metrics.reference`; ``None`` for a
sequence without runs.

Overall values pool every frame of every sequence, so long sequences weigh more: RMSE is the root
of the pooled mean square; mean errors, STED_s, Laplacian consistency and collision are weighted by frames x vertices,
STED_t by frame pairs x vertices, Hausdorff by frames, E_norm and the collapsed share by frames x faces, the surface
share by frames x surface samples (a row's ``surface_samples``), roughness by frames x interior edges (a row's
``interior_edges``), the bend ratio by each row's simulated angle sum (the pooled sums' ratio); the deepest point is the deepest of all; the overall STED combines the overall STED_s and
STED_t. A sequence of one frame has no temporal STED (``None``).
RMSE against the mean and the floor pool their mean squares by frames x vertices over the sequences that
have reference runs only (``references``: how many sequences that is); the corrected figure pools
``e^2 - floor^2 / K`` the same way and clips at zero only once pooled.

Inputs: mesh-sequence ``.npz`` files (:class:`~loosefit.io.mesh_sequence.MeshSequence`; a GT file may
carry the posed body as ``body_verts`` / ``body_faces``), directories of them matched by file name,
or sequences of a dataset store (ground truth) with predictions in a directory as ``<sequence>.npz``.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from loosefit.errors import InputError
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.metrics import sted as sted_mod
from loosefit.metrics.collision import DEFAULT_TOLERANCE, REPORT_DEPTH, Penetration, penetration, penetrations
from loosefit.metrics.errors import check_pair, hausdorff_per_frame, vertex_errors
from loosefit.metrics.reference import References
from loosefit.metrics.surface import (
    collapsed_faces,
    dihedral_pair_deg,
    face_normal_deviation_deg,
    mean_laplacian_consistency,
    roughness_from_dihedrals,
)
from loosefit.paths import atomic_path

#: Reported columns in order: key, table header, format.
COLUMNS = (
    ("frames", "frames", "{:d}"),
    ("vertices", "verts", "{:d}"),
    ("rmse_mm", "RMSE mm", "{:.2f}"),
    ("rmse_vs_mean_mm", "RMSE vs mean mm", "{:.2f}"),
    ("rmse_vs_mean_corrected_mm", "vs mean, corrected mm", "{:.2f}"),
    ("floor_mm", "floor mm", "{:.2f}"),
    ("mean_vertex_error_mm", "mean err mm", "{:.2f}"),
    ("hausdorff_mm", "Hausdorff mm", "{:.2f}"),
    ("sted_spatial", "STED_s", "{:.4f}"),
    ("sted_temporal", "STED_t", "{:.4f}"),
    ("sted", "STED", "{:.4f}"),
    ("e_dist_cm", "E_dist cm", "{:.3f}"),
    ("e_norm_deg", "E_norm deg", "{:.2f}"),
    ("collision_pct", "collision %", "{:.3f}"),
    ("surface_inside_pct", "surface >5mm %", "{:.3f}"),
    ("deepest_mm", "deepest mm", "{:.1f}"),
    ("laplacian_consistency", "Lap. cons.", "{:.4f}"),
    ("collapsed_pct", "collapsed %", "{:.3f}"),
    ("roughness_deg", "rough. deg", "{:.2f}"),
    ("bend_ratio", "bend x sim", "{:.2f}"),
)


@dataclass
class SequencePair:
    """One predicted sequence and its ground truth: ``pred``/``gt (T, V, 3)`` metres on ``faces (F, 3)``,
    optionally the posed body ``body_verts (T, Vb, 3)`` with ``body_faces (Fb, 3)`` for the collision ratio, and
    the reference runs ``references (K, T, V, 3)`` of ``gt`` (its perturbed simulations; None or K = 0: none)."""

    name: str
    pred: np.ndarray
    gt: np.ndarray
    faces: np.ndarray
    body_verts: np.ndarray | None = None
    body_faces: np.ndarray | None = None
    references: np.ndarray | None = None


@dataclass
class EvaluationSettings:
    """STED parameters (see :mod:`loosefit.metrics.sted`), the collision tolerance of the vertices in metres and
    the depth in metres a surface sample must be inside the body to count in ``surface_inside_pct``."""

    sted_rings: int = sted_mod.DEFAULT_RINGS
    sted_dt: float = sted_mod.DEFAULT_DT
    sted_c: float = sted_mod.DEFAULT_C
    collision_tolerance: float = DEFAULT_TOLERANCE
    surface_depth: float = REPORT_DEPTH


def column_header(key: str, header: str, settings: EvaluationSettings | None = None) -> str:
    """The table header of column ``key``: the surface share's names its depth (``surface >5mm %``)."""
    if key == "surface_inside_pct" and settings is not None:
        return f"surface >{1000 * settings.surface_depth:g}mm %"
    return header


@dataclass
class Evaluation:
    """Per-sequence rows (``name``, ``faces`` and the :data:`COLUMNS` keys) and the pooled ``overall`` row."""

    rows: list[dict]
    overall: dict
    settings: EvaluationSettings = field(default_factory=EvaluationSettings)

    def _columns(self) -> list[tuple[str, str, str]]:
        present = {k for row in self.rows for k, v in row.items() if v is not None}
        return [c for c in COLUMNS if c[0] in present]

    def table(self, overall: bool = True) -> str:
        """A fixed-width text table: one line per sequence, then ``overall`` (leave it out with
        ``overall=False`` when the rows are not one population, e.g. several methods on one sequence)."""
        cols = self._columns()
        header = ["sequence"] + [column_header(k, h, self.settings) for k, h, _ in cols]
        lines = []
        for row in self.rows + ([self.overall] if overall else []):
            lines.append([row["name"]] + [_fmt(row.get(k), f) for k, _, f in cols])
        widths = [max(len(header[i]), *(len(line[i]) for line in lines)) for i in range(len(header))]

        def fmt_line(cells: list[str]) -> str:
            # Names left-aligned, numbers right-aligned.
            return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))

        rule = "-" * len(fmt_line(header))
        body = [fmt_line(x) for x in lines]
        return "\n".join([fmt_line(header), rule] + (body[:-1] + [rule, body[-1]] if overall else body))

    def write_csv(self, path: str | Path) -> None:
        """One row per sequence, then the ``overall`` row; empty cells for metrics that do not apply."""
        keys = ["name"] + [k for k, _, _ in self._columns()]
        with atomic_path(path) as tmp:
            with open(tmp, "w", newline="") as f:
                writer = csv.writer(f)
                writer.writerow(keys)
                for row in self.rows + [self.overall]:
                    writer.writerow(["" if row.get(k) is None else row[k] for k in keys])

    def write_json(self, path: str | Path) -> None:
        """``{"settings": ..., "sequences": [...], "overall": {...}}`` with ``null`` for metrics that do not apply."""
        doc = {"settings": vars(self.settings), "sequences": self.rows, "overall": self.overall}
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(doc, indent=2) + "\n")


def _fmt(value, fmt: str) -> str:
    return "-" if value is None else fmt.format(value)


def evaluate_sequence(pair: SequencePair, settings: EvaluationSettings | None = None,
                      inside: Penetration | None = None) -> dict:
    """All metrics of one pair as a row dict (``name``, ``faces``, ``surface_samples``, ``interior_edges`` and the
    :data:`COLUMNS` keys; ``None`` where n/a). ``inside``: the pair's penetration of the body when it is already
    measured (:func:`evaluate` measures the methods of one motion together)."""
    s = settings or EvaluationSettings()
    try:
        pred, gt = check_pair(pair.pred, pair.gt)
        T, V = gt.shape[:2]
        err = vertex_errors(pred, gt)
        spatial = float(sted_mod.sted_spatial_per_frame(pred, gt, pair.faces, s.sted_rings).mean())
        temporal = sted_mod.sted_temporal(pred, gt, s.sted_dt) if T >= 2 else None
        normals = face_normal_deviation_deg(pred, gt, pair.faces)
        laplacian = mean_laplacian_consistency(gt, pred, pair.faces)
        collapsed = collapsed_faces(pred, gt, pair.faces)
        theta_pred, theta_gt = dihedral_pair_deg(pred, gt, pair.faces)
        rough = roughness_from_dihedrals(theta_pred, theta_gt)
        sim_bend = float(np.abs(theta_gt).mean()) if theta_gt.size else 0.0
        if inside is None and pair.body_verts is not None:
            inside = penetration(pred, pair.faces, pair.body_verts, pair.body_faces, s.collision_tolerance,
                                 s.surface_depth)
        against = None
        if pair.references is not None and len(pair.references):
            against = References(gt, pair.references).score(pred)
    except InputError as e:
        raise InputError(f"sequence {pair.name!r}: {e}") from None
    return {
        "name": pair.name,
        "frames": int(T),
        "vertices": int(V),
        "rmse_mm": float(1000 * np.sqrt(np.mean(err * err))),
        "rmse_vs_mean_mm": None if against is None else against.rmse_vs_mean_mm,
        "rmse_vs_mean_corrected_mm": None if against is None else against.rmse_vs_mean_corrected_mm,
        "floor_mm": None if against is None else against.floor_mm,
        "references": None if against is None else against.references,
        "mean_vertex_error_mm": float(1000 * err.mean()),
        "hausdorff_mm": float(1000 * hausdorff_per_frame(pred, gt).mean()),
        "sted_spatial": spatial,
        "sted_temporal": temporal,
        "sted": None if temporal is None else sted_mod.combine(spatial, temporal, s.sted_c),
        "e_dist_cm": float(100 * err.mean()),
        "e_norm_deg": None if np.isnan(normals).all() else float(np.nanmean(normals)),
        "collision_pct": None if inside is None else float(inside.vertex_percent.mean()),
        "surface_inside_pct": None if inside is None else float(inside.surface_percent.mean()),
        "deepest_mm": None if inside is None else float(1000 * inside.deepest_m.max()),
        "laplacian_consistency": laplacian,
        "collapsed_pct": float(100 * collapsed.mean()),
        "roughness_deg": float(rough.mean()) if rough.shape[1] else None,
        "bend_ratio": float(np.abs(theta_pred).mean()) / sim_bend if sim_bend > 0 else None,
        "sim_bend_deg": sim_bend,
        "faces": int(len(pair.faces)),
        "surface_samples": None if inside is None else inside.samples,
        "interior_edges": int(rough.shape[1]),
    }


def _weighted(rows: list[dict], key: str, weight) -> float | None:
    pairs = [(row[key], weight(row)) for row in rows if row.get(key) is not None and weight(row) > 0]
    if not pairs:
        return None
    values, weights = np.array(pairs).T
    return float((values * weights).sum() / weights.sum())


def overall_row(rows: list[dict], settings: EvaluationSettings | None = None) -> dict:
    """Pool per-sequence rows into the ``overall`` row (weights in the module docstring)."""
    s = settings or EvaluationSettings()

    def tv(row: dict) -> int:
        return row["frames"] * row["vertices"]

    ms = _weighted([{**r, "ms": r["rmse_mm"] ** 2} for r in rows], "ms", tv)
    with_refs = [r for r in rows if r.get("floor_mm") is not None]
    ms_mean = _weighted([{**r, "ms": r["rmse_vs_mean_mm"] ** 2} for r in with_refs], "ms", tv)
    ms_floor = _weighted([{**r, "ms": r["floor_mm"] ** 2} for r in with_refs], "ms", tv)
    ms_corrected = _weighted([{**r, "ms": r["rmse_vs_mean_mm"] ** 2 - r["floor_mm"] ** 2 / r["references"]}
                              for r in with_refs], "ms", tv)
    spatial = _weighted(rows, "sted_spatial", tv)
    deepest = [r["deepest_mm"] for r in rows if r.get("deepest_mm") is not None]
    temporal = _weighted(rows, "sted_temporal", lambda r: (r["frames"] - 1) * r["vertices"])
    return {
        "name": "overall",
        "frames": int(sum(r["frames"] for r in rows)),
        "vertices": None,
        "faces": None,
        "rmse_mm": None if ms is None else float(np.sqrt(ms)),
        "rmse_vs_mean_mm": None if ms_mean is None else float(np.sqrt(ms_mean)),
        "rmse_vs_mean_corrected_mm": None if ms_corrected is None else float(np.sqrt(max(0.0, ms_corrected))),
        "floor_mm": None if ms_floor is None else float(np.sqrt(ms_floor)),
        "references": len(with_refs) or None,
        "mean_vertex_error_mm": _weighted(rows, "mean_vertex_error_mm", tv),
        "hausdorff_mm": _weighted(rows, "hausdorff_mm", lambda r: r["frames"]),
        "sted_spatial": spatial,
        "sted_temporal": temporal,
        "sted": None if spatial is None or temporal is None else sted_mod.combine(spatial, temporal, s.sted_c),
        "e_dist_cm": _weighted(rows, "e_dist_cm", tv),
        "e_norm_deg": _weighted(rows, "e_norm_deg", lambda r: r["frames"] * r["faces"]),
        "collision_pct": _weighted(rows, "collision_pct", tv),
        "surface_inside_pct": _weighted(rows, "surface_inside_pct", lambda r: r["frames"] * (r["surface_samples"] or 0)),
        "deepest_mm": max(deepest) if deepest else None,
        "laplacian_consistency": _weighted(rows, "laplacian_consistency", tv),
        "collapsed_pct": _weighted(rows, "collapsed_pct", lambda r: r["frames"] * r["faces"]),
        "roughness_deg": _weighted(rows, "roughness_deg", lambda r: r["frames"] * r["interior_edges"]),
        # the pooled sum of the prediction's angles over the simulation's: rows weighted by their simulated sum
        "bend_ratio": _weighted(rows, "bend_ratio", lambda r: r["frames"] * r["interior_edges"] * r["sim_bend_deg"]),
        "sim_bend_deg": _weighted(rows, "sim_bend_deg", lambda r: r["frames"] * r["interior_edges"]),
        "surface_samples": None,
        "interior_edges": None,
    }


def evaluate(pairs: list[SequencePair], settings: EvaluationSettings | None = None, progress: bool = True) -> Evaluation:
    """Evaluate every pair; returns per-sequence rows and the pooled overall row."""
    if not pairs:
        raise InputError("nothing to evaluate: no sequence pairs")
    s = settings or EvaluationSettings()
    shared = _shared_body_penetrations(pairs, s)
    rows = [evaluate_sequence(p, s, shared.get(k))
            for k, p in enumerate(tqdm(pairs, desc="evaluate", unit="seq", disable=not progress))]
    return Evaluation(rows, overall_row(rows, s), s)


def _shared_body_penetrations(pairs: list[SequencePair], settings: EvaluationSettings) -> dict[int, Penetration]:
    """Penetrations of the pairs that share one posed body (the same ``body_verts`` array: several methods on one
    motion), keyed by pair index: the body's exact distance field is built once a frame for all of them, their
    vertices and surface samples (most of an evaluation's time: about 58 ms a frame for the Anny body)."""
    groups: dict[int, list[int]] = {}
    for k, p in enumerate(pairs):
        if p.body_verts is not None:
            groups.setdefault(id(p.body_verts), []).append(k)
    shared = {}
    for members in groups.values():
        first = pairs[members[0]]
        if len(members) < 2 or any(pairs[k].body_faces is not first.body_faces for k in members):
            continue
        try:
            preds = [check_pair(pairs[k].pred, pairs[k].gt)[0] for k in members]
            if len({pred.shape[0] for pred in preds}) != 1:
                continue
            found = penetrations([(pred, pairs[k].faces) for pred, k in zip(preds, members)], first.body_verts,
                                 first.body_faces, settings.collision_tolerance, settings.surface_depth)
        except InputError:
            continue  # evaluate_sequence measures each pair alone and names the bad one
        shared.update(zip(members, found))
    return shared


def _npz_files(path: Path) -> dict[str, Path]:
    if path.is_dir():
        files = {p.stem: p for p in sorted(path.glob("*.npz"))}
        if not files:
            raise InputError("directory holds no .npz mesh sequences", path)
        return files
    if path.suffix != ".npz" or not path.is_file():
        raise InputError("expected a mesh-sequence .npz file or a directory of them", path)
    return {path.stem: path}


def _check_fps(pred: MeshSequence, gt: MeshSequence, pred_path: Path, gt_path: Path, body: MeshSequence | None,
               body_path: Path | None) -> None:
    """Frame rates must be positive and agree: frame-by-frame errors and STED's temporal term compare
    frame ``t`` of one sequence with frame ``t`` of the other, which is the same instant only at one rate."""
    for seq, path in ((pred, pred_path), (gt, gt_path), (body, body_path)):
        if seq is not None and not 0 < seq.fps < float("inf"):
            raise InputError(f"frame rate must be a positive number, got {seq.fps:g} fps", path)
    if abs(pred.fps - gt.fps) > 1e-6 * gt.fps:
        raise InputError(f"prediction at {pred.fps:g} fps, ground truth {gt_path} at {gt.fps:g} fps: resample one "
                         "(frames are compared one to one)", pred_path)
    if body is not None and abs(body.fps - gt.fps) > 1e-6 * gt.fps:
        raise InputError(f"body at {body.fps:g} fps, ground truth {gt_path} at {gt.fps:g} fps", body_path)


def _pair(name: str, pred: MeshSequence, gt: MeshSequence, pred_path: Path, gt_path: Path, body: MeshSequence | None,
          body_path: Path | None = None) -> SequencePair:
    _check_fps(pred, gt, pred_path, gt_path, body, body_path)
    if pred.verts.shape != gt.verts.shape:
        raise InputError(f"prediction {pred.verts.shape} does not match ground truth {gt.verts.shape} in {gt_path}", pred_path)
    if pred.faces.shape != gt.faces.shape or not np.array_equal(pred.faces, gt.faces):
        raise InputError(f"prediction triangles differ from those of the ground truth {gt_path}", pred_path)
    body_verts, body_faces = gt.extra.get("body_verts"), gt.extra.get("body_faces")
    if body is not None:
        body_verts, body_faces = body.verts, body.faces
    if body_verts is not None:
        if body_faces is None:
            raise InputError("body_verts without body_faces", gt_path)
        if len(body_verts) != len(gt.verts):
            raise InputError(f"body has {len(body_verts)} frames, the sequence {len(gt.verts)}", gt_path)
    return SequencePair(name, pred.verts, gt.verts, gt.faces, body_verts, body_faces)


def pairs_from_files(pred: str | Path, gt: str | Path, body: str | Path | None = None) -> list[SequencePair]:
    """Pairs from mesh-sequence ``.npz`` files: two files, or two directories matched by file name.

    Every ground-truth sequence needs a prediction of the same name; ``body`` (a posed-body mesh
    sequence) overrides the ``body_verts`` a ground-truth file may carry.
    """
    pred_files, gt_files = _npz_files(Path(pred)), _npz_files(Path(gt))
    body_path = None if body is None else Path(body)
    body_seq = MeshSequence.load(body) if body is not None else None
    if len(pred_files) == 1 and len(gt_files) == 1 and not Path(pred).is_dir():
        ((_, p),), ((name, g),) = pred_files.items(), gt_files.items()
        return [_pair(name, MeshSequence.load(p), MeshSequence.load(g), p, g, body_seq, body_path)]
    missing = sorted(set(gt_files) - set(pred_files))
    if missing:
        raise InputError(f"no prediction for ground-truth sequence(s) {missing}", Path(pred))
    return [_pair(n, MeshSequence.load(pred_files[n]), MeshSequence.load(g), pred_files[n], g, body_seq, body_path)
            for n, g in gt_files.items()]


def pairs_from_store(
    store: str | Path,
    pred_dir: str | Path,
    names: list[str] | None = None,
    split: str | None = "test",
    body: str | Path | None = None,
) -> list[SequencePair]:
    """Pairs with ground truth from a dataset store and predictions ``<pred_dir>/<sequence>.npz``.

    ``names`` picks sequences (default: every ``"ok"`` sequence of ``split``; ``split=None`` for all).
    ``body`` (a posed-body mesh sequence) is attached to every pair, so it suits one sequence or
    sequences of one motion; without it there is no collision ratio. A sequence's reference runs, when the store
    has them, come with its pair (RMSE against their mean and the floor).
    """
    from loosefit.data.store import DatasetStore

    body_seq = MeshSequence.load(body) if body is not None else None
    ds = DatasetStore.open(store, "r")
    names = ds.sequence_names(split=split) if names is None else list(names)
    if not names:
        raise InputError(f"no sequences to evaluate (split {split!r})", Path(store))
    pred_dir = Path(pred_dir)
    pairs = []
    for name in names:
        seq = ds.sequence(name)
        path = pred_dir / f"{name}.npz"
        if not path.is_file():
            raise InputError(f"no prediction for dataset sequence {name!r}", path)
        gt = MeshSequence(seq.verts[:], ds.read_array(f"garments/{seq.garment}", "faces"), ds.motion(seq.motion).fps)
        pair = _pair(name, MeshSequence.load(path), gt, path, Path(store), body_seq, None if body is None else Path(body))
        pair.references = ds.references(name)  # (0, T, V, 3) for a sequence without reference runs
        pairs.append(pair)
    return pairs


def is_dataset_store(path: str | Path) -> bool:
    """Whether ``path`` is a Zarr directory (a dataset store) rather than a mesh-sequence file or folder."""
    return Path(path).is_dir() and (Path(path) / ".zgroup").is_file()


def load_pairs(
    pred: str | Path, gt: str | Path, body: str | Path | None = None, names: list[str] | None = None, split: str | None = "test"
) -> list[SequencePair]:
    """Pairs for ``loosefit evaluate PRED GT``: :func:`pairs_from_store` when ``gt`` is a dataset store
    (``names`` / ``split`` pick its sequences), else :func:`pairs_from_files`."""
    if is_dataset_store(gt):
        return pairs_from_store(gt, pred, names, split, body)
    if names is not None:
        raise InputError("sequence names only apply when the ground truth is a dataset store", Path(gt))
    return pairs_from_files(pred, gt, body)
