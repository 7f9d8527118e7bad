"""Cases that need more than one command or a live process: two writers on one store or run folder at once, a
command stopped by SIGINT / SIGTERM while it works, and raw HTTP requests to a running ``loosefit view`` server."""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import socket
import subprocess
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from tests.robustness.harness import (Case, Ctx, Result, Shared, classify, error_line, fill_paths, run_command,
                                      tree_hash)

# ---------------------------------------------------------------------------------------------- two writers


def two_writers(argv_a: list[str], argv_b: list[str], wait_for: str | None, timeout: float = 600.0):
    """A runner: start ``loosefit ARGV_A``; once ``wait_for`` exists (the store it creates; None: at once)
    start ``loosefit ARGV_B`` while A runs. Good: one of them exits 0, the other is refused with exit 2
    and an error line naming the store and the holder's pid; both exiting 0 is ``silent_wrong`` (two
    writers in one store: their data mix)."""

    def runner(case: Case, tmp: Path, sh: Shared) -> list[Result]:
        tokens = sh.tokens(tmp)
        a, b = ([x.format(**tokens) for x in argv] for argv in (argv_a, argv_b))
        start = time.perf_counter()
        procs = [_popen(sh, a, tmp)]
        if wait_for is not None:
            target = Path(wait_for.format(**tokens))
            while not target.exists() and procs[0].poll() is None and time.perf_counter() - start < timeout:
                time.sleep(0.1)
            time.sleep(0.5)  # let A take the store
        procs.append(_popen(sh, b, tmp))
        outs = []
        for p in procs:
            try:
                out, err = p.communicate(timeout=max(1.0, timeout - (time.perf_counter() - start)))
            except subprocess.TimeoutExpired:
                p.kill()
                out, err = p.communicate()
            outs.append((p.returncode, out.decode("utf-8", "replace"), err.decode("utf-8", "replace")))
        result = Result(case.name, f"loosefit {' '.join(a)}  &  loosefit {' '.join(b)}",
                        seconds=time.perf_counter() - start)
        result.returncode = max(rc if rc is not None else 1 for rc, _, _ in outs)
        result.stdout = "\n".join(f"[{w}] {o}" for w, (_, o, _) in zip("AB", outs))
        result.stderr = "\n".join(f"[{w}] {e}" for w, (_, _, e) in zip("AB", outs))
        codes = sorted(rc for rc, _, _ in outs)
        refused = [e for rc, _, e in outs if rc == 2]
        result.error_line = error_line(refused[0]) if refused else ""
        if "Traceback (most recent call last)" in result.output or any(c not in (0, 2) for c in codes):
            result.outcome = "tracebacks"
            result.problem = f"exit statuses {codes}" + (", a Python traceback" if "Traceback" in result.output else "")
        elif codes == [0, 0]:
            result.outcome, result.problem = "silent_wrong", "both writers exited 0: two writers in one store at once"
        elif codes == [2, 2]:
            result.outcome, result.problem = "silent_wrong", "both writers were refused"
        else:
            result.outcome = "clear_errors"
            if case.names and not any(n.lower() in result.error_line.lower() for n in case.names):
                result.problem = f"the refusal names none of {list(case.names)}"
        return [result]

    return runner


