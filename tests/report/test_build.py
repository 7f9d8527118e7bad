"""``loosefit report`` on a tiny simulated dataset with two real runs (body-LBS and a small JointNet):
the tables hold the numbers computed directly from the animations, the figures are real images, the
claims and speed tables carry the benchmark results, and bad input gets clear errors."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import igl
import imageio.v3 as iio
import numpy as np
import pytest

from loosefit.animate import Animator
from loosefit.cli import main
from loosefit.data import DatasetStore
from loosefit.errors import InputError
from loosefit.report import build_report
from loosefit.training import train_model

REPO = Path(__file__).resolve().parents[2]
SMALL_JOINTNET = ["model.gru_hidden=16", "model.features=16", "model.bone_mlp=[32]", "model.psd_mlp=[16]",
                  "model.psd_shapes=4", "train.stages.stage1.epochs=2", "train.stages.stage2.epochs=1",
                  "train.progress=false", "train.tensorboard=false", "data.window=20", "data.stride=10", "data.burn_in=4"]


@pytest.fixture(scope="module")
def report(tiny_store, tmp_path_factory):
    root = tmp_path_factory.mktemp("report")
    train_model("body-lbs", tiny_store, "skirt+average", root / "lbs")
    train_model("jointnet", tiny_store, "skirt+average", root / "jn", overrides=SMALL_JOINTNET)
    results = root / "results"
    results.mkdir()
    for name in ("speed", "accuracy-large-skirt"):  # real benchmark results of the repository
        shutil.copy(REPO / "benchmarks" / "results" / f"{name}.json", results)
    out = root / "out"
    assert main(["report", str(tiny_store), str(root / "lbs"), str(root / "jn"), "--out", str(out),
                 "--results", str(results)]) == 0
    return root, out


def _direct_metrics(store_path, run, name):
    """RMSE, mean error (mm) and Laplacian consistency from the animation after exact collision handling (the
    report's default, as animate's), with numpy and libigl."""
    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.models.collision import handle_motion_collisions

    store = DatasetStore.open(store_path)
    seq = store.sequence(name)
    motion = store.motion(seq.motion)
    garment = store.garment(seq.garment)
    faces = np.asarray(garment.faces)
    body = AnnyBody(AnnyShape.from_array(store.body(seq.body)), rig=motion.rig)
    pred = handle_motion_collisions(Animator(run).animate(motion), faces, body, motion, "exact",
                                    rest=garment.verts).astype(np.float64)  # its fallback, given the rest garment
    gt = np.asarray(seq.verts[:], np.float64)
    d = np.linalg.norm(pred - gt, axis=-1)
    lap = np.mean([np.abs(igl.cotmatrix(p, faces).diagonal() - igl.cotmatrix(g, faces).diagonal())
                   for p, g in zip(pred, gt)])
    # collapsed: under a fifth of the simulated area, or the normal turned against the simulated one
    n_p, n_g = (np.cross(v[:, faces[:, 1]] - v[:, faces[:, 0]], v[:, faces[:, 2]] - v[:, faces[:, 0]]) for v in (pred, gt))
    collapsed = (np.linalg.norm(n_p, axis=-1) < 0.2 * np.linalg.norm(n_g, axis=-1)) | ((n_p * n_g).sum(-1) < 0)
    return {"rmse_mm": 1000 * np.sqrt(np.mean(d**2)), "mean_vertex_error_mm": 1000 * d.mean(),
            "e_dist_cm": 100 * d.mean(), "laplacian_consistency": lap, "collapsed_pct": 100 * collapsed.mean()}


def test_tables_hold_the_directly_computed_metrics(report, tiny_store):
    root, out = report
    doc = json.loads((out / "metrics.json").read_text())
    html, md = (out / "index.html").read_text(), (out / "report.md").read_text()
    assert [m["method"] for m in doc["methods"]] == ["body-lbs", "jointnet"]
    assert doc["collision_handling"] == "exact" and "collision handling exact" in md
    names = DatasetStore.open(tiny_store).sequence_names(split="test")
    for entry, run in zip(doc["methods"], (root / "lbs", root / "jn")):
        assert [r["name"] for r in entry["rows"]] == names
        for row in entry["rows"]:
            direct = _direct_metrics(tiny_store, run, row["name"])
            for key, value in direct.items():
                assert row[key] == pytest.approx(value, rel=1e-4, abs=1e-9), key
            for key in ("hausdorff_mm", "sted", "e_norm_deg", "collision_pct", "surface_inside_pct", "deepest_mm",
                        "roughness_deg"):  # every metric present
                assert row[key] is not None and np.isfinite(row[key])
        # one test sequence: the pooled row is that sequence's
        assert entry["pooled"]["rmse_mm"] == pytest.approx(entry["rows"][0]["rmse_mm"], rel=1e-9)
        shown = f"{entry['pooled']['rmse_mm']:.2f}"
        assert re.search(rf"<td>{entry['method']}</td><td>pooled</td>.*?{re.escape(shown)}", html)
        assert f"| **{entry['method']}** | **pooled** |" in md and f"**{shown}**" in md
        # the body and surface columns in the HTML's second table (one would not fit a 1280-pixel window)
        collapsed = f"{entry['pooled']['collapsed_pct']:.3f}"
        surface = html[html.index('<table id="surface"'):]
        assert re.search(rf"<td>{entry['method']}</td><td>pooled</td>.*?{re.escape(collapsed)}", surface)
    assert "surface &gt;5mm %" in html and "surface >5mm % | deepest mm |" in md
    # the two methods differ: the table does not repeat one number
    assert doc["methods"][0]["pooled"]["rmse_mm"] != pytest.approx(doc["methods"][1]["pooled"]["rmse_mm"], rel=1e-3)


def test_reference_runs_put_the_floor_beside_rmse(report, tiny_store, tmp_path):
    from loosefit.metrics.reference import References

    root, out = report
    assert "floor mm" not in (out / "report.md").read_text()  # a store without reference runs: columns as before
    data = tmp_path / "refs.zarr"
    shutil.copytree(tiny_store, data)
    with DatasetStore.open(data, mode="a") as store:
        (name,) = store.sequence_names(split="test")
        base = np.asarray(store.sequence(name).verts[:])
        rng = np.random.default_rng(0)
        for k in (1, 2, 3):  # stand-ins for perturbed simulations: the base moved by a few millimetres
            store.write_reference(name, k, base + rng.normal(0, 0.003, base.shape).astype(np.float32))
    build_report(data, [root / "lbs"], tmp_path / "out", results_dir=None, images=False, handling="none")
    doc = json.loads((tmp_path / "out" / "metrics.json").read_text())
    (row,) = doc["methods"][0]["rows"]
    store = DatasetStore.open(data)
    refs = References(base, store.references(name))
    pred = Animator(root / "lbs").animate(store.motion(store.sequence(name).motion)).astype(np.float64)
    assert row["floor_mm"] == pytest.approx(refs.floor_mm, rel=1e-6) and row["references"] == 3
    assert row["rmse_mm"] == pytest.approx(1000 * np.sqrt(np.mean(np.sum((pred - base) ** 2, -1))), rel=1e-5)
    assert row["rmse_vs_mean_mm"] == pytest.approx(1000 * np.sqrt(np.mean(np.sum((pred - refs.mean) ** 2, -1))),
                                                   rel=1e-5)
    assert doc["methods"][0]["pooled"]["floor_mm"] == pytest.approx(refs.floor_mm, rel=1e-6)
    md = (tmp_path / "out" / "report.md").read_text()
    assert "RMSE vs mean mm | vs mean, corrected mm | floor mm |" in md and f"{row['floor_mm']:.2f}" in md and "reference runs" in md


def test_figures_are_real_images(report, tiny_store):
    _, out = report
    for plot in json.loads((out / "metrics.json").read_text())["plots"]:
        curve = iio.imread(out / plot["plot"])
        assert curve.shape[:2] == (320, 700) and curve.std() > 10
        emap = iio.imread(out / plot["map"])
        assert emap.shape[:2] == (400, 3 * 320)  # simulation, body-LBS, JointNet
        # the error panels are coloured (inferno), the simulation panel is not: colour spread per pixel
        spread = emap[..., :3].max(-1).astype(int) - emap[..., :3].min(-1)
        assert spread[:, 320:].mean() > spread[:, :320].mean()
        assert f'src="{plot["map"]}"' in (out / "index.html").read_text()


def test_claims_and_speed_tables_carry_the_benchmark_results(report):
    _, out = report
    doc = json.loads((out / "metrics.json").read_text())
    accuracy = json.loads((REPO / "benchmarks/results/accuracy-large-skirt.json").read_text())["results"]["targets"]
    jn = next(t for t in accuracy if t["target"].startswith("JointNet RMSE / VirtualBones RMSE"))
    row = next(c for c in doc["claims"] if c["target"] == jn["target"])
    assert row["paper"] == "JointNet" and row["ours"] == jn["measured"] and row["pass"] is jn["pass"]
    assert "benchmarks/accuracy.py" in row["command"] and "--garments skirt+average" in row["command"]
    fitgar = next(c for c in doc["claims"] if c["paper"] == "FitGar")
    assert fitgar["pass"] is None and "not run" in fitgar["source"]
    speed = json.loads((REPO / "benchmarks/results/speed.json").read_text())["results"]["garments"][0]
    lbs = next(r for r in doc["speed"] if r["garment"] == speed["label"] and r["method"] == "body-lbs")
    assert lbs["stream_fps"] == speed["methods"]["body-lbs"]["stream_fps"]
    assert f"{lbs['stream_fps']:.1f}" in (out / "index.html").read_text()
    md = (out / "report.md").read_text()
    assert f"| {jn['measured']:.3f} | {jn['limit']:g} | {'pass' if jn['pass'] else 'FAIL'} |" in md


def test_measure_speed_times_the_runs_own_models(report, tiny_store, tmp_path):
    root, out = report
    assert "were not timed" in (out / "index.html").read_text()  # not asked: said so, nothing measured
    assert json.loads((out / "metrics.json").read_text())["own_speed"] == []
    build_report(tiny_store, [root / "lbs", root / "jn"], tmp_path / "s", results_dir=None, images=False,
                 handling="none", measure_speed=True)
    doc = json.loads((tmp_path / "s" / "metrics.json").read_text())
    html, md = (tmp_path / "s" / "index.html").read_text(), (tmp_path / "s" / "report.md").read_text()
    store = DatasetStore.open(tiny_store)
    (name,) = store.sequence_names(split="test")
    vertices = store.sequence(name).verts.shape[1]
    assert [r["method"] for r in doc["own_speed"]] == ["body-lbs", "jointnet"]
    for row, run in zip(doc["own_speed"], (root / "lbs", root / "jn")):
        assert row["run"] == str(run) and row["vertices"] == vertices and name in row["source"]
        assert row["parameters"] == sum(p.numel() for p in Animator(run).model.parameters())
        assert 0 < row["stream_fps"] < 1e6 and 0 < row["batch_fps"] < 1e6
        assert f"{row['stream_fps']:.1f}" in html and f"{row['batch_fps']:.1f}" in md
    assert "measured now on this machine" in html and "were not timed" not in html


def test_bad_input_names_the_problem(report, tiny_store, tmp_path, capsys):
    root, out = report
    other = tmp_path / "other"
    shutil.copytree(root / "lbs", other)
    meta = json.loads((other / "model.json").read_text())
    (other / "model.json").write_text(json.dumps({**meta, "garment": "dress+average"}))
    with pytest.raises(InputError, match=r"other.*garment 'dress\+average'"):
        build_report(tiny_store, [other], tmp_path / "r", results_dir=None)
    assert main(["report", str(tiny_store), str(tmp_path / "missing"), "--out", str(tmp_path / "r")]) == 2
    assert "missing: run folder not found" in capsys.readouterr().err
    with pytest.raises(InputError, match="no sequence"):
        build_report(tiny_store, [root / "lbs"], tmp_path / "r", sequences=["nope"], results_dir=None)
    assert (out / "index.html").is_file()  # an earlier report is untouched


def test_collision_targets_read_as_the_others(tmp_path):
    """``benchmarks/collision.py``'s targets (``KIND: text``, a value or an (ours, baseline) pair) enter the
    claims table: the kind as the garment, a pair as its ratio."""
    from loosefit.report.claims import claims_table

    targets = [{"target": "dress: Eq. 10 (neural) removes >= 80% of the collisions left by the collision loss alone",
                "value": 0.9, "pass": True},
               {"target": "dress: d_cons of Eq. 10 (neural) below push-out's", "value": [0.3, 0.6], "pass": True}]
    (tmp_path / "collision-garments.json").write_text(json.dumps({"results": {"targets": targets}}))
    rows = {r["target"][:8]: r for r in claims_table(tmp_path) if r["source"] == "collision-garments.json"}
    assert rows["Eq. 10 ("]["garment"] == "dress" and rows["Eq. 10 ("]["ours"] == 0.9
    assert rows["d_cons o"]["ours"] == pytest.approx(0.5) and rows["d_cons o"]["limit"] == 1.0
