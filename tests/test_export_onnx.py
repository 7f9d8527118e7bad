"""export-onnx on real trained runs: onnxruntime stepping the exported model one frame at a time gives the
vertices of :meth:`Animator.animate` on a 300-frame procedural motion, the bone transforms skin the garment's
low-frequency part, the metadata describes the model, and a damaged run is refused naming the file."""

import json

import numpy as np
import onnx
import onnxruntime as ort
import pytest

from loosefit.animate import Animator
from loosefit.cli import main
from loosefit.errors import InputError
from loosefit.export_onnx import METADATA_KEY, export_onnx, read_metadata
from loosefit.io.onnx_int8 import BLOCK_SIZE
from loosefit.export_rig import predict_bones
from loosefit.motion.heading import heading_frames
from loosefit.motion.procedural import generate
from loosefit.training import train_model

QUIET = ["train.progress=false", "train.tensorboard=false", "data.window=20", "data.stride=10", "data.burn_in=4"]
SMALL = {
    "body-lbs": [],
    "virtualbones": ["model.lf_hidden=16", "model.hf_hidden=16", "model.global_channels=4", "model.edge_channels=[8]",
                     "train.stages.low.epochs=1", "train.stages.high.epochs=1", *QUIET],
    "jointnet": ["model.gru_hidden=16", "model.features=16", "model.bone_mlp=[32]", "model.psd_mlp=[16]",
                 "model.psd_shapes=4", "train.stages.stage1.epochs=1", "train.stages.stage2.epochs=1", *QUIET],
}
SMALL["jointnet-sixd"] = [*SMALL["jointnet"], "model.rotation=sixd"]  # its bones' rotations in 6D
METHOD = {"jointnet-sixd": "jointnet"}  # the method of each run that is not named after it
FRAMES = 300
TOLERANCE = 1e-4  # metres: 0.1 mm


@pytest.fixture(scope="module")
def runs(tiny_store, tmp_path_factory):
    root = tmp_path_factory.mktemp("onnx")
    for method, overrides in SMALL.items():
        train_model(METHOD.get(method, method), tiny_store, "skirt+average", root / method, overrides=overrides)
    return root


@pytest.fixture(scope="module")
def motion(body):
    """300 frames (10 s) of the procedural mix: walking, turning and spinning, so the heading wraps past pi."""
    return generate("mix", FRAMES / 30, 3, body)


def session(path):
    options = ort.SessionOptions()
    options.intra_op_num_threads, options.inter_op_num_threads = 1, 1
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def stream(path, motion, carry_state: bool = True):
    """Vertices ``(T, V, 3)``, bone transforms ``(T, B, 4, 4)`` (None for a model without them) and the last state
    of the model stepped along ``motion``."""
    sess, meta = session(path), read_metadata(path)
    state = np.asarray(meta["initial_state"], np.float32)
    verts, bones = [], []
    for t in range(motion.num_frames):
        v, next_state, *b = sess.run(None, {"joint_rotations": motion.rotations[t].astype(np.float32),
                                            "root_position": motion.translation[t].astype(np.float32), "state": state})
        state = next_state if carry_state else state
        verts.append(v)
        bones += b
    return np.stack(verts), np.stack(bones) if bones else None, next_state


