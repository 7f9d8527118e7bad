"""``loosefit train`` end to end on a real simulated, prepared dataset."""

import json
import logging
import shutil

import numpy as np
import pytest
import torch

from loosefit.animate import Animator
from loosefit.errors import InputError
from loosefit.models.motion_features import MotionHistory
from loosefit.rig.prepare import prepare
from loosefit.training import METHOD_CONFIG, MODEL_META, StaleRunError, train_model

SMALL_JOINTNET = ["model.gru_hidden=16", "model.features=16", "model.bone_mlp=[32]", "model.psd_mlp=[16]",
                  "model.psd_shapes=4", "train.stages.stage1.epochs=2", "train.stages.stage2.epochs=1",
                  "train.progress=false", "train.tensorboard=false", "data.window=20", "data.stride=10", "data.burn_in=4"]


def test_train_writes_a_self_contained_run(tiny_store, tmp_path, caplog):
    """The tiny store has no val split: the run trains without validation, says so, and keeps no best.pt. The
    motion history set in the config travels with the run."""
    run = tmp_path / "jn"
    history = ["model.history_frames=[4, 60]", "model.history_vertical=true"]
    with caplog.at_level(logging.WARNING, logger="loosefit.train.validation"):
        result = train_model("jointnet", tiny_store, "skirt+average", run, overrides=SMALL_JOINTNET + history)
    assert "training without validation" in caplog.text
    meta = json.loads((run / MODEL_META).read_text())
    assert meta["method"] == "jointnet" and meta["sizes"]["num_verts"] > 100
    assert meta["train_sequences"] == ["skirt+average+spin+default", "skirt+average+walk+default"]
    assert meta["val_sequences"] == [] and meta["validation"]["source"] == "none"
    assert (run / METHOD_CONFIG).exists() and (run / "checkpoints" / "last.pt").exists()
    assert result.val_metrics == {} and not (run / "checkpoints" / "best.pt").exists()
    # The run folder alone rebuilds the model (no dataset needed); "best" falls back to the last checkpoint.
    animator = Animator(run)
    assert animator.faces.shape[1] == 3
    assert animator.history == MotionHistory((4.0, 60.0), vertical=True) and meta["sizes"]["root_features"] == 11 + 8


def _weights(model):
    return {k: v.detach().clone() for k, v in model.state_dict().items()}


def test_carved_validation_selects_the_checkpoint_animation_uses(tiny_store, tmp_path):
    """``loosefit train --val-motions spin``: spin validates instead of training, never the test motion sway;
    animation loads best.pt by default and last.pt when asked."""
    from loosefit.cli import main
    from loosefit.train.run import load_checkpoint

    run = tmp_path / "jn"
    options = ["train", "--method", "jointnet", "--data", str(tiny_store), "--garment", "skirt+average"]
    sets = [x for o in SMALL_JOINTNET for x in ("--set", o)]
    assert main([*options, "--out", str(run), *sets, "--set", "train.stages.stage2.epochs=3", "--val-motions", "spin"]) == 0
    meta = json.loads((run / MODEL_META).read_text())
    assert meta["train_sequences"] == ["skirt+average+walk+default"]
    assert meta["val_sequences"] == ["skirt+average+spin+default"]
    assert meta["validation"]["source"] == "carved" and meta["validation"]["motions"] == ["spin"]
    best, last = (load_checkpoint(run / "checkpoints" / f"{n}.pt") for n in ("best", "last"))
    rows = [r for r in last["history"] if r["stage"] == "stage2"]  # best.pt is chosen within the last stage
    val = [r["val_rmse_mm"] for r in rows]
    assert best["best_metric"] == min(val) and best["epoch"] == rows[val.index(min(val))]["epoch"]
    for checkpoint, state in (("best", best), (None, best), ("last", last)):
        animator = Animator(run) if checkpoint is None else Animator(run, checkpoint=checkpoint)
        loaded = _weights(animator.model)
        assert all(torch.equal(loaded[k], state["model"][k]) for k in state["model"]), checkpoint
    # a test motion never validates unless the test split is named
    assert main([*options, "--out", str(tmp_path / "bad"), *sets, "--val-motions", "sway"]) == 2
    assert not (tmp_path / "bad" / "model.json").exists()


def test_the_test_split_validates_only_when_named(tiny_store, tmp_path, caplog):
    run = tmp_path / "jn"
    with caplog.at_level(logging.WARNING, logger="loosefit.train.validation"):
        result = train_model("jointnet", tiny_store, "skirt+average", run, val_split="test",
                             overrides=[*SMALL_JOINTNET, "train.stages.stage1.epochs=1"])
    assert "TEST split" in caplog.text
    assert json.loads((run / MODEL_META).read_text())["val_sequences"] == ["skirt+average+sway+default"]
    assert np.isfinite(result.val_metrics["rmse_mm"])


