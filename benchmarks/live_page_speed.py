"""Frames per second of the live page (``loosefit view --live``) in this machine's headless Chromium: the garment
computed in the page by onnxruntime-web from the exported step model, the body skinned in the page, both drawn by
three.js (software WebGL through SwiftShader, as the viewer tests run it), driven by Playwright.

The garment is the dress of ``configs/datasets/bench.yaml`` (about 4.2k vertices) with an untrained VirtualBones
network at the paper's width (``configs/models/virtualbones.yaml``, built as ``benchmarks/onnx_speed.py`` builds it,
with ``--bones`` stand-in virtual bones): the time per frame does not depend on the weights' values. The paper's
global layer maps the 600 GRU units to 10 channels at every vertex through one dense matrix (600 x 42,090 for this
dress, 101 MB of the model's 115 MB), which every frame reads whole; the same network with that layer factorised
through 64 channels (``model.global_rank=64``, the CPU size of ``benchmarks/_common.py`` and of the shipped skirt)
is measured beside it, and the paper's width with its large matrices in int8 blocks (``export-onnx --int8``,
onnxruntime-web's ``MatMulNBits``). Each run folder is exported as ``loosefit export-onnx`` does and served by the
live server (:func:`loosefit.viz.live.build_live_scene` with the ``.onnx``).

Measured, after ``--warmup`` untimed frames:

- ``stepped``: ``loosefitLive.step(n, true)``, ``--frames`` frames one after another without the animation timer,
  each computed (onnxruntime-web), skinned, given normals and drawn: the page's throughput, timed by the page's
  own clock (``performance.now()``); with the mean milliseconds of inference, body skinning and drawing per frame;
- ``playing``: the page playing on its timer for ``--seconds`` at 1x and at 2x speed: the garment frames and the
  draws per second it reached (1x asks for the motion's 30 frames per second, 2x for 60), as the page shows them.

The target is 30 frames per second (the motion's rate). The machine is shared (2 cores, other jobs): the load
average before and after is recorded.

Run: .venv/bin/python benchmarks/live_page_speed.py [--frames 150] [--warmup 20] [--seconds 6] [--bones 80]
         [--backend wasm] [--viewport 960x640] [--name live-page-speed]
         (writes benchmarks/results/<name>.json)
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import CPU_MODEL, save_results  # noqa: E402
from onnx_speed import paper_model, write_run  # noqa: E402
from speed import bench_dress  # noqa: E402

from loosefit.body import AnnyBody  # noqa: E402
from loosefit.export_onnx import export_onnx  # noqa: E402
from loosefit.viz.live import build_live_scene, serve_live_scene  # noqa: E402
from loosefit.viz.viewer import ViewerServer  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
#: The viewer tests' flags (tests/viz/test_viewer.py): headless, software WebGL.
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run", "--use-gl=swiftshader",
                 "--enable-unsafe-swiftshader"]
TARGET_FPS = 30.0
VIEWPORT = {"width": 960, "height": 640}

STEP_TIMED = """async (n) => {
  const L = window.loosefitLive;
  const t0 = performance.now();
  await L.step(n, true);
  return {seconds: (performance.now() - t0) / 1000, inferMs: L.stats.inferMs, skinMs: L.stats.skinMs,
          drawMs: L.stats.drawMs};
}"""


def play_for(page, seconds: float, speed: float) -> dict:
    """Play on the page's own timer at ``speed`` for ``seconds``: garment frames and draws per second."""
    page.evaluate(f"loosefitLive.setSpeed({speed}); loosefitLive.play()")
    page.wait_for_timeout(1500)  # the first counting window
    start = page.evaluate("[loosefitLive.frame, performance.now()]")
    page.wait_for_timeout(int(1000 * seconds))
    end = page.evaluate("[loosefitLive.frame, performance.now(), loosefitLive.stats]")
    page.evaluate("loosefitLive.pause()")
    elapsed = (end[1] - start[1]) / 1000
    return {"speed": speed, "seconds": elapsed, "garment_fps": (end[0] - start[0]) / elapsed,
            "asked_fps": 30.0 * speed, "page_shown": end[2]}


