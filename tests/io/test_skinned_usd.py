"""UsdSkel stages: USD's own skinning (UsdSkel.BakeSkinning) of the written stage gives SkinnedMesh.skin."""

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel

from loosefit.errors import InputError
from loosefit.io.skinned_usd import joint_paths, usd_name, write_skinned_usd
from tests.io.test_skinned_mesh import random_skinned


def _open(path):
    layer = Sdf.Layer.Find(str(path))
    if layer is not None:  # USD caches layers per process
        layer.Reload()
    return Usd.Stage.Open(str(path))


@pytest.mark.parametrize("suffix", [".usdc", ".usda"])
def test_usd_skinning_of_the_stage_matches(tmp_path, suffix):
    meshes = [random_skinned(seed=0, free=True).limited(8), random_skinned(seed=1, joints=7, name="body").limited(4)]
    write_skinned_usd(tmp_path / f"rig{suffix}", meshes)
    stage = _open(tmp_path / f"rig{suffix}")
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert (stage.GetTimeCodesPerSecond(), stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (24.0, 0.0, 5.0)
    for mesh in meshes:
        root = UsdSkel.Root(stage.GetPrimAtPath(f"/loosefit/{mesh.name}"))
        skeleton = UsdSkel.Skeleton(stage.GetPrimAtPath(f"/loosefit/{mesh.name}/skeleton"))
        assert list(skeleton.GetJointsAttr().Get()) == joint_paths(mesh)
        points = UsdGeom.Mesh(stage.GetPrimAtPath(f"/loosefit/{mesh.name}/mesh")).GetPointsAttr()
        assert np.array_equal(np.asarray(points.Get()), mesh.rest_verts)  # the bind pose before baking
        assert UsdSkel.BakeSkinning(root, Gf.Interval(0, mesh.num_frames - 1))
        assert points.GetTimeSamples() == [float(t) for t in range(mesh.num_frames)]
        baked = np.stack([np.asarray(points.Get(t), np.float64) for t in range(mesh.num_frames)])
        assert np.abs(baked - mesh.skin()).max() < 1e-5  # float32 transforms and points


def test_joint_paths_follow_the_hierarchy_with_usd_names():
    mesh = random_skinned(seed=1, joints=4, influences=2)
    mesh.parents = np.array([-1, 0, 1, 0])
    mesh.joint_names = ["Hips", "Left Leg", "1foot", "Left Leg"]
    assert joint_paths(mesh) == ["Hips", "Hips/Left_Leg", "Hips/Left_Leg/_1foot", "Hips/Left_Leg_1"]
    assert usd_name("") == "_" and usd_name("a.b-c") == "a_b_c"


def test_bad_input_is_refused_and_nothing_written(tmp_path):
    short = random_skinned(seed=1, frames=3, name="body")
    with pytest.raises(InputError, match="rig.usdc: mesh 'body' has 3 frames at 24 fps, 'garment' 6 at 24"):
        write_skinned_usd(tmp_path / "rig.usdc", [random_skinned(), short])
    assert list(tmp_path.iterdir()) == []
