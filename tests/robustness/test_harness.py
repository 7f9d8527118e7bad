"""The classification of the robustness cases, on results built by hand (no subprocess), and the
catalogue's coverage of the command line."""

import pickle

import pytest

from tests.robustness import craft
from tests.robustness.catalog import all_cases, defect_names, result_meta
from tests.robustness.harness import MARKER, Case, Result, Shared, classify, counts, tree_hash
from tests.robustness.kit import bad, ok, wrote

ERR = "Warp 1.19.0 initialized:\nloosefit body: error: {tmp}/g.obj: the mesh has no faces\n"


@pytest.fixture
def shared(tmp_path):
    p = tmp_path / "shared"
    return Shared(root=p, store=p / "s.zarr", run=p / "run", motion=p / "m.npz", seq=p / "q.npz", garment=p / "g.obj",
                  plan=p / "plan.yaml")


def result(rc, stderr="", stdout="", tmp=None):
    return Result("x", "loosefit x", returncode=rc, stdout=stdout, stderr=stderr.format(tmp=tmp))


def test_refusal_naming_the_file_is_a_clear_error(tmp_path, shared):
    case = bad("body/x", [], names=("{tmp}/g.obj",))
    r = classify(case, tmp_path, result(2, ERR, tmp=tmp_path), {}, shared)
    assert (r.outcome, r.problem) == ("clear_errors", "")
    assert r.first_stderr_line() == f"loosefit body: error: {tmp_path}/g.obj: the mesh has no faces"
    unnamed = classify(bad("body/x", [], names=("other.obj",)), tmp_path, result(2, ERR, tmp=tmp_path), {}, shared)
    assert unnamed.outcome == "clear_errors" and "names none of ['other.obj']" in unnamed.problem


def test_exit_0_on_bad_input_is_silent_wrong_unless_it_says_what_it_repaired(tmp_path, shared):
    assert classify(bad("a/b", []), tmp_path, result(0, "", "wrote out.obj"), {}, shared).outcome == "silent_wrong"
    repaired = bad("a/b", [], report=("repaired",))
    r = classify(repaired, tmp_path, result(0, "", "wrote out.obj; repaired {'merged_vertices': 3}"), {}, shared)
    assert r.outcome == "repaired" and r.note.startswith("wrote out.obj; repaired")
    assert classify(repaired, tmp_path, result(0, "", "wrote out.obj"), {}, shared).outcome == "silent_wrong"


def test_traceback_crash_and_timeout_are_tracebacks(tmp_path, shared):
    tb = "Traceback (most recent call last):\n  File ...\nAttributeError: x\n"
    assert classify(bad("a/b", []), tmp_path, result(1, tb), {}, shared).outcome == "tracebacks"
    assert classify(bad("a/b", []), tmp_path, result(2, tb), {}, shared).outcome == "tracebacks"
    assert classify(bad("a/b", []), tmp_path, result(-9, ""), {}, shared).outcome == "tracebacks"
    assert classify(bad("a/b", []), tmp_path, result(None, ""), {}, shared).outcome == "tracebacks"


def test_payload_marker_and_changed_data_outrank_a_clean_refusal(tmp_path, shared):
    kept = tmp_path / "notes"
    kept.write_text("mine")
    before = {str(kept): tree_hash(kept)}
    assert classify(bad("a/b", []), tmp_path, result(2, ERR, tmp=tmp_path), before, shared).outcome == "clear_errors"
    kept.write_text("")
    assert classify(bad("a/b", []), tmp_path, result(2, ERR, tmp=tmp_path), before, shared).outcome == "data_lost"
    (tmp_path / MARKER).touch()
    assert classify(bad("a/b", []), tmp_path, result(2, ERR, tmp=tmp_path), before, shared).outcome == "code_executed"


def test_refusal_that_still_wrote_its_output_is_silent_wrong(tmp_path, shared):
    case = bad("a/b", [], absent=("{tmp}/out.npz",))
    (tmp_path / "out.npz").write_bytes(b"half")
    r = classify(case, tmp_path, result(2, ERR, tmp=tmp_path), {}, shared)
    assert r.outcome == "silent_wrong" and "out.npz" in r.problem


