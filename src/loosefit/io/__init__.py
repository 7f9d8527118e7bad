"""Mesh and animation files: OBJ, mesh-sequence .npz (and, later, glTF, USD, Alembic, PC2)."""
