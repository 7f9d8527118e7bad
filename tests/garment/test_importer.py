"""Garment import: broken files give the documented errors, repairable ones are repaired, units and
up axis are detected, the garment is placed on the body and pushed out of it."""

import numpy as np
import pytest
import trimesh

from loosefit.errors import InputError
from loosefit.garment import import_garment, make_garment
from loosefit.garment.landmarks import measure_body
from loosefit.garment.mesh_checks import mesh_report, unique_edges


@pytest.fixture(scope="module")
def skirt(body):
    return make_garment("skirt", body, seed=3, edge_length=0.04)


@pytest.fixture(scope="module")
def sdf(body):
    return measure_body(body).sdf


def write_obj(path, verts, faces, extra=""):
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(verts, dtype=float).tolist()]
    lines += ["f " + " ".join(str(i + 1) for i in f) for f in np.asarray(faces).tolist()]
    path.write_text("\n".join(lines) + "\n" + extra)
    return path


def clearance(g, sdf):
    edges, _, _ = unique_edges(g.faces)
    mids = 0.5 * (g.verts[edges[:, 0]] + g.verts[edges[:, 1]])
    return min(sdf.query(g.verts).min(), sdf.query(mids).min())


TRI = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "no vertices or no faces"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no vertices or no faces"),
        ("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n", "NaN or infinite"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "line 4: face index out of range 1..3"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nhello world\nf 1 2 3\n", "line 4: not an OBJ statement"),
        ("v 0 0 0\nv 1 0 zero\nv 0 1 0\nf 1 2 3\n", "line 2: vertex coordinates are not numbers"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "line 4: a face needs at least 3 vertices"),
        # Three triangles on one edge: a non-manifold fan.
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nf 1 2 3\nf 2 1 4\nf 1 2 5\n", "1 non-manifold edges"),
        # Two fans touching at one vertex.
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv -1 0 0\nv 0 -1 0\nf 1 2 3\nf 1 4 5\n", "non-manifold vertices"),
    ],
)
def test_broken_obj(tmp_path, body, text, message):
    path = tmp_path / "broken.obj"
    path.write_text(text)
    with pytest.raises(InputError, match=message) as err:
        import_garment(path, body)
    assert str(path) in str(err.value)


def test_file_errors(tmp_path, body):
    with pytest.raises(InputError, match="no such file"):
        import_garment(tmp_path / "missing.obj", body)
    (tmp_path / "g.stl").write_text("solid")
    with pytest.raises(InputError, match="unsupported garment format"):
        import_garment(tmp_path / "g.stl", body)
    (tmp_path / "g.ply").write_text("ply\nformat nonsense\n")
    with pytest.raises(InputError, match="g.ply: unreadable PLY"):
        import_garment(tmp_path / "g.ply", body)


def test_y_up_centimetres_are_converted_and_placed(tmp_path, body, skirt, sdf):
    v = skirt.verts.astype(np.float64)
    y_up = np.stack([v[:, 0], v[:, 2], -v[:, 1]], 1) * 100.0 + [30.0, 50.0, 10.0]  # cm, +Z front, shifted
    g = import_garment(write_obj(tmp_path / "yup.obj", y_up, skirt.faces), body)
    assert g.params["unit"] == "cm" and g.params["up"] == "y"
    assert mesh_report(g.verts, g.faces).ok and g.num_verts == skirt.num_verts
    # Back where it was made, up to the 1 cm placement search and the waistband snug fit.
    assert np.abs(g.verts - skirt.verts).max() < 0.04
    assert clearance(g, sdf) > 0.003
    assert g.pinned.any() and g.verts[g.pinned, 2].min() > g.verts[:, 2].max() - 0.031


def test_garment_made_for_the_body_keeps_its_place(tmp_path, body, skirt):
    g = import_garment(write_obj(tmp_path / "same.obj", skirt.verts * 1000.0, skirt.faces), body)
    assert g.params["unit"] == "mm" and g.params["up"] == "z" and g.params["offset"] == [0.0, 0.0, 0.0]
    np.testing.assert_allclose(g.verts, skirt.verts, atol=1e-5)


def test_soup_duplicates_and_flips_are_repaired(tmp_path, body, skirt, sdf):
    faces = skirt.faces.copy()
    faces[::7] = faces[::7, ::-1]  # inconsistent orientation
    soup = skirt.verts[faces.reshape(-1)]  # every face with its own vertices
    soup_faces = np.arange(len(soup)).reshape(-1, 3)
    soup_faces = np.concatenate([soup_faces, soup_faces[:5], [[0, 0, 1]]])  # duplicates, degenerate
    soup = np.concatenate([soup, [[9.0, 9.0, 9.0]]])  # unreferenced
    g = import_garment(write_obj(tmp_path / "soup.obj", soup, soup_faces), body)
    rep = g.params["repairs"]
    assert rep["merged_vertices"] == len(soup) - 1 - skirt.num_verts
    assert rep["duplicate_faces"] == 5 and rep["degenerate_faces"] == 1 and rep["unreferenced_vertices"] == 1
    assert rep["reoriented_faces"] > 0
    report = mesh_report(g.verts, g.faces)
    assert report.ok and g.num_verts == skirt.num_verts and len(g.faces) == len(skirt.faces)
    assert clearance(g, sdf) > 0.003


def test_pieces(tmp_path, body, skirt):
    far = skirt.verts + [0.0, 0.0, -0.5]
    two = np.concatenate([skirt.verts, far])
    faces = np.concatenate([skirt.faces, skirt.faces + skirt.num_verts])
    with pytest.raises(InputError, match="2 separate pieces"):
        import_garment(write_obj(tmp_path / "two.obj", two, faces), body)
    debris = np.concatenate([skirt.verts, [[0.5, 0.5, 0.5], [0.51, 0.5, 0.5], [0.5, 0.51, 0.5]]])
    faces = np.concatenate([skirt.faces, [[skirt.num_verts, skirt.num_verts + 1, skirt.num_verts + 2]]])
    g = import_garment(write_obj(tmp_path / "debris.obj", debris, faces), body)
    assert g.params["repairs"]["dropped_pieces"] == 1 and g.num_verts == skirt.num_verts


def test_penetration_is_removed_and_ply_reads(tmp_path, body, skirt, sdf):
    v = skirt.verts.astype(np.float64)
    v[:, :2] *= 0.8  # pulled into the hips
    path = tmp_path / "tight.ply"
    trimesh.Trimesh(v, skirt.faces, process=False).export(path)
    assert sdf.query(v).min() < -0.005
    g = import_garment(path, body)
    assert g.params["up"] == "z" and mesh_report(g.verts, g.faces).ok
    assert clearance(g, sdf) > 0.003
