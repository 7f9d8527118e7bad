"""PNG / MP4 / GIF / folder writers: round trips through imageio, atomicity and errors."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.viz.writers import FrameWriter, save_png


def frames(count: int, height: int = 24, width: int = 32) -> list[np.ndarray]:
    """Flat frames of distinct, well separated colours (so that order survives lossy codecs)."""
    colors = [(230, 30, 30), (30, 200, 30), (30, 30, 220), (240, 240, 20), (20, 220, 230)]
    return [np.full((height, width, 3), colors[i % len(colors)], np.uint8) for i in range(count)]


def test_save_png_round_trip_is_exact(tmp_path):
    image = np.random.default_rng(0).integers(0, 256, (7, 9, 3), dtype=np.uint8)
    path = save_png(tmp_path / "sub" / "a.png", image)
    np.testing.assert_array_equal(iio.imread(path), image)
    with pytest.raises(InputError, match=r"must be \(H, W, 3\|4\) uint8"):
        save_png(tmp_path / "b.png", image.astype(np.float32))
    with pytest.raises(InputError, match="writes .png files"):
        save_png(tmp_path / "b.jpg", image)


@pytest.mark.parametrize("size", [(24, 32), (21, 31)])
def test_mp4_has_every_frame_in_order_and_even_size(tmp_path, size):
    path = tmp_path / "v.mp4"
    with FrameWriter(path, fps=12) as writer:
        for frame in frames(5, *size):
            writer.write(frame)
    video = iio.imread(path, index=None)
    even = (size[0] + size[0] % 2, size[1] + size[1] % 2)
    assert video.shape == (5, *even, 3)
    for got, sent in zip(video, frames(5, *even)):
        np.testing.assert_allclose(got[4:-4, 4:-4].mean(axis=(0, 1)), sent[0, 0], atol=8)
    meta = iio.immeta(path, plugin="FFMPEG")
    assert meta["fps"] == pytest.approx(12) and meta["codec"] == "h264"


def test_gif_round_trip(tmp_path):
    path = tmp_path / "v.gif"
    with FrameWriter(path, fps=10) as writer:
        for frame in frames(4):
            writer.write(frame)
    gif = iio.imread(path, index=None)
    assert gif.shape[:3] == (4, 24, 32)
    for got, sent in zip(gif, frames(4)):
        np.testing.assert_allclose(got[..., :3].mean(axis=(0, 1)), sent[0, 0], atol=3)


def test_folder_of_pngs_and_single_png(tmp_path):
    with FrameWriter(tmp_path / "shots") as writer:
        for frame in frames(3):
            writer.write(frame)
    written = sorted((tmp_path / "shots").iterdir())
    assert [p.name for p in written] == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    for path, frame in zip(written, frames(3)):
        np.testing.assert_array_equal(iio.imread(path), frame)
    with pytest.raises(InputError, match="holds one frame"):
        with FrameWriter(tmp_path / "one.png") as writer:
            for frame in frames(2):
                writer.write(frame)
    np.testing.assert_array_equal(iio.imread(tmp_path / "one.png"), frames(1)[0])


def test_failed_writes_leave_nothing_behind(tmp_path):
    with pytest.raises(InputError, match="no frames to write"):
        with FrameWriter(tmp_path / "empty.mp4"):
            pass
    with pytest.raises(RuntimeError, match="renderer died"):
        with FrameWriter(tmp_path / "broken.mp4") as writer:
            writer.write(frames(1)[0])
            raise RuntimeError("renderer died")
    with pytest.raises(InputError, match=r"frame size changed from \(24, 32\) to \(12, 16\)"):
        with FrameWriter(tmp_path / "sizes.gif") as writer:
            writer.write(frames(1)[0])
            writer.write(frames(1, 12, 16)[0])
    assert list(tmp_path.iterdir()) == []


def test_an_existing_video_is_kept_when_a_rewrite_fails(tmp_path):
    path = tmp_path / "v.gif"
    with FrameWriter(path) as writer:
        writer.write(frames(1)[0])
    before = path.read_bytes()
    with pytest.raises(RuntimeError):
        with FrameWriter(path) as writer:
            writer.write(frames(2)[1])
            raise RuntimeError("interrupted")
    assert path.read_bytes() == before


def test_bad_outputs(tmp_path):
    with pytest.raises(InputError, match=r"unsupported output '.avi'"):
        FrameWriter(tmp_path / "v.avi")
    with pytest.raises(InputError, match="fps must be positive"):
        FrameWriter(tmp_path / "v.mp4", fps=0)
    (tmp_path / "dir.mp4").mkdir()
    with pytest.raises(InputError, match="output exists and is a folder"):
        FrameWriter(tmp_path / "dir.mp4")
