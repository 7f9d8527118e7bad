"""Evaluation report: pooled overall values, table, CSV / JSON files, file and dataset inputs; penetration on the
surface and the bounded surface quality against closed forms."""

import csv
import json
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from loosefit.data import DatasetStore
from loosefit.errors import InputError
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.metrics.errors import hausdorff_mm, rmse_mm
from loosefit.metrics.report import (
    EvaluationSettings,
    SequencePair,
    evaluate,
    load_pairs,
    pairs_from_files,
    pairs_from_store,
)
from loosefit.metrics.sted import sted
from tests.metrics.conftest import TRIANGLE, box_depth, fold, strip

SPHERE = trimesh.creation.icosphere(1, radius=0.3)
V, F = np.asarray(SPHERE.vertices), np.asarray(SPHERE.faces)


def sequence(frames, seed, noise=0.005):
    rng = np.random.default_rng(seed)
    gt = V[None] + np.linspace(0, 0.1, frames)[:, None, None] * [0, 1.0, 0] + [0, 0, 1.0]
    return (gt + rng.normal(0, noise, gt.shape)).astype(np.float32), gt.astype(np.float32)


def test_overall_pools_all_frames_and_table_lists_sequences(tmp_path):
    (p1, g1), (p2, g2) = sequence(6, 0), sequence(3, 1, noise=0.02)
    ev = evaluate([SequencePair("a", p1, g1, F), SequencePair("b", p2, g2, F)], progress=False)
    assert [r["name"] for r in ev.rows] == ["a", "b"]
    row = ev.rows[0]
    assert row["rmse_mm"] == pytest.approx(rmse_mm(p1, g1)) and row["hausdorff_mm"] == pytest.approx(hausdorff_mm(p1, g1))
    assert row["sted"] == pytest.approx(sted(p1, g1, F).combined) and row["collision_pct"] is None
    # Overall RMSE is the RMSE of all frames together, not the mean of the two.
    assert ev.overall["rmse_mm"] == pytest.approx(rmse_mm(np.concatenate([p1, p2]), np.concatenate([g1, g2])))
    assert ev.overall["hausdorff_mm"] == pytest.approx((6 * row["hausdorff_mm"] + 3 * ev.rows[1]["hausdorff_mm"]) / 9)
    assert ev.overall["frames"] == 9
    table = ev.table()
    assert "overall" in table and "STED" in table and "collision" not in table
    per_method = ev.table(overall=False).splitlines()
    assert len(per_method) == 4 and "overall" not in "\n".join(per_method)  # header, rule, a, b
    ev.write_csv(tmp_path / "m.csv")
    ev.write_json(tmp_path / "m.json")
    rows = list(csv.DictReader(open(tmp_path / "m.csv")))
    assert [r["name"] for r in rows] == ["a", "b", "overall"]
    assert float(rows[2]["rmse_mm"]) == pytest.approx(ev.overall["rmse_mm"])
    doc = json.loads((tmp_path / "m.json").read_text())
    assert doc["overall"]["frames"] == 9 and doc["settings"]["sted_dt"] == 0.3 and len(doc["sequences"]) == 2


def test_files_directories_body_and_single_frame(tmp_path):
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    for name, seed, frames in (("walk", 0, 4), ("pose", 1, 1)):
        pred, gt = sequence(frames, seed)
        body = np.repeat(np.asarray(box.vertices)[None] + [0, 0, 1.0], frames, 0)
        MeshSequence(gt, F, extra={"body_verts": body, "body_faces": np.asarray(box.faces)}).save(tmp_path / "gt" / f"{name}.npz")
        MeshSequence(pred, F).save(tmp_path / "pred" / f"{name}.npz")
    ev = evaluate(load_pairs(tmp_path / "pred", tmp_path / "gt"), progress=False)
    by_name = {r["name"]: r for r in ev.rows}
    # The 0.3 m sphere sits inside the 1 m box: every vertex collides.
    assert by_name["pose"]["collision_pct"] == pytest.approx(100.0)
    assert by_name["pose"]["sted_temporal"] is None and by_name["walk"]["sted_temporal"] is not None
    assert ev.overall["sted_temporal"] == pytest.approx(by_name["walk"]["sted_temporal"])
    single = pairs_from_files(tmp_path / "pred" / "walk.npz", tmp_path / "gt" / "walk.npz")
    assert len(single) == 1 and single[0].name == "walk" and single[0].body_verts.shape == (4, 8, 3)

    (tmp_path / "pred" / "pose.npz").unlink()
    with pytest.raises(InputError, match=r"no prediction .*pose"):
        pairs_from_files(tmp_path / "pred", tmp_path / "gt")
    MeshSequence(sequence(4, 0)[0], F[:, ::-1]).save(tmp_path / "flipped.npz")
    with pytest.raises(InputError, match="triangles differ"):
        pairs_from_files(tmp_path / "flipped.npz", tmp_path / "gt" / "walk.npz")
    with pytest.raises(InputError, match="sequence names"):
        load_pairs(tmp_path / "pred", tmp_path / "gt", names=["walk"])
    with pytest.raises(InputError, match="mesh-sequence"):
        pairs_from_files(tmp_path / "nothing.obj", tmp_path / "gt")


