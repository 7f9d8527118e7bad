"""load_motion: dispatch on the file's content."""

from __future__ import annotations

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.motion.amass import export_amass
from loosefit.motion.bvh import write_bvh
from loosefit.motion.io import load_motion
from tests.motion.test_retarget import smooth_motion, to_bvh


def test_dispatch_on_content(body, tmp_path):
    motion = smooth_motion(body, 30.0, seconds=0.5)
    motion.save(tmp_path / "own.npz")
    export_amass(tmp_path / "amass.npz", motion, body)
    write_bvh(tmp_path / "clip.bvh", to_bvh(body, motion, up="y", scale=100.0))
    reference = body.pose(motion).joints
    own = load_motion(tmp_path / "own.npz", body)
    assert np.array_equal(own.rotations, motion.rotations)  # a loosefit motion is taken as is
    for name in ("amass.npz", "clip.bvh"):
        loaded = load_motion(tmp_path / name, body)
        assert loaded.num_frames == motion.num_frames
        assert np.abs(body.pose(loaded).joints - reference).max() < 1e-4, name
    with_map = load_motion(tmp_path / "clip.bvh", body, joint_map="cmu")
    assert np.abs(body.pose(with_map).joints - reference).max() < 1e-4


def test_errors_name_the_file(body, tmp_path):
    cases = {}
    np.savez(tmp_path / "other.npz", verts=np.zeros((2, 3)))
    cases["other.npz"] = "expected 'rotations' (loosefit) or 'poses' (AMASS), found ['verts']"
    (tmp_path / "text.npz").write_text("hello")
    cases["text.npz"] = "not a .bvh or .npz motion file"
    np.save(tmp_path / "array.npy", np.zeros(3))
    cases["array.npy"] = "not an .npz archive"
    cases["absent.bvh"] = "motion file not found"
    wrong = smooth_motion(body, 30.0, seconds=0.2)
    wrong.rig = "smpl"
    wrong.save(tmp_path / "wrong.npz")
    cases["wrong.npz"] = "is on rig 'smpl'"
    for name, message in cases.items():
        with pytest.raises(InputError) as err:
            load_motion(tmp_path / name, body)
        assert message in str(err.value) and str(tmp_path / name) in str(err.value), name
    with pytest.raises(InputError, match="a joint map applies to BVH files only"):
        load_motion(tmp_path / "other.npz", body, joint_map="cmu")


def test_a_loosefit_motion_without_a_frame_rate(body, tmp_path):
    """A motion ``.npz`` without ``fps`` needs the rate given (``source_fps``, ``--fps``), and is refused naming
    the file without it; a file with its own rate keeps it, and a rate given that disagrees is refused."""
    motion = smooth_motion(body, 30.0, seconds=0.2)
    np.savez(tmp_path / "bare.npz", rotations=motion.rotations, translation=motion.translation)
    with pytest.raises(InputError, match="no frame rate") as err:
        load_motion(tmp_path / "bare.npz", body)
    assert err.value.path == tmp_path / "bare.npz"
    loaded = load_motion(tmp_path / "bare.npz", body, source_fps=24.0)
    assert loaded.fps == 24.0 and np.array_equal(loaded.rotations, motion.rotations)
    motion.save(tmp_path / "own.npz")
    assert load_motion(tmp_path / "own.npz", body, source_fps=30.0).fps == 30.0
    with pytest.raises(InputError, match="frame rate is 30 fps, --fps says 24"):
        load_motion(tmp_path / "own.npz", body, source_fps=24.0)
