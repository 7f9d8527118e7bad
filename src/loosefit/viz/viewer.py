"""``loosefit view``: a browser viewer of body and garment sequences, served on localhost or exported as
static files.

The page (``viz/static/``: ``index.html``, ``viewer.js``, ``viewer.css`` and the pinned three.js and uPlot
builds in ``vendor/``) plays every panel of a :class:`~loosefit.viz.viewer_scene.ViewerScene` side by side.
Its data is two things:

- ``data/manifest.js``: a classic script setting ``window.LOOSEFIT_MANIFEST`` (titles, fps, per-frame
  metrics, the heat map's range and colour table, and where each array lies in the binary data);
- the binary data: every array as raw little-endian ``float32`` (vertices ``(T, V, 3)`` metres, errors
  ``(T, V)`` mm) or ``uint32`` (faces ``(F, 3)``), back to back at 4-byte aligned offsets. The server sends it
  as ``data/scene.bin`` (fetched as an ArrayBuffer); an export splits it into ``data/chunk-NNN.js`` scripts
  of base64 text, because Chromium refuses ``fetch`` and ES-module imports on pages opened from disk
  (``file://``) but runs classic scripts.

Identical arrays (a body shared by the simulation and its predictions) are stored once.

The server (:class:`ViewerServer`) answers only requests addressed to this machine by name
(:data:`LOOPBACK_HOSTS`: another site's page cannot read the scene through DNS rebinding), lists no
folders, and answers a malformed request with its status (400, 414, 431, 505) rather than a traceback;
a browser that drops a connection mid-answer is not an error.
"""

from __future__ import annotations

import base64
import errno
import functools
import hashlib
import json
import shutil
import sys
import threading
from http import HTTPStatus
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from loosefit.errors import InputError
from loosefit.paths import atomic_path
from loosefit.viz.viewer_scene import DEFAULT_COLLISION_FRAMES, ViewerScene, build_scene

STATIC_DIR = Path(__file__).with_name("static")
#: Raw bytes per ``data/chunk-NNN.js`` of an export.
CHUNK_BYTES = 8 << 20
#: Static files of the live page only (``loosefit view --live``, served, never exported): the page and onnxruntime-web.
LIVE_ONLY = ("live.html", "live.js", "live.css", "vendor/ort")
#: Marker file of an export folder (so that a re-export may replace it, and nothing else is overwritten).
EXPORT_MARKER = ".loosefit-view"


def pack_scene(scene: ViewerScene) -> tuple[dict, bytes]:
    """``(manifest, data)``: the JSON-able description of ``scene`` and its arrays as one byte string.

    Each buffer entry of ``manifest["buffers"]`` is ``{"offset", "bytes", "dtype", "shape"}`` (offsets in
    bytes, multiples of 4); tracks refer to buffers by index.
    """
    parts: list[bytes] = []
    buffers: list[dict] = []
    seen: dict[tuple, int] = {}
    offset = 0

    def add(array: np.ndarray, dtype: str) -> int:
        nonlocal offset
        a = np.ascontiguousarray(array, dtype=np.dtype(dtype).newbyteorder("<"))
        raw = a.tobytes()
        key = (dtype, a.shape, hashlib.sha1(raw).hexdigest())
        if key in seen:
            return seen[key]
        buffers.append({"offset": offset, "bytes": len(raw), "dtype": dtype, "shape": list(a.shape)})
        parts.append(raw)
        offset += len(raw)
        seen[key] = len(buffers) - 1
        return seen[key]

    panels = []
    for panel in scene.panels:
        tracks = []
        for t in panel.tracks:
            tracks.append({
                "role": t.role,
                "color": list(t.color),
                "numFrames": int(t.verts.shape[0]),
                "numVerts": int(t.verts.shape[1]),
                "verts": add(t.verts, "float32"),
                "faces": add(t.faces, "uint32"),
                "errors": None if t.errors is None else add(t.errors, "float32"),
                # frames with an error (the reference's too): the page shows the heat map only there
                "errorFrames": 0 if t.errors is None else int(t.errors.shape[0]),
            })
        metrics = {k: [None if not np.isfinite(x) else float(x) for x in v] for k, v in panel.metrics.items()}
        panels.append({"title": panel.title, "source": panel.source, "tracks": tracks, "metrics": metrics})
    manifest = {
        "format": "loosefit-view/1",
        "fps": float(scene.fps),
        "numFrames": int(scene.num_frames),
        "errorRange": [float(scene.error_range[0]), float(scene.error_range[1])],
        "errorMax": float(scene.error_max),
        "colormap": scene.colormap.reshape(-1).tolist(),
        "panels": panels,
        "buffers": buffers,
        "byteLength": offset,
    }
    return manifest, b"".join(parts)


def manifest_script(manifest: dict) -> bytes:
    """``data/manifest.js``: a classic script that sets ``window.LOOSEFIT_MANIFEST``."""
    return ("window.LOOSEFIT_MANIFEST = " + json.dumps(manifest, separators=(",", ":")) + ";\n").encode()


