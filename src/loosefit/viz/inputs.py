"""Turn the files ``loosefit render`` accepts into panels of mesh tracks.

Inputs:

- a mesh-sequence ``.npz``: ``verts (T, V, 3)``, ``faces (F, 3)``, optionally the body as
  ``body_verts (T, Vb, 3)`` and ``body_faces (Fb, 3)`` (other arrays are ignored);
- a loosefit motion ``.npz`` (``rotations``, ``translation``, ``fps``): the body posed along it;
- a dataset store (``DATA.zarr``) and a sequence name: the simulated garment on the body posed by the
  sequence's motion with the sequence's body shape.

Every loader returns one panel: a list of :class:`~loosefit.viz.scene.MeshTrack`, body first.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.io.npz import load_npz, npz_names
from loosefit.viz.scene import BODY_COLOR, GARMENT_COLOR, MeshTrack

MOTION_ARRAYS = {"rotations", "translation", "fps"}


def _default_body():
    from loosefit.body import AnnyBody

    return AnnyBody()


def _mesh_track(verts, faces, what: str, path: Path, label: str, color) -> MeshTrack:
    """A MeshTrack whose validation errors name ``path`` and ``what`` (the arrays concerned)."""
    try:
        track = MeshTrack(verts, faces, color)
    except InputError as e:
        raise InputError(f"{what}: {e.problem}", path) from None
    track.label = label
    return track


def mesh_sequence_panel(path) -> list[MeshTrack]:
    """The panel of a mesh-sequence ``.npz``: ``[body, garment]`` (or ``[garment]`` without a body).

    Raises:
        InputError: unreadable file, missing ``verts`` / ``faces``, ``body_verts`` without
            ``body_faces``, a frame count that differs between ``verts`` and ``body_verts``, faces out
            of range, wrong shapes or non-finite values.
    """
    path = Path(path)
    arrays = _read_npz(path)
    missing = sorted({"verts", "faces"} - set(arrays))
    if missing:
        raise InputError(f"not a mesh sequence, missing arrays {missing} (has {sorted(arrays)})", path)
    verts = arrays["verts"]
    if verts.ndim != 3 or verts.shape[-1] != 3:
        raise InputError(f"verts must have shape (T, V, 3), got {verts.shape}", path)
    garment = _mesh_track(verts, arrays["faces"], "verts/faces", path, path.stem, GARMENT_COLOR)
    if "body_verts" not in arrays:
        return [garment]
    if "body_faces" not in arrays:
        raise InputError("has body_verts but no body_faces", path)
    body_verts = arrays["body_verts"]
    if body_verts.ndim != 3 or body_verts.shape[0] != verts.shape[0]:
        raise InputError(
            f"body_verts must have shape (T, Vb, 3) with the {verts.shape[0]} frames of verts, got {body_verts.shape}", path
        )
    body = _mesh_track(body_verts, arrays["body_faces"], "body_verts/body_faces", path, "body", BODY_COLOR)
    return [body, garment]


def motion_panel(path, body=None) -> list[MeshTrack]:
    """The panel of a loosefit motion ``.npz``: ``[body]`` posed along it (default body: Anny)."""
    from loosefit.motion.motion import Motion

    path = Path(path)
    motion = Motion.load(path)
    body = body if body is not None else _default_body()
    try:
        posed = body.pose(motion)
    except InputError as e:
        raise InputError(e.problem, path) from None
    return [MeshTrack(posed.verts, body.faces, BODY_COLOR, label=motion.name or path.stem)]


def dataset_panel(path, sequence: str, body=None) -> list[MeshTrack]:
    """The panel of a dataset sequence: ``[body, garment]``.

    The garment's faces come from the sequence's garment entry; the body (default Anny) is posed along
    the sequence's motion with the sequence's body shape. The store's errors (missing sequence,
    corrupt arrays) name the store.
    """
    from loosefit.data.store import DatasetStore

    store = DatasetStore.open(path)
    seq = store.sequence(sequence)
    verts = np.asarray(seq.verts[:], dtype=np.float32)
    faces = store.garment(seq.garment).faces
    motion = store.motion(seq.motion)
    body = body if body is not None else _default_body()
    posed = body.pose(motion, shape=store.body(seq.body))
    if posed.verts.shape[0] < verts.shape[0]:
        raise InputError(f"sequence {sequence!r} has {verts.shape[0]} frames, its motion only {posed.verts.shape[0]}", path)
    garment = _mesh_track(verts, faces, f"sequence {sequence!r}", Path(path), sequence, GARMENT_COLOR)
    # A failed simulation may stop early: show the body over the frames that exist.
    body_track = MeshTrack(posed.verts[: verts.shape[0]], body.faces, BODY_COLOR, label="body")
    return [body_track, garment]


def load_panels(path, sequence: str | None = None, body=None) -> list[list[MeshTrack]]:
    """The panels (here one) to render for one ``loosefit render`` input.

    Args:
        path: a dataset store directory (then ``sequence`` is required), a mesh-sequence ``.npz`` or a
            loosefit motion ``.npz``.
        sequence: sequence name inside a dataset store.
        body: the body posed for motions and dataset sequences (default: Anny, average shape).

    Raises:
        InputError: naming the file and what is wrong.
    """
    path = Path(path)
    if not path.exists():
        raise InputError("no such file or directory", path)
    if path.is_dir():
        if sequence is None:
            raise InputError("a dataset store needs a sequence name (--sequence); see `loosefit info`", path)
        return [dataset_panel(path, sequence, body)]
    if sequence is not None:
        raise InputError("a sequence name only applies to a dataset store (a .zarr directory)", path)
    if path.suffix.lower() != ".npz":
        raise InputError(
            "unsupported input: expected a mesh-sequence or motion .npz, or a dataset store directory "
            "(import BVH / AMASS files first with `loosefit motion import`)",
            path,
        )
    names = set(_read_npz(path, names_only=True))
    if "verts" in names:
        return [mesh_sequence_panel(path)]
    if MOTION_ARRAYS <= names:
        return [motion_panel(path, body)]
    raise InputError(
        f"neither a mesh sequence (verts, faces) nor a loosefit motion (rotations, translation, fps): "
        f"it has arrays {sorted(names)}",
        path,
    )


def _read_npz(path: Path, names_only: bool = False):
    """All arrays of an ``.npz`` as a dict (or only their names), with errors naming the file."""
    return npz_names(path, ".npz") if names_only else load_npz(path, ".npz")
