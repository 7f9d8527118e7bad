"""USD stages: bit-exact round trips, the stage layout other tools rely on, Y-up / centimetre stages, errors."""

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, Vt

from loosefit.errors import InputError
from loosefit.io.usd import read_usd, write_usd
from tests.io.conftest import random_sequence


@pytest.mark.parametrize("suffix", [".usdc", ".usda"])
def test_round_trip_is_exact(tmp_path, suffix):
    seq = random_sequence()
    write_usd(tmp_path / f"a{suffix}", seq)
    back = read_usd(tmp_path / f"a{suffix}")
    assert np.array_equal(back.verts, seq.verts) and np.array_equal(back.faces, seq.faces) and back.fps == 24.0
    assert np.array_equal(back.extra["body_verts"], seq.extra["body_verts"])
    assert np.array_equal(back.extra["body_faces"], seq.extra["body_faces"])
    head = (tmp_path / f"a{suffix}").read_bytes()[:8]
    assert head == (b"PXR-USDC" if suffix == ".usdc" else b"#usda 1.")


def test_stage_layout(tmp_path):
    seq = random_sequence(frames=6, fps=30.0)
    write_usd(tmp_path / "a.usdc", seq)
    stage = Usd.Stage.Open(str(tmp_path / "a.usdc"))
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert (stage.GetTimeCodesPerSecond(), stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (30.0, 0.0, 5.0)
    assert stage.GetDefaultPrim().GetPath() == "/loosefit"
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/loosefit/garment"))
    assert mesh.GetPointsAttr().GetTimeSamples() == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
    assert mesh.GetSubdivisionSchemeAttr().Get() == "none"
    assert list(mesh.GetFaceVertexCountsAttr().Get()) == [3] * 80
    assert np.array_equal(np.asarray(mesh.GetFaceVertexIndicesAttr().Get()), seq.faces.ravel())
    extent = np.asarray(mesh.GetExtentAttr().Get(4))
    assert np.array_equal(extent, [seq.verts[4].min(0), seq.verts[4].max(0)])
    assert np.array_equal(np.asarray(mesh.GetPointsAttr().Get(4)), seq.verts[4])
    assert stage.GetPrimAtPath("/loosefit/body").IsA(UsdGeom.Mesh)


def test_reads_y_up_centimetre_stage_with_transform(tmp_path):
    """A stage from another tool: Y-up, centimetres, the mesh under a translated Xform, quads refused."""
    stage = Usd.Stage.CreateNew(str(tmp_path / "y.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    stage.SetTimeCodesPerSecond(24)
    UsdGeom.Xform.Define(stage, "/rig").AddTranslateOp().Set(Gf.Vec3d(10, 20, 30))
    mesh = UsdGeom.Mesh.Define(stage, "/rig/cloth")
    mesh.CreateFaceVertexCountsAttr([3, 3])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 2, 1, 3])
    local = np.array([[[0, 0, 0], [100, 0, 0], [0, 100, 0], [100, 100, 50]]], np.float32) + np.array([[[0, 0, 0]], [[5, 0, 0]]], np.float32)
    for t, frame in enumerate(local):
        mesh.CreatePointsAttr().Set(Vt.Vec3fArray.FromNumpy(frame), 1001 + t)
    stage.Save()
    back = read_usd(tmp_path / "y.usda")
    world_y_up = (local + [10, 20, 30]) * 0.01
    expected = np.stack([world_y_up[..., 0], -world_y_up[..., 2], world_y_up[..., 1]], axis=-1)  # Y-up -> Z-up
    assert back.verts.shape == (2, 4, 3) and np.abs(back.verts - expected).max() < 1e-6
    assert np.array_equal(back.faces, [[0, 1, 2], [2, 1, 3]]) and back.fps == 24.0 and back.extra == {}

    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 3, 2])
    stage.Save()
    with pytest.raises(InputError, match="y.usda: mesh /rig/cloth has polygons with 4 corners"):
        read_usd(tmp_path / "y.usda")


def test_rewrite_is_read_fresh(tmp_path):
    """USD caches opened layers per process: a stage still open must not hide the new file."""
    write_usd(tmp_path / "a.usdc", random_sequence(seed=0))
    still_open = Usd.Stage.Open(str(tmp_path / "a.usdc"))
    second = random_sequence(seed=1, frames=3)
    write_usd(tmp_path / "a.usdc", second)
    assert np.array_equal(read_usd(tmp_path / "a.usdc").verts, second.verts)
    assert still_open.GetPrimAtPath("/loosefit/garment").IsValid()


def test_bad_files_name_the_file(tmp_path):
    (tmp_path / "junk.usdc").write_bytes(b"not a stage")
    with pytest.raises(InputError, match="junk.usdc: cannot open USD stage"):
        read_usd(tmp_path / "junk.usdc")
    stage = Usd.Stage.CreateNew(str(tmp_path / "empty.usda"))
    UsdGeom.Xform.Define(stage, "/nothing")
    stage.Save()
    with pytest.raises(InputError, match="empty.usda: the stage has no mesh"):
        read_usd(tmp_path / "empty.usda")
    with pytest.raises(InputError, match="missing.usdc: no such USD file"):
        read_usd(tmp_path / "missing.usdc")
