import struct

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.io.pc2 import read_pc2, write_pc2


def test_round_trip_and_header(tmp_path):
    frames = np.random.default_rng(0).normal(size=(5, 7, 3)).astype(np.float32)
    path = tmp_path / "a.pc2"
    write_pc2(path, frames, start_frame=1.0, sample_rate=1.0)
    back, start, rate = read_pc2(path)
    np.testing.assert_array_equal(back, frames)
    assert (start, rate) == (1.0, 1.0)
    raw = path.read_bytes()
    assert raw[:12] == b"POINTCACHE2\0"
    assert struct.unpack("<iiffi", raw[12:32]) == (1, 7, 1.0, 1.0, 5)
    assert len(raw) == 32 + 5 * 7 * 12
    assert struct.unpack("<3f", raw[32:44]) == tuple(frames[0, 0].tolist())


def test_bad_files_name_the_file(tmp_path):
    bad = tmp_path / "bad.pc2"
    bad.write_bytes(b"NOTACACHE\0\0\0" + bytes(20))
    with pytest.raises(InputError, match="bad.pc2.*magic"):
        read_pc2(bad)
    cut = tmp_path / "cut.pc2"
    write_pc2(cut, np.zeros((3, 4, 3), np.float32))
    cut.write_bytes(cut.read_bytes()[:-12])
    with pytest.raises(InputError, match="cut.pc2.*3 samples x 4 points"):
        read_pc2(cut)
    with pytest.raises(InputError, match=r"\(T, V, 3\)"):
        write_pc2(tmp_path / "x.pc2", np.zeros((4, 3), np.float32))
    assert not (tmp_path / "x.pc2").exists()
