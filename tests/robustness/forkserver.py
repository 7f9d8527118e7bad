"""Run ``python -m loosefit.cli ARGV`` as forks of a process that has already imported the heavy libraries.

Every robustness case is one command in a fresh process. Importing torch, PyG and SciPy takes 3-6 s of CPU
on the test machines, more than most cases take to refuse their input, so a pool keeps server processes (one
per command running at once). Each is a Python process, started like the plain command (the same interpreter,
environment and ``PYTHONPATH``), that imports those libraries once and then forks a child per command. The
child changes to the case's folder, points its standard streams at files, starts its own process group, and
runs ``loosefit.cli`` as ``-m`` would, so its exit status, output and tracebacks are those of a fresh process;
only the imports are shared. The libraries imported start no threads, so the fork is safe. Nothing here
imports loosefit.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path

#: Imported by the server before it forks (whichever of them import; none starts a thread).
PRELOAD = ("numpy", "scipy.spatial", "torch", "torch_geometric", "zarr", "loosefit.cli", "loosefit.sim.sequence",
           "loosefit.training", "loosefit.garment", "loosefit.motion.io")

_SERVER = r"""
import importlib, json, os, signal, sys, time
for name in PRELOAD:
    try:
        importlib.import_module(name)
    except Exception:
        pass

def serve():
    # Requests are JSON lines on stdin; the answer to each is the child's exit status (None: timed out).
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        request = json.loads(line)
        pid = os.fork()
        if pid == 0:
            return request
        deadline = time.monotonic() + request["timeout"]
        while True:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                code = os.waitstatus_to_exitcode(status)
                break
            if time.monotonic() > deadline:
                try:
                    os.killpg(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                os.waitpid(pid, 0)
                code = None
                break
            time.sleep(0.01)
        print(json.dumps({"returncode": code}), flush=True)
    return None

request = serve()
if request is not None:
    os.setpgid(0, 0)
    os.chdir(request["cwd"])
    for fd, path, flags in ((0, os.devnull, os.O_RDONLY),
                            (1, request["stdout"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC),
                            (2, request["stderr"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC)):
        os.dup2(os.open(path, flags, 0o644), fd)
    sys.stdin = open(os.devnull)
    sys.argv = [request["module"], *request["argv"]]
    import runpy
    import warnings
    # the server imported the module already (PRELOAD): runpy's warning about that is the harness's, not the CLI's
    warnings.filterwarnings("ignore", message=".*found in sys.modules after import of package", category=RuntimeWarning)
    runpy.run_module(request["module"], run_name="__main__", alter_sys=True)
"""


class ForkServer:
    """One server process; :meth:`run` is a blocking call (one command at a time)."""

    def __init__(self, python: str, env: dict[str, str], preload: tuple[str, ...] = PRELOAD):
        source = f"PRELOAD = {list(preload)!r}\n" + _SERVER
        self.proc = subprocess.Popen([python, "-c", source], env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL, text=True)
        if json.loads(self.proc.stdout.readline() or "{}").get("ready") is not True:
            raise RuntimeError("the fork server did not start")
        self.outputs = Path(tempfile.mkdtemp(prefix="loosefit-forkserver-"))  # not the case's folder: cases list it

    def run(self, argv: list[str], cwd: Path, timeout: float, module: str = "loosefit.cli") -> tuple[int | None, str, str]:
        """``(exit status or None if it timed out, stdout, stderr)`` of ``python -m MODULE ARGV`` in ``cwd``."""
        out, err = self.outputs / "stdout", self.outputs / "stderr"
        request = {"argv": list(argv), "cwd": str(cwd), "stdout": str(out), "stderr": str(err), "timeout": timeout,
                   "module": module}
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        answer = json.loads(self.proc.stdout.readline())
        texts = [p.read_bytes().decode("utf-8", "replace") if p.exists() else "" for p in (out, err)]
        for p in (out, err):
            p.unlink(missing_ok=True)
        return answer["returncode"], texts[0], texts[1]

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.stdin.close()
            self.proc.wait(timeout=30)
        shutil.rmtree(self.outputs, ignore_errors=True)


class ForkServers:
    """A pool of :class:`ForkServer`: :meth:`run` takes an idle one (or starts one), so that as many commands run
    at once as threads call it, and every server is reused by later callers."""

    def __init__(self, python: str, env: dict[str, str]):
        self.python, self.env = python, env
        self._idle: list[ForkServer] = []
        self._all: list[ForkServer] = []
        self._lock = threading.Lock()

    def run(self, argv: list[str], cwd: Path, timeout: float) -> tuple[int | None, str, str]:
        """:meth:`ForkServer.run` on an idle server."""
        with self._lock:
            server = self._idle.pop() if self._idle else None
        if server is None:
            server = ForkServer(self.python, self.env)
            with self._lock:
                self._all.append(server)
        try:
            return server.run(argv, cwd, timeout)
        finally:
            with self._lock:
                self._idle.append(server)

    def close(self) -> None:
        for server in self._all:
            server.close()
