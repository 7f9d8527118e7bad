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
        # Three equal triangles on one edge: split, the third is a piece as large as the others.
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nf 1 2 3\nf 2 1 4\nf 1 2 5\n",
         "2 separate pieces; the second largest has 33% .* after splitting 1 non-manifold edges"),
        # Two fans touching at one vertex: split into two pieces of equal size.
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv -1 0 0\nv 0 -1 0\nf 1 2 3\nf 1 4 5\n", "2 separate pieces; the second largest has 50%"),
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
    """A penetration is pushed out and the push reported, measured against the rigid placement."""
    from loosefit.garment.fitting import outward

    v = skirt.verts.astype(np.float64)
    d, direction = outward(sdf, v)
    dent = d < d.min() + 0.004  # the vertices nearest the hips, moved 6 mm into the body
    v[dent] -= (d[dent] + 0.006)[:, None] * direction[dent]
    path = tmp_path / "tight.ply"
    trimesh.Trimesh(v, skirt.faces, process=False).export(path)
    assert sdf.query(v).min() < -0.005
    g = import_garment(path, body)
    assert g.params["up"] == "z" and mesh_report(g.verts, g.faces).ok
    assert clearance(g, sdf) > 0.003
    rigid = v + np.asarray(g.params["offset"])  # the placement: the same axes and unit, moved
    moved = np.linalg.norm(g.verts - rigid, axis=1)
    assert g.params["pushed_out"]["max_mm"] == pytest.approx(1e3 * moved.max(), abs=0.01)
    assert g.params["pushed_out"]["max_mm"] > 6.0 and g.params["pushed_out"]["over_5mm_percent"] > 0
    moved_before = np.linalg.norm(g.verts[~dent] - rigid[~dent], axis=1)
    assert np.median(moved_before) < 1e-6  # away from the dent the garment keeps its shape


@pytest.mark.parametrize("size, unit, message", [
    (0.7, "cm", r"its largest side is 7 mm in cm, .* \(in the other units: 70 cm in m, 0\.7 mm in mm\)"),  # metres read as cm
    (6.0, None, r"its largest side is 6 m in m, 6 cm in cm, 6 mm in mm"),  # no unit makes a garment of it
    (0.01, None, r"its largest side is 1 cm in m, 0\.1 mm in cm, 0\.01 mm in mm"),
    (6000.0, None, r"its largest side is 6e\+03 m in m, 60 m in cm, 6 m in mm"),
])
def test_a_size_no_unit_makes_a_garment_is_refused(tmp_path, body, skirt, size, unit, message):
    path = tmp_path / "odd.obj"
    v = skirt.verts.astype(np.float64)
    trimesh.Trimesh(v * size / np.ptp(v, axis=0).max(), skirt.faces, process=False).export(path)
    with pytest.raises(InputError, match="no unit gives a garment's size: " + message):
        import_garment(path, body, unit=unit)


# Garments as other tools write them: centred at their own pelvis origin, Y-up (+Z front), in
# metres or centimetres. Each must land where the same template made for the body is.


@pytest.fixture(scope="module")
def tops(body, skirt):
    """Template garments with the three kinds of top, made for the body: ``name -> (verts, faces)``."""
    from loosefit.garment.level_cut import cut_mesh

    lm = measure_body(body)
    straps = make_garment("dress", body, seed=2, edge_length=0.045, sleeve_length=0.0)
    v, f, _ = cut_mesh(straps.verts, straps.faces, straps.verts[:, 2] - (lm.armpit_z - 0.05))
    sleeves = make_garment("dress", body, seed=4, edge_length=0.045, sleeve_length=0.4)
    return {
        "waistband": (skirt.verts, skirt.faces),
        "shoulders": (sleeves.verts, sleeves.faces),
        "straps": (straps.verts, straps.faces),
        "strapless": (v, f),
    }


def pelvis_y_up(body, verts, scale):
    """Vertices of a Z-up garment made for ``body`` as a Y-up file centred at the pelvis (root) joint."""
    v = np.asarray(verts, np.float64) - body.rest_joints()[0]
    return np.stack([v[:, 0], v[:, 2], -v[:, 1]], 1) * scale


@pytest.mark.parametrize(
    "top, unit", [("waistband", "cm"), ("waistband", "m"), ("shoulders", "cm"), ("shoulders", "m"),
                  ("straps", "m"), ("strapless", "cm"), ("strapless", "m")]
)
def test_foreign_garment_lands_where_it_was_made(tmp_path, body, tops, top, unit):
    verts, faces = tops[top]
    path = write_obj(tmp_path / f"{top}.obj", pelvis_y_up(body, verts, {"m": 1.0, "cm": 100.0}[unit]), faces)
    g = import_garment(path, body)
    assert g.params["unit"] == unit and g.params["up"] == "y" and g.params["attachment"] == top
    # The offset that undoes the pelvis origin is the pelvis joint: within 2 cm on every axis.
    err = np.asarray(g.params["offset"]) - body.rest_joints()[0]
    assert np.abs(err).max() < 0.02, err
    assert g.params["top_z"] == pytest.approx(float(np.max(verts[:, 2])), abs=0.02)


