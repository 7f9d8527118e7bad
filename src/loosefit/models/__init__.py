"""Garment deformation models: one module per method plus shared features, data and layers."""
