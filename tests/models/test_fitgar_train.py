"""FitGar on a multi-garment store: the frame dataset, `loosefit train --method fitgar`, the fit attribute
of a new garment from the stored factor model."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.models.fitgar_data import GarmentFrames, Smoother
from loosefit.motion.heading import heading_frames, to_canonical

from .fitgar_fixtures import TINY, TINY_CONFIG, synthetic_store


@pytest.fixture(scope="module")
def store(body, tmp_path_factory):
    return synthetic_store(tmp_path_factory.mktemp("fitgar") / "garments.zarr", body)


def test_frames_of_every_garment_body_and_motion(store, body):
    from loosefit.data.store import DatasetStore

    data = GarmentFrames(store, "train", body=body)
    s = DatasetStore.open(store)
    names = s.sequence_names(split="train")
    assert data.sequence_names == names and len(names) == 4
    assert len(data) == sum(s.sequence(n).num_frames for n in names)
    assert len(data.pairs) == 3  # skirt+average, skirt+heavy, dress+average
    assert data.sizes == {"num_joints": 31, "num_shape": 6, "num_fit_factors": 2, "pose_features": 186}
    # an item: the stored frame in the heading frame, and its fitgar smoothing
    k = len(data) - 1
    i, t = data.index[k]
    seq = s.sequence(data.sequences[i]["name"])
    rot, origin = heading_frames(s.motion(seq.motion))
    item = data[k]
    expected = to_canonical(seq.verts[t:t + 1], rot[t:t + 1], origin[t:t + 1])[0]
    np.testing.assert_allclose(item["verts"], expected, atol=1e-6)
    garment = s.garment(seq.garment)
    np.testing.assert_allclose(item["smooth"], Smoother(garment.faces, len(garment.verts), garment.pinned)(expected),
                               atol=1e-6)
    assert item["anchor"].shape == item["verts"].shape == (len(garment.verts), 3)
    assert np.abs(item["smooth"] - item["verts"]).max() > 1e-3  # the ripple is smoothed out
    assert np.abs(item["smooth"] - item["verts"])[garment.pinned].max() == 0  # pinned vertices kept
    strided = GarmentFrames(store, "train", body=body, frame_stride=4)
    assert len(strided) == sum(-(-s.sequence(n).num_frames // 4) for n in names)
    # a held-pose store's settled frames: the last of every block of 4
    settled = GarmentFrames(store, "train", body=body, frame_stride=4, frame_offset=3)
    assert [t for _, t in settled.index] == [t for n in names for t in range(3, s.sequence(n).num_frames, 4)]
    for offset in (-1, 4):
        with pytest.raises(InputError, match="frame_offset must be in"):
            GarmentFrames(store, "train", body=body, frame_stride=4, frame_offset=offset)


def test_unprepared_or_empty(store, body, tmp_path):
    from loosefit.data.store import DatasetStore

    with pytest.raises(InputError, match="no val sequences"):
        GarmentFrames(store, "val", body=body)
    DatasetStore.create(tmp_path / "empty.zarr")
    with pytest.raises(InputError, match="prepare"):
        GarmentFrames(tmp_path / "empty.zarr", "train", body=body)


@pytest.fixture(scope="module")
def run(store, tmp_path_factory):
    """``loosefit train --method fitgar`` on the store with the tiny config."""
    from loosefit.cli import main

    out = tmp_path_factory.mktemp("fitgar-run") / "run"
    # validated on the held-out dress: the store has no val split
    assert main(["train", "--method", "fitgar", "--data", str(store), "--out", str(out), "--config", str(TINY_CONFIG),
                 "--val-split", "test"]) == 0
    return out


def test_loosefit_train_fitgar(store, run, body):
    """The CLI trains both stages on the store, validates on the held-out dress, writes a run folder that
    rebuilds the model; the coarse loss falls over the epochs."""
    from loosefit.models.fitgar import FitGar
    from loosefit.rig.prepared import load_fit_attribute
    from loosefit.train.run import load_weights

    out = run
    rows = list(csv.DictReader((out / "metrics.csv").open()))
    assert [r["stage"] for r in rows] == ["coarse"] * 20 + ["detail"] * 4
    coarse = [float(r["train_coarse"]) for r in rows[:20]]
    assert coarse[-1] < 0.5 * coarse[0], coarse
    assert float(rows[-1]["val_detail_error_mm"]) > 0 and float(rows[-1]["val_coarse_error_mm"]) > 0
    meta = json.loads((out / "model.json").read_text())
    assert meta["method"] == "fitgar" and meta["garment"] is None
    assert meta["val_sequences"] == ["dress+average+sway+default"]
    # the folder alone rebuilds the model; its factor model gives a new pair's fit attribute
    from loosefit.config import load_config
    from loosefit.models.fitgar import Config

    cfg = load_config(Config, out / "method.yaml")
    assert cfg.model == TINY
    model = FitGar(meta["sizes"], cfg.model)
    load_weights(model, out / "checkpoints" / "last.pt")
    stored, alphas = load_fit_attribute(store)
    from loosefit.garment import make_garment

    new = make_garment("long_shirt", body, seed=2, edge_length=0.06)
    alpha = model.fit_attribute_model().attribute(new.verts, new.faces, body.rest_verts())
    np.testing.assert_allclose(alpha, stored.attribute(new.verts, new.faces, body.rest_verts()), rtol=1e-6)
    assert alpha.shape == (2,)
    # a training pair's attribute recomputed from the checkpoint is the one prepare stored
    from loosefit.data.store import DatasetStore

    skirt = DatasetStore.open(store).garment("skirt+average")
    np.testing.assert_allclose(model.fit_attribute_model().attribute(skirt.verts, skirt.faces, body.rest_verts()),
                               alphas[("skirt+average", "average")], rtol=1e-5, atol=1e-6)


def test_train_fitgar_refuses_a_garment(store, tmp_path):
    from loosefit.training import train_model

    with pytest.raises(InputError, match="every garment"):
        train_model("fitgar", store, "skirt+average", tmp_path / "run")


@pytest.fixture(scope="module")
def heavy_case(body):
    """A garment the model never saw (a long shirt) on a body shape it never saw, and a short motion."""
    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.garment import make_garment
    from loosefit.motion.procedural import generate

    shape = "weight=0.7,height=0.6"
    heavy = AnnyBody(AnnyShape.parse(shape))
    return shape, heavy, make_garment("long_shirt", heavy, seed=0, edge_length=0.06), generate("turn", 0.4, 0, body)


def test_animate_any_garment_frame_by_frame(run, heavy_case):
    from loosefit.animate_any import AnyGarmentAnimator, is_static_run

    shape, heavy, garment, motion = heavy_case
    assert is_static_run(run) and not is_static_run(run.parent)
    animator = AnyGarmentAnimator(run)
    pair = animator.pair(garment.verts, garment.faces, heavy)
    verts = animator.animate(pair, motion)
    assert verts.shape == (motion.num_frames, len(garment.verts), 3) and np.isfinite(verts).all()
    # a static method: frames alone, in other batches, or a slice of the motion give the same vertices
    one = AnyGarmentAnimator(run, frames_per_pass=1).animate(pair, motion)
    np.testing.assert_allclose(one, verts, atol=1e-5)
    part = animator.animate(pair, motion.slice(5, 9))
    np.testing.assert_allclose(part, verts[5:9], atol=1e-5)
    coarse = animator.animate(pair, motion, output="coarse")
    assert 0 < np.abs(coarse - verts).max() < 0.5
    # the garment follows the body: mean distance to the posed body vertices under it is a few cm, not metres
    posed = heavy.pose(motion).verts[:, pair.nearest]
    assert np.linalg.norm(verts - posed, axis=-1).mean() < 0.3
    with pytest.raises(InputError, match="output"):
        animator.animate(pair, motion, output="lf")


def test_a_run_recorded_before_surface_anchors_animates_on_its_own_anchors(run, heavy_case, tmp_path):
    """Its sizes name no anchor: it was trained on closest-vertex anchors. The animator builds pairs on those
    (so `loosefit animate` still animates it); frames built on the surface are refused with a clear error."""
    import shutil

    from loosefit.animate_any import AnyGarmentAnimator
    from loosefit.models.fitgar_inputs import GarmentBodyPair

    assert json.loads((run / "model.json").read_text())["sizes"]["anchor"] == "spread"
    old = tmp_path / "old"
    shutil.copytree(run, old)
    meta = json.loads((old / "model.json").read_text())
    del meta["sizes"]["anchor"]
    (old / "model.json").write_text(json.dumps(meta))
    shape, heavy, garment, motion = heavy_case
    animator = AnyGarmentAnimator(old)
    pair = animator.pair(garment.verts, garment.faces, heavy)
    vertex = GarmentBodyPair.build(garment.verts, garment.faces, heavy, heavy.shape.to_array(), pair.alpha,
                                   anchor="vertex")
    assert np.array_equal(pair.rest_anchors(), vertex.rest_anchors())
    assert np.isfinite(animator.animate(pair, motion)).all()
    projected = GarmentBodyPair.build(garment.verts, garment.faces, heavy, heavy.shape.to_array(), pair.alpha)
    with pytest.raises(InputError, match="trained on 'vertex' anchors .*recorded before.*built with 'spread'"):
        animator.animate(projected, motion)


def test_a_model_trained_elsewhere_saves_as_a_run(store, run, heavy_case, tmp_path):
    """A benchmark's own training loop keeps its model as a run folder: the CLI run's model saved again
    animates to the same vertices, and the folder records its data and no validation."""
    from loosefit.animate import load_run
    from loosefit.animate_any import AnyGarmentAnimator
    from loosefit.training import save_trained_frames_run

    meta, model, cfg = load_run(run)
    data = GarmentFrames(store, "train", names=meta["train_sequences"])
    saved = save_trained_frames_run(tmp_path / "saved", "fitgar", model, cfg, data, store).path
    again = json.loads((saved / "model.json").read_text())
    assert again["sizes"] == meta["sizes"] and again["train_sequences"] == meta["train_sequences"]
    assert again["validation"]["source"] == "none" and again["val_sequences"] == []
    shape, heavy, garment, motion = heavy_case
    verts = []
    for folder in (run, saved):
        animator = AnyGarmentAnimator(folder)
        verts.append(animator.animate(animator.pair(garment.verts, garment.faces, heavy), motion))
    np.testing.assert_array_equal(verts[1], verts[0])


def test_loosefit_animate_cli(run, heavy_case, tmp_path):
    from loosefit.cli import main
    from loosefit.io.mesh_sequence import MeshSequence

    shape, heavy, garment, motion = heavy_case
    garment.save(tmp_path / "shirt.obj")
    motion.save(tmp_path / "turn.npz")
    out = tmp_path / "anim.npz"
    args = ["animate", str(run), "--motion", str(tmp_path / "turn.npz"), "--shape", shape, "--out", str(out)]
    assert main(args) == 2  # no --garment
    assert main(args + ["--garment", str(tmp_path / "shirt.obj")]) == 0
    seq = MeshSequence.load(out)
    assert seq.verts.shape == (motion.num_frames, len(garment.verts), 3)
    assert np.array_equal(seq.faces, garment.faces)


def test_resume_of_a_finished_run_trains_no_further(store, run):
    from loosefit.training import train_model

    before = (run / "checkpoints" / "last.pt").read_bytes()
    result = train_model("fitgar", store, None, run, config=TINY_CONFIG, resume=True, val_split="test")
    assert result.global_step == json.loads((run / "run.json").read_text())["global_step"]
    assert (run / "checkpoints" / "last.pt").read_bytes() == before
