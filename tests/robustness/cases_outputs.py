"""Cases of the verbs that run a trained model or read mesh sequences and write results: ``animate``,
``export-rig``, ``export-onnx``, ``quantize``, ``evaluate``, ``render``, ``report``, ``view`` (and raw requests to its server),
``demo`` and the command line itself."""

from __future__ import annotations

import numpy as np

from tests.robustness import craft
from tests.robustness.cases_files import PROC, motion_edit, parent_file
from tests.robustness.cases_pipeline import store_copy, truncated
from tests.robustness.harness import Case
from tests.robustness.kit import also, bad, both, ext, no_warning, ok, wrote
from tests.robustness.live import Request, server_runner

#: The test sequence of the shared store (tests/conftest.py's TINY_PLAN).
TEST_SEQ = "skirt+average+sway+default"
LIFTED = motion_edit("up.npz", translation=lambda x: x + np.array([0.0, 0.0, 1.0]))


def seq_edit(name: str = "pred.npz", frames: int | None = None, **changes):
    """A copy of the shared mesh sequence (first ``frames`` frames), arrays changed as in :func:`craft.npz_edit`."""
    def setup(tmp, sh):
        arrays = craft.npz_arrays(sh.seq)
        T = arrays["verts"].shape[0]
        if frames is not None:
            arrays = {k: v[:frames] if v.ndim >= 1 and v.shape[0] == T and "verts" in k else v for k, v in arrays.items()}
        np.savez(tmp / name, **arrays)
        craft.npz_edit(tmp / name, tmp / name, **changes)
    return setup


def run_edit(edit):
    """A copy of the shared run as ``{tmp}/run``, ``edit(run)`` applied."""
    return lambda t, s: edit(craft.copy_run(s, t))