def test_dataset_sequences_as_ground_truth(tmp_path):
    store = DatasetStore.create(tmp_path / "data.zarr")
    garment = SimpleNamespace(verts=V.astype(np.float32), faces=F, pinned=np.zeros(len(V), bool), kind="test", params={}, name="ball")
    store.add_garment("ball", garment)
    store.add_body("b", np.full(6, 0.5, np.float32))
    from loosefit.motion import Motion

    store.add_motion("m", Motion(np.zeros((5, 31, 3)), np.zeros((5, 3)), joint_names=[f"j{i}" for i in range(31)]))
    pred, gt = sequence(5, 2)
    store.write_sequence("s1", gt, garment="ball", body="b", motion="m", sim_params={}, stats={}, split="test")
    MeshSequence(pred, F).save(tmp_path / "pred" / "s1.npz")
    pairs = load_pairs(tmp_path / "pred", tmp_path / "data.zarr")
    assert [p.name for p in pairs] == ["s1"] and np.array_equal(pairs[0].gt, gt) and pairs[0].body_verts is None
    assert evaluate(pairs, progress=False).rows[0]["rmse_mm"] == pytest.approx(rmse_mm(pred, gt), rel=1e-6)
    with pytest.raises(InputError, match="no sequences"):
        pairs_from_store(tmp_path / "data.zarr", tmp_path / "pred", split="train")
    with pytest.raises(InputError, match="no prediction"):
        pairs_from_store(tmp_path / "data.zarr", tmp_path / "data.zarr")


def test_methods_on_one_posed_body_share_its_distance_field():
    """Several predictions of one motion (one body array) are measured together, frame by frame; each pair's
    collision percentage equals the one measured alone, and a pair with another body is measured alone."""
    box = trimesh.creation.box(extents=(0.62, 0.62, 0.62))
    body = np.repeat(np.asarray(box.vertices)[None] + [0, 0, 1.0], 4, 0) + np.linspace(0, 0.05, 4)[:, None, None]
    faces = np.asarray(box.faces)
    preds = [sequence(4, seed, noise=0.03) for seed in range(3)]
    pairs = [SequencePair(f"m{k}", p, g, F, body, faces) for k, (p, g) in enumerate(preds)]
    pairs.append(SequencePair("other body", preds[0][0], preds[0][1], F, body.copy(), faces))
    keys = ("collision_pct", "surface_inside_pct", "deepest_mm")
    together = [[r[k] for k in keys] for r in evaluate(pairs, progress=False).rows]
    alone = [[evaluate([p], progress=False).rows[0][k] for k in keys] for p in pairs]
    assert together == alone and together[0] == together[3]
    collision = [c for c, _, _ in together]
    assert len(set(collision[:3])) == 3 and all(0 < c < 100 for c in collision)  # the noise moves vertices across


BOX = trimesh.creation.box(extents=(1.0, 1.0, 1.0))


