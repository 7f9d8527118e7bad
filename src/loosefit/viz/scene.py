"""What to draw: mesh tracks (one mesh sequence each), panels of tracks, and the camera.

A *track* is one mesh sequence with its look (solid colour or per-vertex scalars through a
colormap). A *panel* is a list of tracks drawn together (e.g. body + garment); several panels are
drawn side by side with the same camera. The default camera looks at the body's front-left
(front is -Y, body left is +X, Z up) from slightly above and frames every frame of every panel.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from loosefit.errors import InputError

#: Default colours (RGB in [0, 1]).
BODY_COLOR = (0.80, 0.72, 0.66)
GARMENT_COLOR = (0.30, 0.48, 0.78)

#: Direction from the framed centre to the default camera: the body's front-left (-Y, +X), a bit above.
DEFAULT_VIEW_DIRECTION = (0.45, -1.0, 0.30)
#: Vertical field of view of the default camera, degrees.
DEFAULT_VIEW_ANGLE = 30.0


@dataclass
class MeshTrack:
    """One mesh sequence to draw.

    Attributes:
        verts: ``(T, V, 3)`` float32 vertex positions, metres (``(V, 3)`` is a static mesh, ``T = 1``).
        faces: ``(F, 3)`` int64 triangles indexing ``verts``.
        color: solid RGB in ``[0, 1]``, used when ``scalars`` is None.
        scalars: per-vertex values ``(T, V)`` or ``(V,)`` (the same for every frame), mapped through
            ``cmap`` over the fixed range ``clim``; e.g. the error in mm.
        cmap: a matplotlib colormap name.
        clim: ``(low, high)`` scalar range mapped to the colormap's ends; values outside are clipped.
            None: the range of ``scalars`` over all frames (one range for the whole sequence).
        opacity: in ``(0, 1]``.
        label: the track's name (default panel title when a panel has no explicit title).
        scalar_name: title of the colour bar drawn for ``scalars`` (e.g. ``"error (mm)"``).
    """

    verts: np.ndarray
    faces: np.ndarray
    color: tuple[float, float, float] = GARMENT_COLOR
    scalars: np.ndarray | None = None
    cmap: str = "viridis"
    clim: tuple[float, float] | None = None
    opacity: float = 1.0
    label: str = ""
    scalar_name: str = ""

    @property
    def _name(self) -> str:
        return f"track {self.label!r}: " if self.label else ""

    def __post_init__(self):
        verts = np.asarray(self.verts, dtype=np.float32)
        if verts.ndim == 2:
            verts = verts[None]
        if verts.ndim != 3 or verts.shape[2] != 3 or verts.shape[0] == 0 or verts.shape[1] == 0:
            raise InputError(f"{self._name}verts must have shape (T, V, 3) or (V, 3), got {np.shape(self.verts)}")
        if not np.isfinite(verts).all():
            raise InputError(f"{self._name}verts contain NaN or infinite values")
        self.verts = verts
        self.faces = _check_faces(self.faces, verts.shape[1], self._name)
        color = np.asarray(self.color, dtype=np.float64)
        if color.shape != (3,) or not ((color >= 0) & (color <= 1)).all():
            raise InputError(f"{self._name}color must be 3 numbers in [0, 1], got {self.color!r}")
        self.color = tuple(float(c) for c in color)
        if not 0.0 < self.opacity <= 1.0:
            raise InputError(f"{self._name}opacity must be in (0, 1], got {self.opacity}")
        if self.scalars is not None:
            self._check_scalars()

    def _check_scalars(self) -> None:
        import matplotlib

        s = np.asarray(self.scalars, dtype=np.float32)
        if s.ndim == 1:
            s = s[None]
        n_frames, n_verts = self.verts.shape[:2]
        if s.ndim != 2 or s.shape[1] != n_verts or s.shape[0] not in (1, n_frames):
            raise InputError(
                f"{self._name}scalars must have shape ({n_frames}, {n_verts}) or ({n_verts},), "
                f"got {np.shape(self.scalars)}"
            )
        if not np.isfinite(s).all():
            raise InputError(f"{self._name}scalars contain NaN or infinite values")
        self.scalars = s
        if self.cmap not in matplotlib.colormaps:
            raise InputError(f"{self._name}unknown colormap {self.cmap!r}")
        if self.clim is None:
            low, high = float(s.min()), float(s.max())
            # A constant field still needs a non-empty range; centre it so it shows the middle colour.
            self.clim = (low, high) if high > low else (low - 0.5, high + 0.5)
        elif len(self.clim) != 2 or not float(self.clim[0]) < float(self.clim[1]):
            raise InputError(f"{self._name}clim must be (low, high) with low < high, got {self.clim!r}")
        self.clim = (float(self.clim[0]), float(self.clim[1]))

    @property
    def num_frames(self) -> int:
        return self.verts.shape[0]

    def frame_verts(self, t: int) -> np.ndarray:
        """``(V, 3)`` vertices at frame ``t``; past its last frame a track holds it (a static track
        gives its only frame)."""
        return self.verts[min(t, self.verts.shape[0] - 1)]

    def frame_scalars(self, t: int) -> np.ndarray | None:
        """``(V,)`` scalars at frame ``t`` (held past the last frame), or None for a solid colour track."""
        if self.scalars is None:
            return None
        return self.scalars[min(t, self.scalars.shape[0] - 1)]


def _check_faces(faces, num_verts: int, what: str) -> np.ndarray:
    """``faces`` as int64 ``(F, 3)`` indexing ``num_verts`` vertices; ``what`` prefixes error messages."""
    faces = np.asarray(faces)
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.shape[0] == 0:
        raise InputError(f"{what}faces must have shape (F, 3), got {faces.shape}")
    if not np.issubdtype(faces.dtype, np.integer):
        raise InputError(f"{what}faces must be integers, got {faces.dtype}")
    if faces.min() < 0 or faces.max() >= num_verts:
        raise InputError(f"{what}faces index vertices {faces.min()}..{faces.max()}, the mesh has {num_verts}")
    return faces.astype(np.int64)


Panel = Sequence[MeshTrack]


def check_panels(panels: Sequence[Panel]) -> int:
    """Validate a list of panels; return the frame count ``T`` of the longest track.

    Shorter tracks (sequences of different lengths side by side, a static mesh) hold their last frame
    until the end.
    """
    if not isinstance(panels, (list, tuple)) or not panels:
        raise InputError("panels must be a non-empty list of panels (each a list of MeshTrack)")
    count = 1
    for i, panel in enumerate(panels):
        if isinstance(panel, MeshTrack) or not isinstance(panel, (list, tuple)) or not panel:
            raise InputError(f"panel {i} must be a non-empty list of MeshTrack (wrap a single track as [track])")
        for track in panel:
            if not isinstance(track, MeshTrack):
                raise InputError(f"panel {i} holds a {type(track).__name__}, expected MeshTrack")
            count = max(count, track.num_frames)
    return count


@dataclass(frozen=True)
class Camera:
    """A perspective camera.

    Attributes:
        position: ``(3,)`` eye position, metres.
        focal_point: ``(3,)`` point looked at, metres.
        view_up: ``(3,)`` up direction (Z up by default).
        view_angle: vertical field of view, degrees.
    """

    position: tuple[float, float, float]
    focal_point: tuple[float, float, float]
    view_up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    view_angle: float = DEFAULT_VIEW_ANGLE

    def translated(self, offset) -> "Camera":
        """The same view moved by ``offset (3,)`` metres."""
        offset = np.asarray(offset, dtype=np.float64)
        return replace(
            self,
            position=tuple((np.asarray(self.position) + offset).tolist()),
            focal_point=tuple((np.asarray(self.focal_point) + offset).tolist()),
        )

    def basis(self) -> np.ndarray:
        """``(3, 3)`` rows: the camera's right, up and backward axes in world coordinates."""
        back = np.asarray(self.position, np.float64) - np.asarray(self.focal_point, np.float64)
        back /= np.linalg.norm(back)
        right = np.cross(np.asarray(self.view_up, np.float64), back)
        norm = np.linalg.norm(right)
        if norm < 1e-9:
            raise InputError("camera view_up is parallel to the viewing direction")
        right /= norm
        return np.stack([right, np.cross(back, right), back])

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """``(N, 3)`` world points in camera coordinates (x right, y up, looking down -z)."""
        return (np.asarray(points, np.float64) - np.asarray(self.position, np.float64)) @ self.basis().T

    def project(self, points: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """Project world points into a ``size = (W, H)`` image.

        Returns:
            ``(N, 2)`` pixel coordinates (column, row; row 0 at the top, pixel centres at ``+0.5``) and
            ``(N,)`` depth in metres along the viewing direction (positive in front of the camera).
        """
        width, height = size
        cam = self.to_camera(points)
        depth = -cam[:, 2]
        tan_half = np.tan(np.radians(self.view_angle) / 2.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_ndc = cam[:, 0] / (depth * tan_half * width / height)
            y_ndc = cam[:, 1] / (depth * tan_half)
        pixels = np.stack([(x_ndc + 1.0) * 0.5 * width, (1.0 - y_ndc) * 0.5 * height], axis=1)
        return pixels, depth


def follow_offsets(panels: Sequence[Panel], num_frames: int) -> np.ndarray:
    """``(T, 3)`` horizontal travel of the first track of the first panel (its vertex centroid)
    relative to frame 0; Z stays 0 so that the camera does not bob with jumps."""
    track = panels[0][0]
    centroids = np.stack([track.frame_verts(t).mean(axis=0) for t in range(num_frames)]).astype(np.float64)
    offsets = centroids - centroids[0]
    offsets[:, 2] = 0.0
    return offsets


def travels(panels: Sequence[Panel], num_frames: int) -> bool:
    """Whether the first track moves horizontally farther than its own largest horizontal size
    (a walk across the room), in which case the default camera follows it."""
    offsets = follow_offsets(panels, num_frames)
    size = np.ptp(panels[0][0].frame_verts(0)[:, :2], axis=0).max()
    return bool(np.linalg.norm(offsets[:, :2], axis=1).max() > size)


def fit_camera(
    panels: Sequence[Panel],
    size: tuple[int, int],
    frames: Sequence[int],
    offsets: np.ndarray | None = None,
    direction=DEFAULT_VIEW_DIRECTION,
    view_angle: float = DEFAULT_VIEW_ANGLE,
    margin: float = 1.08,
) -> Camera:
    """A camera looking along ``-direction`` at the centre of the bounding box of every vertex of
    every panel at ``frames``, just far enough for all of them to be in view.

    Args:
        panels: the panels to frame.
        size: image size of one panel ``(W, H)`` pixels (its aspect ratio matters).
        frames: frame indices to frame.
        offsets: ``(T, 3)`` per-frame camera translation when following (see :func:`follow_offsets`);
            vertices are framed relative to it.
        direction: from the framed centre towards the camera.
        view_angle: vertical field of view, degrees.
        margin: > 1 leaves a border: the outermost vertex lands at 1 / margin of the half-width or half-height.
    """
    def shifted_frames():
        for t in frames:
            shift = 0.0 if offsets is None else offsets[t]
            yield [track.frame_verts(t) - shift for panel in panels for track in panel]

    low = np.full(3, np.inf)
    high = np.full(3, -np.inf)
    for verts in shifted_frames():
        for v in verts:
            low = np.minimum(low, v.min(axis=0))
            high = np.maximum(high, v.max(axis=0))
    centre = (low + high) / 2.0
    direction = np.asarray(direction, np.float64)
    direction /= np.linalg.norm(direction)
    basis = Camera(tuple(centre + direction), tuple(centre), view_angle=view_angle).basis()
    tan_v = np.tan(np.radians(view_angle) / 2.0)
    tan_h = tan_v * size[0] / size[1]
    # With the eye at distance d along the camera's back axis, a vertex at camera-basis offset
    # (x, y, z) from the centre is in view when |x| <= (d - z) tan_h and |y| <= (d - z) tan_v.
    distance = 0.0
    for verts in shifted_frames():
        for v in verts:
            rel = (v - centre) @ basis.T
            need = rel[:, 2] + margin * np.maximum(np.abs(rel[:, 0]) / tan_h, np.abs(rel[:, 1]) / tan_v)
            distance = max(distance, float(need.max()), float(rel[:, 2].max()) + 1e-3)
    return Camera(tuple((centre + distance * direction).tolist()), tuple(centre.tolist()), view_angle=view_angle)


@dataclass
class FrameCameras:
    """The camera of every frame: a base camera, moved by per-frame offsets when following."""

    base: Camera
    offsets: np.ndarray | None = None

    def __call__(self, t: int) -> Camera:
        return self.base if self.offsets is None else self.base.translated(self.offsets[t])


def frame_cameras(
    panels: Sequence[Panel],
    size: tuple[int, int],
    frames: Sequence[int],
    num_frames: int,
    camera: Camera | None = None,
    follow: bool | None = None,
) -> FrameCameras:
    """Cameras for rendering ``frames``.

    Args:
        camera: a fixed camera; None for the default (front-left, slightly above, framing all frames).
        follow: move the camera with the first track's horizontal travel; None: follow when it
            travels (see :func:`travels`). With an explicit ``camera``, None means do not follow.
    """
    if follow is None:
        follow = camera is None and num_frames > 1 and travels(panels, num_frames)
    offsets = follow_offsets(panels, num_frames) if follow else None
    if camera is None:
        camera = fit_camera(panels, size, frames, offsets)
    elif offsets is not None:
        # Follow relative to the first rendered frame so that the given camera is exact there.
        offsets = offsets - offsets[frames[0]]
    return FrameCameras(camera, offsets)