#: Host header names the server answers besides its own address: a page of another site that points its
#: own name at 127.0.0.1 (DNS rebinding) sends that name and gets 403, so it cannot read the scene.
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "[::1]")


def host_name(header: str) -> str:
    """The host of a ``Host`` header without its port, lower case: ``"[::1]:8000"`` -> ``"[::1]"``."""
    host = header.strip().lower()
    if host.startswith("["):
        return host[: host.find("]") + 1] if "]" in host else host
    return host.rsplit(":", 1)[0] if ":" in host else host


class _Handler(SimpleHTTPRequestHandler):
    """Static files from ``viz/static`` plus the scene's ``data/manifest.js`` and ``data/scene.bin`` from memory.

    Only ``GET`` and ``HEAD`` of files: no directory listings (404), a path with a NUL byte is no file
    (404), and a request whose ``Host`` is not one of ``hosts`` gets 403. Malformed requests get the base
    class's 400 / 414 / 431 / 505 answers.
    """

    # The base class answers a request line it cannot parse (or of HTTP/2) as HTTP/0.9 would: a body without
    # a status line. HTTP/1.0 gives every error answer its status line.
    default_request_version = "HTTP/1.0"
    # the live page's ES modules and onnxruntime's WebAssembly, whatever the system's MIME table says
    extensions_map = {**SimpleHTTPRequestHandler.extensions_map, ".mjs": "text/javascript",
                      ".wasm": "application/wasm"}

    def __init__(self, *args, files: dict[str, tuple[bytes, str]], hosts: frozenset[str], **kwargs):
        self._files = files
        self._hosts = hosts
        super().__init__(*args, directory=str(STATIC_DIR), **kwargs)

    def _host_allowed(self) -> bool:
        host = self.headers.get("Host")
        if host is None:  # HTTP/1.0 clients may send none (browsers always do); HTTP/1.1 requires one
            if self.request_version != "HTTP/1.1":
                return True
            self.send_error(HTTPStatus.BAD_REQUEST, "Missing Host header")
            return False
        if host_name(host) not in self._hosts:
            self.send_error(HTTPStatus.FORBIDDEN, "Host not allowed",
                            "This viewer answers only requests addressed to this machine (localhost).")
            return False
        return True

    def do_GET(self):
        if self._host_allowed():
            self._get()

    def do_HEAD(self):
        if self._host_allowed():
            super().do_HEAD()

    def _get(self):
        path = self.path.split("?", 1)[0]
        if path in self._files:
            body, ctype = self._files[path]
            self.send_response(200)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)
            return
        super().do_GET()

    def send_head(self):
        try:
            if "\x00" not in unquote(self.path.split("?", 1)[0]):  # no file name holds a NUL byte
                return super().send_head()
        except ValueError:  # an unencodable name: os refuses it, so no such file
            pass
        self.send_error(HTTPStatus.NOT_FOUND, "File not found")
        return None

    def list_directory(self, path):
        self.send_error(HTTPStatus.NOT_FOUND, "File not found")
        return None

    def end_headers(self):
        # error answers to a malformed request line come before the path is parsed
        if not getattr(self, "path", "").startswith("/data/"):
            self.send_header("Cache-Control", "no-cache")
        super().end_headers()

    def log_message(self, format, *args):  # noqa: A002 - the base class's name
        pass


class _Server(ThreadingHTTPServer):
    daemon_threads = True

    def handle_error(self, request, client_address):
        """A browser that closes its connection mid-answer (a reload, a closed tab) is normal: say nothing.
        Anything else: one line on stderr, not a traceback."""
        error = sys.exc_info()[1]
        if isinstance(error, (ConnectionError, TimeoutError)):
            return
        print(f"loosefit view: error answering {client_address[0]}: {type(error).__name__}: {error}",
              file=sys.stderr, flush=True)


class ViewerServer:
    """The page and one scene served on ``http://host:port/`` by a threaded ``http.server``.

    Args:
        scene: what to show; None: nothing until :meth:`show` (the port is taken at once either way).
        port: TCP port; 0 picks a free one (see :attr:`url`).
        host: the address to listen on (default: this machine only).
        allowed_hosts: the ``Host`` header names (without port) answered; the others get 403. Default:
            :data:`LOOPBACK_HOSTS` and ``host``.

    Raises:
        InputError: the port is in use (or cannot be opened).
    """

    def __init__(self, scene: ViewerScene | None, port: int = 8000, host: str = "127.0.0.1",
                 allowed_hosts: tuple[str, ...] | None = None):
        #: What is served from memory besides the static files: ``{path: (body, content type)}``.
        self.files: dict[str, tuple[bytes, str]] = {}
        self._files = self.files
        if allowed_hosts is None:
            allowed_hosts = LOOPBACK_HOSTS + (f"[{host}]" if ":" in host else host,)
        hosts = frozenset(h.lower() for h in allowed_hosts)
        try:
            self.httpd = _Server((host, port), functools.partial(_Handler, files=self._files, hosts=hosts))
        except OSError as e:
            if e.errno == errno.EADDRINUSE:
                raise InputError(f"port {port} on {host} is in use: choose another with --port "
                                 f"(or stop what listens there)") from None
            raise InputError(f"cannot listen on {host}:{port}: {e.strerror or e}") from None
        self.host, self.port = host, self.httpd.server_address[1]
        self._thread: threading.Thread | None = None
        if scene is not None:
            self.show(scene)

    def show(self, scene: ViewerScene) -> None:
        """Serve ``scene`` (a page loaded afterwards shows it)."""
        manifest, data = pack_scene(scene)
        manifest["data"] = {"binary": "data/scene.bin"}
        self._files["/data/manifest.js"] = (manifest_script(manifest), "text/javascript; charset=utf-8")
        self._files["/data/scene.bin"] = (data, "application/octet-stream")

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    def start(self) -> "ViewerServer":
        """Serve in a background thread and return at once."""
        self._thread = threading.Thread(target=self.httpd.serve_forever, name="loosefit-view", daemon=True)
        self._thread.start()
        return self

    def serve_forever(self) -> None:
        """Serve until interrupted (Ctrl-C)."""
        try:
            self.httpd.serve_forever()
        except KeyboardInterrupt:
            pass
        finally:
            self.httpd.server_close()

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
        if self._thread is not None:
            self._thread.join()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.close()


