"""load_npz: damaged files (truncated, a flipped byte, not a zip) and pickles are InputErrors naming the file."""

import struct
import zipfile

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.io.npz import load_npz, npz_names, save_npz


class _Payload:
    """Unpickling this creates the file ``path``."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


@pytest.fixture
def arrays():
    rng = np.random.default_rng(0)
    return {"verts": rng.normal(size=(6, 40, 3)).astype(np.float32), "faces": np.arange(30).reshape(10, 3)}


@pytest.mark.parametrize("compressed", [False, True])
def test_round_trip_and_named_reads(tmp_path, arrays, compressed):
    save_npz(tmp_path / "a.npz", arrays, compressed=compressed)
    back = load_npz(tmp_path / "a.npz", "test data")
    assert back.keys() == arrays.keys() and all(np.array_equal(back[k], arrays[k]) for k in arrays)
    assert list(load_npz(tmp_path / "a.npz", "test data", names=["faces", "absent"])) == ["faces"]
    assert npz_names(tmp_path / "a.npz", "test data") == ["verts", "faces"]


def _damaged(path, arrays, compressed, how):
    save_npz(path, arrays, compressed=compressed)
    data = bytearray(path.read_bytes())
    if how == "truncated":
        data = data[: len(data) // 2]
    elif how == "tail cut":  # the zip directory at the end is gone
        data = data[:-30]
    else:  # one byte of the first member's data flipped: a bad CRC, or a bad deflate stream when compressed
        with zipfile.ZipFile(path) as z:
            info = z.infolist()[0]
        name_len, extra_len = struct.unpack("<HH", data[info.header_offset + 26 : info.header_offset + 30])
        data[info.header_offset + 30 + name_len + extra_len + 30] ^= 0xFF
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("compressed", [False, True])
@pytest.mark.parametrize("how", ["truncated", "tail cut", "flipped byte"])
def test_damaged_files_are_input_errors(tmp_path, arrays, compressed, how):
    path = tmp_path / "damaged.npz"
    _damaged(path, arrays, compressed, how)
    with pytest.raises(InputError, match=r"damaged.npz: cannot read test data: ") as err:
        load_npz(path, "test data")
    if how == "flipped byte":  # zipfile's and zlib's own errors, both caught
        assert ("Error -3 while decompressing" if compressed else "Bad CRC-32") in str(err.value)


@pytest.mark.parametrize("content, message", [
    (b"", "damaged or not an .npz"),
    (b"hello, not a zip", "not an .npz archive .nor an .npy array"),
    (None, "not an .npz archive"),  # a plain .npy
])
def test_other_files_are_input_errors(tmp_path, content, message):
    path = tmp_path / "other.npz"
    if content is None:
        with open(path, "wb") as f:
            np.save(f, np.zeros(3))
    else:
        path.write_bytes(content)
    with pytest.raises(InputError, match=f"other.npz: cannot read test data: .*{message}"):
        load_npz(path, "test data")
    with pytest.raises(InputError, match="other.npz"):
        npz_names(path, "test data")
    with pytest.raises(InputError, match="missing.npz: cannot read test data: No such file"):
        load_npz(tmp_path / "missing.npz", "test data")


def test_pickled_arrays_are_refused_without_running(tmp_path, arrays):
    marker, path = tmp_path / "marker", tmp_path / "evil.npz"
    np.savez(path, **arrays, extra=np.array([_Payload(marker)], dtype=object))
    with pytest.raises(InputError, match="evil.npz: cannot read test data: array 'extra' holds pickled Python objects"):
        load_npz(path, "test data")
    assert list(load_npz(path, "test data", names=["faces"])) == ["faces"]  # the arrays asked for are plain
    assert not marker.exists()
    np.load(path, allow_pickle=True)["extra"]  # the payload is live
    assert marker.exists()