def measure(browser, scene, args) -> dict:
    """The page's speed on ``scene`` (module docstring) in a ``args.viewport`` window."""
    server = ViewerServer(None, port=0)
    serve_live_scene(server, scene)
    query = "?play=0" + (f"&backend={args.backend}" if args.backend else "")
    with server:
        page = browser.new_page(viewport=args.viewport)
        start = time.perf_counter()
        page.goto(server.url + "live.html" + query)
        page.wait_for_function("window.loosefitLive && (loosefitLive.ready || loosefitLive.error)", timeout=300000)
        ready_s = time.perf_counter() - start
        if page.evaluate("loosefitLive.error"):
            raise SystemExit(f"the page failed: {page.evaluate('loosefitLive.error')}")
        page.evaluate(f"loosefitLive.step({args.warmup}, true)")
        stepped = page.evaluate(STEP_TIMED, args.frames)
        stepped["frames"] = args.frames
        stepped["fps"] = args.frames / stepped["seconds"]
        playing = [play_for(page, args.seconds, speed) for speed in (1.0, 2.0)]
        backend = page.evaluate("loosefitLive.backend")
        page.close()
    return {"model_mb": len(scene.model) / 2**20, "backend": backend, "page_ready_s": ready_s, "stepped": stepped,
            "playing": playing, "meets_target": stepped["fps"] >= TARGET_FPS}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=150, help="stepped frames timed")
    parser.add_argument("--warmup", type=int, default=20, help="untimed frames first")
    parser.add_argument("--seconds", type=float, default=6.0, help="seconds played at each speed")
    parser.add_argument("--bones", type=int, default=80, help="virtual bones (the rig's default)")
    parser.add_argument("--backend", default=None, help="force onnxruntime-web's backend (wasm)")
    parser.add_argument("--viewport", default=f"{VIEWPORT['width']}x{VIEWPORT['height']}",
                        help="window size WxH (software WebGL rasterises every pixel on the CPU)")
    parser.add_argument("--name", default="live-page-speed", help="results file name")
    parser.add_argument("--only", default="", help="comma-separated variant labels (default: all: "
                        "'paper width', 'paper width in int8', 'global layer through 64 channels')")
    args = parser.parse_args()
    width, height = (int(x) for x in args.viewport.split("x"))
    args.viewport = {"width": width, "height": height}
    from playwright.sync_api import sync_playwright

    load_before = os.getloadavg()
    body = AnnyBody()
    garment, _ = bench_dress(body)
    # label -> (config overrides, int8 weights: ``export-onnx --int8``, onnxruntime-web's MatMulNBits)
    variants = {"paper width": ([], False), "paper width in int8": ([], True),
                "global layer through 64 channels": (CPU_MODEL["virtualbones"], False)}
    variants = {k: v for k, v in variants.items() if not args.only or k in args.only.split(",")}
    results = {
        "garment": {"name": "bench dress", "vertices": int(len(garment.verts)), "faces": int(len(garment.faces))},
        "method": "virtualbones, untrained", "bones": args.bones, "body_vertices": None, "viewport": args.viewport,
        "target_fps": TARGET_FPS, "networks": {},
    }
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        results["chromium"] = browser.version
        for label, (overrides, int8) in variants.items():
            with tempfile.TemporaryDirectory(prefix="live-speed-") as tmp:
                model, cfg = paper_model("virtualbones", garment, body, args.bones, overrides)
                run = write_run(model, cfg, Path(tmp) / "virtualbones")
                start = time.perf_counter()
                exported = Path(tmp) / "garment.onnx"
                export_onnx(run, exported, checkpoint="last", int8=int8)
                scene = build_live_scene(model_path=exported, body=body, kinds=("walk", "spin"), seconds=8.0)
                export_s = time.perf_counter() - start
            entry = {"overrides": overrides, "int8": int8, "export_s": export_s, **measure(browser, scene, args)}
            results["networks"][label] = entry
            results["body_vertices"] = int(scene.body.rest_verts.shape[0])
            st, pl = entry["stepped"], entry["playing"]
            print(f"live page, bench dress ({len(garment.verts)} vertices), {label} ({entry['model_mb']:.0f} MB), "
                  f"{entry['backend']}: {st['fps']:.1f} fps stepped (inference {st['inferMs']:.1f} ms, skinning and "
                  f"normals {st['skinMs']:.1f} ms, draw {st['drawMs']:.1f} ms); playing 1x {pl[0]['garment_fps']:.1f} "
                  f"fps, 2x {pl[1]['garment_fps']:.1f} fps", flush=True)
        browser.close()
    results["load_average_before"] = load_before
    results["load_average_after"] = os.getloadavg()
    save_results(args.name, results)


if __name__ == "__main__":
    main()
