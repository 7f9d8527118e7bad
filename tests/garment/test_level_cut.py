"""Level-set cut of a planar grid against the exact area of the kept half-plane."""

import numpy as np

from loosefit.garment.level_cut import cut_mesh
from loosefit.garment.mesh_checks import face_areas, mesh_report


def test_level_cut_of_a_plane():
    x, y = np.meshgrid(np.linspace(0, 1, 11), np.linspace(0, 1, 11))
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(121)], 1)
    faces = np.array([[i * 11 + j, i * 11 + j + 1, i * 11 + j + 12] for i in range(10) for j in range(10)]
                     + [[i * 11 + j, i * 11 + j + 12, i * 11 + j + 11] for i in range(10) for j in range(10)])
    phi = verts[:, 0] + 0.5 * verts[:, 1] - 0.63
    out_v, out_f, attrs = cut_mesh(verts, faces, phi, attrs=verts[:, :1], margin=0.0)
    assert mesh_report(out_v, out_f).ok
    assert (out_v[:, 0] + 0.5 * out_v[:, 1] <= 0.63 + 1e-9).all()  # nothing beyond the line
    # Area of {x + y / 2 < 0.63} in the unit square: 0.63 - 0.25 = 0.38, the cut is linear per face.
    np.testing.assert_allclose(face_areas(out_v, out_f).sum(), 0.38, atol=1e-9)
    np.testing.assert_allclose(attrs[:, 0], out_v[:, 0])  # attributes interpolated like positions
    # With the default margin the crossing moves by at most 15 % of an edge.
    clamped_v, clamped_f, _ = cut_mesh(verts, faces, phi)
    assert (clamped_v[:, 0] + 0.5 * clamped_v[:, 1] <= 0.63 + 0.15 * 0.15).all()
    assert mesh_report(clamped_v, clamped_f).ok