def export_scene(scene: ViewerScene, out_dir: str | Path) -> Path:
    """Write the page and ``scene`` as static files under ``out_dir``; open ``out_dir/index.html`` from disk
    or put the folder on any web server. Returns the path of ``index.html``.

    Raises:
        InputError: ``out_dir`` is a file, or a non-empty folder that is not an earlier export (nothing in
            it is touched).
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError("the export folder is a file", out)
    if out.is_dir() and any(out.iterdir()) and not (out / EXPORT_MARKER).is_file():
        raise InputError("the export folder is not empty and not an earlier `loosefit view --export`: "
                         "give a new or empty folder", out)
    manifest, data = pack_scene(scene)
    chunks = [data[i: i + CHUNK_BYTES] for i in range(0, len(data), CHUNK_BYTES)]
    manifest["data"] = {"chunks": len(chunks)}
    out.mkdir(parents=True, exist_ok=True)
    (out / EXPORT_MARKER).write_text("written by loosefit view --export\n")
    for src in sorted(STATIC_DIR.rglob("*")):
        if src.is_file() and not src.relative_to(STATIC_DIR).as_posix().startswith(LIVE_ONLY):
            dst = out / src.relative_to(STATIC_DIR)
            dst.parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(dst, suffix=dst.suffix) as tmp:
                shutil.copyfile(src, tmp)
    data_dir = out / "data"
    if data_dir.is_dir():
        shutil.rmtree(data_dir)
    data_dir.mkdir()
    for i, chunk in enumerate(chunks):
        text = f"LOOSEFIT_CHUNKS[{i}] = \"{base64.b64encode(chunk).decode()}\";\n"
        (data_dir / f"chunk-{i:03d}.js").write_text(text)
    (data_dir / "manifest.js").write_bytes(manifest_script(manifest))
    return out / "index.html"


def print_warnings(scene: ViewerScene) -> None:
    """Each panel's warnings, one stderr line each (``loosefit view: warning: ...``)."""
    for panel in scene.panels:
        for line in panel.warnings:
            print(f"loosefit view: warning: {line}", file=sys.stderr, flush=True)


def view(inputs: list[str], port: int = 8000, export: str | Path | None = None, body=None,
         collisions: bool = True, collision_frames: int = DEFAULT_COLLISION_FRAMES, serve: bool = True,
         handling: str = "exact", joint_map=None, keep_first_frame: bool = False,
         reference: bool = True):
    """``loosefit view INPUT... [--port P] [--export DIR] [--no-reference]``: export the page to ``DIR``, or serve
    it on ``http://127.0.0.1:P/`` until interrupted. Returns the index path (export) or the server
    (``serve=False``: started in the background; close it when done). ``handling``: the runs' collision handling
    (exact, pushout or none); ``joint_map``: the joint map of their BVH motions; ``keep_first_frame``: keep a far
    first frame of their motion files (:func:`loosefit.motion.io.load_motion`); ``reference``: the first input is
    the simulation the others are compared with (``False``: animations, each by itself)."""
    if export is not None:
        scene = build_scene(list(inputs), body=body, collisions=collisions, collision_frames=collision_frames,
                            handling=handling, joint_map=joint_map, keep_first_frame=keep_first_frame,
                            reference=reference)
        print_warnings(scene)
        return export_scene(scene, export)
    server = ViewerServer(None, port=port)  # a port in use fails before the inputs are loaded
    try:
        scene = build_scene(list(inputs), body=body, collisions=collisions, collision_frames=collision_frames,
                            handling=handling, joint_map=joint_map, keep_first_frame=keep_first_frame,
                            reference=reference)
    except BaseException:
        server.httpd.server_close()
        raise
    print_warnings(scene)
    server.show(scene)
    if not serve:
        return server.start()
    print(f"loosefit view: serving {len(scene.panels)} panel(s), {scene.num_frames} frames on {server.url} "
          f"(Ctrl-C to stop)", flush=True)
    server.serve_forever()
    return server
