"""Collision ratio with a closed box as the body: static, per-frame and moving bodies, tolerance."""

import numpy as np
import pytest
import trimesh

from loosefit.errors import InputError
from loosefit.geometry.signed_distance import BodySDF
from loosefit.metrics.collision import collision_mask, collision_ratio, collision_ratio_per_frame

BOX = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
BV, BF = np.asarray(BOX.vertices), np.asarray(BOX.faces)
POINTS = np.array([[0.0, 0, 0], [0.4995, 0, 0], [2.0, 0, 0], [0, 0.3, 0.2]])  # deep, 0.5 mm deep, outside, deep


def test_ratio_counts_vertices_deeper_than_the_tolerance():
    assert collision_mask(POINTS, BodySDF(BV, BF)).tolist() == [[True, False, False, True]]
    assert collision_ratio(POINTS, BodySDF(BV, BF)) == pytest.approx(50.0)
    assert collision_ratio(POINTS, BV, BF, tolerance=0.0) == pytest.approx(75.0)


def test_moving_body_and_per_frame_sdfs():
    garment = np.stack([POINTS, POINTS])
    body = np.stack([BV, BV + [3.0, 0, 0]])  # the box slides away in frame 1
    assert collision_ratio_per_frame(garment, body, BF).tolist() == [50.0, 0.0]
    sdfs = [BodySDF(b, BF) for b in body]
    assert collision_ratio(garment, sdfs) == pytest.approx(25.0)


def test_bad_bodies():
    with pytest.raises(InputError, match="faces"):
        collision_ratio(POINTS, BV)
    with pytest.raises(InputError, match=r"\(3, Vb, 3\)"):
        collision_ratio(np.stack([POINTS] * 3), np.stack([BV, BV]), BF)
    with pytest.raises(InputError, match="tolerance"):
        collision_ratio(POINTS, BV, BF, tolerance=-1)