def test_controls_and_fixes(tmp_path, shared):
    control = ok("a/b", [], check=wrote("{tmp}/out.obj"))
    assert classify(control, tmp_path, result(0), {}, shared).outcome == "controls_failed"
    (tmp_path / "out.obj").write_text("v 0 0 0\n")
    assert classify(control, tmp_path, result(0), {}, shared).outcome == "ok"
    assert classify(control, tmp_path, result(2, ERR, tmp=tmp_path), {}, shared).outcome == "controls_failed"
    fixes = Case("a/b", fixes=True, check=lambda c: None if (c.tmp / "out.obj").exists() else "not re-made")
    assert classify(fixes, tmp_path, result(0), {}, shared).outcome == "repaired"
    (tmp_path / "out.obj").unlink()
    assert classify(fixes, tmp_path, result(0), {}, shared).outcome == "silent_wrong"
    assert counts([classify(fixes, tmp_path, result(0), {}, shared)])["silent_wrong"] == 1
    refused = classify(fixes, tmp_path, result(2, ERR, tmp=tmp_path), {}, shared)
    assert (refused.outcome, refused.problem) == ("clear_errors", "refused; not re-made")
    assert refused.outcome not in fixes.good()


def test_crafted_payloads_do_run_code_when_loaded_unsafely(tmp_path):
    """The pickle payloads are real: loading one the unsafe way creates the marker (so a case that finds
    no marker shows that loosefit refused it)."""
    pickle.loads(craft.payload_pickle(tmp_path))
    assert (tmp_path / MARKER).exists()


def test_catalogue_covers_every_verb_and_every_brief():
    from loosefit.cli import build_parser

    cases = all_cases()
    meta = result_meta(cases)
    assert len(meta) >= 200
    assert sum(m.kind == "control" for m in meta.values()) >= 16 and sum(m.kind == "extreme" for m in meta.values()) >= 6
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    families = {c.family if c.family.startswith("export-") else c.family.split("-")[0] for c in cases} | {"view"}
    assert set(sub.choices) <= families, set(sub.choices) - families
    for brief in ("store", "inputs", "viewer"):
        assert len(defect_names(brief)) >= 5


SCRIPT = """import os, sys, time
mode = sys.argv[1]
if mode == "ok":
    print("out", os.getcwd(), sys.argv[2:], sys.stdin.read() == "")
    print("err", file=sys.stderr)
elif mode == "exit":
    sys.exit(2)
elif mode == "raise":
    raise ValueError("boom")
elif mode == "killed":
    os.kill(os.getpid(), 9)
else:
    time.sleep(60)
"""


def test_fork_server_behaves_as_a_fresh_process(tmp_path):
    """Exit status, output, working folder, traceback and a signal as ``python -m`` gives them; a timeout kills."""
    import os
    import subprocess
    import sys

    from tests.robustness.forkserver import ForkServer

    (tmp_path / "lib").mkdir()
    (tmp_path / "lib" / "probe.py").write_text(SCRIPT)
    env = dict(os.environ, PYTHONPATH=str(tmp_path / "lib"))
    server = ForkServer(sys.executable, env, preload=("json",))
    try:
        for argv in (["ok", "a b"], ["exit"], ["raise"], ["killed"]):
            fresh = subprocess.run([sys.executable, "-m", "probe", *argv], cwd=tmp_path, env=env, capture_output=True,
                                   text=True, stdin=subprocess.DEVNULL)
            code, out, err = server.run(argv, tmp_path, 30, module="probe")
            assert (code, out) == (fresh.returncode, fresh.stdout), argv
            assert err.strip().splitlines()[-1:] == fresh.stderr.strip().splitlines()[-1:], (err, fresh.stderr)
        assert out == "" and code == -9
        assert server.run(["ok"], tmp_path, 30, module="probe")[1] == f"out {tmp_path} [] True\n"
        assert server.run(["sleep"], tmp_path, 0.5, module="probe")[0] is None
        assert server.run(["exit"], tmp_path, 30, module="probe")[0] == 2  # still serving after a timeout
    finally:
        server.close()
    assert not server.outputs.exists()
