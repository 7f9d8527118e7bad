"""How fast ``loosefit view`` opens a large sequence in a real browser (Debian Chromium, headless, software
WebGL through SwiftShader, driven by Playwright), served on localhost and exported to disk (``file://``).

Cases (synthetic meshes of the stated sizes: the load time depends on the sizes, not on the shapes):

- ``one``: a 12,000-vertex garment (a swinging, rippling skirt tube) over 300 frames, alone;
- ``compare``: that garment as the simulation, a prediction of it (the simulation plus smooth offsets up to
  ~15 mm) and a 13,718-vertex body (a capsule of the Anny body's vertex count) under both, 300 frames,
  with the per-vertex error heat map, RMSE and collision curves.

Per case: the Python side (``build_scene``: loading, errors, collision ratio per frame; packing), the binary
size, then ``--repeats`` fresh page loads each way: ``ready_ms`` is the page's own clock (``performance.now()``,
from the start of navigation) when the first frame is drawn with every panel, the legend and the plot;
``wall_ms`` adds Playwright's round trip; ``page_timing_ms``: when the script started (``startMs``),
how long the data took (``dataMs``: the binary fetch, or loading and decoding the export's base64 chunks;
``chunkScriptsMs``: when the chunk scripts had all run). ``step_ms``: the mean time of ``setFrame`` (positions, normals,
heat-map colours and a draw of every panel) over 60 frames. Target: a 12k-vertex, 300-frame
sequence opens in under 2 s on localhost. The machine is shared: the load average is recorded.

Run: .venv/bin/python benchmarks/viewer.py [--repeats 3] [--frames 300] [--vertices 12000]
(writes benchmarks/results/viewer.json and the page's screenshot benchmarks/results/viewer-compare.png)
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, save_results  # noqa: E402

from loosefit.io.mesh_sequence import MeshSequence  # noqa: E402
from loosefit.viz.viewer import ViewerServer, export_scene, pack_scene  # noqa: E402
from loosefit.viz.viewer_scene import build_scene  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run", "--use-gl=swiftshader",
                 "--enable-unsafe-swiftshader"]
BODY_VERTICES = 13718


def skirt(vertices: int, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """A tube skirt of about ``vertices`` vertices (rings x 120 segments), hip ring at z = 1.0 m, swinging and
    rippling over ``frames`` frames: ``(verts (T, V, 3) float32, faces (F, 3))``."""
    segments = 120
    rings = max(2, round(vertices / segments))
    theta = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    depth = np.linspace(0.0, 0.6, rings)[:, None]  # metres below the hip
    t = np.arange(frames)[:, None, None] / 30.0
    radius = 0.18 + 0.25 * depth + 0.02 * depth * np.sin(6 * theta + 4 * t)
    swing = 0.15 * depth * np.sin(2 * np.pi * 0.8 * t)
    x = radius * np.cos(theta) + swing
    y = radius * np.sin(theta)
    z = 1.0 - depth + 0.0 * theta + 0.0 * t
    verts = np.stack(np.broadcast_arrays(x, y, z), -1).reshape(frames, -1, 3).astype(np.float32)
    faces = []
    for r in range(rings - 1):
        a = r * segments + np.arange(segments)
        b = r * segments + (np.arange(segments) + 1) % segments
        faces += [np.stack([a, b, b + segments], 1), np.stack([a, b + segments, a + segments], 1)]
    return verts, np.concatenate(faces)


def body(frames: int) -> tuple[np.ndarray, np.ndarray]:
    """A closed capsule with about the Anny body's vertex count, standing in the skirt (its waistband a little inside)."""
    import trimesh

    capsule = trimesh.creation.capsule(height=1.2, radius=0.19, count=[98, 140])
    v = np.asarray(capsule.vertices) + [0.0, 0.0, 0.9]
    return np.repeat(v[None], frames, 0).astype(np.float32), np.asarray(capsule.faces)