def animate_cases() -> list[Case]:
    a = ["animate", "{run}", "--motion", "{tmp}/m.npz", "--out", "{tmp}/a.npz"]
    mine = ["animate", "{tmp}/run", "--motion", "{motion}", "--out", "{tmp}/a.npz"]
    m = motion_edit()
    return [
        ok("animate/npz", a, m, check=wrote("{tmp}/a.npz")),
        ok("animate/training-motion-no-warning", a, m, check=both(wrote("{tmp}/a.npz"), no_warning)),
        bad("animate/root-lifted-1m", ["animate", "{run}", "--motion", "{tmp}/up.npz", "--out", "{tmp}/a.npz"], LIFTED,
            brief="viewer", defect=True, report=("root height",)),
        bad("animate/motion-truncated", a, also(m, lambda t, s: craft.truncate(t / "m.npz")), brief="inputs",
            defect=True, names=("m.npz",), absent=("{tmp}/a.npz",)),
        bad("animate/motion-flipped-byte", a, also(m, lambda t, s: craft.flip_byte(t / "m.npz")), brief="inputs",
            names=("m.npz",), absent=("{tmp}/a.npz",)),
        ext("animate/motion-nan-rotations", a, motion_edit(rotations=lambda r: r * np.nan), names=("m.npz",),
            absent=("{tmp}/a.npz",)),
        ext("animate/motion-inf-translation", a, motion_edit(translation=lambda x: x + np.inf), names=("m.npz",),
            absent=("{tmp}/a.npz",)),
        bad("animate/motion-wrong-joint-count", a, motion_edit(rotations=lambda r: r[:, :24]), names=("m.npz",)),
        bad("animate/run-missing", ["animate", "{tmp}/none", "--motion", "{motion}", "--out", "{tmp}/a.npz"],
            names=("none",)),
        bad("animate/model-json-truncated", mine, run_edit(lambda r: craft.truncate(r / "model.json")),
            names=("model.json",)),
        bad("animate/model-json-unknown-method", mine, run_edit(lambda r: craft.write(
            r / "model.json", (r / "model.json").read_text().replace('"virtualbones"', '"vbones"'))), names=("model.json",)),
        bad("animate/method-yaml-garbage", mine, run_edit(lambda r: craft.write(r / "method.yaml", "model: [\n")),
            names=("method.yaml",)),
        bad("animate/checkpoint-truncated", mine, run_edit(lambda r: craft.truncate(r / "checkpoints" / "last.pt")),
            names=("last.pt",)),
        bad("animate/checkpoint-garbage", mine, run_edit(lambda r: craft.garbage(r / "checkpoints" / "last.pt")),
            names=("last.pt",)),
        bad("animate/checkpoint-payload", ["animate", "{run}", "--motion", "{motion}", "--out", "{tmp}/a.npz",
                                           "--checkpoint", "{tmp}/evil.pt"], lambda t, s: craft.pt_payload(t / "evil.pt", t),
            brief="inputs", names=("evil.pt",)),
        bad("animate/checkpoint-missing", a + ["--checkpoint", "{tmp}/none.pt"], m, names=("none.pt",)),
        bad("animate/threads-negative", a + ["--threads", "-1"], m, brief="inputs", defect=True, names=("--threads",)),
        bad("animate/threads-zero", a + ["--threads", "0"], m, brief="inputs", names=("--threads",)),
        bad("animate/out-in-proc", a[:-1] + [PROC + ".npz"], m, brief="inputs", defect=True, names=("/proc",)),
        bad("animate/out-parent-is-file", a[:-1] + ["{tmp}/file/a.npz"], also(m, parent_file), brief="inputs",
            defect=True, names=("file/a.npz",)),
        bad("animate/out-unsupported", a[:-1] + ["{tmp}/a.xyz"], m, names=("a.xyz",), absent=("{tmp}/a.xyz",)),
        bad("animate/collision-unknown", a + ["--collision", "sideways"], m, names=("sideways",)),
        bad("animate/collision-margin-not-a-number", a + ["--collision", "{tmp}/sdf", "--collision-margin", "wide"], m,
            names=("wide", "margin", "sdf")),
        bad("animate/garment-for-one-garment-run", a + ["--garment", "{garment}"], m, names=("garment",)),
        # export-rig
        ok("export-rig/glb", ["export-rig", "{run}", "--motion", "{motion}", "--out", "{tmp}/r.glb"],
           check=wrote("{tmp}/r.glb"), cost=2),
        bad("export-rig/out-unsupported", ["export-rig", "{run}", "--motion", "{motion}", "--out", "{tmp}/r.fbx"],
            names=("r.fbx",), absent=("{tmp}/r.fbx",)),
        bad("export-rig/out-in-proc", ["export-rig", "{run}", "--motion", "{motion}", "--out", PROC + ".glb"],
            names=("/proc",)),
        bad("export-rig/out-parent-is-file", ["export-rig", "{run}", "--motion", "{motion}", "--out", "{tmp}/file/r.glb"],
            parent_file, names=("file/r.glb",)),
        bad("export-rig/run-missing", ["export-rig", "{tmp}/none", "--motion", "{motion}", "--out", "{tmp}/r.glb"],
            names=("none",)),
        bad("export-rig/motion-truncated", ["export-rig", "{run}", "--motion", "{tmp}/m.npz", "--out", "{tmp}/r.glb"],
            also(m, lambda t, s: craft.truncate(t / "m.npz")), brief="inputs", names=("m.npz",)),
        ext("export-rig/motion-nan", ["export-rig", "{run}", "--motion", "{tmp}/m.npz", "--out", "{tmp}/r.glb"],
            motion_edit(rotations=lambda r: r * np.nan), names=("m.npz",), absent=("{tmp}/r.glb",)),
        bad("export-rig/threads-negative", ["export-rig", "{run}", "--motion", "{motion}", "--out", "{tmp}/r.glb",
                                            "--threads", "-1"], defect=True, names=("--threads",)),
        bad("export-rig/checkpoint-garbage", ["export-rig", "{tmp}/run", "--motion", "{motion}", "--out", "{tmp}/r.glb"],
            run_edit(lambda r: craft.garbage(r / "checkpoints" / "last.pt")), names=("last.pt",)),
        # export-onnx
        ok("export-onnx/bones", ["export-onnx", "{run}", "--out", "{tmp}/g.onnx", "--bones"], check=wrote("{tmp}/g.onnx"),
           cost=2),
        bad("export-onnx/out-unsupported", ["export-onnx", "{run}", "--out", "{tmp}/g.pb"], names=("g.pb",),
            absent=("{tmp}/g.pb",)),
        bad("export-onnx/out-parent-is-file", ["export-onnx", "{run}", "--out", "{tmp}/file/g.onnx"], parent_file,
            names=("file/g.onnx",)),
        bad("export-onnx/run-missing", ["export-onnx", "{tmp}/none", "--out", "{tmp}/g.onnx"], names=("none",),
            absent=("{tmp}/g.onnx",)),
        bad("export-onnx/checkpoint-garbage", ["export-onnx", "{tmp}/run", "--out", "{tmp}/g.onnx"],
            run_edit(lambda r: craft.garbage(r / "checkpoints" / "last.pt")), names=("last.pt",), absent=("{tmp}/g.onnx",)),
        # quantize
        ok("quantize/copy", ["quantize", "{run}", "--out", "{tmp}/q"], check=wrote("{tmp}/q/model.json"), cost=2),
        bad("quantize/out-not-empty", ["quantize", "{run}", "--out", "{tmp}/full"],
            lambda t, s: craft.write(t / "full" / "mine.txt", "a user's file\n"), names=("full",)),
        bad("quantize/run-missing", ["quantize", "{tmp}/none", "--out", "{tmp}/q"], names=("none",), absent=("{tmp}/q",)),
        bad("quantize/checkpoint-garbage", ["quantize", "{tmp}/run", "--out", "{tmp}/q"],
            run_edit(lambda r: craft.garbage(r / "checkpoints" / "last.pt")), names=("last.pt",), absent=("{tmp}/q",)),
    ]


