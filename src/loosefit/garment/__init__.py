"""Garments: the Garment type, parametric templates fitted to a body, OBJ / PLY import."""

from loosefit.garment.garment import Garment
from loosefit.garment.importer import import_garment
from loosefit.garment.templates import KINDS, PARAMS, draw_params, make_garment

__all__ = ["Garment", "KINDS", "PARAMS", "draw_params", "make_garment", "import_garment"]
