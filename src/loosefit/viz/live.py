"""``loosefit view --live RUN``: a page that animates a trained garment in the browser, one frame at a time.

The run is exported once to an ONNX step model (:mod:`loosefit.export_onnx`: inputs ``joint_rotations (J, 3)``
axis-angle radians, ``root_position (3,)`` metres Z up, ``state (S,)``; outputs ``vertices (V, 3)`` metres Z up and
``next_state (S,)``), and the page runs it with onnxruntime-web (WebAssembly; WebGPU where the browser has an
adapter). Python only serves data; every garment vertex the page shows comes out of the page's own inference.

The page (``viz/static/live.html`` + ``live.js``) plays motions converted once by the server: the procedural kinds
of :mod:`loosefit.motion.procedural` and the user's motion files (``.bvh`` / ``.npz``, retargeted to the body's rig
by :func:`loosefit.motion.io.load_motion`), all at the model's frame rate. It poses the body itself by linear blend
skinning (:mod:`loosefit.geometry.lbs`) from the body's rest geometry and sparse skinning weights, because a
switch of motion blends joint rotations and re-places the root, poses no precomputed mesh sequence holds.

What the server answers besides the static files:

- ``live/manifest.json``: the model's ``loosefit`` metadata (method, fps, joint names, faces, ``initial_state``,
  state layout), the body's joint parents, the motions' names and frame counts, and where each array lies in
  ``live/data.bin``;
- ``live/data.bin``: the arrays back to back, raw little-endian ``float32`` / ``uint32`` at 4-byte aligned
  offsets: body rest vertices ``(Vb, 3)`` and joints ``(J, 3)`` (metres), faces ``(Fb, 3)``, skinning
  influences ``(Vb, K)`` (joint index ``uint32`` and weight ``float32``, rows summing to 1), and per motion its
  joint rotations ``(T, J, 3)`` (axis-angle, radians) and root positions ``(T, 3)`` (metres, Z up);
- ``live/model.onnx``: the step model.
"""

from __future__ import annotations

import json
import logging
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from loosefit.errors import InputError

log = logging.getLogger(__name__)

#: Procedural motions the page offers by default (one clip each, by :func:`loosefit.motion.procedural.generate`).
DEFAULT_KINDS = ("walk", "run", "turn", "spin", "jump", "kick", "squat", "bow", "arm_raise", "wave", "sway")
#: Seconds of each procedural clip, and the seed they are drawn with.
DEFAULT_SECONDS = 8.0
DEFAULT_SEED = 0
#: Skinning influences per body vertex sent to the page (Anny's cmu_mb weights have at most 7 non-zero per vertex).
MAX_INFLUENCES = 8


@dataclass
class LiveMotion:
    """One motion the page can play: ``rotations (T, J, 3)`` float32 axis-angle radians on the run's skeleton,
    ``translation (T, 3)`` float32 root positions (metres, Z up), and where it came from."""

    name: str
    rotations: np.ndarray
    translation: np.ndarray
    source: str


@dataclass
class LiveBody:
    """The body as the page skins it: ``rest_verts (Vb, 3)``, ``rest_joints (J, 3)`` float32 metres,
    ``parents (J,)`` (-1 at the root), ``faces (Fb, 3)``, and its ``K`` strongest skinning influences per vertex,
    ``skin_index (Vb, K)`` uint32 / ``skin_weight (Vb, K)`` float32 (rows summing to 1)."""

    rest_verts: np.ndarray
    rest_joints: np.ndarray
    parents: np.ndarray
    faces: np.ndarray
    skin_index: np.ndarray
    skin_weight: np.ndarray


@dataclass
class LiveScene:
    """Everything ``loosefit view --live`` serves: the step model's bytes and its ``loosefit`` metadata, the body,
    and the motions."""

    model: bytes
    metadata: dict
    body: LiveBody
    motions: list[LiveMotion] = field(default_factory=list)

    @property
    def fps(self) -> float:
        return float(self.metadata.get("fps", 30.0))


