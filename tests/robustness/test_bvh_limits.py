"""Hostile BVH hierarchies: a 10,000-joint chain or a skeleton of thousands of joints is refused naming the file
and the limit (it used to end in a RecursionError); skeletons within the limits still read."""

from __future__ import annotations

import sys

import pytest

from loosefit.cli import main
from loosefit.errors import InputError
from loosefit.motion.bvh import MAX_BVH_DEPTH, MAX_BVH_JOINTS, read_bvh
from tests.robustness.craft import bvh_chain, bvh_flat


def test_ten_thousand_joint_chain_is_refused_naming_the_limit(tmp_path):
    path = tmp_path / "chain.bvh"
    path.write_text(bvh_chain(10_000))
    assert sys.getrecursionlimit() < 10_000 * 2  # the chain would overflow the recursion of a naive parser
    with pytest.raises(InputError) as info:
        read_bvh(path)
    message = str(info.value)
    assert message.startswith(f"{path}: line ") and f"deeper than loosefit reads ({MAX_BVH_DEPTH}" in message, message


def test_too_many_joints_are_refused_naming_the_limit(tmp_path):
    path = tmp_path / "wide.bvh"
    path.write_text(bvh_flat(MAX_BVH_JOINTS + 5))
    with pytest.raises(InputError, match=f"more than {MAX_BVH_JOINTS} joints and end sites") as info:
        read_bvh(path)
    assert str(info.value).startswith(str(path))


def test_skeletons_within_the_limits_read(tmp_path):
    path = tmp_path / "ok.bvh"
    path.write_text(bvh_chain(MAX_BVH_DEPTH))
    bvh = read_bvh(path)
    assert len(bvh.names) == MAX_BVH_DEPTH + 1 and bvh.parents[-1] == MAX_BVH_DEPTH - 1
    path.write_text(bvh_flat(MAX_BVH_JOINTS - 1))
    assert len(read_bvh(path).names) == MAX_BVH_JOINTS


def test_cli_refuses_the_chain_without_traceback(tmp_path, capsys):
    path = tmp_path / "chain.bvh"
    path.write_text(bvh_chain(10_000))
    assert main(["motion", "map", str(path), "--out", str(tmp_path / "map.yaml")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"loosefit motion: error: {path}: line ") and "MAX_BVH_DEPTH" in err, err
    assert not (tmp_path / "map.yaml").exists()