@pytest.mark.parametrize("method", list(SMALL))
def test_onnx_steps_reproduce_animate(runs, motion, method, tmp_path):
    path = tmp_path / f"{method}.onnx"
    summary = export_onnx(runs / method, path, bones=True)
    onnx.checker.check_model(onnx.load(str(path)))
    animator = Animator(runs / method)
    expected = animator.animate(motion)
    verts, bones, _ = stream(path, motion)
    assert verts.shape == expected.shape == (FRAMES, summary["vertices"], 3) and verts.dtype == np.float32
    assert np.abs(verts - expected).max() <= TOLERANCE
    if method != "body-lbs":  # the control: without the state fed back (history, recurrent state) it is elsewhere
        forgetful, _, _ = stream(path, motion, carry_state=False)
        assert np.abs(forgetful - expected).max() > 20 * TOLERANCE

    # the bones: their world node matrices, bone b at rest at c_b with the world axes
    model = animator.model
    centres = (model.rest_joints if method == "body-lbs" else model.bone_rest).numpy().astype(np.float64)
    np.testing.assert_allclose(bones[:, :, 3], np.broadcast_to([0, 0, 0, 1], bones[:, :, 3].shape), atol=0)
    if method == "body-lbs":  # the body joints skin the template with the model's weights into the vertices
        skinning = bones.astype(np.float64).copy()
        skinning[..., :3, 3] -= (skinning[..., :3, :3] @ centres[:, :, None])[..., 0]
        rest = np.concatenate([model.template.numpy(), np.ones((len(model.template), 1))], 1)
        skinned = np.einsum("vb,tbij,vj->tvi", model.weights.numpy(), skinning[..., :3, :], rest)
        assert np.abs(skinned - expected).max() <= TOLERANCE
    else:  # the virtual bones of export-rig: rotation R, position R c + T
        R, T = predict_bones(animator, motion)
        assert np.abs(bones[..., :3, :3] - R).max() <= 1e-4
        assert np.abs(bones[..., :3, 3] - ((R @ centres[:, :, None])[..., 0] + T)).max() <= TOLERANCE


@pytest.mark.parametrize("run", ["pretrained:skirt", "pretrained:skirt/jointnet"])
def test_shipped_garments_export_and_step_as_they_animate(run, motion, tmp_path):
    """The garments loosefit ships, trained for real (3,427 vertices, 80 bones, JointNet's PSD in 256 modes): the
    exported model steps to the vertices of ``Animator.animate`` (100 frames: the
    300-frame comparison is the trained runs' above)."""
    motion = motion.slice(0, 100)
    path = tmp_path / "skirt.onnx"
    export_onnx(run, path)
    verts, bones, _ = stream(path, motion)
    assert bones is None
    assert np.abs(verts - Animator(run).animate(motion)).max() <= TOLERANCE


@pytest.mark.parametrize("run", ["pretrained:skirt", "pretrained:skirt/jointnet"])
def test_int8_weights_stay_within_millimetres_of_the_float_model(run, motion, tmp_path):
    """``--int8``: the shipped garments' large matrices in int8 blocks (under half the file), every vertex
    of 100 frames within 2 mm of the float model (the rounding of the weights: under 1 mm measured), and the
    weights really rounded (the vertices move). ``tests/test_quantize.py`` removes that gap."""
    motion = motion.slice(0, 100)
    exact, small = tmp_path / "float.onnx", tmp_path / "int8.onnx"
    export_onnx(run, exact)
    assert main(["export-onnx", run, "--out", str(small), "--int8"]) == 0  # the command line's flag
    weights = read_metadata(small)["weights"]
    assert weights["storage"] == "int8" and weights["block_size"] == BLOCK_SIZE
    assert weights["weights_int8"] > 3 * weights["weights_float"]
    assert small.stat().st_size < 0.5 * exact.stat().st_size
    assert "MatMulNBits" in {n.op_type for n in onnx.load(str(small)).graph.node}
    gap = np.linalg.norm(stream(small, motion)[0] - stream(exact, motion)[0], axis=-1)
    print(f"{run}: int8 against float32, mean {gap.mean() * 1e3:.3f} mm, max {gap.max() * 1e3:.3f} mm")
    assert 1e-5 < gap.max() <= 2e-3


