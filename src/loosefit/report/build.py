"""``loosefit report DATA.zarr RUN... --out report/``: one comparison of every method on a dataset.

Writes into ``out``:

- ``index.html`` and its Markdown twin ``report.md`` (Jinja2 templates, package data under
  ``loosefit/report/templates``);
- ``metrics.json``: every number of the tables (per method: per-sequence rows and the pooled row of
  :func:`loosefit.metrics.report.evaluate`, every metric; the claims and speed rows);
- ``figures/error-<sequence>.png``: per-frame RMSE of every method over time (matplotlib);
- ``figures/errormap-<sequence>.png``: the frame of largest mean error, the simulation beside every
  method coloured by per-vertex error on one colour scale (offscreen render, :mod:`loosefit.viz`).

The speed table and the paper-claims table read ``benchmarks/results`` (:mod:`loosefit.report.claims`);
from a source checkout that is the repository's folder, otherwise give ``results_dir``.
"""

from __future__ import annotations

import html
import json
import sys
import time
from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.metrics.report import COLUMNS, SequencePair, evaluate
from loosefit.paths import atomic_path
from loosefit.report.claims import claims_table, speed_table
from loosefit.report.own_speed import own_speed_rows
from loosefit.report.figures import error_map_png, error_over_time_png, rmse_per_frame_mm
from loosefit.report.predictions import load_methods, load_sequences

#: ``benchmarks/results`` of the source checkout this package runs from (None when installed elsewhere).
_REPO_RESULTS = Path(__file__).resolve().parents[3] / "benchmarks" / "results"
DEFAULT_RESULTS = _REPO_RESULTS if _REPO_RESULTS.is_dir() else None

#: Metric columns of the report (the keys of :data:`loosefit.metrics.report.COLUMNS` but the sizes).
METRIC_COLUMNS = tuple(c for c in COLUMNS if c[0] not in ("frames", "vertices"))
#: Columns of sequences with reference runs (:mod:`loosefit.metrics.reference`): beside RMSE when present.
REFERENCE_KEYS = ("rmse_vs_mean_mm", "rmse_vs_mean_corrected_mm", "floor_mm")
#: Columns of the HTML report's second metrics table (the body and the surface: collisions, penetration between the
#: vertices, surface quality); the first holds the accuracy against the simulation. One table of every metric (20
#: columns with the reference runs) measured 1,728 pixels in Chromium with four-digit millimetres, cut off in a
#: 1280-pixel window; two fit (``tests/report/test_layout.py``).
SURFACE_KEYS = ("collision_pct", "surface_inside_pct", "deepest_mm", "laplacian_consistency", "collapsed_pct",
                "roughness_deg", "bend_ratio")


def _fmt(value, fmt: str) -> str:
    return "-" if value is None else fmt.format(value)


def _metric_cells(row: dict, columns=METRIC_COLUMNS) -> list[str]:
    return [_fmt(row.get(k), f) for k, _, f in columns]


def _shown_columns(evaluations: list[dict]) -> tuple:
    """The metric columns to show: RMSE against the mean and the floor only when some sequence has reference runs."""
    runs = any(r.get("floor_mm") is not None for e in evaluations for r in e["rows"])
    return tuple(c for c in METRIC_COLUMNS if runs or c[0] not in REFERENCE_KEYS)


def metric_tables(columns, methods: list[dict]) -> list[dict]:
    """The HTML report's metrics tables: ``{"id", "title", "headers", "methods"}`` for the accuracy columns, then for
    :data:`SURFACE_KEYS` (a table with no column left out).

    Args:
        columns: the shown ``(key, header, format)`` columns.
        methods: the template context's methods, each row's ``cells`` in the order of ``columns``.
    """
    accuracy = [i for i, c in enumerate(columns) if c[0] not in SURFACE_KEYS]
    surface = [i for i, c in enumerate(columns) if c[0] in SURFACE_KEYS]
    groups = (("metrics", "Accuracy against the simulation", accuracy), ("surface", "Collisions and surface quality", surface))
    tables = []
    for name, title, picked in groups:
        if not picked:
            continue

        def cut(row: dict) -> dict:
            return {**row, "cells": [row["cells"][i] for i in picked]}

        tables.append({"id": name, "title": title, "headers": [columns[i][1] for i in picked],
                       "methods": [{**m, "rows": [cut(r) for r in m["rows"]], "pooled": cut(m["pooled"])}
                                   for m in methods]})
    return tables


