"""The joint-map writer: on CMU, Mixamo and unknown skeletons (BVH files written here) the map it
writes imports the motion to the source's joint positions; on the real Character Creator clips it
finds the built-in map's pairs."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from loosefit.errors import InputError
from loosefit.motion.bvh import import_bvh, write_bvh
from loosefit.motion.joint_map import builtin_joint_maps, load_joint_map
from loosefit.motion.map_writer import write_joint_map
from tests.conftest import TEST_MOCAP
from tests.motion.test_retarget import MIXAMO, joints, smooth_motion, to_bvh


def test_cmu_skeleton_maps_every_joint_to_itself(body, tmp_path):
    """Y-up centimetres, CMU names: every pair the map writes is a joint with itself, it covers the
    built-in cmu map but for the thumbs (which the longest-finger chain does not reach), and the
    import through it gives the source's joint positions."""
    motion = smooth_motion(body, 30.0)
    write_bvh(tmp_path / "cmu.bvh", to_bvh(body, motion, up="y", scale=100.0, order="ZXY"))
    written, notes = write_joint_map(tmp_path / "cmu.bvh", body, tmp_path / "cmu.yaml")
    assert all(alts == (t,) for t, alts in written.joints.items())
    assert set(builtin_joint_maps()["cmu"].joints) - set(written.joints) == {"LThumb", "RThumb"}
    assert written.ignore == ("LThumb", "RThumb") and not [n for n in notes if "not fit" in n]
    reread = load_joint_map(tmp_path / "cmu.yaml")  # the YAML holds the same map
    assert reread.joints == written.joints and reread.ignore == written.ignore
    imported = import_bvh(tmp_path / "cmu.bvh", body, tmp_path / "cmu.yaml")
    assert np.abs(joints(body, imported) - joints(body, motion)).max() < 1e-4


def test_mixamo_skeleton_finds_the_builtin_pairs(body, tmp_path):
    """Mixamo names with the namespace prefix, no hip sockets, three spine joints named one lower
    than CMU's (Spine, Spine1, Spine2 for LowerBack, Spine, Spine1): the chain order pairs them as
    the built-in mixamo map does."""
    motion = smooth_motion(body, 30.0)
    keep = [j for j, n in enumerate(body.joint_names) if n not in ("LHipJoint", "RHipJoint", "Neck1")]
    names = ["mixamorig:" + MIXAMO.get(body.joint_names[j], body.joint_names[j]) for j in keep]
    write_bvh(tmp_path / "mixamo.bvh", to_bvh(body, motion, names=names, keep=keep, order="XYZ"))
    written, _ = write_joint_map(tmp_path / "mixamo.bvh", body, tmp_path / "mixamo.yaml")
    builtin = builtin_joint_maps()["mixamo"].joints
    assert {t: alts[0].split(":")[-1] for t, alts in written.joints.items() if t in builtin} == {
        t: alts[0] for t, alts in builtin.items()}
    imported = import_bvh(tmp_path / "mixamo.bvh", body, tmp_path / "mixamo.yaml")
    assert np.abs(joints(body, imported) - joints(body, motion)).max() < 1e-4


@pytest.mark.parametrize("mirror", [False, True])
def test_unknown_skeleton_without_side_names(body, tmp_path, mirror):
    """Names that say nothing (``bone07``), right side first in the file when ``mirror``: the import
    refuses it and names the command that writes a map; the written map tells left from right by the
    facing and imports the motion to the source's joint positions."""
    motion = smooth_motion(body, 30.0, yaw=0.3)
    order = list(range(body.num_joints))
    if mirror:  # swap which subtree comes first under every joint: the file lists the right side first
        order = sorted(order, key=lambda j: body.joint_names[j].replace("Left", "~").replace("LHip", "~")
                       .replace("LThumb", "~"))
        order = _parents_first(order, body.parents)
    names = [f"bone{k:02d}" for k in range(len(order))]
    write_bvh(tmp_path / "odd.bvh", to_bvh(body, motion, names=names, keep=order, up="y", scale=100.0))
    with pytest.raises(InputError, match="loosefit motion map FILE.bvh --out MAP.yaml"):
        import_bvh(tmp_path / "odd.bvh", body)
    written, _ = write_joint_map(tmp_path / "odd.bvh", body, tmp_path / "odd.yaml")
    text = (tmp_path / "odd.yaml").read_text()
    assert "skeleton's facing" in text and yaml.safe_load(text)["joints"]["LeftUpLeg"] == names[
        order.index(body.joint_names.index("LeftUpLeg"))]
    imported = import_bvh(tmp_path / "odd.bvh", body, tmp_path / "odd.yaml")
    assert np.abs(joints(body, imported) - joints(body, motion)).max() < 1e-4


def _parents_first(order: list[int], parents) -> list[int]:
    """``order`` rearranged so that every joint comes after its parent (stable otherwise)."""
    out, placed = [], set()
    while len(out) < len(order):
        for j in order:
            if j not in placed and (parents[j] < 0 or parents[j] in placed):
                out.append(j)
                placed.add(j)
    return out


def test_real_character_creator_clip_gives_the_cc_pairs(body, tmp_path):
    """On a real CMU clip on the 99-joint Character Creator skeleton (twist, share, finger, toe and
    face bones), the written map pairs the 23 joints of the built-in cc map as it does."""
    written, notes = write_joint_map(TEST_MOCAP / "007_01.bvh", body, tmp_path / "cc.yaml")
    builtin = builtin_joint_maps()["cc"].joints
    assert {t: written.joints.get(t) for t in builtin} == builtin
    assert not [n for n in notes if "not fit" in n]
