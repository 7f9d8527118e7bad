"""A zip-bomb ``.npz`` (a few MB that inflate to GBs) is refused from its arrays' declared sizes before any is
inflated, naming the file, the array and the limit; ordinary files still read."""

from __future__ import annotations

import time
import tracemalloc

import numpy as np
import pytest

from loosefit.cli import main
from loosefit.errors import InputError
from loosefit.io import npz
from loosefit.io.npz import MAX_NPZ_BYTES, load_npz
from loosefit.motion.motion import Motion
from tests.robustness.craft import zip_bomb


@pytest.fixture(scope="module")
def bomb(tmp_path_factory):
    path = tmp_path_factory.mktemp("bomb") / "bomb.npz"
    zip_bomb(path)
    return path


def test_zip_bomb_refused_before_inflating(bomb):
    assert bomb.stat().st_size < 1e6  # well under a MB on disk
    tracemalloc.start()
    start = time.perf_counter()
    try:
        with pytest.raises(InputError) as info:
            load_npz(bomb, "motion")
        seconds, peak = time.perf_counter() - start, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    message = str(info.value)
    assert message.startswith(f"{bomb}: cannot read motion: array 'rotations' declares shape (375000000, 1, 3)"), message
    assert "MAX_NPZ_BYTES" in message
    assert peak < 50e6 and seconds < 2.0, (peak, seconds)


def test_cli_refuses_a_zip_bomb_motion(bomb, tmp_path, capsys):
    out = tmp_path / "body.npz"
    assert main(["body", "--motion", str(bomb), "--resolution", "low", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"error: {bomb}: cannot read motion: array 'rotations' declares" in err and "Traceback" not in err, err
    assert not out.exists()


def test_the_limit_counts_all_arrays_read(tmp_path, monkeypatch):
    path = tmp_path / "two.npz"
    np.savez(path, a=np.zeros(100, np.float32), b=np.zeros(100, np.float32))
    monkeypatch.setattr(npz, "MAX_NPZ_BYTES", 600)  # each fits, both together do not
    with pytest.raises(InputError, match="array 'b' declares shape \\(100,\\) of float32"):
        load_npz(path, "test file")
    assert list(load_npz(path, "test file", names=["a"])) == ["a"]


def test_ordinary_files_still_read(tmp_path):
    motion = Motion(np.zeros((10, 3, 3), np.float32), np.zeros((10, 3), np.float32), fps=30.0, name="walk")
    motion.save(tmp_path / "m.npz")
    assert Motion.load(tmp_path / "m.npz").num_frames == 10
    assert MAX_NPZ_BYTES >= 1.6e9  # a 10,000-frame sequence of the full-resolution body
