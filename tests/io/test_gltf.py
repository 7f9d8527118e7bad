"""glTF morph-target animations: round trips, document structure, a real viewer (Blender's importer) plays them."""

import struct
import warnings

import numpy as np
import pytest
from pygltflib import GLTF2
from pygltflib.validator import validate

from loosefit.errors import InputError
from loosefit.io.gltf import from_y_up, read_glb, to_y_up, write_glb
from loosefit.io.mesh_sequence import MeshSequence
from tests.io.conftest import random_sequence


def _one_step(a, b):
    """Equal up to one float32 rounding of ``base + (frame - base)``: |a - b| <= 2 ulp of the largest magnitude."""
    return a.shape == b.shape and np.abs(a - b).max() <= 2 * np.spacing(np.abs(b).max())


def _accessor(gltf, index):
    accessor = gltf.accessors[index]
    view = gltf.bufferViews[accessor.bufferView]
    dtype = {5126: np.float32, 5125: np.uint32}[accessor.componentType]
    width = {"SCALAR": 1, "VEC3": 3}[accessor.type]
    start = view.byteOffset + accessor.byteOffset
    assert start + accessor.count * width * 4 <= view.byteOffset + view.byteLength <= len(gltf.binary_blob())
    return np.frombuffer(gltf.binary_blob(), dtype, accessor.count * width, start).reshape(accessor.count, width)


def test_axis_conversion_is_a_proper_rotation():
    points = np.random.default_rng(0).normal(size=(5, 3)).astype(np.float32)
    assert np.array_equal(from_y_up(to_y_up(points)), points)
    assert np.array_equal(to_y_up(np.eye(3, dtype=np.float32)), [[1, 0, 0], [0, 0, -1], [0, 1, 0]])  # +Z goes to +Y


@pytest.mark.parametrize("interpolation", ["STEP", "LINEAR"])
def test_round_trip(tmp_path, interpolation):
    seq = random_sequence()
    write_glb(tmp_path / "a.glb", seq, interpolation=interpolation)
    back = read_glb(tmp_path / "a.glb")
    assert _one_step(back.verts, seq.verts) and back.verts.max() > 1.0  # tolerance 2 ulp, i.e. < 1e-6 m here
    assert np.array_equal(back.faces, seq.faces) and back.fps == 24.0
    assert _one_step(back.extra["body_verts"], seq.extra["body_verts"])
    assert np.array_equal(back.extra["body_faces"], seq.extra["body_faces"])
    samplers = GLTF2.load_binary(tmp_path / "a.glb").animations[0].samplers
    assert [s.interpolation for s in samplers] == [interpolation] * 2


def test_document_structure(tmp_path):
    seq = random_sequence(frames=6, fps=30.0)
    write_glb(tmp_path / "a.glb", seq)
    raw = (tmp_path / "a.glb").read_bytes()
    assert raw[:4] == b"glTF" and struct.unpack("<II", raw[4:12]) == (2, len(raw))
    gltf = GLTF2.load_binary(tmp_path / "a.glb")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the validator warns that it is provisional
        assert validate(gltf) == []
    assert [n.name for n in gltf.nodes] == ["garment", "body"] and gltf.scenes[gltf.scene].nodes == [0, 1]
    primitive = gltf.meshes[0].primitives[0]
    assert np.array_equal(_accessor(gltf, primitive.indices).reshape(-1, 3), seq.faces)
    position = gltf.accessors[primitive.attributes.POSITION]
    base = _accessor(gltf, primitive.attributes.POSITION)
    assert position.count == 50 and np.array_equal(base, to_y_up(seq.verts[0]))
    assert position.min == base.min(0).tolist() and position.max == base.max(0).tolist()
    assert len(primitive.targets) == 6 and gltf.meshes[0].extras["targetNames"][5] == "frame_00005"
    for t, target in enumerate(primitive.targets):
        accessor, delta = gltf.accessors[target["POSITION"]], _accessor(gltf, target["POSITION"])
        assert accessor.count == 50 and _one_step(base + delta, to_y_up(seq.verts[t]))
        assert accessor.min == delta.min(0).tolist() and accessor.max == delta.max(0).tolist()
    animation = gltf.animations[0]
    assert animation.extras["fps"] == 30.0 and len(animation.channels) == 2
    for node, channel in enumerate(animation.channels):
        assert (channel.target.node, channel.target.path) == (node, "weights")
        sampler = animation.samplers[channel.sampler]
        times, weights = _accessor(gltf, sampler.input).ravel(), _accessor(gltf, sampler.output).reshape(6, 6)
        assert np.array_equal(times, np.arange(6, dtype=np.float32) / np.float32(30.0))
        assert gltf.accessors[sampler.input].min == [0.0] and gltf.accessors[sampler.input].max == [float(times[-1])]
        assert sampler.interpolation == "STEP" and np.array_equal(weights, np.eye(6))
    assert gltf.meshes[0].weights == [1.0, 0, 0, 0, 0, 0]


