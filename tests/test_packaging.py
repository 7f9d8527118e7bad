"""Packaging: the wheel builds, installs into a fresh venv, keeps Blender, Newton, Ray and the renderers
in extras, ships the report templates, and a user without Blender who simulates is told the extra
(scripts/check_wheel.py does the work; about 10 s)."""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_wheel_builds_and_installs_without_blender():
    had_build = (ROOT / "build").exists()
    done = subprocess.run([sys.executable, str(ROOT / "scripts" / "check_wheel.py")], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "FAIL" not in done.stdout
    numbers = json.loads(done.stdout.strip().splitlines()[-1])
    print(numbers)
    # the package and its data, no vendored weights beyond the shipped garments (each at most 20 MB) and the live
    # page's onnxruntime-web (its WebAssembly runtime alone is 28.7 MB, 7.1 MB compressed)
    shipped = sum(p.stat().st_size for p in (ROOT / "src" / "loosefit" / "pretrained").glob("*/checkpoints/best.pt"))
    shipped += sum(p.stat().st_size for p in (ROOT / "src" / "loosefit" / "viz" / "static" / "vendor").glob("ort*"))
    assert 50_000 < numbers["wheel_bytes"] < 5_000_000 + shipped
    assert (ROOT / "build").exists() == had_build  # the checkout is left as it was
