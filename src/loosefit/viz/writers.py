"""Frame sinks: PNG files, MP4 (H.264 through imageio-ffmpeg) and GIF, written atomically.

Frames are written one at a time as they are rendered. MP4 streams to ffmpeg; a GIF is kept by
Pillow until it is closed (GIFs are for short clips); a folder gets one PNG per frame, each written
atomically, so an interrupted render keeps the frames written so far.
"""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path

import numpy as np

from loosefit.errors import InputError
from loosefit.extras import require
from loosefit.paths import atomic_path

#: imageio-ffmpeg quality in [1, 10]; 7 gives x264 CRF 15 (visually lossless for renders).
MP4_QUALITY = 7
VIDEO_SUFFIXES = (".mp4", ".gif")


def _check_image(image: np.ndarray, path) -> np.ndarray:
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (3, 4):
        raise InputError(f"image must be (H, W, 3|4) uint8, got {image.shape} {image.dtype}", path)
    return image


def save_png(path, image: np.ndarray) -> Path:
    """Write ``image (H, W, 3|4) uint8`` to ``path`` (``.png``), atomically; returns the path."""
    iio = require("imageio.v3", "writing PNG images")

    path = Path(path)
    if path.suffix.lower() != ".png":
        raise InputError("save_png writes .png files", path)
    image = _check_image(image, path)
    with atomic_path(path) as tmp:
        iio.imwrite(tmp, image, extension=".png")
    return path


class FrameWriter:
    """Writes ``(H, W, 3)`` uint8 frames to ``path`` as they come; use as a context manager.

    The output kind follows ``path``: ``.mp4`` (H.264, yuv420p; odd sizes are padded to even by
    repeating the last row / column), ``.gif``, ``.png`` (exactly one frame), or no suffix: a folder
    of ``frame_00000.png`` ... The file appears at ``path`` only when the writer closes without error.
    """

    def __init__(self, path, fps: float = 30.0):
        self.path = Path(path)
        self.fps = float(fps)
        suffix = self.path.suffix.lower()
        if suffix not in VIDEO_SUFFIXES + (".png", ""):
            raise InputError(f"unsupported output {suffix!r}: use .mp4, .gif, .png or a folder (no suffix)", self.path)
        if not self.fps > 0:
            raise InputError(f"fps must be positive, got {fps}", self.path)
        if self.path.exists() and (self.path.is_dir() != (suffix == "")):
            raise InputError("output exists and is " + ("a folder" if self.path.is_dir() else "a file"), self.path)
        self.kind = suffix or "folder"
        self.count = 0
        self._stack = ExitStack()
        self._encoder = None  # the ffmpeg generator or the GIF writer, opened on the first frame
        self._size: tuple[int, int] | None = None
        self._tmp = None

    def __enter__(self) -> "FrameWriter":
        if self.kind == "folder":
            self.path.mkdir(parents=True, exist_ok=True)
        elif self.kind != ".png":
            self._tmp = self._stack.enter_context(atomic_path(self.path))
        return self

    def write(self, frame: np.ndarray) -> None:
        """Append one ``(H, W, 3)`` uint8 frame (all frames must have the same size)."""
        frame = _check_image(frame, self.path)[:, :, :3]
        if self.kind == ".png":
            if self.count:
                raise InputError("a .png output holds one frame; select one frame or write a folder", self.path)
            save_png(self.path, frame)
        elif self.kind == "folder":
            save_png(self.path / f"frame_{self.count:05d}.png", frame)
        elif self.kind == ".mp4":
            self._write_mp4(frame)
        else:
            self._write_gif(frame)
        self.count += 1

    def _write_mp4(self, frame: np.ndarray) -> None:
        imageio_ffmpeg = require("imageio_ffmpeg", "writing MP4 video")

        # H.264 with 4:2:0 chroma needs even dimensions.
        frame = np.pad(frame, ((0, frame.shape[0] % 2), (0, frame.shape[1] % 2), (0, 0)), mode="edge")
        if self._encoder is None:
            self._size = frame.shape[:2]
            self._encoder = imageio_ffmpeg.write_frames(
                str(self._tmp),
                (frame.shape[1], frame.shape[0]),
                fps=self.fps,
                codec="libx264",
                pix_fmt_in="rgb24",
                pix_fmt_out="yuv420p",
                quality=MP4_QUALITY,
                macro_block_size=1,
                output_params=["-f", "mp4"],
            )
            self._encoder.send(None)
        if frame.shape[:2] != self._size:
            raise InputError(f"frame size changed from {self._size} to {frame.shape[:2]}", self.path)
        self._encoder.send(np.ascontiguousarray(frame))

    def _write_gif(self, frame: np.ndarray) -> None:
        iio2 = require("imageio.v2", "writing GIF animations")

        if self._encoder is None:
            self._size = frame.shape[:2]
            self._encoder = iio2.get_writer(self._tmp, format="GIF", mode="I", duration=1000.0 / self.fps, loop=0)
        if frame.shape[:2] != self._size:
            raise InputError(f"frame size changed from {self._size} to {frame.shape[:2]}", self.path)
        self._encoder.append_data(frame)

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if self._encoder is not None:
                self._encoder.close()
            if exc_type is None and self.kind in VIDEO_SUFFIXES and self.count == 0:
                raise InputError("no frames to write", self.path)
        except Exception as error:
            if exc_type is None:
                # Closing failed: drop the temporary file and report that error.
                self._stack.__exit__(type(error), error, error.__traceback__)
                raise
        # On an exception the temporary file is removed; otherwise it is renamed onto the path.
        self._stack.__exit__(exc_type, exc, tb)
