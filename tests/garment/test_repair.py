"""Diagnosis and --repair of messy garment meshes built here, checked against brute-force counts over the
faces as written and against the clean mesh they were made from."""

import re
from collections import defaultdict

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.garment.diagnosis import diagnose
from loosefit.garment.mesh_file import read_mesh_file
from loosefit.garment.repair import repair_mesh

S, R = 12, 5  # segments around, rings up


def tube(radius=0.2, height=0.4):
    """A tube open at both ends, ``R`` rings of ``S`` vertices, faces wound outward: ``(verts, faces)``."""
    theta = 2 * np.pi * np.arange(S) / S
    z = np.linspace(0.0, height, R)
    verts = np.stack(np.broadcast_arrays(radius * np.cos(theta)[None], radius * np.sin(theta)[None], z[:, None]), -1)
    faces = []
    for r in range(R - 1):
        for s in range(S):
            a, b = r * S + s, r * S + (s + 1) % S
            faces += [[a, b, b + S], [a, b + S, a + S]]
    return verts.reshape(-1, 3), np.array(faces)


V0, F0 = tube()
FIN = (S + 3, 2 * S + 3)  # a vertical interior edge (0-based vertices)
FLIPPED, DUPS, SEP = 50, (10, 30), 9.0


def messy():
    """The tube with, in the file's order: face FLIPPED wound the other way, 3 fin faces on edge FIN,
    face 10 again, face 30 again wound the other way, a degenerate face, and a 2-face piece far away."""
    a, b = FIN
    mid = 0.5 * (V0[a] + V0[b])
    out = np.array([mid[0], mid[1], 0.0]) / np.linalg.norm(mid[:2])
    apex = [mid + 0.05 * out * np.cos(t) + 0.05 * np.array([-out[1], out[0], 0.0]) * np.sin(t) for t in (0.0, 0.6, -0.6)]
    far = np.array([[SEP, 0, 0], [SEP + 0.01, 0, 0], [SEP, 0.01, 0], [SEP + 0.01, 0.01, 0]])
    verts = np.concatenate([V0, apex, far])
    n = len(V0)
    faces = F0.copy()
    faces[FLIPPED] = faces[FLIPPED, ::-1]
    extra = [[a, b, n], [b, a, n + 1], [a, b, n + 2],  # the fin
             F0[DUPS[0]], F0[DUPS[1], ::-1],  # duplicates
             [0, 0, 1],  # degenerate
             [n + 3, n + 4, n + 5], [n + 4, n + 6, n + 5]]  # a small piece
    return verts, np.concatenate([faces, extra])


