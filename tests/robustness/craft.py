"""Bad input files for the robustness cases, written with NumPy, Zarr and plain text (not through loosefit's
own writers, so that the files are the same whichever source tree is measured).

Damage: :func:`truncate`, :func:`flip_byte`, :func:`garbage`. Payloads: :func:`payload_pickle` (a pickle that
creates the case's marker file when it is loaded), in ``.pkl``, ``.npz`` (object array), ``.pt`` and Zarr
(Pickle codec). Copies of the shared store and run to damage. Meshes (OBJ, PLY), BVH cuts, AMASS files.
Hostile files: YAML bombs and deep nesting, BVH hierarchies too deep or too wide, a zip-bomb ``.npz``.
"""

from __future__ import annotations

import builtins
import io
import json
import os
import pickle
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np

from tests.conftest import TEST_MOCAP
from tests.robustness.harness import MARKER, Shared

#: A real CMU clip the tests keep (tests/data/cmu-cc).
BVH_CLIP = "002_03.bvh"


def mocap_clip() -> Path:
    """The real clip :data:`BVH_CLIP`."""
    return TEST_MOCAP / BVH_CLIP


def write(path: Path, data: bytes | str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    (path.write_bytes if isinstance(data, bytes) else path.write_text)(data)
    return path


def truncate(path: Path, keep: float = 0.5) -> Path:
    """Cut a file to ``keep`` of its bytes (a copy interrupted mid-way)."""
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    return path


def flip_byte(path: Path, at: float = 0.5) -> Path:
    """Invert the bits of one byte at fraction ``at`` of the file (bit rot)."""
    data = bytearray(path.read_bytes())
    i = min(int(len(data) * at), len(data) - 1)
    data[i] ^= 0xFF
    path.write_bytes(bytes(data))
    return path


def garbage(path: Path, size: int = 600, seed: int = 0) -> Path:
    return write(path, np.random.default_rng(seed).integers(0, 256, size, dtype=np.uint8).tobytes())


class _Payload:
    """Unpickling this creates ``path`` (harmless, but proof that loading the file ran code)."""

    def __init__(self, path: Path):
        self.path = str(path)

    def __reduce__(self):
        return (builtins.open, (self.path, "w"))


def payload_pickle(tmp: Path, wrap=None) -> bytes:
    """A pickle (protocol 2, as SMPL files are) whose loading creates ``tmp/MARKER``; ``wrap(payload)``
    puts the payload inside a structure (e.g. a SMPL-looking dict)."""
    payload = _Payload(tmp / MARKER)
    return pickle.dumps(wrap(payload) if wrap else payload, protocol=2)


def npz_payload(path: Path, tmp: Path, key: str, **arrays) -> Path:
    """An ``.npz`` whose array ``key`` is an object array holding the payload."""
    obj = np.empty(1, dtype=object)
    obj[0] = _Payload(tmp / MARKER)
    np.savez(path, **{key: obj}, **arrays)
    return path


def pt_payload(path: Path, tmp: Path) -> Path:
    """A ``torch.save`` file (a checkpoint look-alike) whose unpickling creates the marker."""
    import torch

    torch.save({"format": "loosefit-checkpoint", "model": _Payload(tmp / MARKER)}, path)
    return path


def npz_arrays(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def npz_edit(src: Path, dst: Path, **changes) -> Path:
    """Copy an ``.npz`` with arrays replaced (a value) or removed (None)."""
    arrays = npz_arrays(src)
    for key, value in changes.items():
        if value is None:
            arrays.pop(key, None)
        else:
            arrays[key] = value(arrays[key]) if callable(value) else value
    np.savez(dst, **arrays)
    return dst


# ---------------------------------------------------------------------------------------------- stores


def copy_store(sh: Shared, tmp: Path, name: str = "d.zarr") -> Path:
    return Path(shutil.copytree(sh.store, tmp / name))


def sequences(store: Path) -> dict[str, dict]:
    """Each sequence's attributes (read from its ``.zattrs``)."""
    out = {}
    for d in sorted((store / "sequences").iterdir()):
        if (d / ".zattrs").is_file():
            out[d.name] = json.loads((d / ".zattrs").read_text())
    return out


def sequence_named(store: Path, split: str = "train") -> str:
    """The first sequence of ``split`` (sorted by name)."""
    return next(n for n, a in sequences(store).items() if a.get("split") == split)


def first_chunk(store: Path, seq: str, array: str = "verts") -> Path:
    return next(p for p in sorted((store / "sequences" / seq / array).iterdir()) if not p.name.startswith("."))


def pickle_codec_array(store: Path, seq: str, tmp: Path) -> Path:
    """Replace a sequence's ``verts`` by an object array stored with the numcodecs Pickle codec, holding the
    payload (a store must never decode pickles)."""
    import numcodecs
    import zarr

    path = store / "sequences" / seq / "verts"
    shape = json.loads((path / ".zarray").read_text())["shape"]
    shutil.rmtree(path)
    arr = zarr.open_array(str(path), mode="w", shape=(shape[0],), chunks=(shape[0],), dtype=object,
                          object_codec=numcodecs.Pickle())
    values = np.empty(shape[0], dtype=object)
    values[:] = [_Payload(tmp / MARKER) for _ in range(shape[0])]
    arr[:] = values
    return path


def dead_pid() -> int:
    """The pid of a process that has exited (a stale lock or creation leftover's owner)."""
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    pid = int(proc.stdout)
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return pid
    raise RuntimeError(f"pid {pid} was reused at once")


def copy_run(sh: Shared, tmp: Path, name: str = "run") -> Path:
    return Path(shutil.copytree(sh.run, tmp / name))


# ---------------------------------------------------------------------------------------------- meshes


def read_obj_simple(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``v`` and triangle ``f`` lines of an OBJ written by loosefit (0-based faces)."""
    verts, faces = [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if parts and parts[0] == "v":
            verts.append([float(x) for x in parts[1:4]])
        elif parts and parts[0] == "f":
            faces.append([int(x.split("/")[0]) - 1 for x in parts[1:4]])
    return np.array(verts, np.float64), np.array(faces, np.int64)


def obj_text(verts, faces, header: str = "# robustness case") -> str:
    lines = [header] + [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(verts, float).tolist()]
    lines += ["f " + " ".join(str(i + 1) for i in f) for f in np.asarray(faces).tolist()]
    return "\n".join(lines) + "\n"


def ply_text(verts, faces) -> str:
    verts, faces = np.asarray(verts, float), np.asarray(faces)
    head = ["ply", "format ascii 1.0", f"element vertex {len(verts)}", "property float x", "property float y",
            "property float z", f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    body = [f"{x:.7g} {y:.7g} {z:.7g}" for x, y, z in verts.tolist()] + [f"3 {a} {b} {c}" for a, b, c in faces.tolist()]
    return "\n".join(head + body) + "\n"


def garment_mesh(sh: Shared) -> tuple[np.ndarray, np.ndarray]:
    """The shared garment's vertices and faces (a loosefit-made skirt, metres, Z up)."""
    return read_obj_simple(sh.garment)


def copy_garment(sh: Shared, tmp: Path, name: str = "g.obj") -> Path:
    """The shared garment with its sidecar, under ``name`` (a garment file as ``garment make`` writes it)."""
    shutil.copy(sh.garment, tmp / name)
    shutil.copy(sh.garment.with_suffix(".json"), (tmp / name).with_suffix(".json"))
    return tmp / name


# ---------------------------------------------------------------------------------------------- motions


def bvh_cut(dst: Path, frames: int = 30, edit=None) -> Path:
    """The first ``frames`` frames of the real clip (CC skeleton, Y up, cm, 60 fps); ``edit(header lines,
    frame lines)`` may change either list in place before the file is written."""
    lines = mocap_clip().read_text().splitlines()
    m = lines.index("MOTION")
    header, data = lines[: m + 3], lines[m + 3 : m + 3 + frames]
    header[m + 1] = f"Frames: {len(data)}"
    if edit is not None:
        edit(header, data)
    return write(dst, "\n".join(header + data) + "\n")


def amass(dst: Path, frames: int = 60, fps: float | None = 60.0, **changes) -> Path:
    """An AMASS SMPL-H ``.npz``: root turned to Z up, walking forward along +Y at 1 m/s, limbs at rest;
    ``changes`` replace arrays (None removes one)."""
    poses = np.zeros((frames, 156))
    poses[:, 0] = np.pi / 2
    trans = np.zeros((frames, 3))
    trans[:, 1] = np.arange(frames) / (fps or 60.0)
    trans[:, 2] = 0.95
    arrays = {"poses": poses, "trans": trans, "betas": np.zeros(16), "gender": np.str_("neutral")}
    if fps is not None:
        arrays["mocap_framerate"] = np.float64(fps)
    for key, value in changes.items():
        if value is None:
            arrays.pop(key, None)
        else:
            arrays[key] = value
    np.savez(dst, **arrays)
    return dst


def smpl_pkl(dst: Path) -> Path:
    """A small SMPL model in the real pickle layout (numpy arrays, a scipy.sparse J_regressor), as the body
    tests write it."""
    from tests.body.test_smpl_body import write_smpl_pkl

    write_smpl_pkl(dst)
    return dst


def smpl_npz(dst: Path) -> Path:
    """The same model as an ``.npz`` of plain arrays (the dense regressor)."""
    src = smpl_pkl(dst.with_suffix(".src.pkl"))
    with open(src, "rb") as f:
        model = pickle.load(f, encoding="latin1")  # our own file, written just above
    model["J_regressor"] = model["J_regressor"].toarray()
    np.savez(dst, **{k: np.asarray(v) for k, v in model.items()})
    src.unlink()
    return dst


# ---------------------------------------------------------------------------------------------- hostile files


def yaml_bomb(levels: int = 10) -> str:
    """A "billion laughs" document: ten lists of ten aliases of the level below, ``levels`` deep (10**levels values)."""
    lines = ["l0: &l0 [" + ", ".join(["lol"] * 10) + "]"]
    for k in range(1, levels):
        lines.append(f"l{k}: &l{k} [" + ", ".join([f"*l{k - 1}"] * 10) + "]")
    return "\n".join(lines) + "\n"


def yaml_deep(levels: int) -> str:
    """A YAML mapping whose value is ``levels`` flow lists nested in each other."""
    return "a: " + "[" * levels + "1" + "]" * levels + "\n"


def bvh_chain(depth: int) -> str:
    """A BVH whose joints form one chain ``depth`` long (an end site at its tip), one frame."""
    lines = ["HIERARCHY", "ROOT j0", "{", "OFFSET 0 0 0", "CHANNELS 6 Xposition Yposition Zposition Zrotation "
             "Xrotation Yrotation"]
    for k in range(1, depth):
        lines += [f"JOINT j{k}", "{", "OFFSET 0 0.01 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    lines += ["End Site", "{", "OFFSET 0 0.01 0", "}"] + ["}"] * depth
    lines += ["MOTION", "Frames: 1", "Frame Time: 0.0333333", " ".join(["0"] * (6 + 3 * (depth - 1)))]
    return "\n".join(lines) + "\n"


def bvh_flat(children: int) -> str:
    """A BVH whose root has ``children`` end-site children (no channels but the root's)."""
    lines = ["HIERARCHY", "ROOT r", "{", "OFFSET 0 0 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    for k in range(children):
        lines += [f"JOINT c{k}", "{", "OFFSET 0 0.01 0", "CHANNELS 0", "}"]
    lines += ["}", "MOTION", "Frames: 1", "Frame Time: 0.0333333", "0 0 0"]
    return "\n".join(lines) + "\n"


def zip_bomb(path, gigabytes: float = 4.5, stored_mb: int = 64) -> None:
    """A motion-like ``.npz`` whose ``rotations`` array declares ``gigabytes`` of float32 and holds its first
    ``stored_mb`` MB of zeros, deflated (a real bomb holds them all; the header alone must refuse it)."""
    count = int(gigabytes * 1e9 / 4 / 3)
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False, "shape": (count, 1, 3)})
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for name, value in (("fps", np.array(30.0)), ("translation", np.zeros((count, 3), np.float32)[:1])):
            buf = io.BytesIO()
            np.save(buf, value)
            z.writestr(f"{name}.npy", buf.getvalue())
        with z.open("rotations.npy", "w", force_zip64=True) as f:  # streamed: never held in memory here
            f.write(header.getvalue())
            block = bytes(64 * 1024 * 1024)
            left = min(count * 12, stored_mb * 1024 * 1024)
            while left > 0:
                f.write(block[:min(left, len(block))])
                left -= len(block)
