import numpy as np
import pytest

from loosefit.body import AnnyBody
from loosefit.data.mirror import GarmentMirror
from loosefit.errors import InputError
from loosefit.motion.mirror import REFLECTION, joint_partners, mirror_motion
from loosefit.motion.procedural import generate


@pytest.fixture(scope="module")
def proxy():
    return AnnyBody(resolution="low")


def test_a_symmetric_mesh_maps_onto_itself(proxy):
    """The body's collision proxy is symmetric about x = 0: every vertex's mirror image lies on its surface, and
    mirroring a frame twice gives it back up to the interpolation inside a triangle (none at rest)."""
    rest = proxy.rest_verts().astype(np.float64)
    mirror = GarmentMirror.build(rest, proxy.faces)
    assert mirror.asymmetry.max() < 1e-5
    np.testing.assert_allclose(mirror(rest[None])[0], rest, atol=2e-5)
    np.testing.assert_allclose(mirror(mirror(rest[None]))[0], rest, atol=2e-5)


def test_the_mirrored_motion_poses_the_mirror_image(proxy):
    """Posed by the mirrored motion, the body read back through the correspondence is the body posed by the motion:
    the motion's and the mesh's mirrors agree, to the rig's own asymmetry (the neck's joint stands 1.5 mm off the
    midline; a sign error moves limbs by decimetres)."""
    motion = generate("spin", 1.0, 2, proxy)
    mirrored = mirror_motion(motion, joint_partners(proxy.joint_names, proxy.rest_joints()))
    mirror = GarmentMirror.build(proxy.rest_verts(), proxy.faces)
    original, image = proxy.pose(motion).verts, mirror(proxy.pose(mirrored).verts)
    assert np.sqrt(((image - original) ** 2).sum(-1).mean()) < 5e-4
    assert np.linalg.norm(image - original, axis=-1).max() < 0.01


def test_an_asymmetric_mesh_reports_how_far(proxy):
    rest = proxy.rest_verts().astype(np.float64)
    moved = rest.copy()
    moved[rest[:, 0] > 0.05, 0] += 0.03  # the left side 3 cm further out
    mirror = GarmentMirror.build(moved, proxy.faces)
    assert 0.02 < mirror.asymmetry.max() < 0.031
    with pytest.raises(InputError, match="frames of 3 vertices"):
        mirror(np.zeros((2, 3, 3)))
