"""What ``loosefit view`` shows: panels of body and garment sequences, the per-vertex error of each
prediction against the simulation, and per-frame metrics.

Inputs (one panel each, side by side, in the order given):

- ``SEQ.npz``: a mesh sequence as written by ``loosefit animate`` / :class:`~loosefit.io.mesh_sequence.MeshSequence`
  (``verts (T, V, 3)``, ``faces (F, 3)``, optional ``body_verts (T, Vb, 3)`` / ``body_faces``, ``fps``);
- ``DATA.zarr:NAME``: the simulated sequence ``NAME`` of a dataset store on its posed body;
- ``RUN:MOTION``: a trained run folder (``loosefit train``) animated on a motion (``.npz`` / ``.bvh``),
  with the body posed along the motion.

By default the first input is the reference (the simulation). Every later input is a prediction of the same garment:
it must have the reference's garment vertex count. Each input plays for its own length (a run animated on a
motion longer or shorter than the simulated sequence): the page plays the longest, and a shorter input holds
its last frame. For a prediction the viewer shows the per-vertex error ``e_ti = 1000 * ||pred_ti - ref_ti||``
(mm) as a heat map and its per-frame RMSE ``sqrt(mean_i e_ti^2)`` (mm, :mod:`loosefit.metrics.errors`) over the
frames both have (``t < min(T_ref, T_pred)``; past them the garment takes its plain colour); for every panel
with a body, the per-frame collision ratio (% of garment vertices inside the body by more than 1 mm,
:mod:`loosefit.metrics.collision`) over its own frames.

Without a reference (``reference=False``, ``loosefit view --no-reference``), every input is an animation shown
by itself (an animation on a user's own motion has no simulation to compare with): any garments, each with its
body when its file has one, each playing its own length; no errors, no RMSE, the collision ratio as above.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.io.npz import load_npz
from loosefit.viz.scene import BODY_COLOR, GARMENT_COLOR

#: The heat map's colour map (matplotlib name) and its number of entries.
COLORMAP = "viridis"
COLORMAP_SIZE = 256
#: The heat map spans 0 mm to this percentile of every prediction's errors (a few outlying vertices would
#: otherwise leave the rest of the garment in the bottom colour); larger errors take the top colour.
ERROR_RANGE_PERCENTILE = 99.0
#: Frames per panel at which the collision ratio is computed by default (evenly spaced).
DEFAULT_COLLISION_FRAMES = 100


@dataclass
class ViewerTrack:
    """One mesh sequence of a panel: ``verts (T, V, 3)`` float32 metres, ``faces (F, 3)`` int64;
    ``errors (Te, V)`` float32 mm against the reference (predicted garments only) at the first ``Te <= T``
    frames, those the reference has too; ``role`` is ``"body"`` or ``"garment"``."""

    role: str
    verts: np.ndarray
    faces: np.ndarray
    color: tuple[float, float, float]
    errors: np.ndarray | None = None


@dataclass
class ViewerPanel:
    """One input: its title, the source it came from, its tracks (body first), its per-frame metrics
    (``{"rmse_mm": (Te,), "collision_pct": (T,)}``, each present only when defined; ``Te`` the frames both the
    prediction and the reference have) and warnings about it (its length differs from the reference's;
    a run's motion outside the run's training range: :mod:`loosefit.motion_range`)."""

    title: str
    source: str
    tracks: list[ViewerTrack]
    metrics: dict[str, np.ndarray] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    @property
    def garment(self) -> ViewerTrack | None:
        return next((t for t in self.tracks if t.role == "garment"), None)

    @property
    def body(self) -> ViewerTrack | None:
        return next((t for t in self.tracks if t.role == "body"), None)


@dataclass
class ViewerScene:
    """Everything the page plays: panels, ``fps``, ``num_frames``, the heat map's range ``error_range``
    (mm, low and high ends of the colour map; larger errors take the top colour), its colour table
    ``colormap (256, 3)`` uint8 RGB, and the largest error ``error_max`` (mm)."""

    panels: list[ViewerPanel]
    fps: float
    num_frames: int
    error_range: tuple[float, float]
    colormap: np.ndarray
    error_max: float = 0.0


def colormap_table(name: str = COLORMAP, size: int = COLORMAP_SIZE) -> np.ndarray:
    """``(size, 3)`` uint8 RGB entries of a matplotlib colour map; value ``x`` in ``[0, 1]`` maps to entry
    ``min(floor(x * size), size - 1)`` (matplotlib's own lookup rule)."""
    import matplotlib

    rgba = matplotlib.colormaps[name].resampled(size)(np.arange(size))
    return np.round(rgba[:, :3] * 255).astype(np.uint8)


def _panel_from_tracks(tracks, title: str, source: str) -> ViewerPanel:
    """A panel from ``loosefit.viz.inputs`` MeshTracks (body first when there is one)."""
    roles = ["body", "garment"][-len(tracks):]
    return ViewerPanel(title, source, [ViewerTrack(r, t.verts, t.faces, t.color) for r, t in zip(roles, tracks)])


def _npz_panel(path: Path) -> tuple[ViewerPanel, float]:
    from loosefit.viz.inputs import mesh_sequence_panel

    tracks = mesh_sequence_panel(path)  # errors name the file; the file is readable past this line
    fps = float(load_npz(path, "mesh sequence", names=["fps"]).get("fps", 30.0))
    return _panel_from_tracks(tracks, path.stem, str(path)), fps


def _dataset_panel(store: Path, name: str, body) -> tuple[ViewerPanel, float]:
    from loosefit.data.store import DatasetStore
    from loosefit.viz.inputs import dataset_panel

    tracks = dataset_panel(store, name, body)
    opened = DatasetStore.open(store, mode="r")
    fps = float(opened.motion(opened.sequence(name).motion).fps)
    return _panel_from_tracks(tracks, name, f"{store}:{name}"), fps


def _run_panel(run: Path, motion_path: Path, body, handling: str = "exact",
               joint_map=None, keep_first_frame: bool = False) -> tuple[ViewerPanel, float]:
    from loosefit.animate import Animator
    from loosefit.animate_any import is_static_run
    from loosefit.motion.io import load_motion

    if not motion_path.exists():
        raise InputError("no such motion file", motion_path)
    if is_static_run(run):
        raise InputError("this run animates any garment: run `loosefit animate RUN --garment G.obj --with-body` "
                         "and view the .npz it writes", run)
    if body is None:
        from loosefit.body import AnnyBody

        body = AnnyBody()
    motion = load_motion(motion_path, body, joint_map=joint_map, keep_first_frame=keep_first_frame)
    animator = Animator(run)
    verts = animator.animate_batch([motion])[0]
    from loosefit.models.collision import post_process

    verts = post_process(verts, animator.faces, body, motion, handling, animator.rest_garment)  # as `animate` does
    posed = body.pose(motion)
    tracks = [ViewerTrack("body", posed.verts[: len(verts)], body.faces, BODY_COLOR),
              ViewerTrack("garment", verts, animator.faces, GARMENT_COLOR)]
    name = run.name if run.name == animator.method else f"{run.name} ({animator.method})"
    return ViewerPanel(f"{name} on {motion_path.stem}", f"{run}:{motion_path}", tracks,
                       warnings=animator.range_warnings(motion, motion_path)), motion.fps


def load_input(spec: str, body=None, handling: str = "exact", joint_map=None,
               keep_first_frame: bool = False) -> tuple[ViewerPanel, float]:
    """One viewer input (see the module docstring) as ``(panel, fps)``; a run's animation gets collision
    handling ``handling`` (``"exact"``, ``"pushout"`` or ``"none"``, as ``loosefit animate --collision``), its
    BVH motion the joint map ``joint_map`` (as ``loosefit animate --joint-map``) and ``keep_first_frame``
    (:func:`~loosefit.motion.io.load_motion`).

    Raises:
        InputError: a missing file, an unreadable or malformed one, an unknown kind of input.
    """
    path = Path(spec)
    if path.is_file():
        if path.suffix.lower() != ".npz":
            raise InputError("unsupported input: expected a mesh-sequence .npz, DATA.zarr:SEQUENCE or RUN:MOTION", path)
        return _npz_panel(path)
    left, sep, right = spec.rpartition(":")
    if sep and left:
        lpath = Path(left)
        if lpath.is_dir():
            from loosefit.metrics.report import is_dataset_store

            if is_dataset_store(lpath):
                return _dataset_panel(lpath, right, body)
            return _run_panel(lpath, Path(right), body, handling, joint_map, keep_first_frame)
        if not lpath.exists():
            raise InputError("no such file or directory", lpath)
    if path.is_dir():
        raise InputError("a dataset store or run folder needs a sequence or motion: DATA.zarr:SEQUENCE or RUN:MOTION", path)
    raise InputError("no such file or directory", path)


def _rmse_per_frame(errors_mm: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(errors_mm.astype(np.float64) ** 2, axis=1))


def collision_frame_indices(num_frames: int, max_frames: int) -> np.ndarray:
    """The frames whose collision ratio is computed: all of them when ``max_frames`` is 0 or at least
    ``num_frames``, else ``max_frames`` evenly spaced ones, first and last included."""
    if max_frames <= 0 or max_frames >= num_frames:
        return np.arange(num_frames)
    return np.unique(np.round(np.linspace(0, num_frames - 1, max(2, max_frames))).astype(int))


def _collisions(panels: list[ViewerPanel], max_frames: int) -> None:
    """Set ``metrics["collision_pct"] (T,)`` of every panel with a body and a garment (NaN at frames not
    computed). Panels on the same body share its signed-distance tree, built once per frame."""
    from tqdm import tqdm

    from loosefit.geometry.signed_distance import BodySDF
    from loosefit.metrics.collision import collision_ratio_per_frame

    groups: list[list[ViewerPanel]] = []
    for panel in panels:
        if panel.body is None or panel.garment is None:
            continue
        for group in groups:
            b = group[0].body
            if (b.verts.shape == panel.body.verts.shape and np.array_equal(b.faces, panel.body.faces)
                    and np.array_equal(b.verts, panel.body.verts)):
                group.append(panel)
                break
        else:
            groups.append([panel])
    for group in groups:
        body = group[0].body
        num_frames = min(body.verts.shape[0], *(p.garment.verts.shape[0] for p in group))
        frames = collision_frame_indices(num_frames, max_frames)
        for panel in group:
            panel.metrics["collision_pct"] = np.full(panel.garment.verts.shape[0], np.nan)
        for t in tqdm(frames, desc="collision ratio", unit="frame", leave=False):
            sdf = BodySDF(body.verts[t], body.faces)
            for panel in group:
                panel.metrics["collision_pct"][t] = collision_ratio_per_frame(panel.garment.verts[t], sdf)[0]


def build_scene(inputs: list[str], body=None, collisions: bool = True,
                collision_frames: int = DEFAULT_COLLISION_FRAMES, handling: str = "exact",
                joint_map=None, keep_first_frame: bool = False, reference: bool = True) -> ViewerScene:
    """The scene of ``loosefit view INPUT...``: the first input is the reference (simulation), the others
    predictions compared with it; with ``reference=False`` every input is an animation by itself.

    Args:
        inputs: input specs (see the module docstring).
        body: the body posed for dataset sequences and runs (default: Anny, average shape).
        collisions: compute the per-frame collision ratio of panels that have a body.
        handling: collision handling of the runs' animations (:func:`load_input`).
        joint_map: the joint map of the runs' BVH motions (:func:`load_input`).
        keep_first_frame: keep a far first frame of the runs' motion files (:func:`load_input`).
        reference: compare the later inputs with the first (the simulation); ``False``: show each by itself,
            whatever its garment (no errors, no RMSE), at the first input's frame rate.
        collision_frames: compute it at this many evenly spaced frames (0: every frame); the others are
            NaN (one signed-distance tree of a 13.7k-vertex body and a 12k-vertex query take ~0.5 s a frame
            on the 2-core machines).

    Raises:
        InputError: a bad input (naming it), or a prediction whose garment vertex count differs from the
            reference's. A prediction of another frame count plays for its own length; its error and RMSE
            cover the frames both have, and the panel warns of the difference.
    """
    if not inputs:
        raise InputError("give at least one input: SEQ.npz, DATA.zarr:SEQUENCE or RUN:MOTION")
    from loosefit.models.collision import check_post_process

    check_post_process(handling)  # before any input is loaded
    loaded = [load_input(spec, body, handling, joint_map, keep_first_frame) for spec in inputs]
    panels = [p for p, _ in loaded]
    fps = loaded[0][1]
    if not reference:
        for panel, rate in loaded[1:]:
            if rate != fps:
                panel.warnings.append(f"{panel.source}: {rate:g} fps, the page plays every input at the first's "
                                      f"{fps:g} fps")
        return _scene(panels, fps, collisions, collision_frames)
    ref = panels[0]
    ref_garment = ref.garment
    for panel in panels[1:]:
        garment = panel.garment
        if garment is None or ref_garment is None:
            continue
        if garment.verts.shape[1] != ref_garment.verts.shape[1]:
            raise InputError(
                f"the garment has {garment.verts.shape[1]} vertices but the simulation ({ref.source}, the first input) "
                f"has {ref_garment.verts.shape[1]}: a prediction must be of the same garment", panel.source)
        n, n_ref = garment.verts.shape[0], ref_garment.verts.shape[0]
        both = min(n, n_ref)
        if n != n_ref:
            panel.warnings.append(
                f"{panel.source}: {n} frames, the simulation ({ref.source}) {n_ref}: each plays its own length "
                f"(the shorter holds its last frame); error and RMSE over the first {both} frames")
        diff = garment.verts[:both].astype(np.float64) - ref_garment.verts[:both].astype(np.float64)
        garment.errors = (1000.0 * np.linalg.norm(diff, axis=-1)).astype(np.float32)
        panel.metrics["rmse_mm"] = _rmse_per_frame(garment.errors)
    return _scene(panels, fps, collisions, collision_frames)


def _scene(panels: list[ViewerPanel], fps: float, collisions: bool, collision_frames: int) -> ViewerScene:
    """The scene of loaded panels (errors set where there are any): collision ratios, length, heat map range."""
    if collisions:
        _collisions(panels, collision_frames)
    num_frames = max(t.verts.shape[0] for p in panels for t in p.tracks)
    errors = [t.errors.ravel() for p in panels for t in p.tracks if t.errors is not None]
    high = float(np.percentile(np.concatenate(errors), ERROR_RANGE_PERCENTILE)) if errors else 0.0
    if not high > 0:
        high = max([float(e.max()) for e in errors] + [0.0]) or 1.0
    return ViewerScene(panels, fps, num_frames, (0.0, high), colormap_table(),
                       max((float(e.max()) for e in errors), default=0.0))