def write_obj(path, verts, faces):
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(verts, float).tolist()]
    lines += ["f " + " ".join(str(i + 1) for i in f) for f in np.asarray(faces).tolist()]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_ply(path, verts, faces):
    head = ["ply", "format ascii 1.0", f"element vertex {len(verts)}", "property float x", "property float y",
            "property float z", f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    body = [f"{x!r} {y!r} {z!r}" for x, y, z in np.asarray(verts, float).tolist()]
    body += [f"{len(f)} " + " ".join(str(int(i)) for i in f) for f in faces]
    path.write_text("\n".join(head + body) + "\n")
    return path


def brute_force(verts, faces):
    """Counts by plain loops over the faces as written: each defect counted as diagnose defines it."""
    faces = [tuple(int(i) for i in f) for f in faces]
    degenerate = [k for k, f in enumerate(faces) if len(set(f)) < 3
                  or np.linalg.norm(np.cross(verts[f[1]] - verts[f[0]], verts[f[2]] - verts[f[0]])) == 0]
    seen, duplicate = {}, []
    for k, f in enumerate(faces):
        if k in degenerate:
            continue
        if frozenset(f) in seen:
            duplicate.append((k, seen[frozenset(f)]))
        else:
            seen[frozenset(f)] = k
    clean = [faces[k] for k in sorted(seen.values())]
    edge_faces = defaultdict(list)
    for k, f in enumerate(clean):
        for c in range(3):
            edge_faces[frozenset((f[c], f[(c + 1) % 3]))].append(k)
    nonmanifold = sorted(tuple(sorted(e)) for e, fs in edge_faces.items() if len(fs) > 2)
    border = [tuple(e) for e, fs in edge_faces.items() if len(fs) == 1]
    parent = {}

    def find(x):
        while parent.setdefault(x, x) != x:
            x = parent[x]
        return x

    for a, b in border:
        parent[find(a)] = find(b)
    loops = len({find(a) for a, _ in border})
    degree = defaultdict(int)
    for a, b in border:
        degree[a] += 1
        degree[b] += 1
    for f in clean:  # pieces: faces joined through shared vertices
        parent[find(("v", f[0]))] = find(("v", f[1]))
        parent[find(("v", f[1]))] = find(("v", f[2]))
    pieces = len({find(("v", f[0])) for f in clean})
    return dict(degenerate=degenerate, duplicate=duplicate, nonmanifold=nonmanifold, loops=loops,
                open_vertices=sorted(v for v, d in degree.items() if d > 2), pieces=pieces)


def oriented_manifold(faces):
    """Every edge has at most two faces, and an edge with two is run once in each direction."""
    directed = defaultdict(int)
    undirected = defaultdict(int)
    for f in np.asarray(faces).tolist():
        for c in range(3):
            directed[(f[c], f[(c + 1) % 3])] += 1
            undirected[frozenset((f[c], f[(c + 1) % 3]))] += 1
    return (max(undirected.values()) <= 2 and max(directed.values()) == 1
            and all(directed[(b, a)] == 1 for (a, b) in directed if undirected[frozenset((a, b))] == 2))


def canonical(faces):
    """Faces as a sorted list of tuples, each rotated to start at its smallest vertex (winding kept)."""
    return sorted(tuple(np.roll(f, -int(np.argmin(f))).tolist()) for f in np.asarray(faces))


def test_diagnosis_counts_and_file_numbers(tmp_path):
    verts, faces = messy()
    v, f, numbers = read_mesh_file(write_obj(tmp_path / "messy.obj", verts, faces))
    ref = brute_force(verts, faces)
    d = diagnose(v, f, numbers)
    assert d.degenerate_faces == len(ref["degenerate"]) == 1
    assert d.duplicate_faces == len(ref["duplicate"]) == 2
    assert d.nonmanifold_edges == len(ref["nonmanifold"]) == 1 and ref["nonmanifold"] == [tuple(sorted(FIN))]
    assert d.boundary_loops == ref["loops"] == 4  # the tube's 2, the fin's, the small piece's
    assert d.open_boundary_vertices == len(ref["open_vertices"]) == 2  # the fin's ends: 3 boundary edges each
    assert d.pieces == ref["pieces"] == 2 and d.nonorientable_pieces == 0 and d.misoriented_faces == 1
    # OBJ numbers from 1; face k is on line len(verts) + k.
    nv, nf = len(V0) + 7, len(F0)
    text = d.text()
    assert f"vertices {FIN[0] + 1}-{FIN[1] + 1} with 5 faces" in text
    assert f"face {nf + 4} (line {nv + nf + 4}) repeats {DUPS[0] + 1} (line {nv + DUPS[0] + 1})" in text
    assert f"{nf + 5} (line {nv + nf + 5}) repeats {DUPS[1] + 1} (line {nv + DUPS[1] + 1})" in text
    assert f"1 degenerate face (faces {nf + 6} (line {nv + nf + 6}))" in text
    assert f"1 face wound against their neighbours (faces {FLIPPED + 1} (line {nv + FLIPPED + 1}))" in text
    assert f"vertices where a boundary is not a simple loop (vertices {FIN[0] + 1}, {FIN[1] + 1})" in text
    # PLY numbers from 0, without lines.
    v, f, numbers = read_mesh_file(write_ply(tmp_path / "messy.ply", verts, faces))
    text = diagnose(v, f, numbers).text()
    assert f"vertices {FIN[0]}-{FIN[1]} with 5 faces" in text and f"face {nf + 3} repeats {DUPS[0]};" in text
    assert f"(faces {FLIPPED})" in text and "line" not in text


def test_repair_gives_back_the_tube(tmp_path):
    verts, faces = messy()
    v, f, numbers = read_mesh_file(write_obj(tmp_path / "messy.obj", verts, faces))
    out_v, out_f, report = repair_mesh(v, f, numbers)
    assert len(out_f) == len(F0) and oriented_manifold(out_f)
    np.testing.assert_array_equal(out_v, V0)  # the file's vertices in order, the unused ones gone
    assert canonical(out_f) == canonical(F0)  # the flipped face wound back, the fin and the rest gone
    assert report.counts() == {"degenerate_faces": 1, "duplicate_faces": 2, "nonmanifold_faces": 3,
                               "reoriented_faces": 1, "dropped_pieces": 1, "unused_vertices": 7}
    assert report.after.clean and report.after.boundary_loops == 2 and report.after.pieces == 1
    nv, nf = len(V0) + 7, len(F0)
    lines = "\n".join(report.lines())
    assert f"dropped 3 faces on 1 non-manifold edge, the smallest sheets' first (faces {nf + 1} (line {nv + nf + 1}), " \
           f"{nf + 2} (line {nv + nf + 2}), {nf + 3} (line {nv + nf + 3}))" in lines
    assert f"flipped 1 face to the winding of most of their piece (faces {FLIPPED + 1} (line {nv + FLIPPED + 1}))" in lines
    assert len(report.lines()) == 6
    assert np.array_equal(report.numbers.vertex, np.arange(len(V0)))  # back to the file's vertices


def quad_mess():
    """The tube with four of its quads written with both diagonals: 14 and 15 side by side, 3 at the hem
    below 15, 40 at the top; the second pair wound either way."""
    faces = [F0]
    for q in (14, 15, 3, 40):  # quad q = faces 2q, 2q+1 (vertices a, b, b+S, a+S)
        a, b, c, d = F0[2 * q][0], F0[2 * q][1], F0[2 * q][2], F0[2 * q + 1][2]
        faces.append([[a, b, d], [b, c, d] if q % 2 else [d, c, b]])
    return V0, np.concatenate(faces).reshape(-1, 3)


def test_repair_keeps_one_triangulation_of_each_quad():
    verts, faces = quad_mess()
    ref = brute_force(verts, faces)
    d = diagnose(verts, faces)
    # Sides of 3 faces or more: 4 of quads 14 and 15, one shared; 3 of quads 3 and 40 (their side on the
    # tube's boundary has 2 faces now), one of quad 3's shared with quad 15.
    assert d.nonmanifold_edges == len(ref["nonmanifold"]) == 4 + 4 - 1 + 3 - 1 + 3
    out_v, out_f, report = repair_mesh(verts, faces)
    assert len(out_f) == len(F0) and oriented_manifold(out_f) and report.after.clean
    assert report.after.boundary_loops == 2 and report.counts()["nonmanifold_faces"] == 8
    area = lambda v, f: 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum()  # noqa: E731
    assert area(out_v, out_f) == pytest.approx(area(V0, F0), rel=1e-3)


def test_welded_soup_names_the_file_vertices(tmp_path):
    """Every face written with its own vertices: welding renumbers, the message names the file's vertices."""
    verts, faces = messy()
    soup = verts[faces.reshape(-1)]
    soup_faces = np.arange(len(soup)).reshape(-1, 3)
    v, f, numbers = read_mesh_file(write_obj(tmp_path / "soup.obj", soup, soup_faces))
    text = diagnose(*_welded(v, f, numbers)).text()
    a, b = map(int, re.search(r"vertices (\d+)-(\d+) with 5 faces", text).groups())
    # The first of the file's vertices at the fin edge's two ends.
    first = [int(np.nonzero((soup == verts[k]).all(1))[0][0]) + 1 for k in FIN]
    assert sorted((a, b)) == sorted(first)


def _welded(v, f, numbers):
    from loosefit.garment.seam_repair import weld

    diag = np.linalg.norm(v.max(0) - v.min(0))
    v, f, _, kept = weld(v, f, 1e-4 * diag, return_kept=True)
    return v, f, numbers.select(vertex=kept)


def moebius(n: int = 12):
    """A Moebius strip of ``n`` quads: one boundary loop and no right side."""
    t = 2 * np.pi * np.arange(n) / n
    verts = []
    for ti in t:
        centre = np.array([np.cos(ti), np.sin(ti), 0.0])
        across = 0.2 * (np.cos(ti / 2) * centre + np.sin(ti / 2) * np.array([0.0, 0.0, 1.0]))
        verts += [centre - across, centre + across]
    faces = []
    for i in range(n):
        a, b = 2 * i, 2 * i + 1
        c, d = (2 * i + 2, 2 * i + 3) if i < n - 1 else (1, 0)  # the last quad joins with a half twist
        faces += [[a, c, b], [b, c, d]]
    return np.array(verts), np.array(faces)


def test_unrepairable_meshes_are_refused_with_what_is_left(tmp_path):
    path = write_obj(tmp_path / "moebius.obj", *moebius())
    v, f, numbers = read_mesh_file(path)
    assert diagnose(v, f, numbers).nonorientable_pieces == 1
    with pytest.raises(InputError, match=r"found no wearable piece: the piece of 100% of the area is not orientable\. "
                                         r"Left after the repairs: 1 piece; .* 1 non-orientable piece") as err:
        repair_mesh(v, f, numbers, path=path)
    assert str(path) in str(err.value)
    # A flat grid: manifold, but no garment (one opening).
    grid_v = np.array([[x, y, 0.0] for y in range(4) for x in range(4)])
    grid_f = np.array([[r * 4 + c, r * 4 + c + 1, r * 4 + c + 5] for r in range(3) for c in range(3)]
                      + [[r * 4 + c, r * 4 + c + 5, r * 4 + c + 4] for r in range(3) for c in range(3)])
    with pytest.raises(InputError, match=r"the piece of 100% of the area is not a garment"):
        repair_mesh(grid_v, grid_f)


# The import: a skirt written as other tools write messy files.


def double_triangulated(faces, quads: int, seed: int = 0):
    """``faces`` plus the other diagonal of ``quads`` quads (pairs of faces sharing an edge, no face in two
    pairs), the added pairs wound either way, then 30 faces written again the other way round."""
    rng = np.random.default_rng(seed)
    edge_faces = defaultdict(list)
    for k, f in enumerate(faces.tolist()):
        for c in range(3):
            edge_faces[frozenset((f[c], f[(c + 1) % 3]))].append(k)
    pairs = [(e, fs) for e, fs in edge_faces.items() if len(fs) == 2]
    extra, used = [], set()
    for i in rng.permutation(len(pairs)):
        e, (f1, f2) = pairs[i]
        if f1 in used or f2 in used or len(extra) >= 2 * quads:
            continue
        used |= {f1, f2}
        a, b = sorted(e)
        c, d = (next(x for x in faces[k] if x not in (a, b)) for k in (f1, f2))
        extra += [[a, c, d], [b, d, c]]
    return np.concatenate([faces, extra, faces[rng.choice(len(faces), 30)][:, ::-1]])


@pytest.fixture(scope="module")
def skirt(body):
    from loosefit.garment import make_garment

    return make_garment("skirt", body, seed=3, edge_length=0.04)


def test_import_refusal_counts_in_the_file_numbers(tmp_path, body, skirt):
    from loosefit.garment import import_garment

    faces = double_triangulated(skirt.faces, 40)
    path = write_obj(tmp_path / "messy.obj", skirt.verts, faces)
    ref = brute_force(skirt.verts.astype(float), faces)
    with pytest.raises(InputError) as err:
        import_garment(path, body)
    text = str(err.value)
    assert text.startswith(f"{path}: ") and "boundary is not closed" not in text
    assert f"{len(ref['nonmanifold'])} non-manifold edges (more than 2 faces)" in text
    assert f"{len(ref['duplicate'])} duplicate faces" in text and "0 degenerate faces" in text
    assert "1 piece;" in text and "0 non-orientable pieces" in text and "`--repair`" in text
    # Every edge named is one of more than two faces in the file, by its 1-based vertex numbers.
    named = re.findall(r"(\d+)-(\d+)", text)
    assert len(named) >= 5
    bad = {(a + 1, b + 1) for a, b in ref["nonmanifold"]}
    assert all(tuple(sorted((int(a), int(b)))) in bad for a, b in named)


def test_cli_repair_imports_and_says_what_changed(tmp_path, body, skirt, capsys):
    from loosefit.cli import main
    from loosefit.garment import Garment

    faces = double_triangulated(skirt.faces, 40)
    path = write_obj(tmp_path / "messy.obj", skirt.verts, faces)
    assert main(["garment", "import", str(path), "--repair", "--out", str(tmp_path / "g.obj")]) == 0
    out = capsys.readouterr().out.splitlines()
    changes = [line for line in out if line.startswith("repair: ")]
    assert [line.split()[1] for line in changes] == ["merged", "dropped", "flipped"]
    assert changes[0].startswith(f"repair: merged 30 duplicate faces into the first of each (faces {len(skirt.faces) + 81} "
                                 f"(line {len(skirt.verts) + len(skirt.faces) + 81})")
    over = len(brute_force(skirt.verts.astype(float), faces)["nonmanifold"])
    assert f" faces on {over} non-manifold edges" in changes[1]
    assert out[-1].startswith(f"wrote {tmp_path / 'g.obj'}")
    g = Garment.load(tmp_path / "g.obj")
    assert oriented_manifold(g.faces) and g.params["repair"]["file"]["nonmanifold_edges"] == over
    # Each quad keeps one of its triangulations, none folded over another.
    assert len(g.faces) == len(skirt.faces)
    area = lambda v, f: 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum()  # noqa: E731
    assert area(g.verts, g.faces) == pytest.approx(area(skirt.verts, skirt.faces), rel=0.01)


def test_polygons_keep_their_file_numbers(tmp_path):
    """A quad is cut into two triangles of one file face; comments, texture lines and relative indices do not
    shift the numbers."""
    obj = tmp_path / "quad.obj"
    obj.write_text("# a quad, a triangle and the quad's first half again\nv 0 0 0\nv 1 0 0\nvt 0 0\nv 1 1 0\nv 0 1 0\n"
                   "v 2 2 2\n\nf 1/1 2/1 3/1 4/1\nf 2 5 3\nf -5 -4 -3\n")
    v, f, numbers = read_mesh_file(obj)
    assert f.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 2], [0, 1, 2]]
    assert numbers.face.tolist() == [0, 0, 1, 2] and numbers.line.tolist() == [9, 9, 10, 11]
    assert "1 duplicate face (face 3 (line 11) repeats 1 (line 9))" in diagnose(v, f, numbers).text()
    ply = tmp_path / "quad.ply"
    write_ply(ply, v, [[0, 1, 2, 3], [1, 4, 2], [0, 1, 2]])
    v, f, numbers = read_mesh_file(ply)
    assert f.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 2], [0, 1, 2]] and numbers.face.tolist() == [0, 0, 1, 2]
    assert "1 duplicate face (face 2 repeats 0)" in diagnose(v, f, numbers).text()


def test_import_of_a_one_sided_surface_says_so(tmp_path, body):
    from loosefit.garment import import_garment

    verts, faces = moebius()
    path = write_obj(tmp_path / "moebius.obj", verts * 0.3 + [0.0, 0.0, 1.0], faces)
    with pytest.raises(InputError, match=r"moebius.obj: the surface is not orientable \(a Moebius-like strip\) where "
                                         r"faces \d+ \(line \d+\) meet their neighbours\. The file has .*"
                                         r"1 non-orientable piece .* the file needs mending where it was made") as err:
        import_garment(path, body)
    assert "--repair" not in str(err.value)
