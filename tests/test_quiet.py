"""Third-party start-up output: Warp's banner and module load timings only with ``loosefit -v``."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

SRC = Path(__file__).parents[1] / "src"
ENV = {**os.environ, "PYTHONPATH": str(SRC)}


def _warp_lines(done: subprocess.CompletedProcess) -> list[str]:
    return [line for line in (done.stdout + done.stderr).splitlines() if line.startswith(("Warp ", "Module "))]


def test_loosefit_is_quiet_unless_verbose(tmp_path):
    """``motion generate`` poses the Anny body, which starts Warp: no banner, no load timing, no no-driver note;
    with ``-v`` Warp's banner is back."""
    argv = [sys.executable, "-m", "loosefit.cli", "motion", "generate", "--kind", "walk", "--seconds", "0.2"]
    quiet = subprocess.run(argv + ["--out", str(tmp_path / "q.npz")], capture_output=True, text=True, env=ENV)
    assert quiet.returncode == 0, quiet.stderr
    assert not _warp_lines(quiet), quiet.stdout + quiet.stderr
    assert quiet.stdout.startswith("wrote ")
    verbose = subprocess.run([*argv[:3], "-v", *argv[3:], "--out", str(tmp_path / "v.npz")], capture_output=True,
                             text=True, env=ENV)
    assert verbose.returncode == 0, verbose.stderr
    assert any(line.startswith("Warp ") and "initialized" in line for line in _warp_lines(verbose)), verbose.stdout


def test_quiet_is_restored_after():
    """Warp imported inside (through the import hook) or before: quiet while active, its own level after,
    the hook gone."""
    script = """
import sys
from loosefit.quiet import quiet_third_party
with quiet_third_party():
    import warp
    assert warp.config.log_level == warp.LOG_WARNING, warp.config.log_level
assert warp.config.log_level == warp.LOG_INFO, warp.config.log_level
assert not any(type(f).__name__ == "_WarpFinder" for f in sys.meta_path)
with quiet_third_party():
    assert warp.config.log_level == warp.LOG_WARNING
assert warp.config.log_level == warp.LOG_INFO
with quiet_third_party(quiet=False):
    assert warp.config.log_level == warp.LOG_INFO
print("ok")
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=ENV)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stdout + done.stderr
    assert not _warp_lines(done), done.stdout + done.stderr
