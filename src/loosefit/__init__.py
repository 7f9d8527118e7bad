"""loosefit: learning-based animation of loose-fitting garments.

Pipeline: simulate -> prepare -> train -> animate -> evaluate / render / export.
Units are metres, Z is up, 30 frames per second, float32 arrays, right-handed.
"""

__version__ = "0.1.0"