def sparse_weights(weights: np.ndarray, k: int = MAX_INFLUENCES) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` largest of each row of dense skinning weights ``(V, J)``, renormalised to sum to 1:
    ``(index (V, k) uint32, weight (V, k) float32)``. Exact when no row has more than ``k`` non-zero weights."""
    w = np.asarray(weights, dtype=np.float64)
    k = min(k, w.shape[1])
    index = np.argsort(-w, axis=1, kind="stable")[:, :k]
    top = np.take_along_axis(w, index, axis=1)
    top /= top.sum(axis=1, keepdims=True)
    return index.astype(np.uint32), top.astype(np.float32)


def live_body(body) -> LiveBody:
    """The body's rest geometry and sparse skinning weights (:class:`LiveBody`)."""
    index, weight = sparse_weights(body.skinning_weights())
    return LiveBody(body.rest_verts().astype(np.float32), body.rest_joints().astype(np.float32),
                    np.asarray(body.parents, dtype=np.int64), np.asarray(body.faces, dtype=np.int64), index, weight)


def read_step_model(path: str | Path) -> tuple[bytes, dict]:
    """``(bytes, metadata)`` of an exported step model: its file content and its ``loosefit`` metadata
    (:func:`loosefit.export_onnx.read_metadata`).

    Raises:
        InputError: not an ONNX file, one without the metadata or of another format version, or metadata without
            what the page needs (joint names, faces, initial state); the message names the file.
    """
    from loosefit.export_onnx import read_metadata

    path = Path(path)
    metadata = read_metadata(path)
    for key in ("joint_names", "faces", "initial_state"):
        if key not in metadata:
            raise InputError(f"the model's metadata lacks {key!r}", path)
    if metadata.get("weights", {}).get("storage") == "int8":
        # onnxruntime-web has no fast 8-bit kernels: the page would be several times slower (benchmarks/README.md)
        log.warning("%s: int8 weights (export-onnx --int8) run several times slower in the page than float32; "
                    "export the run without --int8 for the live page", path)
    return path.read_bytes(), metadata


def export_step_model(run: str | Path, checkpoint: str = "best") -> tuple[bytes, dict]:
    """Export a trained run to the ONNX step model once (in a temporary folder): ``(bytes, metadata)``."""
    from loosefit.export_onnx import export_onnx

    with tempfile.TemporaryDirectory(prefix="loosefit-live-") as tmp:
        out = Path(tmp) / "garment.onnx"
        export_onnx(run, out, checkpoint=checkpoint)
        return read_step_model(out)


def _check_skeleton(metadata: dict, body, where) -> None:
    names = list(metadata["joint_names"])
    if names != list(body.joint_names):
        raise InputError(f"the run's skeleton ({len(names)} joints: {', '.join(names[:4])}, ...) is not the body's "
                         f"rig {body.rig!r} ({body.num_joints} joints): the page poses the body along the run's joints",
                         where)


def procedural_motions(body, fps: float, kinds=DEFAULT_KINDS, seconds: float = DEFAULT_SECONDS,
                       seed: int = DEFAULT_SEED) -> list[LiveMotion]:
    """One clip of ``seconds`` per procedural kind, at ``fps``, on ``body``'s rig."""
    from loosefit.motion.procedural import generate

    out = []
    for kind in kinds:
        m = generate(kind, seconds, seed, body, fps=fps)
        out.append(LiveMotion(kind, m.rotations, m.translation, m.name))
    return out


def file_motion(path: str | Path, body, fps: float, joint_map=None, keep_first_frame: bool = False) -> LiveMotion:
    """A motion file (``.bvh`` / ``.npz``) retargeted to ``body`` and resampled to ``fps``."""
    from loosefit.motion.io import load_motion
    from loosefit.motion.resample import resample

    path = Path(path)
    motion = load_motion(path, body, joint_map=joint_map, fps=fps, keep_first_frame=keep_first_frame)
    if abs(motion.fps - fps) > 1e-6:
        motion = resample(motion, fps)
    if motion.num_frames < 2:
        raise InputError(f"the motion has {motion.num_frames} frame at {fps:g} fps: the page needs at least 2", path)
    return LiveMotion(path.stem, motion.rotations, motion.translation, str(path))


def build_live_scene(run: str | Path | None = None, motions=(), body=None, kinds=DEFAULT_KINDS,
                     seconds: float = DEFAULT_SECONDS, model_path: str | Path | None = None,
                     checkpoint: str = "best", joint_map=None, keep_first_frame: bool = False) -> LiveScene:
    """The scene of ``loosefit view --live RUN [--motion FILE ...]``.

    Args:
        run: a trained run folder (or ``pretrained:NAME``), exported once to ONNX; or None with ``model_path``.
        motions: motion files offered after the procedural clips, each retargeted to the body's rig.
        body: the body the garment is worn on (default: Anny, average shape, as the runs are trained on).
        kinds: procedural kinds offered (one clip each of ``seconds``); empty: only the files.
        model_path: an already exported step model (``.onnx``) instead of ``run``.

    Raises:
        InputError: a bad run, model or motion file (naming it); a run whose skeleton is not the body's;
            no motion at all.
    """
    if model_path is not None:
        model, metadata = read_step_model(model_path)
        where = model_path
    elif run is not None:
        model, metadata = export_step_model(run, checkpoint)
        where = run
    else:
        raise InputError("give a run folder or an exported .onnx step model")
    if body is None:
        from loosefit.body import AnnyBody

        body = AnnyBody()
    _check_skeleton(metadata, body, where)
    fps = float(metadata.get("fps", 30.0))
    clips = procedural_motions(body, fps, kinds, seconds)
    clips += [file_motion(p, body, fps, joint_map, keep_first_frame) for p in motions]
    if not clips:
        raise InputError("no motion to play: give procedural kinds or --motion FILE")
    names = [c.name for c in clips]
    for i, clip in enumerate(clips):  # two files of one stem: the list must tell them apart
        if names.count(clip.name) > 1:
            clip.name = f"{clip.name} ({i + 1})"
    return LiveScene(model, metadata, live_body(body), clips)


class _Packer:
    """Arrays back to back as little-endian bytes at 4-byte aligned offsets (every dtype here is 4 bytes wide)."""

    def __init__(self):
        self.parts: list[bytes] = []
        self.buffers: list[dict] = []
        self.offset = 0

    def add(self, array: np.ndarray, dtype: str) -> int:
        a = np.ascontiguousarray(array, dtype=np.dtype(dtype).newbyteorder("<"))
        raw = a.tobytes()
        self.buffers.append({"offset": self.offset, "bytes": len(raw), "dtype": dtype, "shape": list(a.shape)})
        self.parts.append(raw)
        self.offset += len(raw)
        return len(self.buffers) - 1


def pack_live_scene(scene: LiveScene) -> tuple[dict, bytes]:
    """``(manifest, data)``: the JSON-able description of ``scene`` (see the module docstring) and its arrays."""
    pack = _Packer()
    b = scene.body
    body = {
        "numVerts": int(b.rest_verts.shape[0]),
        "influences": int(b.skin_index.shape[1]),
        "parents": [int(p) for p in b.parents],
        "restVerts": pack.add(b.rest_verts, "float32"),
        "restJoints": pack.add(b.rest_joints, "float32"),
        "faces": pack.add(b.faces, "uint32"),
        "skinIndex": pack.add(b.skin_index, "uint32"),
        "skinWeight": pack.add(b.skin_weight, "float32"),
    }
    motions = [{"name": m.name, "source": m.source, "numFrames": int(m.rotations.shape[0]),
                "rotations": pack.add(m.rotations, "float32"), "translation": pack.add(m.translation, "float32")}
               for m in scene.motions]
    manifest = {
        "format": "loosefit-live/1",
        "fps": scene.fps,
        "model": "live/model.onnx",
        "data": "live/data.bin",
        "metadata": scene.metadata,
        "body": body,
        "motions": motions,
        "buffers": pack.buffers,
        "byteLength": pack.offset,
    }
    return manifest, b"".join(pack.parts)


def serve_live_scene(server, scene: LiveScene) -> None:
    """Add the scene's files to a :class:`~loosefit.viz.viewer.ViewerServer` (served from then on)."""
    manifest, data = pack_live_scene(scene)
    server.files["/live/manifest.json"] = (json.dumps(manifest, separators=(",", ":")).encode(),
                                           "application/json")
    server.files["/live/data.bin"] = (data, "application/octet-stream")
    server.files["/live/model.onnx"] = (scene.model, "application/octet-stream")


def view_live(run: str | Path | None, motions=(), port: int = 8000, serve: bool = True, body=None,
              kinds=DEFAULT_KINDS, seconds: float = DEFAULT_SECONDS, model_path: str | Path | None = None,
              checkpoint: str = "best", joint_map=None, keep_first_frame: bool = False):
    """``loosefit view --live RUN [--motion FILE ...] [--port P]``: serve the live page on
    ``http://127.0.0.1:P/live.html`` until interrupted; ``serve=False``: start the server in the background and
    return it (close it when done)."""
    from loosefit.viz.viewer import ViewerServer

    server = ViewerServer(None, port=port)  # a port in use fails before the export
    try:
        scene = build_live_scene(run, motions, body, kinds, seconds, model_path, checkpoint, joint_map,
                                 keep_first_frame)
    except BaseException:
        server.httpd.server_close()
        raise
    serve_live_scene(server, scene)
    if not serve:
        return server.start()
    print(f"loosefit view: {scene.metadata.get('method', 'garment')} live on {server.url}live.html, "
          f"{len(scene.motions)} motions (Ctrl-C to stop)", file=sys.stdout, flush=True)
    server.serve_forever()
    return server


def view_live_command(args) -> None:
    """The CLI's ``loosefit view --live``: exactly one input, the run folder (or an exported ``.onnx``)."""
    if len(args.input) != 1:
        raise InputError(f"--live takes one run folder (or an exported .onnx), got {len(args.input)} inputs")
    spec = Path(args.input[0])
    is_model = spec.suffix.lower() == ".onnx"
    if not is_model and not (spec.is_dir() or str(spec).startswith("pretrained:")):
        raise InputError("no such run folder", spec)
    view_live(None if is_model else args.input[0], motions=args.motion, port=args.port,
              model_path=spec if is_model else None, joint_map=args.joint_map,
              keep_first_frame=args.keep_first_frame)
