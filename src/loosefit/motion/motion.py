"""The Motion type: per-frame local joint rotations of a named rig, root translation and frame rate."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.io.npz import load_npz
from loosefit.paths import atomic_path

DEFAULT_FPS = 30.0


@dataclass
class Motion:
    """A body motion on a named rig.

    Attributes:
        rotations: ``(T, J, 3)`` float32 axis-angle local joint rotations, radians, in the rig
            convention of :mod:`loosefit.geometry.lbs` (world-aligned joint frames at rest; the
            root's rotation is the global orientation).
        translation: ``(T, 3)`` float32 world position of the root joint, metres, Z up.
        fps: frames per second.
        rig: name of the rig the joints belong to (``"cmu_mb"`` for the default Anny body).
        joint_names: ``J`` joint names, in the order of ``rotations``.
        name: free text (source file, generator spec).
    """

    rotations: np.ndarray
    translation: np.ndarray
    fps: float = DEFAULT_FPS
    rig: str = "cmu_mb"
    joint_names: list[str] = field(default_factory=list)
    name: str = ""

    def __post_init__(self):
        self.rotations = np.asarray(self.rotations, dtype=np.float32)
        self.translation = np.asarray(self.translation, dtype=np.float32)
        self.joint_names = list(self.joint_names)
        if self.rotations.ndim != 3 or self.rotations.shape[2] != 3:
            raise InputError(f"motion rotations must have shape (T, J, 3), got {self.rotations.shape}")
        if self.translation.shape != (self.rotations.shape[0], 3):
            raise InputError(
                f"motion translation must have shape ({self.rotations.shape[0]}, 3), got {self.translation.shape}"
            )
        if self.joint_names and len(self.joint_names) != self.rotations.shape[1]:
            raise InputError(
                f"motion has {self.rotations.shape[1]} joints but {len(self.joint_names)} joint names"
            )
        if not (np.isfinite(self.rotations).all() and np.isfinite(self.translation).all()):
            raise InputError("motion contains NaN or infinite values")
        if not self.fps > 0:
            raise InputError(f"motion fps must be positive, got {self.fps}")

    @property
    def num_frames(self) -> int:
        return self.rotations.shape[0]

    @property
    def num_joints(self) -> int:
        return self.rotations.shape[1]

    @property
    def duration(self) -> float:
        """Seconds covered by the frames."""
        return self.num_frames / self.fps

    def slice(self, start: int, stop: int | None = None) -> "Motion":
        """Frames ``[start, stop)`` as a new Motion."""
        return Motion(self.rotations[start:stop], self.translation[start:stop], self.fps, self.rig, self.joint_names, self.name)

    def cut(self, start: float | None = None, seconds: float | None = None) -> "Motion":
        """The part from ``start`` seconds (default 0) lasting ``seconds`` (default: to the end): frames
        ``round(start * fps)`` to ``round((start + seconds) * fps)``, at least one.

        Raises:
            InputError: a negative ``start`` or non-positive ``seconds``, or a part that reaches past the
                end of the motion (the message gives its duration).
        """
        if start is None and seconds is None:
            return self
        start = 0.0 if start is None else float(start)
        if not (np.isfinite(start) and start >= 0):
            raise InputError(f"start must be a non-negative number of seconds, got {start}")
        first = int(round(start * self.fps))
        if first >= self.num_frames:
            raise InputError(f"start {start:g} s is past the end of the motion ({self.duration:g} s, "
                             f"{self.num_frames} frames at {self.fps:g} fps)")
        if seconds is None:
            return self.slice(first)
        seconds = float(seconds)
        if not (np.isfinite(seconds) and seconds > 0):
            raise InputError(f"seconds must be a positive number, got {seconds}")
        stop = max(int(round((start + seconds) * self.fps)), first + 1)
        if stop > self.num_frames:
            raise InputError(f"{start:g} s + {seconds:g} s reaches past the end of the motion ({self.duration:g} s, "
                             f"{self.num_frames} frames at {self.fps:g} fps)")
        return self.slice(first, stop)

    def save(self, path: str | Path) -> None:
        """Write an ``.npz`` (rotations, translation, fps, rig, joint_names, name), atomically."""
        with atomic_path(path, suffix=".npz") as tmp:
            np.savez(
                tmp,
                rotations=self.rotations,
                translation=self.translation,
                fps=np.float64(self.fps),
                rig=np.str_(self.rig),
                joint_names=np.array(self.joint_names, dtype=np.str_),
                name=np.str_(self.name),
            )

    @classmethod
    def load(cls, path: str | Path, fps: float | None = None) -> "Motion":
        """Read a Motion ``.npz`` written by :meth:`save`; errors name the file and the problem.

        Args:
            fps: the frame rate of a file that stores none (no ``fps`` array, as some tools write it);
                a file that stores one keeps its own (the caller checks that they agree).
        """
        path = Path(path)
        z = load_npz(path, "motion")  # any damage to the file: an InputError naming it
        missing = {"rotations", "translation"} - set(z)
        if missing:
            raise InputError(f"not a loosefit motion, missing arrays {sorted(missing)}", path)
        if "fps" not in z and fps is None:
            raise InputError("the motion stores no frame rate (no 'fps' array): give it, e.g. --fps 30", path)
        try:
            return cls(
                rotations=z["rotations"],
                translation=z["translation"],
                fps=float(z["fps"]) if "fps" in z else float(fps),
                rig=str(z["rig"]) if "rig" in z else "cmu_mb",
                joint_names=[str(n) for n in z["joint_names"]] if "joint_names" in z else [],
                name=str(z["name"]) if "name" in z else path.stem,
            )
        except InputError as e:
            if e.path is None:
                raise InputError(e.problem, path) from None
            raise
        except (ValueError, TypeError) as e:
            raise InputError(f"cannot read motion: {e}", path) from None
