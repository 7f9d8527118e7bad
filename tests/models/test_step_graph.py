"""The one-frame graph of the ONNX export, in torch: stepping it with its flat state gives the vertices of
``Animator.animate`` for configurations the trained test runs do not reach (no motion history, a vertical
history, JointNet's summed Fourier prior and a one-layer bone MLP, VirtualBones' factorised global layer and a
hidden head, the low-frequency module's own outputs fed back, joints not read, the pelvis frame), with random
weights and rig buffers on a small grid garment."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.animate import Animator
from loosefit.errors import InputError
from loosefit.models.jointnet import JointNet, JointNetConfig
from loosefit.models.layers.edge_conv import neighbour_table
from loosefit.models.motion_features import MotionHistory
from loosefit.models.step_graph import StepGraph
from loosefit.models.virtualbones import VirtualBones, VirtualBonesConfig
from loosefit.motion.procedural import generate

BONES = 5
FRAMES = 45


def grid_garment(n: int = 8):
    """A ``n x n`` vertex sheet around the hips (metres, Z up) and its triangles."""
    u, v = np.meshgrid(np.linspace(-0.25, 0.25, n), np.linspace(0.5, 1.0, n))
    verts = np.stack([u.ravel(), np.full(n * n, -0.15), v.ravel()], 1).astype(np.float32)
    quads = [(i * n + j, i * n + j + 1, (i + 1) * n + j, (i + 1) * n + j + 1)
             for i in range(n - 1) for j in range(n - 1)]
    faces = np.array([f for a, b, c, d in quads for f in ((a, b, c), (b, d, c))], np.int64)
    return verts, faces


def build(cls, config, body, history: MotionHistory | None):
    verts, faces = grid_garment()
    V = len(verts)
    sizes = {"num_verts": V, "num_joints": body.num_joints, "num_faces": len(faces),
             "root_features": history.root_features if history else 11,
             "history_frames": list(history.frames) if history else [],
             "history_vertical": bool(history and history.vertical), "num_bones": BONES,
             "max_degree": int(neighbour_table(faces, V).shape[1]), "joint_names": list(body.joint_names),
             "parents": [int(p) for p in body.parents], **({"frame": config.frame} if config.frame != "heading" else {}),
             **({"rotation": config.rotation} if getattr(config, "rotation", "euler") != "euler" else {})}
    torch.manual_seed(0)
    model = cls(sizes, config)
    g = torch.Generator().manual_seed(1)
    weights = torch.rand(V, BONES, generator=g) ** 4
    buffers = {"faces": torch.from_numpy(faces), "template": torch.from_numpy(verts),
               "rest_verts": torch.from_numpy(verts), "rig_rest": torch.from_numpy(verts),
               "skin_weights": weights / weights.sum(1, keepdim=True),
               "bone_rest": torch.from_numpy(verts[:: V // BONES][:BONES].copy()),
               "root_std": 0.5 + torch.rand(model.root_features, generator=g),
               "joints_mean": 0.1 * torch.randn(body.num_joints - 1, 6, generator=g),
               "euler_std": 0.2 + torch.rand(BONES, 3, generator=g),
               "sixd_mean": torch.tensor([1.0, 0, 0, 0, 1, 0]) + 0.2 * torch.randn(BONES, 6, generator=g),
               "sixd_std": 0.1 + 0.2 * torch.rand(BONES, 6, generator=g),
               "offset_std": 0.02 + 0.01 * torch.rand(BONES, 3, generator=g),
               "joint_read": (torch.arange(body.num_joints - 1) % 3 > 0).float()[:, None]}
    if cls is VirtualBones:
        buffers["neighbours"] = torch.from_numpy(neighbour_table(faces, V))
        buffers["offset_std"] = torch.full((3,), 0.01)
        buffers["position_std"] = torch.full((3,), 0.05)
        buffers["position_mean"] = buffers["bone_rest"]
    with torch.no_grad():
        for name, value in buffers.items():
            if isinstance(getattr(model, name, None), torch.Tensor):  # each model has some of them
                getattr(model, name).copy_(value)
        if cls is JointNet:
            model.psd_basis.normal_(0, 1e-3, generator=g)
    return model.eval()


CASES = {
    "jointnet-add-one-layer-vertical": (JointNet, JointNetConfig(gru_hidden=12, features=8, bone_mlp=[], psd_mlp=[8],
                                                                 psd_shapes=3, fourier="add", association="l1"),
                                        MotionHistory((4.0, 9.0), vertical=True)),
    "jointnet-no-history": (JointNet, JointNetConfig(gru_hidden=12, features=8, bone_mlp=[16], psd_mlp=[8],
                                                     psd_shapes=3), None),
    "virtualbones-rank-head": (VirtualBones, VirtualBonesConfig(lf_hidden=10, hf_hidden=12, global_channels=3,
                                                                global_rank=4, edge_channels=(4, 6), head_hidden=(5,)),
                               MotionHistory((6.0, 15.0, 30.0), vertical=True)),
    "virtualbones-no-history": (VirtualBones, VirtualBonesConfig(lf_hidden=10, hf_hidden=12, global_channels=3,
                                                                 edge_channels=(4,)), None),
    "virtualbones-fed-back": (VirtualBones, VirtualBonesConfig(lf_hidden=10, hf_hidden=12, global_channels=3,
                                                               edge_channels=(4,), feedback_frames=2,
                                                               exclude_joints=("Arm",)),
                              MotionHistory((6.0, 15.0))),
    "virtualbones-pelvis": (VirtualBones, VirtualBonesConfig(lf_hidden=10, hf_hidden=12, global_channels=3,
                                                             edge_channels=(4,), frame="pelvis"),
                            MotionHistory((6.0,))),
    "jointnet-pelvis": (JointNet, JointNetConfig(gru_hidden=12, features=8, bone_mlp=[16], psd_mlp=[8], psd_shapes=3,
                                                 frame="pelvis"), None),
    "jointnet-sixd": (JointNet, JointNetConfig(gru_hidden=12, features=8, bone_mlp=[16], psd_mlp=[8], psd_shapes=3,
                                               rotation="sixd"), MotionHistory((6.0,))),
    "virtualbones-raised": (VirtualBones, VirtualBonesConfig(lf_hidden=10, hf_hidden=12, global_channels=3,
                                                             edge_channels=(4,), frame="raised"), None),
}


@pytest.mark.parametrize("case", list(CASES))
def test_stepping_the_graph_is_animate(case, body):
    cls, config, history = CASES[case]
    model = build(cls, config, body, history)
    motion = generate("spin", FRAMES / 30, 2, body)
    expected = Animator.from_model(model).animate(motion)
    graph = StepGraph(model, bones=True)
    state = torch.from_numpy(graph.initial_state())
    frames = []
    with torch.no_grad():
        for t in range(FRAMES):
            verts, state, bones = graph(torch.from_numpy(motion.rotations[t]).float(),
                                        torch.from_numpy(motion.translation[t]).float(), state)
            frames.append(verts.numpy())
    assert state.shape == (graph.state_size,) and bones.shape == (BONES, 4, 4)
    names = [f.name for f in graph.layout()]
    assert ("history" in names) == (history is not None)
    assert np.abs(np.stack(frames) - expected).max() <= 1e-5
    assert np.ptp(expected, axis=0).max() > 0.01  # the garment moves: the comparison is not of constants


@pytest.mark.parametrize("case", ["virtualbones-pelvis", "jointnet-pelvis", "virtualbones-raised"])
def test_a_model_in_a_root_frame_carries_its_garment_with_the_root_joint(case, body):
    """A model trained in the raised or the pelvis frame: ``animate`` and the stream put its canonical output ``c``
    at ``R c + p_root``, ``p_root`` the root joint's position and ``R`` the root's heading (raised) or its whole
    rotation (pelvis), not in the heading frame on the floor (checked, so that the comparison can fail)."""
    from loosefit.geometry.rotations import axis_angle_to_matrix
    from loosefit.models.motion_features import motion_features
    from loosefit.motion.heading import heading_angles, motion_frames, rot_z, to_world

    cls, config, history = CASES[case]
    model = build(cls, config, body, history)
    assert model.frame == config.frame
    motion = generate("walk", 1.0, 3, body)
    feats = motion_features(motion, model.history)
    with torch.no_grad():
        canonical = model(torch.from_numpy(feats["root"])[None], torch.from_numpy(feats["joints"])[None])["verts"][0]
    R = axis_angle_to_matrix(torch.from_numpy(motion.rotations[:, 0]).double()).numpy()
    if config.frame == "raised":
        R = rot_z(heading_angles(R))
    expected = np.einsum("tij,tvj->tvi", R, canonical.double().numpy()) + motion.translation[:, None]
    animator = Animator.from_model(model)
    assert np.abs(animator.animate(motion) - expected).max() <= 1e-5
    stream = animator.stream()
    streamed = np.stack([stream.step(motion.rotations[t], motion.translation[t]) for t in range(motion.num_frames)])
    assert np.abs(streamed - expected).max() <= 1e-5
    heading = to_world(canonical.numpy(), *motion_frames(motion, "heading"))
    assert np.abs(heading - expected).max() > 0.5  # the pelvis sits ~0.9 m above the heading frame's origin


def test_methods_without_a_frame_graph_are_refused(body):
    class Other:
        method = "swingar"

    with pytest.raises(InputError, match="no one-frame graph"):
        StepGraph(Other())