def test_fixed_baseline_gets_a_checkpoint(tiny_store, tmp_path):
    assert train_model("body-lbs", tiny_store, "skirt+average", tmp_path / "lbs") is None
    animator = Animator(tmp_path / "lbs")
    assert animator.method == "body-lbs"


def test_bad_method_and_garment(tiny_store, tmp_path):
    with pytest.raises(InputError, match="unknown method"):
        train_model("tailornet", tiny_store, "skirt+average", tmp_path / "x")
    with pytest.raises(InputError, match="no garment 'gown'"):
        train_model("jointnet", tiny_store, "gown", tmp_path / "y", overrides=SMALL_JOINTNET)


def test_a_training_fraction_is_for_per_garment_methods(tiny_store, tmp_path):
    """The CLI passes --train-fraction through (recorded in the run's validation note); SwinGar refuses it."""
    from loosefit.cli import main

    run = tmp_path / "jn"
    sets = [x for o in SMALL_JOINTNET for x in ("--set", o)]
    assert main(["train", "--method", "jointnet", "--data", str(tiny_store), "--garment", "skirt+average",
                 "--out", str(run), *sets, "--set", "train.stages.stage2.epochs=0", "--train-fraction", "0.5"]) == 0
    assert "fraction 0.5 of each kind" in json.loads((run / MODEL_META).read_text())["validation"]["note"]
    with pytest.raises(InputError, match="a training fraction is for the per-garment methods"):
        train_model("swingar", tiny_store, None, tmp_path / "sg", train_fraction=0.5)


def test_resume_refuses_a_run_of_other_data(tiny_store, tmp_path):
    run = tmp_path / "jn"
    train_model("jointnet", tiny_store, "skirt+average", run, overrides=SMALL_JOINTNET)
    # the same data resumes (the finished run is reloaded, nothing lost)
    before = (run / "checkpoints" / "last.pt").read_bytes()
    train_model("jointnet", tiny_store, "skirt+average", run, overrides=SMALL_JOINTNET, resume=True)
    assert (run / "checkpoints" / "last.pt").read_bytes() == before
    # the store prepared again with other rig settings: refused, naming the run, the run kept
    again = tmp_path / "again.zarr"
    shutil.copytree(tiny_store, again)
    prepare(again, bones=6, progress=False)
    with pytest.raises(StaleRunError, match="rig differ") as e:
        train_model("jointnet", again, "skirt+average", run, overrides=SMALL_JOINTNET, resume=True)
    assert str(run) in str(e.value)
    assert (run / "checkpoints" / "last.pt").read_bytes() == before
    # the same data in another frame is another model: refused too, naming the setting (the run records its frame)
    assert json.loads((run / MODEL_META).read_text())["sizes"]["frame"] == "raised"  # the default
    with pytest.raises(InputError, match="model.frame: 'raised' in the run, 'heading' now"):
        train_model("jointnet", tiny_store, "skirt+average", run, resume=True,
                    overrides=[*SMALL_JOINTNET, "model.frame=heading"])
    assert (run / "checkpoints" / "last.pt").read_bytes() == before



def test_a_run_made_before_a_default_changed_resumes_only_with_its_former_value(tiny_store, tmp_path):
    """A run whose method.yaml predates ``model.frame`` and ``model.pose_noise`` was trained in the heading frame
    without pose noise: resuming it under today's defaults (raised, 0.5) would train it on other targets in silence.
    Refused, naming both; given its former values it resumes."""
    import yaml

    run = tmp_path / "vb"
    small = ["model.lf_hidden=8", "model.hf_hidden=8", "model.global_channels=2", "model.edge_channels=[4]",
             "train.stages.low.epochs=1", "train.stages.high.epochs=1", "train.progress=false",
             "train.tensorboard=false", "model.frame=heading", "model.pose_noise=0"]
    train_model("virtualbones", tiny_store, "skirt+average", run, overrides=small)
    saved = yaml.safe_load((run / "method.yaml").read_text())
    del saved["model"]["frame"], saved["model"]["pose_noise"]  # as a run made before either existed
    (run / "method.yaml").write_text(yaml.safe_dump(saved, sort_keys=False))
    written = (run / "method.yaml").read_bytes()
    today = [o for o in small if not o.startswith(("model.frame", "model.pose_noise"))]
    with pytest.raises(InputError, match="model.frame: 'heading' in the run, 'raised' now; model.pose_noise: 0.0 in "
                                         "the run, 0.5 now"):
        train_model("virtualbones", tiny_store, "skirt+average", run, overrides=today, resume=True)
    assert (run / "method.yaml").read_bytes() == written
    train_model("virtualbones", tiny_store, "skirt+average", run, overrides=small, resume=True)  # its own values
