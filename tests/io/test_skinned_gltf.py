"""Skinned glTF: a valid document of the documented layout, and Blender's importer plays back SkinnedMesh.skin."""

import warnings

import numpy as np
import pytest
from pygltflib import GLTF2
from pygltflib.validator import validate

from loosefit.errors import InputError
from loosefit.io.gltf import from_y_up
from loosefit.io.skinned_gltf import gltf_quaternions, write_skinned_glb
from tests.io.conftest import blender_skinned_frames
from tests.io.test_skinned_mesh import random_skinned


def _accessor(gltf, index):
    accessor = gltf.accessors[index]
    view = gltf.bufferViews[accessor.bufferView]
    dtype = {5126: np.float32, 5125: np.uint32, 5123: np.uint16, 5121: np.uint8}[accessor.componentType]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[accessor.type]
    count = accessor.count * width
    assert (accessor.byteOffset or 0) + count * np.dtype(dtype).itemsize <= view.byteLength
    return np.frombuffer(gltf.binary_blob(), dtype, count, view.byteOffset + (accessor.byteOffset or 0)).reshape(-1, width)


def _meshes():
    return [random_skinned(seed=0, free=True).limited(8), random_skinned(seed=1, joints=7, name="body").limited(4)]


def test_document_is_valid_and_laid_out_as_documented(tmp_path):
    garment, body = _meshes()
    write_skinned_glb(tmp_path / "rig.glb", [garment, body])
    gltf = GLTF2.load_binary(tmp_path / "rig.glb")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the validator warns that it is provisional
        assert validate(gltf) == []
    names = [n.name for n in gltf.nodes]
    assert names == ["garment_rig", *garment.joint_names, "garment", "body_rig", *body.joint_names, "body"]
    assert gltf.scenes[0].nodes == [10, 0, 19, 11]
    for node, mesh, sets in ((10, garment, 2), (19, body, 1)):
        skin = gltf.skins[gltf.nodes[node].skin]
        assert gltf.nodes[skin.skeleton].name == f"{mesh.name}_rig" and len(skin.joints) == mesh.num_joints
        ibm = _accessor(gltf, skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
        assert np.allclose(from_y_up(-ibm[:, :3, 3]), mesh.bind_positions) and np.allclose(ibm[:, :3, :3], np.eye(3))
        attributes = gltf.meshes[gltf.nodes[node].mesh].primitives[0].attributes
        joints = np.concatenate([_accessor(gltf, getattr(attributes, f"JOINTS_{s}")) for s in range(sets)], 1)
        weights = np.concatenate([_accessor(gltf, getattr(attributes, f"WEIGHTS_{s}")) for s in range(sets)], 1)
        assert joints.dtype == np.uint8 and np.array_equal(joints[:, : mesh.influences], mesh.weight_indices)
        assert np.array_equal(weights[:, : mesh.influences], mesh.weight_values) and (weights[:, mesh.influences :] == 0).all()
        assert np.array_equal(from_y_up(_accessor(gltf, attributes.POSITION)), mesh.rest_verts)
    assert getattr(gltf.meshes[1].primitives[0].attributes, "JOINTS_1", None) is None
    animation = gltf.animations[0]
    assert animation.extras == {"fps": 24.0}
    # garment: 9 free bones, rotation + translation; body: rotation of 7 joints, translation of the moving ones
    assert len(animation.channels) == 18 + 7 + 7  # random translations move every body joint here
    times = _accessor(gltf, animation.samplers[0].input).ravel()
    assert np.array_equal(times, np.arange(6, dtype=np.float32) / np.float32(24.0))


def test_quaternions_are_y_up_and_continuous():
    angles = np.linspace(0, 4 * np.pi, 40)  # two full turns about Z: w changes sign twice
    R = np.zeros((40, 1, 3, 3))
    R[:, 0, 0, 0], R[:, 0, 0, 1], R[:, 0, 1, 0], R[:, 0, 1, 1], R[:, 0, 2, 2] = (np.cos(angles), -np.sin(angles),
                                                                              np.sin(angles), np.cos(angles), 1)
    q = gltf_quaternions(R)[:, 0]
    assert np.abs(q[:, [0, 2]]).max() < 1e-6  # a turn about Z-up is a turn about glTF's Y
    half = angles / 2
    assert np.allclose(np.abs(q[:, 1]), np.abs(np.sin(half)), atol=1e-6) and np.allclose(np.abs(q[:, 3]), np.abs(np.cos(half)), atol=1e-6)
    assert ((q[1:] * q[:-1]).sum(-1) > 0).all()  # neighbours in one hemisphere


def test_blender_plays_back_the_skinning(tmp_path):
    """Blender's importer (an independent glTF reader) evaluates the skins at every keyframe as SkinnedMesh.skin."""
    meshes = _meshes()
    write_skinned_glb(tmp_path / "rig.glb", meshes)
    played = blender_skinned_frames(tmp_path / "rig.glb", ["garment", "body"], 6, 24.0)
    for mesh in meshes:
        expected = mesh.skin()
        assert played[mesh.name].shape == expected.shape
        assert np.abs(played[mesh.name] - expected).max() < 1e-5  # float32 file, positions of a few metres


def test_bad_input_is_refused_and_nothing_written(tmp_path):
    garment, body = _meshes()
    with pytest.raises(InputError, match="rig.glb: mesh 'garment' has 9 influences per vertex"):
        write_skinned_glb(tmp_path / "rig.glb", [random_skinned(influences=9)])
    short = random_skinned(seed=1, frames=3, name="body")
    with pytest.raises(InputError, match="rig.glb: mesh 'body' has 3 frames at 24 fps, 'garment' 6 at 24"):
        write_skinned_glb(tmp_path / "rig.glb", [garment, short])
    with pytest.raises(InputError, match="rig.glb: no mesh to write"):
        write_skinned_glb(tmp_path / "rig.glb", [])
    assert list(tmp_path.iterdir()) == []


def test_more_than_256_joints_use_short_indices(tmp_path):
    mesh = random_skinned(seed=4, joints=300, influences=4, free=True, frames=2)
    write_skinned_glb(tmp_path / "rig.glb", [mesh])
    gltf = GLTF2.load_binary(tmp_path / "rig.glb")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert validate(gltf) == []
    joints = _accessor(gltf, gltf.meshes[0].primitives[0].attributes.JOINTS_0)
    assert joints.dtype == np.uint16 and np.array_equal(joints, mesh.weight_indices) and joints.max() > 255