def test_given_rest_mesh_is_the_base(tmp_path):
    seq = random_sequence(body=False)
    rest = seq.verts.mean(axis=0)
    write_glb(tmp_path / "a.glb", seq, rest=rest)
    gltf = GLTF2.load_binary(tmp_path / "a.glb")
    assert np.array_equal(_accessor(gltf, gltf.meshes[0].primitives[0].attributes.POSITION), to_y_up(rest))
    assert _one_step(read_glb(tmp_path / "a.glb").verts, seq.verts)


def test_garment_sized_file_has_the_documented_size(tmp_path):
    """3,000 vertices x 30 frames: the binary chunk is indices + base + T targets + times + T x T weights."""
    grid = np.stack(np.meshgrid(np.linspace(-0.3, 0.3, 60), np.linspace(0.4, 1.0, 50), indexing="ij"), -1).reshape(-1, 2)
    rest = np.column_stack([grid[:, 0], np.zeros(len(grid)), grid[:, 1]]).astype(np.float32)  # a 0.6 m cloth panel
    quads = (np.arange(59)[:, None] * 50 + np.arange(49)[None]).ravel()
    faces = np.concatenate([np.stack([quads, quads + 50, quads + 1], 1), np.stack([quads + 1, quads + 50, quads + 51], 1)])
    swing = np.sin(np.linspace(0, np.pi, 30))[:, None, None] * (1.0 - rest[None, :, 2:]) * np.array([0.0, 0.2, 0.0])
    seq = MeshSequence(rest[None] + swing, faces, 30.0)
    write_glb(tmp_path / "skirt.glb", seq)
    raw = (tmp_path / "skirt.glb").read_bytes()
    json_length = struct.unpack("<I", raw[12:16])[0]
    bin_length = struct.unpack("<I", raw[20 + json_length : 24 + json_length])[0]
    assert bin_length == len(faces) * 12 + 3000 * 12 * (1 + 30) + 30 * 4 + 30 * 30 * 4
    assert np.abs(read_glb(tmp_path / "skirt.glb").verts - seq.verts).max() < 1e-7


def test_blender_importer_plays_the_animation(tmp_path):
    """An independent glTF reader: Blender's importer turns the morph targets into animated shape keys."""
    import bpy
    import addon_utils  # importable once bpy is

    seq = random_sequence(body=False)
    write_glb(tmp_path / "a.glb", seq)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    try:
        addon_utils.enable("io_scene_gltf2")
        scene = bpy.context.scene
        scene.render.fps = 24  # the importer puts keyframe t / 24 s at scene frame t
        bpy.ops.import_scene.gltf(filepath=str(tmp_path / "a.glb"))
        obj = bpy.data.objects["garment"]
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for frame in range(10):
            scene.frame_set(frame)
            mesh = obj.evaluated_get(depsgraph).data
            points = np.empty(len(mesh.vertices) * 3, np.float32)
            mesh.vertices.foreach_get("co", points)
            assert np.abs(points.reshape(-1, 3) - seq.verts[frame]).max() < 1e-6  # Blender converts Y-up back to Z-up
    finally:
        bpy.ops.wm.read_factory_settings(use_empty=True)


def test_errors_name_the_file(tmp_path):
    with pytest.raises(InputError, match="a.glb: interpolation must be one of"):
        write_glb(tmp_path / "a.glb", random_sequence(), interpolation="CUBICSPLINE")
    with pytest.raises(InputError, match="a.glb: rest mesh must be finite"):
        write_glb(tmp_path / "a.glb", random_sequence(), rest=np.zeros((3, 3)))
    assert not (tmp_path / "a.glb").exists()
    (tmp_path / "junk.glb").write_bytes(b"junk" * 10)
    with pytest.raises(InputError, match="junk.glb: cannot read glTF binary"):
        read_glb(tmp_path / "junk.glb")
