"""The Anny body against Anny's own forward pass, and its shape / proxy / error behaviour."""

import numpy as np
import pytest
import torch

from loosefit.body import AnnyShape
from loosefit.body.anny_body import load_anny
from loosefit.errors import InputError
from loosefit.geometry.rotations import axis_angle_to_matrix, rigid
from loosefit.motion import Motion


def random_motion(body, frames=6, seed=0, scale=0.4):
    rng = np.random.default_rng(seed)
    return Motion(
        rotations=rng.normal(0, scale, (frames, body.num_joints, 3)),
        translation=body.rest_root_position() + rng.normal(0, 0.2, (frames, 3)),
        joint_names=body.joint_names,
        name="random",
    )


def anny_reference(body, motion, shape: AnnyShape):
    """Anny's own forward pass ('local-ref' parameterisation: world-aligned deltas, root delta = world pose)."""
    model = load_anny(body.rig, "anny")
    T, J = motion.rotations.shape[:2]
    R = axis_angle_to_matrix(torch.from_numpy(motion.rotations).double())
    offset = body.anny_offset(shape)
    pose = rigid(R, torch.zeros(T, J, 3, dtype=torch.float64))
    pose[:, 0, :3, 3] = torch.from_numpy(motion.translation - offset)
    with torch.no_grad():
        out = model(pose_parameters=pose, phenotype_kwargs={k: v for k, v in vars(shape).items()})
    return out["vertices"].numpy() + offset, out["bone_poses"][..., :3, 3].numpy() + offset


@pytest.mark.parametrize("shape", [AnnyShape(), AnnyShape(gender=0.9, weight=0.2, height=0.8)])
def test_pose_matches_anny_forward_pass(body, shape):
    motion = random_motion(body)
    posed = body.pose(motion, shape=shape)
    ref_verts, ref_joints = anny_reference(body, motion, shape)
    assert posed.verts.shape == (6, 13718, 3) and posed.verts.dtype == np.float32
    assert np.abs(posed.verts - ref_verts).max() < 2e-5  # metres: float32 round-off only
    assert np.abs(posed.joints - ref_joints).max() < 2e-5


def test_rest_pose_frame_and_skinning_weights(body):
    verts, joints = body.rest_verts(), body.rest_joints()
    assert verts[:, 2].min() == pytest.approx(0.0, abs=1e-6)  # soles on the floor
    assert np.allclose(joints[0, :2], 0.0, atol=1e-6)  # root above the origin
    height = verts[:, 2].max()
    assert height > 1.5 and height < 1.9  # an adult, metres
    assert joints[body.joint_names.index("LeftArm"), 0] > 0  # body left is +X
    assert joints[body.joint_names.index("LeftToeBase"), 1] < joints[body.joint_names.index("LeftFoot"), 1]  # faces -Y
    w = body.skinning_weights()
    assert w.shape == (13718, 31) and (w >= 0).all() and np.allclose(w.sum(1), 1, atol=1e-5)
    posed = body.pose(body.rest_motion(2))
    assert np.abs(posed.verts - verts).max() < 1e-5
    assert np.allclose(posed.joint_transforms[:, :, :3, :3], np.eye(3), atol=1e-6)


def test_shape_changes_rest_mesh(body):
    tall = body.rest_verts(AnnyShape(height=1.0))
    short = body.rest_verts(AnnyShape(height=0.0))
    assert tall[:, 2].max() - short[:, 2].max() > 0.2  # metres
    assert tall[:, 2].min() == pytest.approx(0.0, abs=1e-6)


def test_collision_proxy_shares_frame(body, proxy_body):
    assert proxy_body.num_verts == 1229 and proxy_body.joint_names == body.joint_names
    assert np.abs(proxy_body.rest_joints() - body.rest_joints()).max() < 1e-6
    motion = random_motion(body, frames=3, seed=2)
    fine, coarse = body.pose(motion), proxy_body.pose(motion)
    assert np.abs(fine.joints - coarse.joints).max() < 1e-5
    # Every proxy vertex lies near the full surface (decimation error only).
    from scipy.spatial import cKDTree

    d, _ = cKDTree(fine.verts[1]).query(coarse.verts[1])
    assert np.median(d) < 0.01 and d.max() < 0.06


def test_shape_parsing_and_errors(body):
    assert AnnyShape.parse("gender=0.8, weight=0.3") == AnnyShape(gender=0.8, weight=0.3)
    assert AnnyShape.from_array(AnnyShape(age=0.1).to_array()) == AnnyShape(age=0.1)
    with pytest.raises(InputError, match="height"):
        AnnyShape(height=1.5)
    with pytest.raises(InputError, match="NAME=VALUE"):
        AnnyShape.parse("tallness=0.3")
    bad = random_motion(body)
    bad.rig = "mixamo"
    with pytest.raises(InputError, match="rig"):
        body.pose(bad)
    short = Motion(np.zeros((2, 5, 3)), np.zeros((2, 3)), rig="cmu_mb")
    with pytest.raises(InputError, match="5 joints"):
        body.pose(short)


def test_loading_waits_for_another_process_on_the_cache_lock():
    """While another process holds the cache's lock (it may be writing the cache), loading waits; it goes on
    as soon as the lock is free."""
    import fcntl
    import threading

    from loosefit.body.anny_body import load_anny
    from loosefit.paths import anny_cache_dir

    done = threading.Event()
    with open(anny_cache_dir() / ".loosefit-lock", "a") as held:  # a second open file: flock excludes it too
        fcntl.flock(held, fcntl.LOCK_EX)
        worker = threading.Thread(target=lambda: (load_anny.__wrapped__("cmu_mb", "notoes_collapse10pc"), done.set()))
        worker.start()
        assert not done.wait(1.5)
    worker.join(60)
    assert done.is_set()


def test_collision_proxy_is_made_once_per_shape_and_topology_is_shared_read_only(body):
    from loosefit.body import AnnyBody

    proxy = body.collision_proxy()
    assert body.collision_proxy() is proxy  # asked for by every motion's collision handling
    other = AnnyBody(AnnyShape(gender=1.0))
    assert other.collision_proxy() is not proxy and other.collision_proxy().shape == other.shape
    # a body's topology is Anny's, read once per process: equal to the model's own, each body with its own copy
    model = load_anny(body.rig, "anny")
    np.testing.assert_array_equal(other.faces, model.get_triangular_faces().numpy())
    other.faces[0, 0] += 1
    np.testing.assert_array_equal(body.faces, model.get_triangular_faces().numpy())
    np.testing.assert_array_equal(AnnyBody(AnnyShape()).faces, body.faces)
