"""Point Cache 2 (``.pc2``) files: the vertex animation format Blender's Mesh Cache modifier reads.

Layout (little endian): a 32-byte header -- ``b"POINTCACHE2\\0"``, int32 version (1), int32 point
count, float32 start frame, float32 sample rate (frames per sample), int32 sample count -- then
``samples x points x 3`` float32 positions.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.paths import atomic_path

MAGIC = b"POINTCACHE2\0"
_HEADER = np.dtype(
    [("magic", "S12"), ("version", "<i4"), ("points", "<i4"), ("start", "<f4"), ("rate", "<f4"), ("samples", "<i4")]
)


def write_pc2(path: str | Path, frames: np.ndarray, start_frame: float = 0.0, sample_rate: float = 1.0) -> None:
    """Write ``frames (T, V, 3)`` (metres) to a ``.pc2`` file, atomically."""
    frames = np.asarray(frames, dtype="<f4")
    if frames.ndim != 3 or frames.shape[2] != 3 or frames.shape[0] == 0:
        raise InputError(f"pc2 frames must have shape (T, V, 3) with T > 0, got {frames.shape}", path)
    header = np.array([(MAGIC, 1, frames.shape[1], start_frame, sample_rate, frames.shape[0])], dtype=_HEADER)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(header.tobytes())
        f.write(np.ascontiguousarray(frames).tobytes())


def read_pc2(path: str | Path) -> tuple[np.ndarray, float, float]:
    """Read a ``.pc2`` file.

    Returns:
        ``(frames (T, V, 3) float32, start_frame, sample_rate)``.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise InputError(f"cannot read pc2 file: {e}", path) from None
    if len(raw) < _HEADER.itemsize:
        raise InputError(f"pc2 file too short for its {_HEADER.itemsize}-byte header ({len(raw)} bytes)", path)
    if raw[: len(MAGIC)] != MAGIC:
        raise InputError("not a pc2 file (bad magic)", path)
    head = np.frombuffer(raw, dtype=_HEADER, count=1)[0]
    points, samples = int(head["points"]), int(head["samples"])
    expected = _HEADER.itemsize + points * samples * 12
    if points < 0 or samples < 0 or len(raw) != expected:
        raise InputError(
            f"pc2 header says {samples} samples x {points} points ({expected} bytes), file has {len(raw)} bytes", path
        )
    frames = np.frombuffer(raw, dtype="<f4", offset=_HEADER.itemsize).reshape(samples, points, 3).astype(np.float32)
    return frames, float(head["start"]), float(head["rate"])