def _popen(sh: Shared, argv: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(sh.command(argv), cwd=cwd, env=sh.env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            stdin=subprocess.DEVNULL, preexec_fn=default_sigint)


def default_sigint() -> None:
    """In a child before it starts: Ctrl-C does what it does at a terminal. A shell without job control starts
    background commands with SIGINT ignored, their children inherit that, and Python then never installs its
    handler: a case or test run in the background would find every SIGINT without effect."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def then(argv2: list[str], check2: Callable[[Result], str | None]):
    """A runner: the case's own command, then ``loosefit ARGV2`` in the same folder; the case's outcome
    stands unless ``check2`` finds a problem in the second command's result (e.g. ``info`` after a repair
    still lists the dropped sequence, or a second resume still finds litter)."""

    def runner(case: Case, tmp: Path, sh: Shared) -> list[Result]:
        tokens = sh.tokens(tmp)
        before = {p: tree_hash(Path(p)) for p in fill_paths(case.keep, tmp, sh)}
        first = run_command(sh, [a.format(**tokens) for a in case.argv], tmp, case.timeout, case.name)
        result = classify(case, tmp, first, before, sh)
        if result.outcome in case.good():
            second = run_command(sh, [a.format(**tokens) for a in argv2], tmp, case.timeout)
            problem = check2(second)
            if problem:
                result.outcome, result.problem = "silent_wrong", problem
        return [result]

    return runner


# ---------------------------------------------------------------------------------------------- interrupts

#: The line a stopped command prints (after any progress bar left on its line).
_INTERRUPTED = re.compile(r"^loosefit[\w -]*: interrupted \(SIG(INT|TERM)\): ")
#: The exit status a command line gives when stopped by each signal (128 + its number).
STOPPED_STATUS = {signal.SIGINT: 130, signal.SIGTERM: 143}


def descendants(pid: int) -> set[int]:
    """The live processes descended from ``pid`` (read from /proc; zombies left out)."""
    parents: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        fields = text[text.rindex(")") + 2:].split()  # after the command name, which may hold spaces
        if fields[0] != "Z":
            parents.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    found, todo = set(), [pid]
    while todo:
        for child in parents.get(todo.pop(), []):
            if child not in found:
                found.add(child)
                todo.append(child)
    return found


def alive(pids: set[int]) -> set[int]:
    """Those of ``pids`` still running (not gone, not zombies)."""
    left = set()
    for pid in pids:
        try:
            state = Path(f"/proc/{pid}/stat").read_text()
        except OSError:
            continue
        if state[state.rindex(")") + 2:].split()[0] != "Z":
            left.add(pid)
    return left


def interrupted(sig: int, ready: Callable[[Path, int], bool], settle: float = 0.0, grace: float = 30.0):
    """A runner: start the case's command; once ``ready(tmp, pid)`` holds (it is working; then ``settle``
    seconds more) send it ``sig``. Good (``clear_errors``): exit 130 (SIGINT) or 143 (SIGTERM), no traceback,
    exactly one line ``loosefit VERB: interrupted (SIG...): ...`` naming one of the case's ``names`` (what was
    kept, the command that resumes), none of the processes it started still running ``grace`` seconds later
    (Ray's workers), and the case's ``check`` passing. An exit before the signal, another status or a
    traceback, no line or several, or processes left running are failures."""

    def runner(case: Case, tmp: Path, sh: Shared) -> list[Result]:
        argv = [a.format(**sh.tokens(tmp)) for a in case.argv]
        result = Result(case.name, f"loosefit {' '.join(argv)}  (then {signal.Signals(sig).name})")
        start = time.perf_counter()
        proc = _popen(sh, argv, tmp)
        while proc.poll() is None and not ready(tmp, proc.pid) and time.perf_counter() - start < case.timeout:
            time.sleep(0.1)
        early = proc.poll() is not None
        time.sleep(0 if early else settle)
        family = descendants(proc.pid)
        if proc.poll() is None:
            proc.send_signal(sig)
        try:
            out, err = proc.communicate(timeout=max(60.0, case.timeout - (time.perf_counter() - start)))
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
        result.seconds = time.perf_counter() - start
        result.returncode, result.stdout = proc.returncode, out.decode("utf-8", "replace")
        result.stderr = err.decode("utf-8", "replace")
        deadline = time.perf_counter() + grace
        while alive(family) and time.perf_counter() < deadline:
            time.sleep(0.5)
        left = alive(family)
        lines = [ln.strip() for ln in result.stderr.splitlines() if _INTERRUPTED.match(ln.strip())]
        result.error_line = lines[-1] if lines else ""
        problem = None
        if case.check is not None:
            try:
                problem = case.check(Ctx(tmp, sh, result))
            except Exception as e:  # noqa: BLE001 - a check that cannot read the outputs found them wrong
                problem = f"the outputs could not be checked: {type(e).__name__}: {e}"
        traceback = "Traceback (most recent call last)" in result.output
        if early:
            result.outcome = "silent_wrong"
            result.problem = f"the command ended (exit {result.returncode}) before it was interrupted"
        elif traceback or result.returncode != STOPPED_STATUS[sig]:
            result.outcome = "tracebacks"
            result.problem = f"exit {result.returncode}" + (", a Python traceback" if traceback else "")
        elif len(lines) != 1:
            result.outcome, result.problem = "silent_wrong", f"{len(lines)} lines say it was interrupted, not one"
        elif left:
            result.outcome, result.problem = "silent_wrong", f"processes it started still run: {sorted(left)}"
        elif problem:
            result.outcome, result.problem = "silent_wrong", problem
        else:
            result.outcome = "clear_errors"
            names = fill_paths(case.names, tmp, sh)
            if names and not any(n.lower() in result.error_line.lower() for n in names):
                result.problem = f"the line names none of {names}"
        for pid in left:  # never leave them behind the matrix
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
        return [result]

    return runner


def file_exists(template: str) -> Callable[[Path, int], bool]:
    """Ready when the file ``template`` (``{tmp}/...``) exists."""
    return lambda tmp, pid: Path(template.format(tmp=tmp)).exists()


def stored_ok(store: str, count: int = 1) -> Callable[[Path, int], bool]:
    """Ready when the store ``{tmp}/STORE`` holds ``count`` sequences stored ok (read from their attributes)."""
    def ready(tmp: Path, pid: int) -> bool:
        done = 0
        for attrs in (tmp / store).glob("sequences/*/.zattrs"):
            try:
                done += json.loads(attrs.read_text()).get("status") == "ok"
            except (OSError, ValueError):
                pass
        return done >= count
    return ready


def module_loaded(name: str) -> Callable[[Path, int], bool]:
    """Ready when the process has mapped a library whose path holds ``name`` (``/bpy/``: Blender is loaded; a bare
    ``bpy`` would match ``.pyenv``)."""
    def ready(tmp: Path, pid: int) -> bool:
        try:
            return name in Path(f"/proc/{pid}/maps").read_text()
        except OSError:
            return False
    return ready


# ---------------------------------------------------------------------------------------------- HTTP server


@dataclass
class Request:
    """One raw request to the viewer server.

    Attributes:
        name: the case name (``view-server/...``).
        raw: the bytes sent (``{host}`` is replaced by ``127.0.0.1:PORT``).
        status: the acceptable status codes (None: any answer, or none, as long as nothing crashes).
        control: a valid request (``ok`` when answered with one of ``status``).
        abort: close the connection right after sending, with a reset (a client that goes away).
        defect: one of the viewer brief's defects.
    """

    name: str
    raw: bytes
    status: tuple[int, ...] | None
    control: bool = False
    abort: bool = False
    defect: bool = True


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def send(port: int, raw: bytes, abort: bool = False, timeout: float = 20.0) -> tuple[str, bytes]:
    """Send ``raw`` and return the status line and the whole answer ("" when the server answered nothing)."""
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as s:
        s.sendall(raw.replace(b"{host}", f"127.0.0.1:{port}".encode()))
        if abort:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")
            return "", b""
        s.shutdown(socket.SHUT_WR)  # nothing more comes: an empty request ends here
        chunks = []
        try:
            while True:
                data = s.recv(65536)
                if not data:
                    break
                chunks.append(data)
        except (socket.timeout, ConnectionResetError):
            pass
    answer = b"".join(chunks)
    return answer.split(b"\r\n", 1)[0].decode("latin-1"), answer


def server_runner(requests: list[Request], argv: list[str], start_timeout: float = 300.0):
    """A runner: start ``loosefit view ... --port PORT`` once, send each request in turn, and classify each
    by its status line and what the server printed on stderr meanwhile (a traceback is ``tracebacks``)."""

    def runner(case: Case, tmp: Path, sh: Shared) -> list[Result]:
        port = free_port()
        cmd = [a.format(**sh.tokens(tmp)) for a in argv] + ["--port", str(port)]
        proc = _popen(sh, cmd, tmp)
        lines: dict[str, list[str]] = {"out": [], "err": []}
        for key, stream in (("out", proc.stdout), ("err", proc.stderr)):
            threading.Thread(target=_pump, args=(stream, lines[key]), daemon=True).start()
        t0 = time.perf_counter()
        while not any("serving" in ln for ln in lines["out"]) and proc.poll() is None \
                and time.perf_counter() - t0 < start_timeout:
            time.sleep(0.2)
        command = "loosefit " + " ".join(cmd)
        results = []
        try:
            for req in requests:
                results.append(_one_request(req, port, proc, lines, command))
        finally:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
        return results

    return runner


def _pump(stream, into: list[str]) -> None:
    for raw in iter(stream.readline, b""):
        into.append(raw.decode("utf-8", "replace"))


def _one_request(req: Request, port: int, proc: subprocess.Popen, lines: dict, command: str) -> Result:
    result = Result(req.name, f"{command}  <<  {req.raw[:80]!r}{'...' if len(req.raw) > 80 else ''}")
    if proc.poll() is not None:
        result.returncode = proc.returncode
        result.stderr = "".join(lines["err"])[-3000:]
        result.outcome = "controls_failed" if req.control else "tracebacks"
        result.problem = f"the server is not running (exit {proc.returncode})"
        return result
    seen = len(lines["err"])
    start = time.perf_counter()
    try:
        status, _ = send(port, req.raw, abort=req.abort)
    except OSError as e:
        status = ""
        result.problem = f"{type(e).__name__}: {e}"
    time.sleep(0.5)  # a handler thread's traceback arrives after the connection closes
    result.seconds = time.perf_counter() - start
    result.stderr = "".join(lines["err"][seen:])
    result.stdout = status
    result.returncode = 0 if proc.poll() is None else proc.returncode
    result.error_line = status
    code = int(status.split()[1]) if len(status.split()) > 1 and status.split()[1].isdigit() else None
    if "Traceback" in result.stderr or proc.poll() is not None:
        result.outcome = "controls_failed" if req.control else "tracebacks"
        result.problem = "the server printed a traceback" if "Traceback" in result.stderr else "the server exited"
    elif req.control:
        ok = code in (req.status or ())
        result.outcome, result.problem = ("ok", "") if ok else ("controls_failed", f"answered {status or 'nothing'}")
    elif req.status is None or code in req.status:
        result.outcome = "clear_errors"
    else:
        result.outcome = "silent_wrong"
        result.problem = f"answered {status!r}, expected {req.status}" if status else \
            f"no answer (the connection was dropped), expected {req.status}"
    return result
