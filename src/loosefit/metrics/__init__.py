"""Evaluation metrics, one module per family:

- :mod:`~loosefit.metrics.errors`: RMSE, mean vertex error, Hausdorff distance (mm).
- :mod:`~loosefit.metrics.sted`: STED, spatial and temporal parts (Vasa and Skala 2011).
- :mod:`~loosefit.metrics.surface`: E_dist (cm), E_norm (degrees), Laplacian consistency (SwinGar); the bounded
  collapsed-triangle share (%) and roughness (degrees).
- :mod:`~loosefit.metrics.collision`: garment-body collision ratio (%), penetration on the surface between the
  vertices (%) and the deepest point (m).
- :mod:`~loosefit.metrics.report`: evaluate sequences, print a table, write CSV and JSON.
"""
