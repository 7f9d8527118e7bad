"""Turn the files ``loosefit render`` accepts into panels of mesh tracks.

Inputs:

- a mesh-sequence ``.npz``: ``verts (T, V, 3)``, ``faces (F, 3)``, optionally the body as
  ``body_verts (T, Vb, 3)`` and ``body_faces (Fb, 3)`` (other arrays are ignored);
- a loosefit motion ``.npz`` (``rotations``, ``translation``, ``fps``): the body posed along it;
- a dataset store (``DATA.zarr``) and a sequence name: the simulated garment on the body posed by the
  sequence's motion with the sequence's body shape;
- a garment mesh ``.obj`` / ``.ply`` in the body's rest pose (as ``loosefit garment make|import`` write
  it): the garment on the body at rest (the body's shape from the garment's sidecar when it has one), or,
  with a motion, the body posed along it and the garment skinned to the body (the body-LBS baseline,
  :func:`loosefit.sim.attach.body_lbs`: each garment vertex follows its nearest rest body vertex's joints).

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


#: A garment in metres on the rest body is smaller than this (largest side, m); larger is another unit.
MAX_GARMENT_SIZE = 2.5


def garment_panel(path, motion=None, body=None, joint_map=None, keep_first_frame: bool = False) -> list[MeshTrack]:
    """The panel of a garment mesh (``.obj`` / ``.ply``, metres, Z up, in the body's rest pose): ``[body,
    garment]``, one frame at rest, or ``T`` frames posed along ``motion`` (a motion file or a
    :class:`~loosefit.motion.motion.Motion`; the garment by body-LBS, :func:`loosefit.sim.attach.body_lbs`).

    The body is ``body``, else Anny in the shape of the garment's sidecar (``<stem>.json``, written by
    ``loosefit garment make|import``), else Anny's average shape.

    Raises:
        InputError: an unreadable mesh, a garment that is not on the body (in another unit or place: a
            mesh from another tool needs ``loosefit garment import`` first), a motion not on the body's rig.
    """
    from loosefit.garment.mesh_file import read_mesh_file
    from loosefit.sim.attach import body_lbs

    path = Path(path)
    verts, faces, _ = read_mesh_file(path)
    if len(verts) == 0 or len(faces) == 0:
        raise InputError("the mesh has no vertices or no faces", path)
    if not np.isfinite(verts).all():
        raise InputError("vertices have NaN or infinite coordinates", path)
    body = body if body is not None else _garment_body(path)
    rest = body.rest_verts()
    size = float(np.ptp(verts, axis=0).max())
    apart = np.maximum(rest.min(0) - verts.max(0), verts.min(0) - rest.max(0)).max()
    if size > MAX_GARMENT_SIZE or apart > 0:
        where = (f"its largest side is {size:.3g} (metres expected, at most {MAX_GARMENT_SIZE} m)" if size > MAX_GARMENT_SIZE
                 else f"it lies {apart:.3g} m away from the body")
        raise InputError(f"the garment is not on the body's rest pose: {where}; import a mesh from another tool "
                         "first (`loosefit garment import FILE --out G.obj` finds its unit, up axis and place)", path)
    if motion is None:
        body_verts, garment_verts, body_label = rest[None], verts[None], "body"
    else:
        source = path
        if not hasattr(motion, "rotations"):
            from loosefit.motion.io import load_motion

            source = Path(motion)
            motion = load_motion(source, body, joint_map=joint_map, keep_first_frame=keep_first_frame)
        try:
            body_verts = body.pose(motion).verts
            garment_verts = body_lbs(verts, body, motion)
        except InputError as e:  # a motion on another rig
            raise InputError(e.problem, source) from None
        body_label = motion.name or "body"
    garment = _mesh_track(np.asarray(garment_verts, np.float32), faces, "the garment mesh", path, path.stem,
                          GARMENT_COLOR)
    return [MeshTrack(body_verts, body.faces, BODY_COLOR, label=body_label), garment]


def _garment_body(path: Path):
    """Anny in the shape recorded in the garment's sidecar, else in its average shape."""
    import json

    from loosefit.body import AnnyBody, AnnyShape
    from loosefit.garment.garment import Garment

    side = Garment.sidecar_path(path)
    shape = None
    if side.is_file():
        try:
            shape = json.loads(side.read_text()).get("body_shape")
            shape = AnnyShape(**shape) if shape else None
        except (ValueError, TypeError, AttributeError) as err:
            raise InputError(f"unreadable garment sidecar: {err}", side) from None
    return AnnyBody(shape) if shape is not None else AnnyBody()


def load_panels(path, sequence: str | None = None, body=None, motion=None, joint_map=None,
                keep_first_frame: bool = False) -> list[list[MeshTrack]]:
    """The panels (here one) to render for one ``loosefit render`` input.

    Args:
        path: a dataset store directory (then ``sequence`` is required), a mesh-sequence ``.npz``, a
            loosefit motion ``.npz`` or a garment mesh ``.obj`` / ``.ply``.
        sequence: sequence name inside a dataset store.
        body: the body posed for motions and dataset sequences (default: Anny, average shape) and under a
            garment mesh (default: Anny in the garment's own shape, :func:`garment_panel`).
        motion: a motion file or :class:`~loosefit.motion.motion.Motion` a garment mesh is posed along
            (:func:`garment_panel`); an error for other inputs.
        joint_map: the joint map of a BVH ``motion``.
        keep_first_frame: keep a far first frame of a ``motion`` file (:func:`loosefit.motion.io.load_motion`).

    Raises:
        InputError: naming the file and what is wrong.
    """
    path = Path(path)
    if not path.exists():
        raise InputError("no such file or directory", path)
    if path.is_file() and path.suffix.lower() in (".obj", ".ply"):
        if sequence is not None:
            raise InputError("a sequence name only applies to a dataset store (a .zarr directory)", path)
        return [garment_panel(path, motion, body, joint_map, keep_first_frame)]
    if motion is not None:
        raise InputError("a motion poses a garment mesh (.obj / .ply); this input has its own frames", path)
    if path.is_dir():
        if sequence is None:
            raise InputError("a dataset store needs a sequence name (--sequence); see `loosefit info`", path)
        return [dataset_panel(path, sequence, body)]
    if sequence is not None:
        raise InputError("a sequence name only applies to a dataset store (a .zarr directory)", path)
    if path.suffix.lower() != ".npz":
        raise InputError(
            "unsupported input: expected a mesh-sequence or motion .npz, a garment .obj / .ply, or a dataset store "
            "directory (import BVH / AMASS files first with `loosefit motion import`)",
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
