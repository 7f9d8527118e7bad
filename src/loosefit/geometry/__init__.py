"""Geometry: rotations, linear blend skinning, Laplacians, smoothing, normals, distances, sampling."""
