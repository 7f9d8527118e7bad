"""Network layers shared by the garment models (generic: no garment, rig or method knowledge)."""
