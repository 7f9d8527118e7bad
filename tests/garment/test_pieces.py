"""Garments of several pieces: a crop top and a skirt kept as one garment (each pinned at its own top), one
piece kept with ``piece``, a piece that hangs free refused with the way out named."""

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.garment import import_garment, make_garment
from loosefit.garment.landmarks import measure_body
from loosefit.garment.level_cut import cut_mesh
from loosefit.garment.mesh_checks import face_areas

from .test_importer import pelvis_y_up, write_obj


@pytest.fixture(scope="module")
def two_piece(body):
    """A crop top (a strap dress cut 8 cm above the waist) and a skirt, made for the body: the vertices,
    faces and the pieces' own ``(verts, faces)``."""
    lm = measure_body(body)
    shirt = make_garment("dress", body, seed=2, edge_length=0.05, sleeve_length=0.0)
    top_v, top_f, _ = cut_mesh(shirt.verts, shirt.faces, lm.waist_z + 0.08 - shirt.verts[:, 2])  # keeps the top
    skirt = make_garment("skirt", body, seed=2, edge_length=0.05, length=0.4)
    verts = np.concatenate([top_v, skirt.verts])
    faces = np.concatenate([top_f, skirt.faces + len(top_v)])
    return verts, faces, (np.asarray(top_v), top_f), (skirt.verts, skirt.faces)


def test_attached_pieces_are_one_garment(tmp_path, body, two_piece):
    verts, faces, (top_v, top_f), (skirt_v, skirt_f) = two_piece
    g = import_garment(write_obj(tmp_path / "two.obj", pelvis_y_up(body, verts, 100.0), faces), body)
    assert g.params["pieces"] == 2 and g.num_verts == len(verts) and len(g.faces) == len(faces)
    assert g.params["attachment"] == "straps" and g.params["unit"] == "cm"
    # Placed where it was made (the pelvis origin undone), the pieces in the file's order.
    np.testing.assert_allclose(g.verts, verts, atol=0.02)
    # Each piece is pinned at its own top: the shoulders and the skirt's waistband.
    top_pins, skirt_pins = g.pinned[: len(top_v)], g.pinned[len(top_v):]
    assert top_pins.any() and skirt_pins.any()
    assert g.verts[len(top_v):][skirt_pins, 2].min() > skirt_v[:, 2].max() - 0.03 - 0.02
    assert g.verts[: len(top_v)][top_pins, 2].min() > top_v[:, 2].max() - 0.03 - 0.02


def test_one_piece_is_kept(tmp_path, body, two_piece):
    verts, faces, (top_v, top_f), (skirt_v, skirt_f) = two_piece
    path = write_obj(tmp_path / "two.obj", verts, faces)
    areas = [face_areas(np.asarray(top_v, float), top_f).sum(), face_areas(np.asarray(skirt_v, float), skirt_f).sum()]
    sizes = [len(top_v), len(skirt_v)]
    largest = int(np.argmax(areas))
    g = import_garment(path, body, piece="largest")
    assert g.num_verts == sizes[largest] and g.params["pieces"] == 1 and g.params["repairs"]["dropped_pieces"] == 1
    g = import_garment(path, body, piece=2)
    assert g.num_verts == sizes[1 - largest]
    assert g.params["attachment"] == ("waistband" if largest == 0 else "straps")
    with pytest.raises(InputError, match=r"two.obj: no piece 3: the file has 2 piece\(s\)"):
        import_garment(path, body, piece=3)


def test_a_piece_hanging_free_is_refused_naming_piece(tmp_path, body, two_piece):
    verts, faces, (top_v, _), _ = two_piece
    low = verts.copy()
    low[len(top_v):] -= [0.0, 0.0, 0.45]  # the skirt dropped to the shins
    path = write_obj(tmp_path / "dropped.obj", low, faces)
    with pytest.raises(InputError, match=r"dropped.obj: 2 separate pieces, not all attached: a piece with \d+% of "
                                         r"the area has its top at 0\.[0-9]+ m.*--piece largest\|N"):
        import_garment(path, body, fit=None)  # refused on the first body shape that places it


def test_cli_piece_option(tmp_path, body, two_piece, capsys):
    from loosefit.cli import main

    verts, faces, (top_v, _), (skirt_v, _) = two_piece
    path = write_obj(tmp_path / "two.obj", verts, faces)
    with pytest.raises(SystemExit) as exit_:  # a usage error: pieces are numbered from 1
        main(["garment", "import", str(path), "--piece", "0", "--out", str(tmp_path / "g.obj")])
    assert exit_.value.code == 2 and "--piece" in capsys.readouterr().err
    assert main(["garment", "import", str(path), "--piece", "2", "--out", str(tmp_path / "g.obj")]) == 0
    assert "wrote" in capsys.readouterr().out
    from loosefit.garment import Garment

    assert Garment.load(tmp_path / "g.obj").num_verts in (len(top_v), len(skirt_v))
