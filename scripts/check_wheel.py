"""Build loosefit's wheel and install it into a fresh virtual environment: the CI step of packaging.

1. ``python -m build --wheel --no-isolation`` (the build backend of this environment, no download) on a
   copy of ``pyproject.toml``, ``README.md`` and ``src/`` (the checkout gets no ``build/`` folder).
2. A fresh venv (``python3.11 -m venv --without-pip``); the wheel installed into it with ``--no-deps``
   (the dependencies are this environment's, put on ``PYTHONPATH``: installing torch afresh takes
   minutes and is pip's job, not loosefit's).
3. Checks, in the fresh venv: ``loosefit`` imports from the venv (not from the checkout); the wheel's
   metadata puts Blender, Newton and Ray behind ``[sim]`` and the renderers behind ``[viz]``, nothing
   of them in the core; the report templates and the native kernel's C source are in the wheel; ``loosefit
   --help`` runs from the venv's console script; with ``bpy`` absent, ``loosefit simulate`` fails with an error
   naming ``loosefit[sim]``.

Prints the wheel's size and the install time and exits non-zero on a failed check.

Run: .venv/bin/python scripts/check_wheel.py   (make package-check)
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
import zipfile
from email.parser import Parser
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The interpreter this environment was made from (the fresh venv's base).
BASE_PYTHON = getattr(sys, "_base_executable", None) or "python3.11"
#: The caller's environment without PYTHONPATH (a test runner's would put the checkout on the path).
CLEAN_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}

#: Run inside the fresh venv with ``bpy`` unimportable, as on a machine without Blender.
WITHOUT_BLENDER = """
import sys, importlib.abc
class NoBlender(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name == "bpy" or name.startswith("bpy."):
            raise ImportError("No module named 'bpy'")
sys.meta_path.insert(0, NoBlender())
import loosefit, loosefit.cli, loosefit.train, loosefit.animate
print(loosefit.__file__)
sys.exit(loosefit.cli.main(["simulate", "--garment", "g.obj", "--motion", "m.npz", "--out", "x.npz"]))
"""


def run(cmd: list[str], env: dict | None = None, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, env=CLEAN_ENV if env is None else env, **kw)


def main() -> int:
    failures: list[str] = []

    def check(ok: bool, what: str) -> None:
        print(("ok    " if ok else "FAIL  ") + what)
        if not ok:
            failures.append(what)

    with tempfile.TemporaryDirectory(prefix="loosefit-wheel-") as tmp:
        tmp = Path(tmp)
        source = tmp / "source"
        junk = shutil.ignore_patterns("__pycache__", "*.egg-info", "*.pyc")
        shutil.copytree(ROOT / "src", source / "src", ignore=junk)
        for name in ("pyproject.toml", "README.md"):
            shutil.copy(ROOT / name, source)
        t = time.perf_counter()
        built = run([sys.executable, "-m", "build", "--wheel", "--no-isolation", "--outdir", str(tmp / "dist"), str(source)])
        build_s = time.perf_counter() - t
        if built.returncode != 0:
            print(built.stdout[-3000:], built.stderr[-3000:])
            return 1
        wheel = next((tmp / "dist").glob("loosefit-*.whl"))
        size = wheel.stat().st_size

        with zipfile.ZipFile(wheel) as z:
            names = z.namelist()
            meta = Parser().parsestr(z.read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode())
        requires = meta.get_all("Requires-Dist") or []
        core = [r for r in requires if "extra ==" not in r]
        extra_of = {r.split("==")[0].split("[")[0].strip().lower(): r.split("extra ==")[1].strip(" '\"")
                    for r in requires if "extra ==" in r and "loosefit" not in r.split(";")[0]}
        check(not any(r.lower().startswith(("bpy", "newton", "ray", "pyvista", "matplotlib")) for r in core),
              f"core requirements hold no simulator or renderer ({len(core)} core)")
        check(all(extra_of.get(p) == "sim" for p in ("bpy", "newton", "ray")), "bpy, newton, ray are the [sim] extra")
        check(all(extra_of.get(p) == "viz" for p in ("pyvista", "matplotlib", "jinja2")), "renderers, jinja2 are [viz]")
        check(extra_of.get("smplx") == "smpl", "smplx is the [smpl] extra")
        check("view" in (meta.get_all("Provides-Extra") or []), "the [view] extra exists")
        check("loosefit/models/layers/gat_ln_cpu.c" in names, "the native GAT-LN kernel's source is package data")
        check(any(n.startswith("loosefit/report/templates/") and n.endswith(".j2") for n in names),
              "report templates are package data")
        live = ("live.html", "live.js", "vendor/ort.webgpu.min.mjs", "vendor/ort-wasm-simd-threaded.asyncify.mjs",
                "vendor/ort-wasm-simd-threaded.asyncify.wasm")
        check(all(f"loosefit/viz/static/{n}" in names for n in live),
              "the live page and onnxruntime-web (its ES modules and WebAssembly) are package data")

        t = time.perf_counter()
        venv = tmp / "venv"
        made = run([BASE_PYTHON, "-m", "venv", "--without-pip", str(venv)])
        installed = run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install",
                         "--no-deps", "--no-index", "--quiet", str(wheel)])
        install_s = time.perf_counter() - t
        check(made.returncode == 0 and installed.returncode == 0, f"installed into a fresh venv {installed.stderr[-500:]}")

        env = {"PYTHONPATH": sysconfig.get_paths()["purelib"], "PATH": "/usr/bin:/bin", "HOME": str(tmp)}
        helped = run([str(venv / "bin" / "loosefit"), "--help"], env=env)
        check(helped.returncode == 0 and "report" in helped.stdout and "train" in helped.stdout,
              "the loosefit console script runs")
        bare = run([str(venv / "bin" / "python"), "-c", WITHOUT_BLENDER], env=env, cwd=tmp)
        lines = bare.stdout.strip().splitlines()
        check(bool(lines) and lines[0].startswith(str(venv)), f"loosefit imports from the venv ({lines[:1]})")
        check(bare.returncode == 2 and "loosefit[sim]" in bare.stderr,
              f"simulate without Blender names the extra: {bare.stderr.strip()[-300:]}")

    print(json.dumps({"wheel": wheel.name, "wheel_bytes": size, "build_s": round(build_s, 1),
                      "venv_and_install_s": round(install_s, 1)}))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