def evaluate_cases() -> list[Case]:
    e = ["evaluate", "{tmp}/pred.npz", "{seq}", "--out", "{tmp}/m"]
    shifted = seq_edit(verts=lambda v: v + np.float32(0.01))
    return [
        ok("evaluate/pair", e, shifted, check=wrote("{tmp}/m/metrics.json")),
        bad("evaluate/negative-fps", e, seq_edit(fps=np.float64(-30)), brief="inputs", defect=True,
            names=("pred.npz", "fps")),
        bad("evaluate/fps-mismatch", e, seq_edit(fps=np.float64(60)), brief="inputs", defect=True, names=("fps",)),
        bad("evaluate/zero-fps", e, seq_edit(fps=np.float64(0)), brief="inputs", names=("pred.npz", "fps")),
        bad("evaluate/vertex-count-mismatch", e, seq_edit(verts=lambda v: v[:, :-5]), names=("pred.npz", "vert")),
        bad("evaluate/frame-count-mismatch", e, seq_edit(verts=lambda v: v[:-5]), names=("pred.npz", "frame")),
        bad("evaluate/faces-mismatch", e, seq_edit(faces=lambda f: f[:, ::-1].copy()), names=("pred.npz", "faces")),
        ext("evaluate/nan-prediction", e, seq_edit(verts=lambda v: v * np.nan), names=("pred.npz",)),
        bad("evaluate/prediction-truncated", e, also(shifted, lambda t, s: craft.truncate(t / "pred.npz")),
            brief="inputs", defect=True, names=("pred.npz",)),
        bad("evaluate/ground-truth-flipped-byte", ["evaluate", "{tmp}/pred.npz", "{tmp}/gt.npz", "--out", "{tmp}/m"],
            also(shifted, seq_edit("gt.npz"), lambda t, s: craft.flip_byte(t / "gt.npz", 0.3)), brief="inputs",
            defect=True, names=("gt.npz",)),
        bad("evaluate/out-in-proc", e[:-1] + [PROC], shifted, brief="inputs", names=("/proc",)),
        bad("evaluate/out-is-a-file", e[:-1] + ["{tmp}/notes"], also(shifted, lambda t, s: craft.write(t / "notes", "x")),
            brief="inputs", defect=True, names=("notes",), keep=("{tmp}/notes",)),
        bad("evaluate/sted-rings-negative", e + ["--sted-rings", "-1"], shifted, names=("rings",)),
        bad("evaluate/tolerance-negative", e + ["--tolerance", "-1"], shifted, names=("tolerance",)),
        bad("evaluate/store-unknown-sequence", ["evaluate", "{tmp}", "{store}", "--sequence", "nope", "--out", "{tmp}/m"],
            names=("nope",)),
        bad("evaluate/store-unknown-split", ["evaluate", "{tmp}", "{store}", "--split", "holdout", "--out", "{tmp}/m"],
            names=("holdout", "split")),
        bad("evaluate/empty-prediction-folder", ["evaluate", "{tmp}/preds", "{seq}", "--out", "{tmp}/m"],
            lambda t, s: (t / "preds").mkdir(), names=("preds",)),
    ]


