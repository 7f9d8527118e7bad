"""Mesh and animation files: OBJ and OBJ sequences, mesh-sequence .npz, USD, glTF (.glb), Alembic, PC2."""
