"""export-rig on real trained runs: Blender's glTF importer and USD's skinning play back the low-frequency
prediction of VirtualBones and JointNet (to float tolerance with the same truncated weights), the body as posed."""

import warnings

import numpy as np
import pytest
import torch
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel
from pygltflib import GLTF2
from pygltflib.validator import validate

from loosefit.animate import Animator
from loosefit.cli import main
from loosefit.data import DatasetStore
from loosefit.errors import InputError
from loosefit.export_rig import body_rig, export_rig, garment_rig
from loosefit.models.motion_features import motion_features
from loosefit.motion.heading import motion_frames, to_world
from loosefit.motion import Motion
from loosefit.training import train_model
from tests.io.conftest import blender_skinned_frames

QUIET = ["train.progress=false", "train.tensorboard=false", "data.window=20", "data.stride=10", "data.burn_in=4"]
SMALL = {
    "virtualbones": ["model.lf_hidden=16", "model.hf_hidden=16", "model.global_channels=4", "model.edge_channels=[8]",
                     "train.stages.low.epochs=1", "train.stages.high.epochs=1", *QUIET],
    "jointnet": ["model.gru_hidden=16", "model.features=16", "model.bone_mlp=[32]", "model.psd_mlp=[16]",
                 "model.psd_shapes=4", "train.stages.stage1.epochs=1", "train.stages.stage2.epochs=1", *QUIET],
}
FRAMES = 12  # frames exported (the first of the held-out motion)
FLOAT_TOLERANCE = 1e-5  # metres: float32 transforms and positions of a metre or two


@pytest.fixture(scope="module")
def runs(tiny_store, tmp_path_factory):
    root = tmp_path_factory.mktemp("rigs")
    for method, overrides in SMALL.items():
        train_model(method, tiny_store, "skirt+average", root / method, overrides=overrides)
    return root


@pytest.fixture(scope="module")
def motion(tiny_store):
    store = DatasetStore.open(tiny_store)
    return store.motion(store.sequence(store.sequence_names(split="test")[0]).motion).slice(0, FRAMES)


def _jointnet_low_frequency(run, motion):
    """JointNet's garment without its pose-space deformation: the bones' skinning of the rig, in the world."""
    model = Animator(run).model
    feats = motion_features(motion, model.history)
    with torch.no_grad():
        out = model(torch.from_numpy(feats["root"])[None], torch.from_numpy(feats["joints"])[None], psd=False)
    return to_world(out["verts"][0].numpy(), *motion_frames(motion, model.frame)).astype(np.float64)


def test_blender_plays_the_virtualbones_prediction(runs, motion, body, tmp_path):
    summary = export_rig(runs / "virtualbones", motion, tmp_path / "dress.glb", body=body, influences=4)
    played = blender_skinned_frames(tmp_path / "dress.glb", ["garment", "body"], FRAMES, motion.fps)
    garment, posed = garment_rig(runs / "virtualbones", motion), body_rig(body, motion)
    # the rig's full weights are loosefit's low-frequency prediction; Blender plays its 4-influence version
    low_frequency = Animator(runs / "virtualbones").animate(motion, output="lf")
    assert np.abs(garment.skin() - low_frequency).max() < FLOAT_TOLERANCE
    assert np.abs(played["garment"] - garment.limited(4).skin()).max() < FLOAT_TOLERANCE
    assert np.abs(posed.skin() - body.pose(motion).verts).max() < FLOAT_TOLERANCE
    assert np.abs(played["body"] - posed.limited(4).skin()).max() < FLOAT_TOLERANCE
    # the truncation error the export reports is what the file shows against the full weights
    for name, full in (("garment", low_frequency), ("body", body.pose(motion).verts)):
        error = np.linalg.norm(played[name] - full, axis=-1)
        assert summary[name]["vertices_truncated"] > 0 and summary[name]["max_mm"] > 0.01
        assert abs(error.max() * 1e3 - summary[name]["max_mm"]) < 0.01
    assert summary["garment"]["influences_in_rig"] == 8 and summary["body"]["joints"] == body.num_joints


def test_blender_plays_jointnet_bones_with_8_influences(runs, motion, tmp_path):
    summary = export_rig(runs / "jointnet", motion, tmp_path / "dress.glb", influences=8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the validator warns that it is provisional
        assert validate(GLTF2.load_binary(tmp_path / "dress.glb")) == []
    played = blender_skinned_frames(tmp_path / "dress.glb", ["garment"], FRAMES, motion.fps)["garment"]
    assert "body" not in summary and summary["garment"]["vertices_truncated"] == 0  # the rig has 8: nothing dropped
    assert np.abs(played - _jointnet_low_frequency(runs / "jointnet", motion)).max() < FLOAT_TOLERANCE


def test_usd_skinning_plays_jointnet_and_the_body(runs, motion, body, tmp_path):
    export_rig(runs / "jointnet", motion, tmp_path / "dress.usdc", body=body, influences=4)
    layer = Sdf.Layer.Find(str(tmp_path / "dress.usdc"))
    if layer is not None:
        layer.Reload()
    stage = Usd.Stage.Open(str(tmp_path / "dress.usdc"))
    expected = {"garment": garment_rig(runs / "jointnet", motion).limited(4).skin(),
                "body": body_rig(body, motion).limited(4).skin()}
    for name, reference in expected.items():
        assert UsdSkel.BakeSkinning(UsdSkel.Root(stage.GetPrimAtPath(f"/loosefit/{name}")), Gf.Interval(0, FRAMES - 1))
        points = UsdGeom.Mesh(stage.GetPrimAtPath(f"/loosefit/{name}/mesh")).GetPointsAttr()
        baked = np.stack([np.asarray(points.Get(t), np.float64) for t in range(FRAMES)])
        assert np.abs(baked - reference).max() < FLOAT_TOLERANCE
    full = garment_rig(runs / "jointnet", motion).skin()
    assert np.abs(full - _jointnet_low_frequency(runs / "jointnet", motion)).max() < FLOAT_TOLERANCE


def test_command_line(runs, motion, tmp_path, capsys):
    motion.save(tmp_path / "m.npz")
    argv = ["export-rig", str(runs / "virtualbones"), "--motion", str(tmp_path / "m.npz"), "--out"]
    assert main([*argv, str(tmp_path / "a.glb"), "--influences", "8", "--no-body"]) == 0
    out = capsys.readouterr().out
    assert f"wrote {tmp_path / 'a.glb'}" in out and f"{FRAMES} frames at 30 fps, 8 influences" in out
    assert (tmp_path / "a.glb").read_bytes()[:4] == b"glTF"
    assert main([*argv, str(tmp_path / "a.fbx"), "--no-body"]) == 2
    assert "a.fbx: unknown rig format '.fbx'; use one of .glb, .usdc" in capsys.readouterr().err


def test_bad_runs_and_motions_are_refused(runs, tiny_store, motion, tmp_path):
    train_model("body-lbs", tiny_store, "skirt+average", tmp_path / "lbs")
    with pytest.raises(InputError, match="body-lbs has no virtual bones"):
        export_rig(tmp_path / "lbs", motion, tmp_path / "a.glb")
    wrong = Motion(np.zeros((3, 5, 3), np.float32), np.zeros((3, 3), np.float32), rig="x")
    with pytest.raises(InputError, match="has 5 joints, the run was trained on 31"):
        export_rig(runs / "virtualbones", wrong, tmp_path / "a.glb")
    with pytest.raises(InputError, match="a.glb: influences per vertex must be one of"):
        export_rig(runs / "virtualbones", motion, tmp_path / "a.glb", influences=3)
    assert not (tmp_path / "a.glb").exists()