def test_implausible_placements_are_refused(tmp_path, body, skirt, tops):
    v = skirt.verts.astype(np.float64)
    wide = write_obj(tmp_path / "wide.obj", v * [2.2, 2.2, 1.0], skirt.faces)  # a 2.2 times too wide cape
    with pytest.raises(InputError, match=r"no plausible placement.*cm gap at the top") as err:
        import_garment(wide, body)
    assert str(wide) in str(err.value) and "tried z-up as" in str(err.value)
    tight = write_obj(tmp_path / "tight.obj", v * [0.6, 0.6, 1.0], skirt.faces)  # would sit inside the hips
    with pytest.raises(InputError, match=r"tight.obj: no plausible placement.*1[0-9]% of points over 1 cm inside"):
        import_garment(tight, body)
    dress, faces = tops["shoulders"]
    side = write_obj(tmp_path / "side.obj", pelvis_y_up(body, dress, 1.0), faces)
    with pytest.raises(InputError, match="side.obj: no plausible placement.*tried z-up as"):
        import_garment(side, body, up="z")  # the dress on its side, forced


def test_file_position_is_kept_only_where_plausible(tmp_path, body, tops):
    dress, faces = tops["shoulders"]
    # The dress around the shins (hugging them at 90 cm below its place): moved up to the shoulders.
    g = import_garment(write_obj(tmp_path / "shins.obj", dress - [0.0, 0.0, 0.9], faces), body)
    assert g.params["attachment"] == "shoulders" and g.params["offset"][2] == pytest.approx(0.9, abs=0.02)
    g = import_garment(write_obj(tmp_path / "here.obj", dress, faces), body)
    assert g.params["offset"] == [0.0, 0.0, 0.0]