def page_times(playwright, url: str, repeats: int, screenshot: Path | None = None) -> dict:
    """Open ``url`` ``repeats`` times, each in a freshly launched browser (a second WebGL page in the same
    headless browser waits seconds for SwiftShader to release the first one's context)."""
    ready, wall, errors, timings = [], [], [], []
    step_ms = None
    for i in range(repeats):
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1400, "height": 720})
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        t0 = time.perf_counter()
        page.goto(url)
        page.wait_for_function("window.loosefitViewer && window.loosefitViewer.ready", timeout=60000, polling=10)
        wall.append(1000 * (time.perf_counter() - t0))
        ready.append(page.evaluate("loosefitViewer.timing.readyMs"))
        timings.append(page.evaluate("loosefitViewer.timing"))
        if i == 0:
            step_ms = page.evaluate("""(() => { const t0 = performance.now();
                for (let k = 1; k <= 60; k++) loosefitViewer.setFrame(k);
                return (performance.now() - t0) / 60; })()""")
            if screenshot is not None:
                page.evaluate("loosefitViewer.setFrame(75)")
                page.screenshot(path=str(screenshot))
        browser.close()
    return {"ready_ms": [round(x, 1) for x in ready], "ready_ms_median": round(float(np.median(ready)), 1),
            "wall_ms": [round(x, 1) for x in wall], "wall_ms_median": round(float(np.median(wall)), 1),
            "step_ms": round(step_ms, 2), "console_errors": errors,
            "page_timing_ms": [{k: round(v, 1) for k, v in t.items()} for t in timings]}


def run_case(name: str, inputs: list[str], playwright, repeats: int, root: Path, screenshot: Path | None) -> dict:
    t0 = time.perf_counter()
    scene = build_scene(inputs)
    build_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    manifest, data = pack_scene(scene)
    pack_s = time.perf_counter() - t0
    out = {"panels": len(scene.panels), "frames": scene.num_frames,
           "vertices": [[t.verts.shape[1] for t in p.tracks] for p in scene.panels],
           "build_scene_s": round(build_s, 2), "pack_s": round(pack_s, 2), "binary_mb": round(len(data) / 2**20, 1)}
    with ViewerServer(scene, port=0) as server:
        out["served"] = page_times(playwright, server.url, repeats, screenshot)
    t0 = time.perf_counter()
    index = export_scene(scene, root / f"export-{name}")
    out["export_s"] = round(time.perf_counter() - t0, 2)
    out["export_mb"] = round(sum(f.stat().st_size for f in index.parent.rglob("*") if f.is_file()) / 2**20, 1)
    out["file"] = page_times(playwright, index.as_uri(), repeats)
    shutil.rmtree(index.parent)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--vertices", type=int, default=12000)
    args = ap.parse_args(argv)
    from playwright.sync_api import sync_playwright

    root = Path(tempfile.mkdtemp(prefix="loosefit-viewer-bench-"))
    try:
        sim, faces = skirt(args.vertices, args.frames)
        rng = np.random.default_rng(0)
        V = sim.shape[1]
        # A smooth prediction error: a few low-frequency waves over the vertices and time, up to ~15 mm.
        phase = rng.uniform(0, 2 * np.pi, 3)
        idx = np.arange(V) / V
        t = np.arange(args.frames)[:, None] / args.frames
        offset = np.stack([0.005 * np.sin(2 * np.pi * (3 * idx + 2 * t) + p) for p in phase], -1)
        pred = sim + offset.astype(np.float32)
        body_verts, body_faces = body(args.frames)
        extra = {"body_verts": body_verts, "body_faces": body_faces}
        MeshSequence(sim, faces).save(root / "one.npz")
        MeshSequence(sim, faces, 30.0, extra).save(root / "sim.npz")
        MeshSequence(pred, faces, 30.0, extra).save(root / "pred.npz")
        results = {"load_average": os.getloadavg(), "chromium_args": CHROMIUM_ARGS}
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            results["chromium"] = browser.version
            browser.close()
            results["one"] = run_case("one", [str(root / "one.npz")], p, args.repeats, root, None)
            results["compare"] = run_case("compare", [str(root / "sim.npz"), str(root / "pred.npz")], p,
                                          args.repeats, root, RESULTS / "viewer-compare.png")
        # The target is the one-sequence case served on localhost; the others are reported beside it.
        results["target_ms"] = 2000
        results["under_target"] = {f"{c}_{w}": results[c][w]["wall_ms_median"] < 2000
                                   for c in ("one", "compare") for w in ("served", "file")}
        results["load_average_after"] = os.getloadavg()
        save_results("viewer", results)
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