def render_cases() -> list[Case]:
    small = seq_edit("s.npz", frames=3)
    r = ["render", "{tmp}/s.npz", "--width", "64", "--height", "48", "--backend", "matplotlib", "--out"]
    return [
        ok("render/gif", r + ["{tmp}/x.gif"], small, check=wrote("{tmp}/x.gif")),
        bad("render/png-of-many-frames", r + ["{tmp}/x.png"], small, names=("x.png", "frame")),
        bad("render/unsupported-output", r + ["{tmp}/x.txt"], small, names=("x.txt",), absent=("{tmp}/x.txt",)),
        bad("render/fps-zero", r + ["{tmp}/x.gif", "--fps", "0"], small, names=("fps",)),
        bad("render/fps-negative", r + ["{tmp}/x.gif", "--fps", "-5"], small, names=("fps",)),
        bad("render/width-zero", r + ["{tmp}/x.gif", "--width", "0"], small, names=("width",)),
        bad("render/height-negative", r + ["{tmp}/x.gif", "--height", "-10"], small, names=("height",)),
        bad("render/out-in-proc", r + [PROC + ".gif"], small, brief="inputs", defect=True, names=("/proc",)),
        bad("render/out-parent-is-file", r + ["{tmp}/file/x.gif"], also(small, parent_file), brief="inputs", defect=True,
            names=("file/x.gif",)),
        bad("render/input-truncated", r + ["{tmp}/x.gif"], also(small, lambda t, s: craft.truncate(t / "s.npz")),
            brief="inputs", names=("s.npz",)),
        bad("render/input-flipped-byte", r + ["{tmp}/x.gif"], also(small, lambda t, s: craft.flip_byte(t / "s.npz", 0.3)),
            brief="inputs", names=("s.npz",)),
        ext("render/nan-vertices", r + ["{tmp}/x.gif"], seq_edit("s.npz", frames=3, verts=lambda v: v * np.nan),
            names=("s.npz",)),
        bad("render/missing-input", ["render", "{tmp}/none.npz", "--out", "{tmp}/x.gif"], names=("none.npz",)),
        bad("render/store-without-sequence", ["render", "{store}", "--out", "{tmp}/x.gif"], names=("sequence",)),
        bad("render/store-unknown-sequence", ["render", "{store}", "--sequence", "nope", "--out", "{tmp}/x.gif"],
            names=("nope",)),
        bad("render/store-truncated-chunk", ["render", "{tmp}/d.zarr", "--sequence", TEST_SEQ, "--out", "{tmp}/x.gif",
                                             "--backend", "matplotlib"], store_copy(truncated, "test"),
            brief="store", names=("d.zarr",), keep=("{tmp}/d.zarr",)),
    ]


def report_cases() -> list[Case]:
    rep = ["report", "{store}", "{run}", "--no-images", "--out"]
    return [
        ok("report/no-images", rep + ["{tmp}/rep"], check=wrote("{tmp}/rep/report.md"), cost=3),
        bad("report/run-missing", ["report", "{store}", "{tmp}/none", "--out", "{tmp}/rep"], names=("none",)),
        bad("report/unknown-split", rep + ["{tmp}/rep", "--split", "holdout"], names=("holdout", "split")),
        bad("report/unknown-sequence", rep + ["{tmp}/rep", "--sequence", "nope"], names=("nope",)),
        bad("report/out-in-proc", rep + [PROC], defect=True, names=("/proc",)),
        bad("report/out-is-a-file", rep + ["{tmp}/notes"], lambda t, s: craft.write(t / "notes", "x"), defect=True,
            names=("notes",), keep=("{tmp}/notes",)),
        bad("report/store-truncated-chunk", ["report", "{tmp}/d.zarr", "{run}", "--no-images", "--out", "{tmp}/rep",
                                             "--split", "train"], store_copy(truncated), brief="store",
            names=("d.zarr",), keep=("{tmp}/d.zarr",), cost=2),
        bad("report/model-json-garbage", ["report", "{store}", "{tmp}/run", "--no-images", "--out", "{tmp}/rep"],
            run_edit(lambda r: craft.write(r / "model.json", "{oops")), names=("model.json",)),
    ]