def test_metadata_round_trips_and_describes_the_state(runs, motion, body, tmp_path):
    path = tmp_path / "jn.onnx"
    assert main(["export-onnx", str(runs / "jointnet"), "--out", str(path)]) == 0  # the command line, no --bones
    meta = read_metadata(path)
    proto = onnx.load(str(path))
    assert json.loads({p.key: p.value for p in proto.metadata_props}[METADATA_KEY]) == meta
    model = Animator(runs / "jointnet").model
    assert meta["method"] == "jointnet" and meta["fps"] == 30 and meta["up_axis"] == "Z"
    assert meta["joint_names"] == list(body.joint_names) == list(motion.joint_names)
    assert meta["vertex_count"] == len(model.template)
    np.testing.assert_array_equal(np.reshape(meta["faces"], (-1, 3)), model.faces.numpy())
    fields = meta["state_layout"]
    offsets = np.cumsum([0] + [int(np.prod(f["shape"])) for f in fields])
    assert [f["offset"] for f in fields] == offsets[:-1].tolist() and offsets[-1] == meta["state_size"]
    assert meta["initial_state"] == [0.0] * meta["state_size"]
    assert [f["name"] for f in fields] == ["started", "previous_root_position", "previous_heading", "history",
                                           "gru_joints"]
    assert fields[-1]["shape"] == [len(model.selected), model.gru.hidden]
    sess = session(path)
    assert [(i.name, i.shape) for i in sess.get_inputs()] == [
        ("joint_rotations", [31, 3]), ("root_position", [3]), ("state", [meta["state_size"]])]
    assert [(o.name, o.shape) for o in sess.get_outputs()] == [("vertices", [len(model.template), 3]),
                                                               ("next_state", [meta["state_size"]])]
    # the layout says where the graph keeps the previous frame: after frame 5, its root position and heading
    state = np.asarray(meta["initial_state"], np.float32)
    for t in range(6):
        _, state = sess.run(None, {"joint_rotations": motion.rotations[t].astype(np.float32),
                                   "root_position": motion.translation[t].astype(np.float32), "state": state})
    field = {f["name"]: f for f in fields}

    def read(name):
        f = field[name]
        return state[f["offset"]:f["offset"] + int(np.prod(f["shape"]))]

    assert read("started")[0] == 1.0
    np.testing.assert_allclose(read("previous_root_position"), motion.translation[5], atol=1e-6)
    rot, _ = heading_frames(motion.slice(5, 6))  # rot_z(psi)
    psi = read("previous_heading")[0]
    np.testing.assert_allclose([np.cos(psi), np.sin(psi)], [rot[0, 0, 0], rot[0, 1, 0]], atol=1e-6)


def test_a_damaged_run_is_refused_naming_the_file(runs, tmp_path, capsys):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(runs / "virtualbones", run)
    checkpoint = run / "checkpoints" / "last.pt"
    checkpoint.write_bytes(b"not a checkpoint")
    with pytest.raises(InputError, match="corrupt") as info:
        export_onnx(run, tmp_path / "a.onnx")
    assert info.value.path == checkpoint
    assert main(["export-onnx", str(run), "--out", str(tmp_path / "a.onnx")]) == 2
    err = capsys.readouterr().err
    assert "last.pt" in err and "corrupt" in err and "Traceback" not in err
    checkpoint.unlink()
    with pytest.raises(InputError, match="checkpoint not found") as info:
        export_onnx(run, tmp_path / "a.onnx")
    assert info.value.path == checkpoint
    assert not (tmp_path / "a.onnx").exists()
    with pytest.raises(InputError, match="not a loosefit run folder"):
        export_onnx(tmp_path, tmp_path / "a.onnx")
    meta = json.loads((run / "model.json").read_text())
    for method, says in (("swingar", "SwinGar animates any garment"), ("fitgar", "FitGar is a static"),
                         ("collision", "body distance field")):
        (run / "model.json").write_text(json.dumps({**meta, "method": method}))
        with pytest.raises(InputError, match=says) as info:
            export_onnx(run, tmp_path / "a.onnx")
        assert info.value.path == run
    (tmp_path / "b.onnx").write_bytes(b"\x00 not protobuf")
    with pytest.raises(InputError, match="not an ONNX model") as info:
        read_metadata(tmp_path / "b.onnx")
    assert info.value.path == tmp_path / "b.onnx"
