"""A picture of the live page (``loosefit view --live``) in the middle of a motion switch, and the garment's
continuity across it, in this machine's headless Chromium (software WebGL, the viewer tests' flags).

The garment is the shipped VirtualBones skirt (``pretrained:skirt``). The page plays ``--before`` frames of a walk,
switches to a spin, and is photographed ``--into`` frames into the blend (of 10). Recorded beside the picture: the
largest per-vertex garment step (mm) of each frame around the switch, the bound the tests hold it to (3x the largest
step of the 10 walk frames before), the root's steps, and the frame of the picture.

Run: .venv/bin/python benchmarks/live_page_switch.py [--before 45] [--into 5]
(writes benchmarks/results/renders/live-page-switch.png and benchmarks/results/live-page-switch.json)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, save_results  # noqa: E402
from live_page_speed import CHROMIUM, CHROMIUM_ARGS, VIEWPORT  # noqa: E402

from loosefit.body import AnnyBody  # noqa: E402
from loosefit.viz.live import build_live_scene, serve_live_scene  # noqa: E402
from loosefit.viz.viewer import ViewerServer  # noqa: E402

PICTURE = RESULTS / "renders" / "live-page-switch.png"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", type=int, default=45, help="walk frames before the switch")
    parser.add_argument("--into", type=int, default=5, help="frames into the blend when photographed")
    args = parser.parse_args()
    from playwright.sync_api import sync_playwright

    scene = build_live_scene("pretrained:skirt", body=AnnyBody(), kinds=("walk", "spin"), seconds=8.0)
    server = ViewerServer(None, port=0)
    serve_live_scene(server, scene)
    with server, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport=VIEWPORT)
        page.goto(server.url + "live.html?play=0")
        page.wait_for_function("window.loosefitLive && (loosefitLive.ready || loosefitLive.error)", timeout=300000)
        if page.evaluate("loosefitLive.error"):
            raise SystemExit(f"the page failed: {page.evaluate('loosefitLive.error')}")
        page.evaluate("loosefitLive.record = true; loosefitLive.log = []")
        page.evaluate(f"loosefitLive.step({args.before - 1})")
        page.evaluate("loosefitLive.switchTo('spin')")
        page.evaluate(f"loosefitLive.step({args.into})")
        shown = page.evaluate("loosefitLive.current()")
        PICTURE.parent.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(PICTURE))
        log = page.evaluate("loosefitLive.log")
        browser.close()
    verts = np.asarray([e["vertices"] for e in log], np.float32).reshape(len(log), -1, 3)
    root = np.asarray([e["root_position"] for e in log], np.float64)
    steps = 1000 * np.linalg.norm(np.diff(verts, axis=0), axis=2).max(axis=1)  # steps[i]: log frame i -> i + 1
    switch = args.before - 2  # from the last walk frame to the first blended one
    bound = 3.0 * steps[switch - 10: switch].max()
    body_z = root[-1, 2]
    results = {
        "garment": "pretrained:skirt (virtualbones)", "vertices": int(verts.shape[1]), "picture": str(PICTURE),
        "switch": f"walk -> spin after {args.before} frames", "photographed": shown,
        "garment_step_mm": {"before": steps[switch - 10: switch].round(2).tolist(), "at_switch": float(steps[switch]),
                            "during_blend": steps[switch + 1:].round(2).tolist()},
        "bound_mm": float(bound), "continuous": bool(steps[switch:].max() <= bound),
        "root_step_mm": (1000 * np.linalg.norm(np.diff(root, axis=0), axis=1))[switch - 3:].round(2).tolist(),
        "garment_height_m": [float(verts[-1, :, 2].min()), float(verts[-1, :, 2].max())], "root_height_m": body_z,
    }
    print(f"garment step at the switch {steps[switch]:.1f} mm (bound {bound:.1f} mm); picture {PICTURE}")
    save_results("live-page-switch", results)


if __name__ == "__main__":
    main()
