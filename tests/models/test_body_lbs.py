"""The body-LBS baseline: nearest-vertex weights, canonical forward kinematics from the features, closed forms."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from loosefit.config import load_config
from loosefit.geometry.rotations import axis_angle_to_matrix
from loosefit.models.body_lbs import BodyLBS, BodyLBSConfig, Config, training_body
from loosefit.models.motion_features import motion_features
from loosefit.motion.heading import heading_frames, to_world
from loosefit.motion.motion import Motion
from loosefit.sim.attach import skin_garment

CONFIG_FILE = Path(__file__).parents[2] / "configs" / "models" / "body-lbs.yaml"


def _world(model: BodyLBS, motion: Motion) -> np.ndarray:
    """The model's garment along ``motion``, in the world: ``(T, V, 3)``."""
    f = motion_features(motion)
    with torch.no_grad():
        canonical = model(torch.from_numpy(f["root"])[None], torch.from_numpy(f["joints"])[None])["verts"][0]
    return to_world(canonical.numpy(), *heading_frames(motion))


def test_weights_are_those_of_the_nearest_rest_body_vertex(tiny_train):
    model = BodyLBS.from_data(tiny_train, BodyLBSConfig())
    body = training_body(tiny_train)
    garment, rest = tiny_train.garment.verts, body.rest_verts()
    nearest = np.array([np.argmin(((rest - v) ** 2).sum(1)) for v in garment])  # brute force
    assert np.array_equal(model.weights.numpy(), body.skinning_weights()[nearest])
    assert np.allclose(model.weights.sum(1).numpy(), 1, atol=1e-5)
    assert BodyLBS.trainable is False and model.stages() == [] and not list(model.parameters())


def test_rest_motion_gives_the_rest_garment(tiny_train):
    model = BodyLBS.from_data(tiny_train, BodyLBSConfig())
    body = training_body(tiny_train)
    world = _world(model, body.rest_motion(3))
    assert np.abs(world - tiny_train.garment.verts[None]).max() < 1e-5


def test_rigid_root_motion_moves_the_garment_rigidly(tiny_train):
    model = BodyLBS.from_data(tiny_train, BodyLBSConfig())
    body = training_body(tiny_train)
    T = 6
    motion = body.rest_motion(T)
    t = np.linspace(0, 1, T, dtype=np.float32)[:, None]
    motion.rotations[:, 0] = t * np.array([0.3, -0.2, 2.5], np.float32)  # tilt and heading (up to ~150 degrees)
    motion.translation = motion.translation + t * np.array([0.4, -0.7, 0.1], np.float32)
    R = axis_angle_to_matrix(torch.from_numpy(motion.rotations[:, 0]).double()).numpy()
    root = body.rest_root_position()
    expected = np.einsum("tij,vj->tvi", R, tiny_train.garment.verts - root) + motion.translation[:, None]
    assert np.abs(_world(model, motion) - expected).max() < 1e-5


def test_follows_the_body_skeleton_like_the_simulator_pins(tiny_train):
    # The canonical forward kinematics from the features equals the world skinning the simulator
    # uses for the pinned vertices (same weights), on a real procedural motion.
    model = BodyLBS.from_data(tiny_train, BodyLBSConfig())
    body = training_body(tiny_train)
    motion = tiny_train.sequences[0].motion
    expected = skin_garment(tiny_train.garment.verts, model.weights.numpy(), body, motion)
    assert np.abs(_world(model, motion) - expected).max() < 1e-5


def test_config_file_has_only_an_empty_model_section():
    assert load_config(Config, CONFIG_FILE) == Config()


def test_only_joints_that_skin_the_garment_and_only_their_own_frame_move_it(tiny_train):
    """What the method reads: each frame's own pose, and of it only the joints with a skinning weight on
    the garment (or their ancestors); a joint that weighs on no garment vertex is irrelevant."""
    model = BodyLBS.from_data(tiny_train, BodyLBSConfig())
    s = tiny_train.sequences[0]
    root, joints = torch.from_numpy(s.root)[None, :6], torch.from_numpy(s.joints)[None, :6]
    weight = model.weights.sum(0).numpy()  # (J,) total weight of each joint on the garment
    parents = model.parents
    ancestors = set()
    for j in np.flatnonzero(weight > 0):
        while j >= 0:
            ancestors.add(int(j))
            j = parents[j]
    unused = next(j for j in range(1, len(weight)) if j not in ancestors)
    used = max(np.flatnonzero(weight > 0), key=lambda j: weight[j])
    with torch.no_grad():
        base = model(root, joints)["verts"]

        def change(joint: int) -> torch.Tensor:
            j = joints.clone()
            j[:, 3, joint - 1] += 0.3
            return (model(root, j)["verts"] - base).norm(dim=-1).amax(-1)[0]

        moved, still = change(int(used)), change(unused)
        r = root.clone()
        r[:, 3, 0] += 0.05
        lifted = model(r, joints)["verts"] - base
    assert moved[3] > 1e-3 and moved[[0, 1, 2, 4, 5]].max() == 0
    assert still.max() == 0
    # the root height lifts every vertex of that frame by exactly its change
    assert torch.allclose(lifted[0, 3], torch.tensor([0.0, 0.0, 0.05]).expand_as(lifted[0, 3]), atol=1e-5)
    assert lifted[0, [0, 1, 2, 4, 5]].abs().max() == 0