def _requests() -> list[Request]:
    get = b"GET %s HTTP/1.1\r\nHost: %s\r\nConnection: close\r\n\r\n"
    return [
        Request("view-server/get-index", get % (b"/", b"{host}"), (200,), control=True, defect=False),
        Request("view-server/garbage-request-line", b"HELLO THERE\r\n\r\n", (400,)),
        Request("view-server/bad-http-version", b"GET / HTTP/9.9\r\nHost: {host}\r\n\r\n", (505,)),
        Request("view-server/malformed-http-version", b"GET / FOO/1.0\r\nHost: {host}\r\n\r\n", (400,)),
        Request("view-server/url-over-64k", get % (b"/" + b"a" * 70000, b"{host}"), (414,)),
        Request("view-server/nul-in-path", get % (b"/%00", b"{host}"), (400, 404)),
        Request("view-server/directory-listing", get % (b"/vendor/", b"{host}"), (403, 404)),
        Request("view-server/foreign-host", get % (b"/", b"evil.example"), (403, 421)),
        Request("view-server/foreign-host-with-port", get % (b"/data/manifest.js", b"evil.example:8000"), (403, 421)),
        Request("view-server/client-goes-away", get % (b"/data/scene.bin", b"{host}") * 1, None, abort=True),
        Request("view-server/client-goes-away-again", get % (b"/data/scene.bin", b"{host}"), None, abort=True),
        Request("view-server/path-traversal", get % (b"/../../../../etc/passwd", b"{host}"), (400, 403, 404),
                defect=False),
        Request("view-server/encoded-traversal", get % (b"/%2e%2e/%2e%2e/%2e%2e/etc/passwd", b"{host}"), (400, 403, 404),
                defect=False),
        Request("view-server/header-over-64k", b"GET / HTTP/1.1\r\nHost: {host}\r\nX-Big: " + b"a" * 70000 + b"\r\n\r\n",
                (400, 431), defect=False),
        Request("view-server/post", b"POST / HTTP/1.1\r\nHost: {host}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
                (405, 501), defect=False),
        Request("view-server/empty-connection", b"", None, defect=False),
        Request("view-server/host-localhost", get % (b"/", b"localhost"), (200,), control=True),
        Request("view-server/host-ipv6-loopback", get % (b"/data/manifest.js", b"[::1]:8000"), (200,), control=True),
        Request("view-server/get-index-afterwards", get % (b"/", b"{host}"), (200,), control=True),
    ]


REQUESTS = _requests()


def view_cases() -> list[Case]:
    v = ["view", "--no-collisions", "--export", "{tmp}/page"]
    return [
        ok("view/export", v + ["{seq}"], check=wrote("{tmp}/page/index.html"), cost=2),
        bad("view/port-negative", ["view", "{seq}", "--port", "-1"], brief="inputs", defect=True, names=("--port",)),
        bad("view/port-too-large", ["view", "{seq}", "--port", "70000"], brief="inputs", defect=True, names=("--port",)),
        bad("view/collision-frames-negative", ["view", "{seq}", "--collision-frames", "-1", "--export", "{tmp}/page"],
            brief="inputs", defect=True, names=("--collision-frames",), absent=("{tmp}/page",)),
        bad("view/missing-input", v + ["{tmp}/none.npz"], names=("none.npz",), absent=("{tmp}/page",)),
        bad("view/truncated-npz", v + ["{tmp}/s.npz"], also(seq_edit("s.npz"), lambda t, s: craft.truncate(t / "s.npz")),
            brief="inputs", defect=True, names=("s.npz",), absent=("{tmp}/page",)),
        bad("view/store-unknown-sequence", v + ["{store}:nope"], names=("nope",), absent=("{tmp}/page",)),
        bad("view/store-truncated-chunk", v + ["{tmp}/d.zarr:" + TEST_SEQ], store_copy(truncated, "test"),
            brief="store", defect=True, names=("d.zarr",), keep=("{tmp}/d.zarr",), absent=("{tmp}/page",)),
        bad("view/export-is-a-file", ["view", "--no-collisions", "--export", "{tmp}/notes", "{seq}"],
            lambda t, s: craft.write(t / "notes", "x"), names=("notes",), keep=("{tmp}/notes",)),
        bad("view/export-in-proc", ["view", "--no-collisions", "--export", PROC, "{seq}"], brief="inputs",
            names=("/proc",)),
        bad("view/export-into-other-folder", ["view", "--no-collisions", "--export", "{tmp}/mine", "{seq}"],
            lambda t, s: craft.write(t / "mine" / "thesis.tex", "years of work\n"), names=("mine",), keep=("{tmp}/mine",)),
        bad("view/run-motion-lifted-1m", v + ["{seq}", "{run}:{tmp}/up.npz"], LIFTED, brief="viewer", defect=True,
            report=("root height",), cost=2),
        Case("view-server", setup=None, runner=server_runner(REQUESTS, ["view", "{seq}", "--no-collisions"]),
             results=tuple(r.name for r in REQUESTS), brief="viewer", defect=True, cost=6),
    ]


def other_cases() -> list[Case]:
    return [
        bad("demo/out-in-proc", ["demo", "--out", PROC], defect=True, names=("/proc",), timeout=180),
        bad("demo/out-is-a-file", ["demo", "--out", "{tmp}/notes"], lambda t, s: craft.write(t / "notes", "x"),
            defect=True, names=("notes",), keep=("{tmp}/notes",), timeout=180),
        bad("cli/no-arguments", [], names=("command", "required")),
        bad("cli/unknown-verb", ["simulte"], names=("simulte",)),
        bad("cli/unknown-option", ["info", "{store}", "--bogus"], names=("--bogus",)),
    ]
