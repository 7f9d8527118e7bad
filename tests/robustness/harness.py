"""Run robustness cases through the ``loosefit`` command line in subprocesses and classify what happened.

A :class:`Case` is one command run in its own scratch folder on inputs its ``setup`` writes there (bad
files, crafted payloads, damaged copies of a shared store or run). The outcome of a bad input is one of

- ``clear_errors``: exit status 2, no ``Traceback``, an error line ``loosefit VERB: error: ...`` (argparse's
  usage error counts: it exits 2 the same way);
- ``repaired``: success, and the output says what was repaired, dropped, or is out of range (the case's
  ``report`` text is in stdout or stderr);
- ``tracebacks``: a Python traceback, or an exit status other than 0 and 2 (a crash, a signal);
- ``silent_wrong``: exit 0 where the case says it must not happen, or the case's own check of the
  outputs failed (a refused command that still wrote its output, a damaged store reported clean ...);
- ``code_executed``: a crafted pickle payload created its marker file;
- ``data_lost``: a file or folder that existed before the command (the case's ``keep``) changed;

and ``ok`` / ``controls_failed`` for valid controls. Nothing here imports loosefit: the same cases
measure any source tree (``PYTHONPATH``), and the inputs are written with NumPy, Zarr and plain text.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import re
import shutil
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from tests.robustness.forkserver import ForkServers

OUTCOMES = ("clear_errors", "repaired", "tracebacks", "silent_wrong", "code_executed", "data_lost")
CONTROL_OUTCOMES = ("ok", "controls_failed")
#: The file a crafted pickle payload creates when it runs (in the case's scratch folder).
MARKER = "PAYLOAD-RAN"
#: Briefs that own the fix of a defect family (cases from elsewhere carry "").
BRIEFS = ("store", "inputs", "viewer", "hostile")
#: loosefit's error line (argparse's too); a progress bar left unfinished may precede it on its line.
_ERROR_LINE = re.compile(r"loosefit[\w -]*: error: .+$")


@dataclass
class Shared:
    """Expensive inputs made once and only read by the cases (a case that damages one copies it first).

    Attributes:
        store: a prepared dataset store (``skirt+average``: ``walk`` and ``spin`` train, ``sway`` test).
        run: a virtualbones run folder trained on ``store``.
        motion: a motion ``.npz``: the store's training motion ``walk``.
        seq: a mesh-sequence ``.npz`` (the run's animation of ``motion``, with the body).
        garment: a garment ``.obj`` with its ``.json`` sidecar (a coarse skirt).
        plan: the plan YAML that made ``store``.
        python: the interpreter running the command line; src: a ``PYTHONPATH`` for it (None: installed).
    """

    root: Path
    store: Path
    run: Path
    motion: Path
    seq: Path
    garment: Path
    plan: Path
    python: str = sys.executable
    src: str | None = None
    forks: ForkServers | None = None  # pre-imported processes whose forks run the commands (None: fresh ones)

    def tokens(self, tmp: Path) -> dict[str, str]:
        return {"tmp": str(tmp), "store": str(self.store), "run": str(self.run), "motion": str(self.motion),
                "seq": str(self.seq), "garment": str(self.garment), "plan": str(self.plan)}

    def env(self) -> dict[str, str]:
        env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONUNBUFFERED="1")
        if self.src:
            env["PYTHONPATH"] = self.src
        return env

    def command(self, argv: list[str]) -> list[str]:
        return [self.python, "-m", "loosefit.cli", *argv]


@dataclass
class Result:
    """What one case did: the command's status and output, and the classification."""

    name: str
    command: str
    returncode: int | None = None
    stdout: str = ""
    stderr: str = ""
    seconds: float = 0.0
    outcome: str = ""
    problem: str = ""  # why the outcome is not the good one (or the setup's failure)
    error_line: str = ""
    note: str = ""  # for a repaired input: the line saying what was repaired

    @property
    def output(self) -> str:
        return self.stdout + "\n" + self.stderr

    def first_stderr_line(self) -> str:
        """The error line, else the first line of stderr that is not chatter."""
        lines = [ln.strip() for ln in self.stderr.splitlines() if not _noise(ln)]
        return self.error_line or (lines[0] if lines else "")

    def exception(self) -> str:
        """The last line of the last Python traceback in the output ("" without one)."""
        text = self.output
        if "Traceback (most recent call last)" not in text:
            return ""
        tail = text[text.rindex("Traceback (most recent call last)"):].splitlines()[1:]
        lines = [ln.strip() for ln in tail if ln.strip() and not ln.startswith((" ", "\t")) and not _noise(ln)]
        return lines[0] if lines else ""

    def describe(self) -> str:
        tail = "\n".join(self.stderr.strip().splitlines()[-12:])
        return (f"{self.name}: {self.outcome} ({self.problem})\n  $ {self.command}\n  exit {self.returncode}"
                f"\n  stdout: {self.stdout.strip()[-600:]}\n  stderr (last lines):\n{tail}")

    def record(self) -> dict:
        return {"name": self.name, "command": self.command, "outcome": self.outcome, "exit": self.returncode,
                "seconds": round(self.seconds, 1), "first_stderr_line": self.first_stderr_line()[:300],
                **({"problem": self.problem} if self.problem else {}), **({"said": self.note[:300]} if self.note else {}),
                **({"exception": self.exception()[:300]} if self.exception() else {})}


Check = Callable[["Ctx"], "str | None"]


@dataclass
class Case:
    """One command on one kind of input.

    Attributes:
        name: ``family/what``; family is the verb or format.
        argv: the command line after ``loosefit``; ``{tmp}`` (the scratch folder) and the :class:`Shared`
            paths (``{store}``, ``{run}``, ``{motion}``, ``{seq}``, ``{garment}``, ``{plan}``) are filled in.
        setup: ``setup(tmp, shared)`` writes the inputs into the scratch folder.
        kind: ``"bad"`` input, ``"control"`` (must succeed) or ``"extreme"`` (NaN / inf / huge / tiny values).
        brief: which fix owns the defect family (``store``, ``inputs``, ``viewer``, ``hostile``), "" for none.
        names: the error line must contain one of these (the file or the argument).
        report: for a bad input that may succeed: the text the output must contain (a repair, a warning).
        check: a further check of the outputs, returning a problem (counted ``silent_wrong``) or None.
        keep: paths that exist before the command and must be unchanged after it (hashed).
        absent: paths that must not exist after a refused command (nothing written where it failed).
        defect: one of the defects the three briefs list (the pytest suite runs these).
        fixes: exit 0 is the right answer to this bad input when ``check`` passes (the command repairs it:
            re-simulates a damaged sequence, cleans stale litter): ``repaired``.
        runner: replaces the single-command run (two concurrent writers, raw socket requests).
    """

    name: str
    argv: list[str] = field(default_factory=list)
    setup: Callable[[Path, Shared], None] | None = None
    kind: str = "bad"
    brief: str = ""
    names: tuple[str, ...] = ()
    report: tuple[str, ...] = ()
    check: Check | None = None
    keep: tuple[str, ...] = ()
    absent: tuple[str, ...] = ()
    defect: bool = False
    fixes: bool = False
    timeout: float = 600.0
    cost: int = 1  # rough relative run time (Blender and training cases more): the slow ones start first
    runner: Callable[["Case", Path, Shared], list[Result]] | None = None
    results: tuple[str, ...] = ()  # with a runner: the names of the results it returns (default: name)

    @property
    def family(self) -> str:
        return self.name.split("/", 1)[0]

    def good(self) -> tuple[str, ...]:
        """The outcomes that count as handled well."""
        if self.kind == "control":
            return ("ok",)
        if self.fixes:
            return ("repaired",)
        return ("clear_errors", "repaired") if self.report else ("clear_errors",)


@dataclass
class Ctx:
    """What a check sees: the scratch folder, the shared inputs and the command's result."""

    tmp: Path
    shared: Shared
    result: Result


_ANSI = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")


def _noise(line: str) -> bool:
    """Chatter on stderr that says nothing about the input: warp's start-up banner, progress bars, cursor
    moves, socketserver's separator lines (a two-writer case prefixes each line with ``[A]`` / ``[B]``)."""
    s = re.sub(r"^\[[AB]\]\s*", "", _ANSI.sub("", line).strip()).strip()
    return (not s or set(s) <= {"-"} or "it/s]" in s or "s/it]" in s or "%|" in s or "?seq/s]" in s
            or s.startswith(("Warp ", "CUDA Toolkit", "Devices:", '"cpu"', '"cuda', "Kernel cache:", "Module ",
                             "/root/.cache", "Warp CUDA warning")))


def tree_hash(path: Path) -> str:
    """A digest of a file, or of every file under a folder (relative names and bytes; a store's ``.lock``
    left out: holding it is not a change of the data)."""
    h = hashlib.sha256()
    if path.is_file():
        h.update(path.read_bytes())
    elif path.is_dir():
        for p in sorted(path.rglob("*")):
            if p.is_file() and p.name != ".lock":
                h.update(str(p.relative_to(path)).encode() + b"\0" + p.read_bytes())
    else:
        h.update(b"<missing>")
    return h.hexdigest()


def run_command(shared: Shared, argv: list[str], cwd: Path, timeout: float, name: str = "") -> Result:
    """Run ``loosefit ARGV`` in ``cwd``; a timeout is reported as exit status None."""
    cmd = shared.command(argv)
    result = Result(name=name, command="loosefit " + " ".join(_quote(a) for a in argv))
    start = time.perf_counter()
    try:
        if shared.forks is not None:
            result.returncode, result.stdout, result.stderr = shared.forks.run(argv, cwd, timeout)
            if result.returncode is None:
                result.stderr += f"\n(timed out after {timeout:g} s)"
        else:
            proc = subprocess.run(cmd, cwd=cwd, env=shared.env(), capture_output=True, timeout=timeout,
                                  stdin=subprocess.DEVNULL)
            result.returncode = proc.returncode
            result.stdout = proc.stdout.decode("utf-8", "replace")
            result.stderr = proc.stderr.decode("utf-8", "replace")
    except subprocess.TimeoutExpired as e:
        result.stdout = (e.stdout or b"").decode("utf-8", "replace")
        result.stderr = (e.stderr or b"").decode("utf-8", "replace") + f"\n(timed out after {timeout:g} s)"
    result.seconds = time.perf_counter() - start
    return result


def _quote(arg: str) -> str:
    return arg if arg and re.fullmatch(r"[\w@%+=:,./-]+", arg) else repr(arg)


def error_line(stderr: str) -> str:
    """The last ``loosefit VERB: error: ...`` line of stderr ("" when there is none)."""
    found = [m.group(0).strip() for m in map(_ERROR_LINE.search, stderr.splitlines()) if m]
    return found[-1] if found else ""


def classify(case: Case, tmp: Path, result: Result, before: dict[str, str], shared: Shared) -> Result:
    """Set ``result.outcome`` (and ``problem``) from the command's status, output and files."""
    result.error_line = error_line(result.stderr)
    problem = None
    if result.returncode is not None and case.check is not None:
        try:
            problem = case.check(Ctx(tmp, shared, result))
        except Exception as e:  # noqa: BLE001 - a check that cannot read the outputs found them wrong
            problem = f"the outputs could not be checked: {type(e).__name__}: {e}"
    changed = [p for p, digest in before.items() if tree_hash(Path(p)) != digest]
    written = [p for p in fill_paths(case.absent, tmp, shared) if Path(p).exists()]
    traceback = "Traceback (most recent call last)" in result.output
    if case.kind == "control":
        good = result.returncode == 0 and not traceback and not problem and not changed
        result.outcome = "ok" if good else "controls_failed"
        result.problem = "" if good else (problem or ("a Python traceback" if traceback else "") or
                                          (f"changed: {', '.join(changed)}" if changed else "") or
                                          f"exit {result.returncode}: {result.first_stderr_line()}")
    elif (tmp / MARKER).exists():
        result.outcome, result.problem = "code_executed", f"the crafted payload created {MARKER}"
    elif changed:
        result.outcome, result.problem = "data_lost", f"changed: {', '.join(changed)}"
    elif result.returncode is None:
        result.outcome, result.problem = "tracebacks", "timed out"
    elif traceback or result.returncode not in (0, 2):
        result.outcome = "tracebacks"
        result.problem = f"exit {result.returncode}" + (", a Python traceback" if traceback else "")
    elif result.returncode == 0:
        said = [t for t in case.report if t.lower() in result.output.lower()]
        if problem:
            result.outcome, result.problem = "silent_wrong", problem
        elif (case.report and said) or case.fixes:
            result.outcome = "repaired"
            result.note = next((ln.strip() for ln in result.output.splitlines()
                                if any(t.lower() in ln.lower() for t in said)), "")
        else:
            result.outcome = "silent_wrong"
            result.problem = (f"exit 0 without saying {' / '.join(case.report)!r}" if case.report
                              else "exit 0 must not happen")
    elif (problem and not case.fixes) or written:
        result.outcome = "silent_wrong"
        result.problem = problem or f"refused, but wrote {', '.join(written)}"
    else:
        result.outcome = "clear_errors"
        if problem:  # a command that repairs its input refused it: say what is left undone
            result.problem = f"refused; {problem}"
        elif not result.error_line:
            result.problem = "exit 2 without a `loosefit VERB: error:` line"
        else:
            names = fill_paths(case.names, tmp, shared)
            if names and not any(n.lower() in result.error_line.lower() for n in names):
                result.problem = f"the error line names none of {names}"
    return result


def fill_paths(paths: tuple[str, ...], tmp: Path, shared: Shared) -> list[str]:
    tokens = shared.tokens(tmp)
    return [p.format(**tokens) for p in paths]


def scratch_for(root: Path, case: Case) -> Path:
    """A fresh, empty scratch folder for ``case`` under ``root``."""
    tmp = root / re.sub(r"[^\w.-]+", "_", case.name)
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    return tmp


def run_case(case: Case, root: Path, shared: Shared) -> list[Result]:
    """Set the case up in a fresh scratch folder under ``root``, run it and classify it (a case with a
    runner may give several results: one per request sent to one server)."""
    tmp = scratch_for(root, case)
    argv = [a.format(**shared.tokens(tmp)) for a in case.argv]
    try:
        if case.setup is not None:
            case.setup(tmp, shared)
    except Exception as e:  # noqa: BLE001 - a setup failure is reported, not raised through the pool
        return [Result(name, "loosefit " + " ".join(argv), outcome="setup_failed",
                       problem=f"setup: {type(e).__name__}: {e}") for name in case.results or (case.name,)]
    if case.runner is not None:
        return case.runner(case, tmp, shared)
    before = {p: tree_hash(Path(p)) for p in fill_paths(case.keep, tmp, shared)}
    result = run_command(shared, argv, tmp, case.timeout, case.name)
    return [classify(case, tmp, result, before, shared)]


def run_cases(cases: list[Case], root: Path, shared: Shared, workers: int = 2,
              progress: Callable[[Result], None] | None = None, fork: bool = hasattr(os, "fork")) -> list[Result]:
    """Run ``cases`` on a small thread pool (each case is a process); results in the cases' order.
    The costliest cases (:attr:`Case.cost`) start first, so that they overlap the cheap ones. With ``fork``
    each single command is a fork of a process that imported the heavy libraries once
    (:mod:`tests.robustness.forkserver`; ``shared.forks`` when the caller keeps a pool across calls, else
    one for this call); without, a fresh interpreter."""
    forks = ForkServers(shared.python, shared.env()) if fork and shared.forks is None else None
    if forks is not None:
        shared = dataclasses.replace(shared, forks=forks)

    def one(case: Case) -> list[Result]:
        results = run_case(case, root, shared)
        for result in results if progress is not None else ():
            progress(result)
        return results

    order = sorted(range(len(cases)), key=lambda i: -cases[i].cost)
    try:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            futures = {i: pool.submit(one, cases[i]) for i in order}
            return [r for i in range(len(cases)) for r in futures[i].result()]
    finally:
        if forks is not None:
            forks.close()


def counts(results: list[Result]) -> dict[str, int]:
    """How many results fall in each outcome (every outcome key present)."""
    out = {k: 0 for k in (*OUTCOMES, *CONTROL_OUTCOMES)}
    for r in results:
        out[r.outcome] = out.get(r.outcome, 0) + 1
    return out
