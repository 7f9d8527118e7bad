"""``loosefit train`` end to end on a real simulated, prepared dataset."""

import json
import shutil

import numpy as np
import pytest

from loosefit.animate import Animator
from loosefit.errors import InputError
from loosefit.rig.prepare import prepare
from loosefit.training import METHOD_CONFIG, MODEL_META, StaleRunError, train_model

SMALL_JOINTNET = ["model.gru_hidden=16", "model.features=16", "model.bone_mlp=[32]", "model.psd_mlp=[16]",
                  "model.psd_shapes=4", "train.stages.stage1.epochs=2", "train.stages.stage2.epochs=1",
                  "train.progress=false", "train.tensorboard=false", "data.window=20", "data.stride=10", "data.burn_in=4"]


def test_train_writes_a_self_contained_run(tiny_store, tmp_path):
    run = tmp_path / "jn"
    result = train_model("jointnet", tiny_store, "skirt+average", run, overrides=SMALL_JOINTNET)
    meta = json.loads((run / MODEL_META).read_text())
    assert meta["method"] == "jointnet" and meta["sizes"]["num_verts"] > 100
    assert meta["train_sequences"] and meta["val_sequences"] == ["skirt+average+sway+default"]
    assert (run / METHOD_CONFIG).exists() and (run / "checkpoints" / "last.pt").exists()
    assert np.isfinite(result.val_metrics["rmse_mm"])
    # The run folder alone rebuilds the model (no dataset needed).
    assert Animator(run).faces.shape[1] == 3


def test_fixed_baseline_gets_a_checkpoint(tiny_store, tmp_path):
    assert train_model("body-lbs", tiny_store, "skirt+average", tmp_path / "lbs") is None
    animator = Animator(tmp_path / "lbs")
    assert animator.method == "body-lbs"


def test_bad_method_and_garment(tiny_store, tmp_path):
    with pytest.raises(InputError, match="unknown method"):
        train_model("tailornet", tiny_store, "skirt+average", tmp_path / "x")
    with pytest.raises(InputError, match="no garment 'gown'"):
        train_model("jointnet", tiny_store, "gown", tmp_path / "y", overrides=SMALL_JOINTNET)


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