def speed_rows(speed: list[dict]) -> list[dict]:
    """The rows of :func:`loosefit.report.claims.speed_table` with the speed table's formatted ``cells``."""
    return [{**r, "cells": [r["garment"], str(r["vertices"]), r["method"], _fmt(r["parameters"], "{:,}"),
                            _fmt(r["simulator_ms"], "{:.0f}"), _fmt(r["stream_fps"], "{:.1f}"),
                            _fmt(r["batch_fps"], "{:.1f}"), _fmt(r["stream_speedup"], "{:.1f}x"),
                            _fmt(r["batch_speedup"], "{:.1f}x")]} for r in speed]


def own_speed_cells(rows: list[dict]) -> list[dict]:
    """The rows of :func:`loosefit.report.own_speed.own_speed_rows` with the formatted ``cells`` of the table of
    the runs' own speed (garment, vertices, method, parameters, stream fps, batch fps, how it was measured)."""
    return [{**r, "cells": [r["garment"], str(r["vertices"]), r["method"], _fmt(r["parameters"], "{:,}"),
                            _fmt(r["stream_fps"], "{:.1f}"), _fmt(r["batch_fps"], "{:.1f}"), r["source"]]}
            for r in rows]


def claim_rows(claims: list[dict]) -> list[dict]:
    """The rows of :func:`loosefit.report.claims.claims_table` with the claims table's formatted texts."""
    return [{**r, "ours_text": _fmt(r["ours"], "{:.3f}"), "limit_text": _fmt(r["limit"], "{:g}"),
             "verdict": "not run" if r["pass"] is None else ("pass" if r["pass"] else "FAIL")} for r in claims]


def markdown_text(value) -> str:
    """``value`` as plain text in a Markdown table cell or heading: HTML is escaped (a run named
    ``<img onerror=...>`` shows as written, as in ``index.html``), a ``|`` cannot end the cell, a newline the row."""
    text = html.escape(str(value), quote=False)
    return text.replace("\\", "\\\\").replace("|", "\\|").replace("`", "\\`").replace("\r", " ").replace("\n", " ")


