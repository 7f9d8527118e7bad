"""The viewer's HTTP server against raw requests on real sockets: malformed and hostile requests get a
status line and no traceback, and the page is still served afterwards."""

from __future__ import annotations

import socket
import struct
import threading
import time

import numpy as np
import pytest

from loosefit.viz.viewer import STATIC_DIR, ViewerServer, host_name
from loosefit.viz.viewer_scene import ViewerPanel, ViewerScene, ViewerTrack

T, V = 40, 20000  # 9.6 MB of vertices: larger than the socket buffers, so a client that leaves breaks the answer


@pytest.fixture(scope="module")
def scene() -> ViewerScene:
    rng = np.random.default_rng(0)
    verts = rng.normal(size=(T, V, 3)).astype(np.float32)
    faces = np.arange(3 * (V // 3)).reshape(-1, 3)
    track = ViewerTrack("garment", verts, faces, (0.5, 0.5, 0.5))
    return ViewerScene([ViewerPanel("noise", "memory", [track])], 30.0, T, (0.0, 1.0),
                       np.zeros((256, 3), np.uint8))


def exchange(port: int, data: bytes) -> bytes:
    """Send ``data`` on a new connection and read the answer until the server closes it."""
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(data)
        chunks = []
        while chunk := s.recv(1 << 16):
            chunks.append(chunk)
    return b"".join(chunks)


def get(port: int, path: str, host: str = "127.0.0.1") -> bytes:
    return exchange(port, f"GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode())


def status(answer: bytes) -> int:
    line = answer.split(b"\r\n", 1)[0].split()
    assert line and line[0].startswith(b"HTTP/1."), answer[:200]
    return int(line[1])


def body(answer: bytes) -> bytes:
    return answer.split(b"\r\n\r\n", 1)[1]


def wait_for_handlers(timeout: float = 10.0) -> None:
    """Until every request-handling thread has ended (so that all they print has been printed)."""
    end = time.monotonic() + timeout
    while any("process_request" in t.name for t in threading.enumerate()):
        assert time.monotonic() < end, "request handlers still running"
        time.sleep(0.02)


@pytest.fixture
def server(scene, capfd):
    with ViewerServer(scene, port=0) as s:
        assert status(get(s.port, "/")) == 200
        yield s
        wait_for_handlers()
        # the page and its data are still served after whatever the test sent
        index = get(s.port, "/")
        assert status(index) == 200 and body(index) == (STATIC_DIR / "index.html").read_bytes()
        manifest = get(s.port, "/data/manifest.js")
        assert status(manifest) == 200 and body(manifest).startswith(b"window.LOOSEFIT_MANIFEST = ")
        wait_for_handlers()
    out, err = capfd.readouterr()
    assert err == "" and "Traceback" not in out, err


@pytest.mark.parametrize("request_line, code", [
    (b"garbage", 400),
    (b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03", 400),  # a TLS hello on the plain port
    (b"GET / HTTP/1.x", 400),
    (b"GET / FTP/1.1", 400),
    (b"GET / HTTP/2.0", 505),
    (b"GET / HTTP/3.0", 505),
    (b"GET /" + b"a" * 70_000 + b" HTTP/1.1", 414),
])
def test_malformed_request_lines_get_a_status_line(server, request_line, code):
    answer = exchange(server.port, request_line + b"\r\nHost: 127.0.0.1\r\n\r\n")
    assert status(answer) == code


@pytest.mark.parametrize("path", ["/%00", "/index.html%00", "/%00/../index.html", "/vendor/%00three.min.js",
                                  "/data/%00", "/%ed%a0%80"])
def test_nul_bytes_and_bad_names_in_the_path_are_no_file(server, path):
    assert status(get(server.port, path)) == 404


def test_no_directory_listing(server):
    listing = get(server.port, "/vendor/")
    assert status(listing) == 404 and b"three.min.js" not in listing
    assert status(get(server.port, "/vendor")) == 301  # the base class's redirect to "/vendor/", then 404
    assert status(get(server.port, "/vendor/three.min.js")) == 200
    assert (STATIC_DIR.parent / "viewer.py").is_file()
    for path in ("/../viewer.py", "/%2e%2e/viewer.py", "/vendor/../../viewer.py"):  # no way out of static/
        assert status(get(server.port, path)) == 404


@pytest.mark.parametrize("host, code", [
    ("127.0.0.1", 200), ("localhost", 200), ("[::1]", 200), ("LocalHost", 200),
    ("evil.example", 403), ("127.0.0.1.evil.example", 403), ("localhost.evil.example", 403),
    ("[::2]", 403), ("", 403),
])
def test_only_local_host_names_are_answered(server, host, code):
    for name in (host, f"{host}:{server.port}") if host else ("",):  # with and without the port
        for path in ("/", "/data/manifest.js", "/data/scene.bin"):
            answer = exchange(server.port, f"GET {path} HTTP/1.1\r\nHost: {name}\r\nConnection: close\r\n\r\n".encode())
            assert status(answer) == code, (name, path)
            if code == 403:
                assert b"LOOSEFIT" not in answer and len(answer) < 2000


def test_a_request_without_host(server):
    assert status(exchange(server.port, b"GET / HTTP/1.1\r\nConnection: close\r\n\r\n")) == 400
    assert status(exchange(server.port, b"GET / HTTP/1.0\r\n\r\n")) == 200  # HTTP/1.0 has no Host header


def test_clients_that_leave_mid_answer_print_nothing(server):
    assert len(server._files["/data/scene.bin"][0]) > 8 << 20
    for _ in range(20):
        s = socket.create_connection(("127.0.0.1", server.port), timeout=10)
        s.sendall(f"GET /data/scene.bin HTTP/1.1\r\nHost: localhost:{server.port}\r\n\r\n".encode())
        assert s.recv(4096).startswith(b"HTTP/1.0 200")
        s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))  # close with a reset
        s.close()
    for _ in range(5):  # connections that send nothing, or half a request
        with socket.create_connection(("127.0.0.1", server.port), timeout=10) as s:
            s.sendall(b"GET /index.html HT")


def test_host_name():
    assert host_name("LOCALHOST:8000") == "localhost"
    assert host_name("[::1]:8000") == "[::1]" and host_name("[::1]") == "[::1]"
    assert host_name("127.0.0.1") == "127.0.0.1" and host_name(" evil.example:1 ") == "evil.example"
