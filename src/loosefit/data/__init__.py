"""The on-disk dataset (Zarr): garments, bodies, motions, simulated sequences, splits, manifest.

The PyTorch adapter lives in :mod:`loosefit.data.windows` (imported separately: it needs torch).
"""

from loosefit.data.manifest import format_info, format_repair
from loosefit.data.store import FORMAT_VERSION, SPLITS, STATUSES, DatasetStore, Sequence

__all__ = ["DatasetStore", "Sequence", "format_info", "format_repair", "FORMAT_VERSION", "SPLITS", "STATUSES"]