def build_report(data: str | Path, runs: list[str | Path], out: str | Path, sequences: list[str] | None = None,
                 split: str | None = "test", results_dir: str | Path | None = DEFAULT_RESULTS, device: str = "cpu",
                 images: bool = True, handling: str = "exact", measure_speed: bool = False) -> Path:
    """Animate the held-out ``sequences`` (default: the ``split``) of ``data`` with every run, evaluate
    them, draw the figures and write the report into ``out``; returns ``out/index.html``. The animations get
    collision handling ``handling`` (``"exact"``, ``"pushout"`` or ``"none"``), as ``loosefit animate`` does.
    ``measure_speed``: also time every run's own model on this machine (:mod:`loosefit.report.own_speed`), beside
    the speed table copied from the benchmark results.

    Raises:
        InputError: a missing store or run, a run for a garment none of the sequences wears, an unknown
            sequence, a damaged results file; each names the file.
    """
    from loosefit.extras import require

    require("jinja2", "loosefit report")
    require("matplotlib", "loosefit report's plots")

    data, out = Path(data), Path(out)
    if not (data / ".zgroup").is_file():
        raise InputError("not a loosefit dataset store (no .zgroup)", data)
    for run in runs:
        if not Path(run).is_dir():
            raise InputError("run folder not found", run)
    if results_dir is not None and not Path(results_dir).is_dir():
        raise InputError("benchmark results folder not found", results_dir)
    seqs = load_sequences(data, sequences, split)
    methods = load_methods(runs, seqs, device, handling)
    for m in methods:  # its predictions of these motions are extrapolations
        for line in m.warnings:
            print(f"loosefit report: warning: {m.label}: {line}", file=sys.stderr, flush=True)
    figures = out / "figures"
    figures.mkdir(parents=True, exist_ok=True)

    evaluations = []
    for m in methods:
        pairs = [SequencePair(s.name, m.predictions[s.name], s.gt, s.faces, s.body_verts, s.body_faces, s.references)
                 for s in seqs if s.name in m.predictions]
        ev = evaluate(pairs, progress=False)
        evaluations.append({"method": m.label, "run": str(m.run), "rows": ev.rows, "pooled": ev.overall,
                            "warnings": m.warnings})

    plots = []
    for s in seqs:
        preds = {m.label: m.predictions[s.name] for m in methods if s.name in m.predictions}
        if not preds:
            continue
        series = {label: rmse_per_frame_mm(p, s.gt) for label, p in preds.items()}
        entry = {"sequence": s.name, "garment": s.garment, "frames": len(s.gt),
                 "plot": f"figures/error-{s.name}.png", "map": None, "map_frame": None, "map_top_mm": None}
        error_over_time_png(out / entry["plot"], f"{s.name}: RMSE per frame", series, s.fps)
        if images:
            frame = int(np.argmax(np.mean(list(series.values()), axis=0)))
            _, top = error_map_png(out / f"figures/errormap-{s.name}.png", s.gt, s.faces, s.body_verts, s.body_faces,
                                   preds, frame)
            entry.update(map=f"figures/errormap-{s.name}.png", map_frame=frame, map_top_mm=top)
        plots.append(entry)

    claims, speed = claims_table(results_dir), speed_table(results_dir)
    own_speed = own_speed_rows(methods, seqs) if measure_speed else []
    columns = _shown_columns(evaluations)
    context = {
        "title": f"loosefit report: {data.name}",
        "data": str(data.resolve()),
        "date": time.strftime("%Y-%m-%d %H:%M"),
        "results_dir": None if results_dir is None else str(results_dir),
        "which": ("the named sequences" if sequences is not None else f"the {split} split")
                 + f"; collision handling {handling}",
        "headers": [h for _, h, _ in columns],
        "references": any(c[0] in REFERENCE_KEYS for c in columns),
        "methods": [{"label": e["method"], "run": e["run"],
                     "rows": [{"name": r["name"], "frames": r["frames"], "cells": _metric_cells(r, columns)}
                              for r in e["rows"]],
                     "pooled": {"frames": e["pooled"]["frames"], "cells": _metric_cells(e["pooled"], columns)},
                     "warnings": e["warnings"]}
                    for e in evaluations],
        "sequences": [{"name": s.name, "garment": s.garment, "frames": len(s.gt), "vertices": s.gt.shape[1],
                       "references": len(s.references) if s.references is not None else 0} for s in seqs],
        "plots": plots,
        "speed": speed_rows(speed),
        "own_speed": own_speed_cells(own_speed),
        "measured_speed": measure_speed,
        "claims": claim_rows(claims),
        "view_command": f"loosefit view {data}:{seqs[0].name}" if seqs else "",
    }
    context["tables"] = metric_tables(columns, context["methods"])
    page, md = render_pages(context)
    doc = {"data": context["data"], "collision_handling": handling, "methods": evaluations, "sequences": context["sequences"], "plots": plots,
           "speed": speed, "own_speed": own_speed, "claims": claims}
    with atomic_path(out / "metrics.json") as tmp:
        tmp.write_text(json.dumps(doc, indent=2) + "\n")
    with atomic_path(out / "report.md") as tmp:
        tmp.write_text(md)
    index = out / "index.html"
    with atomic_path(index) as tmp:
        tmp.write_text(page)
    return index


def render_pages(context: dict) -> tuple[str, str]:
    """``index.html`` and ``report.md`` of a report from its template ``context`` (what :func:`build_report` fills:
    the tables' rows as formatted cells)."""
    from jinja2 import Environment, PackageLoader, StrictUndefined, select_autoescape

    env = Environment(loader=PackageLoader("loosefit.report", "templates"), undefined=StrictUndefined,
                      autoescape=select_autoescape(enabled_extensions=("html.j2",), default_for_string=False),
                      trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)
    env.filters["md"] = markdown_text
    return env.get_template("index.html.j2").render(**context), env.get_template("report.md.j2").render(**context)