def test_surface_penetration_columns_of_a_triangle_across_a_box(tmp_path):
    """The triangle's corners are outside the box, two edge midpoints and its centroid inside (0.3 m deep): collision
    0, the surface share that of the 4 samples deeper than the depth (by the box's depth formula), deepest 300 mm.
    A second sequence, lifted off the box, pools by frames x samples; the deepest is the deepest of all."""
    from loosefit.metrics.collision import surface_samples

    faces = np.array([[0, 1, 2]])
    tri = np.repeat(TRIANGLE[None], 3, 0)
    body = np.repeat(np.asarray(BOX.vertices)[None], 3, 0)
    samples = surface_samples(TRIANGLE, faces)
    for depth in (0.005, 0.1):
        ev = evaluate([SequencePair("across", tri, tri, faces, body, np.asarray(BOX.faces))],
                      EvaluationSettings(surface_depth=depth), progress=False)
        (row,) = ev.rows
        assert row["collision_pct"] == 0.0 and row["surface_samples"] == 4
        assert row["surface_inside_pct"] == pytest.approx(100.0 * (box_depth(samples) > depth).mean())  # 75, 25
        assert row["deepest_mm"] == pytest.approx(300.0, abs=1e-3)
        assert f"surface >{1000 * depth:g}mm %" in ev.table()
    lifted = SequencePair("lifted", tri[:1] + [0, 0, 2.0], tri[:1], faces, body[:1], np.asarray(BOX.faces))
    ev = evaluate([SequencePair("across", tri, tri, faces, body, np.asarray(BOX.faces)), lifted], progress=False)
    assert ev.rows[1]["surface_inside_pct"] == 0.0 and ev.rows[1]["deepest_mm"] == 0.0
    assert ev.overall["surface_inside_pct"] == pytest.approx((3 * 75.0 + 1 * 0.0) / 4)
    assert ev.overall["deepest_mm"] == pytest.approx(300.0, abs=1e-3)
    ev.write_json(tmp_path / "m.json")
    doc = json.loads((tmp_path / "m.json").read_text())
    assert doc["settings"]["surface_depth"] == 0.005 and doc["overall"]["deepest_mm"] == pytest.approx(300.0, abs=1e-3)
    # without a body there is nothing to be inside
    plain = evaluate([SequencePair("no body", tri, tri, faces)], progress=False).rows[0]
    assert plain["surface_inside_pct"] is None and plain["deepest_mm"] is None


def test_collapsed_and_roughness_columns_pool_by_faces_and_interior_edges():
    """A strip of 3 squares (6 triangles, 5 interior edges) with one triangle flipped in one of its 2 frames, and a
    strip of 5 (10 triangles, 9 interior edges) folded by 60 degrees along a rung in each of its 4 frames:
    collapsed 1 / 12 and 0 %, roughness 180 / 10 (the flipped triangle folds its diagonal flat onto its neighbour) and
    60 / 9 degrees; pooled by frames x faces and frames x interior edges."""
    flat3, faces3 = strip(3)
    flipped = flat3.copy()
    flipped[3 + 1] = [1.0, 0.0, 0.0]  # t_0 mirrored across the diagonal b_0-t_1
    flat5, faces5 = strip(5)
    folded = fold(flat5, 2.0, 60.0)
    pairs = [SequencePair("flip", np.stack([flipped, flat3]), np.stack([flat3, flat3]), faces3),
             SequencePair("fold", np.repeat(folded[None], 4, 0), np.repeat(flat5[None], 4, 0), faces5)]
    ev = evaluate(pairs, progress=False)
    flip, fold_row = ev.rows
    assert flip["collapsed_pct"] == pytest.approx(100.0 / 12) and fold_row["collapsed_pct"] == 0.0
    assert flip["interior_edges"] == 5 and fold_row["interior_edges"] == 9
    assert fold_row["roughness_deg"] == pytest.approx(60.0 / 9)
    # the flipped triangle's one interior edge, the diagonal b_0-t_1, folds by 180 degrees in one of two frames
    assert flip["roughness_deg"] == pytest.approx(180.0 / (2 * 5))
    assert ev.overall["collapsed_pct"] == pytest.approx(100.0 * 1 / (2 * 6 + 4 * 10))
    assert ev.overall["roughness_deg"] == pytest.approx((2 * 5 * flip["roughness_deg"] + 4 * 9 * 60.0 / 9) / (2 * 5 + 4 * 9))
    table = ev.table()
    assert "collapsed %" in table and "rough. deg" in table
    same = evaluate([SequencePair("same", flat5[None], flat5[None], faces5)], progress=False).rows[0]
    assert same["collapsed_pct"] == 0.0 and same["roughness_deg"] == 0.0
    single = evaluate([SequencePair("one", TRIANGLE[None], TRIANGLE[None], np.array([[0, 1, 2]]))], progress=False)
    assert single.rows[0]["roughness_deg"] is None and single.overall["roughness_deg"] is None