def test_nonmanifold_seams_are_repaired_and_simulated(tmp_path, body, skirt):
    """The skirt as two panel edges of a front seam written twice (1e-5 m apart), with a 1 cm ruffle
    stitched into the seam (three faces on each seam edge): welded, split, the ruffle dropped,
    the skirt as made, and Blender simulates it with the quality gate passing."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    from loosefit.motion.procedural import generate
    from loosefit.sim import SimParams, simulate_sequence

    v, f = skirt.verts.astype(np.float64), skirt.faces
    edges, _, _ = unique_edges(f)
    length = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    graph = coo_matrix((length, (edges[:, 0], edges[:, 1])), shape=(len(v), len(v)))
    front = np.nonzero(v[:, 1] < 0)[0]
    top = front[np.argmin(np.abs(v[front, 0]) + 10 * (v[:, 2].max() - v[front, 2]))]
    low = front[np.argmin(np.abs(v[front, 0]) + 10 * (v[front, 2] - v[:, 2].min()))]
    _, pred = dijkstra(graph, directed=False, indices=top, return_predecessors=True)
    seam = [low]
    while seam[-1] != top:
        seam.append(pred[seam[-1]])
    seam = np.array(seam[::-1])
    # Panel copies: faces right of the seam use their own copies of the seam vertices.
    copies = np.arange(len(v), len(v) + len(seam))
    faces = f.copy()
    right = v[f].mean(1)[:, 0] > 0
    for s, c in zip(seam, copies):
        faces[right & (f == s).any(1)] = np.where(faces[right & (f == s).any(1)] == s, c, faces[right & (f == s).any(1)])
    ruffle = v[seam] + [0.0, -0.01, 0.0]
    r = np.arange(len(v) + len(seam), len(v) + 2 * len(seam))
    stitched = [[seam[i], seam[i + 1], r[i]] for i in range(len(seam) - 1)]
    stitched += [[seam[i + 1], r[i + 1], r[i]] for i in range(len(seam) - 1)]
    verts = np.vstack([v, v[seam] + 1e-5, ruffle])
    path = write_obj(tmp_path / "seams.obj", verts, np.vstack([faces, stitched]))
    # Welded, the seam edges really carry three faces each.
    assert len(mesh_report(*weld_all(verts, np.vstack([faces, stitched]))).nonmanifold_edges) == len(seam) - 1
    g = import_garment(path, body)
    rep = g.params["repairs"]
    assert rep["merged_vertices"] == len(seam) and rep["nonmanifold_edges"] == len(seam) - 1
    assert rep["dropped_pieces"] == 1 and g.num_verts == skirt.num_verts and len(g.faces) == len(skirt.faces)
    np.testing.assert_allclose(g.verts, skirt.verts, atol=1e-4)
    motion = generate("walk", 0.5, 0, body)
    result = simulate_sequence(g, body, motion, SimParams(preroll=0.3))
    assert result.status == "ok", result.reason
    assert result.verts.shape == (motion.num_frames, skirt.num_verts, 3)


def weld_all(verts, faces):
    from loosefit.garment.seam_repair import weld

    v, f, _ = weld(verts, faces, 1e-4)
    return v, f


def test_garment_made_for_another_body(tmp_path, body):
    """A strap dress made for a taller Anny (height 0.8), written Y-up in cm about that body's
    pelvis: its top lands as far above this body's neck joint as it was above that body's, within 2 cm."""
    from loosefit.body import AnnyBody
    from loosefit.body.anny_body import AnnyShape

    tall = AnnyBody(AnnyShape(height=0.8))
    dress = make_garment("dress", tall, seed=5, edge_length=0.05)
    v = dress.verts.astype(np.float64)
    g = import_garment(write_obj(tmp_path / "tall.obj", pelvis_y_up(tall, v, 100.0), dress.faces), body)
    neck = lambda b: measure_body(b).joints["neck"][0][2]  # noqa: E731
    assert g.params["attachment"] == "straps"
    assert g.params["top_z"] - neck(body) == pytest.approx(v[:, 2].max() - neck(tall), abs=0.02)
    assert measure_body(tall).joints["neck"][0][2] - neck(body) > 0.05  # the bodies really differ


def _tube(n, rings=2, radius=0.2, height=0.5):
    """A cylinder side of ``rings`` rings of ``n`` vertices: two openings of ``n`` vertices each."""
    angle = 2 * np.pi * np.arange(n) / n
    verts = [[radius * np.cos(a), radius * np.sin(a), z] for z in np.linspace(1.0, 1.0 - height, rings) for a in angle]
    faces = []
    for r in range(rings - 1):
        for i in range(n):
            a, b, c, d = r * n + i, r * n + (i + 1) % n, (r + 1) * n + i, (r + 1) * n + (i + 1) % n
            faces += [[a, c, b], [b, c, d]]
    return np.array(verts), np.array(faces)


def _grid(n, size=0.5):
    """A flat square of ``n`` x ``n`` vertices: one opening."""
    u = np.linspace(0, size, n)
    verts = np.array([[x, 0.0, 1.0 - y] for y in u for x in u])
    faces = [[j * n + i, j * n + i + 1, (j + 1) * n + i] for j in range(n - 1) for i in range(n - 1)]
    faces += [[j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i] for j in range(n - 1) for i in range(n - 1)]
    return verts, np.array(faces)


@pytest.mark.parametrize("mesh, message", [
    ((np.array([[0, 0, 0], [0.5, 0, 0], [0, 0.5, 0]]), np.array([[0, 1, 2]])),
     r"not a garment: 3 vertices, 1 faces with 1 opening\(s\)"),
    (_grid(12), r"not a garment: 144 vertices, 242 faces with 1 opening\(s\)"),  # a cape: nothing to put on
    ((trimesh.creation.icosphere(2, 0.3).vertices, trimesh.creation.icosphere(2, 0.3).faces),
     r"not a garment: 162 vertices, 320 faces with 0 opening\(s\)"),  # a closed surface
    (_tube(6, rings=4), r"too coarse to be a garment: 24 vertices, 36 faces, its largest opening has 6 vertices"),
])
def test_meshes_too_small_to_wear_are_refused(tmp_path, body, mesh, message):
    path = write_obj(tmp_path / "small.obj", *mesh)
    with pytest.raises(InputError, match=message) as err:
        import_garment(path, body)
    assert str(err.value).startswith(str(path))


def test_the_smallest_wearable_tube_is_imported(tmp_path, body):
    # 8 vertices around and two openings: wearable by the counts, so it reaches placement (around the chest),
    # but its 13 cm chords cut up to 3 cm into the body, which the push refuses; 16 vertices around do not.
    with pytest.raises(InputError, match="too deep inside the body: pushing them out would move them up to"):
        import_garment(write_obj(tmp_path / "tube8.obj", *_tube(8, rings=6, radius=0.17)), body)
    g = import_garment(write_obj(tmp_path / "tube.obj", *_tube(16, rings=6, radius=0.17)), body)
    assert g.num_verts == 96 and g.params["attachment"] in ("strapless", "waistband")
