"""The HTML report's layout in a real browser (Debian's Chromium driven by Playwright, as the viewer's tests): at a
1280-pixel-wide window the page does not scroll sideways and the metrics tables show every column, with the
reference-run columns, long method and sequence names and wide numbers, beside the repository's speed and claims
tables."""

from __future__ import annotations

from pathlib import Path

import pytest

from loosefit.report.build import METRIC_COLUMNS, claim_rows, metric_tables, own_speed_cells, render_pages, speed_rows
from loosefit.report.claims import claims_table, speed_table

REPO = Path(__file__).resolve().parents[2]

#: Widest plausible cells per metric key: four digits before the point where the metric can reach them.
WIDE = {"frames": "1800", "rmse_mm": "1234.56", "rmse_vs_mean_mm": "1234.56", "rmse_vs_mean_corrected_mm": "1234.56",
        "floor_mm": "123.45", "mean_vertex_error_mm": "1234.56", "hausdorff_mm": "1234.56", "sted_spatial": "12.3456",
        "sted_temporal": "12.3456", "sted": "12.3456", "e_dist_cm": "123.456", "e_norm_deg": "123.45",
        "collision_pct": "100.000", "surface_inside_pct": "100.000", "deepest_mm": "1234.5",
        "laplacian_consistency": "12.3456", "collapsed_pct": "100.000", "roughness_deg": "180.00", "bend_ratio": "123.45"}


def context() -> dict:
    """A report's template context at its widest: every metric column, three methods (two with the run folder in
    their label), every cell as wide as :data:`WIDE`."""
    cells = [WIDE[k] for k, _, _ in METRIC_COLUMNS]
    rows = [{"name": name, "frames": 1800, "cells": cells} for name in ("skirt-terrain-003_01", "skirt-spin_test")]
    methods = [{"label": label, "run": f"runs/{label}", "rows": rows, "pooled": {"frames": 3600, "cells": cells},
                "warnings": []} for label in ("virtualbones", "jointnet (jointnet-memory-v9)", "swingar (swingar-prior)")]
    return {"title": "loosefit report: demo.zarr", "data": "/work/demo/demo.zarr", "date": "2025-01-01 12:00",
            "results_dir": None, "which": "the test split; collision handling exact",
            "headers": [h for _, h, _ in METRIC_COLUMNS], "references": True, "methods": methods,
            "tables": metric_tables(METRIC_COLUMNS, methods),
            "sequences": [{"name": r["name"], "garment": "skirt+average", "frames": 1800, "vertices": 1229,
                           "references": 4} for r in rows],
            "plots": [], "view_command": "loosefit view demo.zarr:skirt-spin_test",
            "speed": speed_rows(speed_table(REPO / "benchmarks" / "results")),
            # the runs' own speed at its widest (--measure-speed): a long label and source, five-digit rates
            "own_speed": own_speed_cells([{"garment": "skirt+average", "vertices": 12024, "method": m["label"],
                                           "parameters": 123456789, "stream_fps": 12345.6, "batch_fps": 12345.6,
                                           "source": "measured now: skirt-terrain-003_01, 120 frames, 1 thread"}
                                          for m in methods]),
            "measured_speed": True,
            "claims": claim_rows(claims_table(REPO / "benchmarks" / "results"))}


@pytest.fixture(scope="module")
def page(browser, tmp_path_factory):
    html, _ = render_pages(context())
    index = tmp_path_factory.mktemp("layout") / "index.html"
    index.write_text(html)
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    page.goto(index.as_uri())
    yield page
    page.close()


def test_the_metrics_tables_fit_a_1280_pixel_page(page):
    """Every metric is in one of the tables, each wholly in view (not cut, not scrolled), and the page does not
    scroll sideways."""
    sizes = page.evaluate("""() => [...document.querySelectorAll('table.metrics')].map(table => ({
        id: table.id, table: table.scrollWidth, right: table.getBoundingClientRect().right,
        box: table.parentElement.clientWidth, headers: [...table.rows[0].cells].slice(3).map(c => c.textContent)}))""")
    assert [s["id"] for s in sizes] == ["metrics", "surface"]
    assert sorted(h for s in sizes for h in s["headers"]) == sorted(h for _, h, _ in METRIC_COLUMNS)
    for s in sizes:
        assert s["table"] <= s["box"] and s["right"] <= 1280, s
    assert page.evaluate("document.getElementById('claims').rows.length") > 10  # the page holds its long tables too
    assert page.evaluate("document.documentElement.scrollWidth") <= 1280
