"""Cases of interrupts, hostile files and two processes at once: outputs over a run folder's or a
store's own files (``overwrite``), Ctrl-C and SIGTERM while a verb works (``interrupt``), refusals that must
change nothing (``keep``), locks (``lock``: a symbolic link as the lock file, two ``train`` into one run
folder), hostile files (``hostile``: YAML bombs and deep nesting, a 10,000-joint BVH chain, a zip-bomb
``.npz``, an endless procedural motion) and values that used to pass silently (``silent``: a motion at another
frame rate, a checkpoint holding NaN, NaN options, a shape key given twice, HTML in a run's name).

Every case belongs to the brief ``hostile``. Those the unit tests do not already run through the command line
are ``defect`` cases (tests/robustness/test_hostile_defects.py runs them); the others are measured by
``benchmarks/robustness.py`` (their direct tests: test_interrupts.py, test_refusals_keep_files.py,
test_yaml_limits.py, test_bvh_limits.py, test_npz_limits.py, test_option_values.py, test_silent_outputs.py).
"""

from __future__ import annotations

import signal
from pathlib import Path

import numpy as np

from tests.robustness import craft
from tests.robustness.cases_pipeline import GARMENT, TINY_TRAIN, plan, single_motion
from tests.robustness.harness import Case, Ctx
from tests.robustness.kit import also, bad, both, ext, ok, wrote
from tests.robustness.live import file_exists, interrupted, module_loaded, stored_ok, two_writers

BRIEF = "hostile"


def _epochs(options: list[str], low: int) -> list[str]:
    """``options`` (:data:`TINY_TRAIN`) with ``low`` epochs in the first stage."""
    return [a if a != "train.stages.low.epochs=2" else f"train.stages.low.epochs={low}" for a in options]


#: Long enough that a signal always lands while training works (hundreds of epochs of a tiny model).
LONG_TRAIN = _epochs(TINY_TRAIN, 500)
#: A plan whose short walk is stored in seconds while its 20 s spin still simulates.
SLOW_PLAN = """\
name: slow
garments:
  skirt: {template: skirt, seed: 0, edge_length: 0.06, params: {length: 0.4, flare: 20}}
motions:
  walk: {procedural: walk, seconds: 0.3, seed: 0}
  spin: {procedural: spin, seconds: 20.0, seed: 1}
sim_params:
  default: {preroll: 0.2}
"""


def copy_run(tmp: Path, sh) -> None:
    """The shared run as ``{tmp}/run``."""
    craft.copy_run(sh, tmp)


def copy_store(tmp: Path, sh) -> None:
    """The shared store as ``{tmp}/d.zarr``."""
    craft.copy_store(sh, tmp)


def long_motion(tmp: Path, sh) -> None:
    """``{tmp}/m.npz``: the shared walk, then its last pose held for 20 s (600 frames to simulate)."""
    craft.npz_edit(sh.motion, tmp / "m.npz",
                   rotations=lambda r: np.concatenate([r, np.repeat(r[-1:], 600, axis=0)]),
                   translation=lambda x: np.concatenate([x, np.repeat(x[-1:], 600, axis=0)]))


def linked_lock(folder: str):
    """``{tmp}/FOLDER/.lock`` is a symbolic link to ``{tmp}/victim.txt`` (which must stay as it is)."""
    def setup(tmp: Path, sh) -> None:
        craft.write(tmp / "victim.txt", "precious\n")
        (tmp / folder / ".lock").symlink_to(tmp / "victim.txt")
    return setup


def nan_checkpoint(tmp: Path, sh) -> None:
    """A copy of the shared run whose ``last.pt`` holds NaN in its first floating-point weight."""
    import torch

    path = craft.copy_run(sh, tmp) / "checkpoints" / "last.pt"
    state = torch.load(path, map_location="cpu", weights_only=True)  # our own file, made by the shared run
    name = next(k for k, v in state["model"].items() if torch.is_floating_point(v))
    state["model"][name] = torch.full_like(state["model"][name], float("nan"))
    torch.save(state, path)


def no_lock(folder: str):
    """The write lock of ``{tmp}/FOLDER`` was let go."""
    def check(c: Ctx):
        return f"{folder}/.lock is left behind" if (c.tmp / folder / ".lock").exists() else None
    return check


def resampled_to_30(c: Ctx):
    """``{tmp}/a.npz`` plays at 30 fps and covers the motion's duration (45 frames at 60 fps: 0.75 s)."""
    with np.load(c.tmp / "a.npz") as z:
        fps, frames = float(z["fps"]), z["verts"].shape[0]
    return None if fps == 30.0 and 22 <= frames <= 23 else f"wrote {frames} frames at {fps:g} fps"


def escaped(c: Ctx):
    """The run named with HTML, a pipe and backticks appears in report.md escaped, never raw."""
    text = (c.tmp / "rep" / "report.md").read_text()
    if "<b>" in text or "r<b>" in text:
        return "report.md holds the run's name unescaped"
    return None if "&lt;b&gt;" in text else "report.md does not name the run"


def overwrite_cases() -> list[Case]:
    """Outputs that would land on a run folder's own files or inside a store: refused naming the file, the run and
    the store byte-identical; ``--force`` writes; ordinary outputs beside a run's files still work."""
    run = ("{tmp}/run",)
    store = ("{tmp}/d.zarr",)
    anim = ["animate", "{run}", "--motion", "{motion}", "--out"]
    return [
        bad("overwrite/motion-map-over-method-yaml", ["motion", "map", "{tmp}/clip.bvh", "--out", "{tmp}/run/method.yaml"],
            also(copy_run, lambda t, s: craft.bvh_cut(t / "clip.bvh")), brief=BRIEF, defect=True,
            names=("method.yaml",), keep=run),
        bad("overwrite/garment-sidecar-over-model-json", ["garment", "make", "--kind", "skirt", "--edge-length", "0.05",
                                                          "--out", "{tmp}/run/model.obj"], copy_run, brief=BRIEF,
            defect=True, names=("model.json",), keep=run, absent=("{tmp}/run/model.obj",)),
        bad("overwrite/evaluate-over-training-log", ["evaluate", "{seq}", "{seq}", "--out", "{tmp}/run"], copy_run,
            brief=BRIEF, defect=True, names=("metrics.csv",), keep=run),
        bad("overwrite/render-into-run-folder", ["render", "{seq}", "--frame", "0", "--backend", "matplotlib", "--width",
                                                 "64", "--height", "48", "--out", "{tmp}/run"], copy_run, brief=BRIEF,
            defect=True, names=("run",), keep=run),
        bad("overwrite/animate-into-checkpoints", anim + ["{tmp}/run/checkpoints/best.npz"], copy_run, brief=BRIEF,
            defect=True, names=("checkpoints",), keep=run, absent=("{tmp}/run/checkpoints/best.npz",)),
        bad("overwrite/export-rig-link-to-checkpoint", ["export-rig", "{run}", "--motion", "{motion}", "--out",
                                                        "{tmp}/rig.glb"],
            also(copy_run, lambda t, s: (t / "rig.glb").symlink_to(t / "run" / "checkpoints" / "last.pt")),
            brief=BRIEF, defect=True, names=("rig.glb",), keep=run),
        bad("overwrite/motion-generate-into-store", ["motion", "generate", "--kind", "walk", "--seconds", "1", "--out",
                                                     "{tmp}/d.zarr/motions/walk.npz"], copy_store, brief=BRIEF,
            defect=True, names=("d.zarr",), keep=store, absent=("{tmp}/d.zarr/motions/walk.npz",)),
        bad("overwrite/simulate-single-into-store", ["simulate", "--garment", "{tmp}/g.obj", "--motion", "{tmp}/m.npz",
                                                     "--out", "{tmp}/d.zarr/s.npz"],
            also(copy_store, lambda t, s: craft.copy_garment(s, t), single_motion), brief=BRIEF, defect=True,
            names=("d.zarr",), keep=store, absent=("{tmp}/d.zarr/s.npz",)),
        bad("overwrite/report-into-store", ["report", "{tmp}/d.zarr", "{run}", "--no-images", "--out",
                                            "{tmp}/d.zarr/report"], copy_store, brief=BRIEF, defect=True,
            names=("d.zarr",), keep=store, absent=("{tmp}/d.zarr/report",)),
        bad("overwrite/view-export-into-store", ["view", "--no-collisions", "--export", "{tmp}/d.zarr/page", "{seq}"],
            copy_store, brief=BRIEF, defect=True, names=("d.zarr",), keep=store, absent=("{tmp}/d.zarr/page",)),
        bad("overwrite/train-into-store", ["train", "--method", "virtualbones", "--garment", GARMENT, *TINY_TRAIN,
                                           "--data", "{tmp}/d.zarr", "--out", "{tmp}/d.zarr"], copy_store, brief=BRIEF,
            defect=True, names=("d.zarr",), keep=store, absent=("{tmp}/d.zarr/checkpoints",)),
        bad("overwrite/body-into-store", ["body", "--resolution", "low", "--out", "{tmp}/d.zarr/bodies/x.npz"],
            copy_store, brief=BRIEF, defect=True, names=("d.zarr",), keep=store),
        bad("overwrite/demo-into-run-folder", ["demo", "--out", "{tmp}/run"], copy_run, brief=BRIEF, defect=True,
            names=("run",), keep=run, timeout=180),
        ok("overwrite/force-evaluate-over-training-log", ["evaluate", "{seq}", "{seq}", "--out", "{tmp}/run", "--force"],
           copy_run, brief=BRIEF, defect=True, check=wrote("{tmp}/run/metrics.json")),
        ok("overwrite/animation-beside-run-files", ["animate", "{tmp}/run", "--motion", "{motion}", "--out",
                                                    "{tmp}/run/walk.npz"], copy_run, brief=BRIEF, defect=True,
           check=wrote("{tmp}/run/walk.npz")),
        ok("overwrite/own-earlier-output", ["motion", "generate", "--kind", "walk", "--seconds", "1", "--out",
                                            "{tmp}/m.npz"], lambda t, s: craft.write(t / "m.npz", b"an earlier try"),
           brief=BRIEF, defect=True, check=lambda c: None if (c.tmp / "m.npz").stat().st_size > 100 else "m.npz not replaced"),
    ]


def interrupt_cases() -> list[Case]:
    """Ctrl-C and SIGTERM in every long verb: exit 130 / 143, one line naming what was kept and the command that
    resumes, nothing left running, the store's or run's lock let go."""
    train = ["train", "--method", "virtualbones", "--data", "{store}", "--garment", GARMENT, "--out", "{tmp}/r",
             *LONG_TRAIN]
    slow = ["simulate", "{tmp}/slow.yaml", "--out", "{tmp}/d.zarr"]
    single = ["simulate", "--garment", "{tmp}/g.obj", "--motion", "{tmp}/m.npz", "--out", "{tmp}/s.npz"]
    sgl = also(lambda t, s: craft.copy_garment(s, t), long_motion)
    # a Ctrl-C waits for the native SSDR solve under way to return: long enough to land in, short enough to wait for
    prep = ["prepare", "{tmp}/d.zarr", "--force", "--set", "iterations=200"]
    last = file_exists("{tmp}/r/checkpoints/last.pt")
    return [
        Case("interrupt/train-sigint", train, kind="bad", brief=BRIEF, names=("last.pt",), check=no_lock("r"), cost=6,
             runner=interrupted(signal.SIGINT, last)),
        Case("interrupt/train-sigterm", train, kind="bad", brief=BRIEF, names=("last.pt",), check=no_lock("r"), cost=6,
             runner=interrupted(signal.SIGTERM, last)),
        Case("interrupt/simulate-plan-sigint", slow, plan(SLOW_PLAN, "slow.yaml"), kind="bad", brief=BRIEF,
             names=("1 finished sequence",), check=no_lock("d.zarr"), cost=10,
             runner=interrupted(signal.SIGINT, stored_ok("d.zarr"))),
        Case("interrupt/simulate-ray-sigint", slow + ["--workers", "2"], plan(SLOW_PLAN, "slow.yaml"), kind="bad",
             brief=BRIEF, names=("1 finished sequence",), check=no_lock("d.zarr"), cost=12,
             runner=interrupted(signal.SIGINT, stored_ok("d.zarr"))),
        Case("interrupt/simulate-ray-sigterm", slow + ["--workers", "2"], plan(SLOW_PLAN, "slow.yaml"), kind="bad",
             brief=BRIEF, names=("1 finished sequence",), check=no_lock("d.zarr"), cost=12,
             runner=interrupted(signal.SIGTERM, stored_ok("d.zarr"))),
        Case("interrupt/simulate-single-sigint", single, sgl, kind="bad", brief=BRIEF, names=("s.npz",),
             absent=("{tmp}/s.npz",), cost=8, runner=interrupted(signal.SIGINT, module_loaded("/bpy/"), settle=15.0)),
        Case("interrupt/simulate-single-sigterm", single, sgl, kind="bad", brief=BRIEF, names=("s.npz",),
             absent=("{tmp}/s.npz",), cost=8, runner=interrupted(signal.SIGTERM, module_loaded("/bpy/"), settle=15.0)),
        Case("interrupt/prepare-sigterm", prep, copy_store, kind="bad", brief=BRIEF, names=("d.zarr",),
             check=no_lock("d.zarr"), cost=6, runner=interrupted(signal.SIGTERM, file_exists("{tmp}/d.zarr/.lock"),
                                                                 settle=1.0)),
    ]


def keep_cases() -> list[Case]:
    """Refusals change nothing (the folder hashed before and after), and say why."""
    resume = ["train", "--method", "virtualbones", "--data", "{store}", "--garment", GARMENT, *TINY_TRAIN, "--out",
              "{tmp}/run", "--resume"]
    return [
        bad("keep/resume-with-changed-model-setting", resume + ["--set", "model.lf_hidden=32"], copy_run, brief=BRIEF,
            names=("lf_hidden",), keep=("{tmp}/run",)),
        bad("keep/resume-with-changed-epochs", resume + ["--set", "train.stages.low.epochs=3"], copy_run, brief=BRIEF,
            names=("epochs",), keep=("{tmp}/run",)),
        bad("keep/resume-of-a-missing-run", resume[:-2] + ["{tmp}/never", "--resume"], brief=BRIEF, names=("never",),
            absent=("{tmp}/never",)),
        bad("keep/resume-of-a-folder-without-a-run", resume[:-2] + ["{tmp}/mine", "--resume"],
            lambda t, s: craft.write(t / "mine" / "notes.txt", "mine\n"), brief=BRIEF, names=("mine",),
            keep=("{tmp}/mine",)),
        bad("keep/prepare-bad-setting", ["prepare", "{tmp}/d.zarr", "--force", "--set", "influences=0"], copy_store,
            brief=BRIEF, names=("influences",), keep=("{tmp}/d.zarr",)),
        bad("keep/prepare-unknown-smoothing", ["prepare", "{tmp}/d.zarr", "--force", "--set", "smoothing=bogus"],
            copy_store, brief=BRIEF, names=("smoothing", "bogus"), keep=("{tmp}/d.zarr",)),
    ]


def lock_cases() -> list[Case]:
    """A lock file that is a symbolic link is refused and never followed; one run folder, one ``train``."""
    train = ["train", "--method", "virtualbones", "--data", "{store}", "--garment", GARMENT, "--out", "{tmp}/r"]
    return [
        bad("lock/store-lock-symlinked", ["info", "{tmp}/d.zarr", "--repair"], also(copy_store, linked_lock("d.zarr")),
            brief=BRIEF, names=(".lock",), keep=("{tmp}/d.zarr", "{tmp}/victim.txt")),
        bad("lock/run-lock-symlinked", ["train", "--method", "virtualbones", "--data", "{store}", "--garment", GARMENT,
                                        *TINY_TRAIN, "--out", "{tmp}/run", "--resume"],
            also(copy_run, linked_lock("run")), brief=BRIEF, defect=True, names=(".lock",),
            keep=("{tmp}/run", "{tmp}/victim.txt")),
        bad("lock/two-trains-one-run-folder", [], brief=BRIEF, names=("pid",), cost=10,
            runner=two_writers(train + _epochs(TINY_TRAIN, 200), train + TINY_TRAIN,
                               wait_for="{tmp}/r/checkpoints/last.pt")),
    ]


def hostile_cases() -> list[Case]:
    """Hostile files: refused quickly, naming the file and the limit, nothing written."""
    return [
        bad("hostile/yaml-bomb-plan", ["simulate", "{tmp}/bomb.yaml", "--out", "{tmp}/d.zarr"],
            plan(craft.yaml_bomb(), "bomb.yaml"), brief=BRIEF, names=("bomb.yaml",), absent=("{tmp}/d.zarr",),
            timeout=120),
        bad("hostile/yaml-deep-config", ["train", "--method", "virtualbones", "--data", "{store}", "--garment", GARMENT,
                                         "--config", "{tmp}/deep.yaml", "--out", "{tmp}/r"],
            plan("train:\n  stages: " + "{a: " * 5000 + "1" + "}" * 5000 + "\n", "deep.yaml"), brief=BRIEF,
            names=("deep.yaml",), absent=("{tmp}/r",), timeout=120),
        bad("hostile/yaml-self-alias-params", ["simulate", "--garment", "{tmp}/g.obj", "--motion", "{tmp}/m.npz",
                                               "--params", "{tmp}/p.yaml", "--out", "{tmp}/s.npz"],
            also(lambda t, s: craft.copy_garment(s, t), single_motion, plan("bending: &a [1, *a]\n", "p.yaml")),
            brief=BRIEF, names=("p.yaml",), absent=("{tmp}/s.npz",), timeout=120),
        bad("hostile/bvh-10000-joint-chain", ["motion", "map", "{tmp}/chain.bvh", "--out", "{tmp}/map.yaml"],
            lambda t, s: craft.write(t / "chain.bvh", craft.bvh_chain(10_000)), brief=BRIEF, names=("chain.bvh",),
            absent=("{tmp}/map.yaml",), timeout=120),
        bad("hostile/bvh-5000-joints", ["motion", "import", "{tmp}/wide.bvh", "--out", "{tmp}/m.npz"],
            lambda t, s: craft.write(t / "wide.bvh", craft.bvh_flat(5000)), brief=BRIEF, names=("wide.bvh",),
            absent=("{tmp}/m.npz",), timeout=120),
        bad("hostile/npz-zip-bomb-motion", ["body", "--motion", "{tmp}/bomb.npz", "--resolution", "low", "--out",
                                            "{tmp}/b.npz"], lambda t, s: craft.zip_bomb(t / "bomb.npz"), brief=BRIEF,
            names=("bomb.npz",), absent=("{tmp}/b.npz",), timeout=120),
        ext("hostile/generate-a-million-seconds", ["motion", "generate", "--kind", "walk", "--seconds", "1000000",
                                                   "--out", "{tmp}/m.npz"], brief=BRIEF, names=("MAX_SECONDS",),
            absent=("{tmp}/m.npz",), timeout=120),
        ext("hostile/generate-at-100000-fps", ["motion", "generate", "--kind", "walk", "--fps", "100000", "--out",
                                               "{tmp}/m.npz"], brief=BRIEF, names=("MAX_FPS",),
            absent=("{tmp}/m.npz",), timeout=120),
    ]


def silent_cases() -> list[Case]:
    """Values that used to pass without a word."""
    return [
        bad("silent/animate-motion-at-60-fps", ["animate", "{run}", "--motion", "{tmp}/m.npz", "--out", "{tmp}/a.npz"],
            lambda t, s: craft.npz_edit(s.motion, t / "m.npz", fps=np.float64(60.0)), brief=BRIEF,
            report=("resampled",), check=resampled_to_30),
        ext("silent/checkpoint-with-nan", ["animate", "{tmp}/run", "--motion", "{motion}", "--checkpoint", "last",
                                           "--out", "{tmp}/a.npz"], nan_checkpoint, brief=BRIEF,
            names=("last.pt",), absent=("{tmp}/a.npz",)),
        ext("silent/evaluate-sted-c-nan", ["evaluate", "{seq}", "{seq}", "--sted-c", "nan", "--out", "{tmp}/m"],
            brief=BRIEF, names=("--sted-c",), absent=("{tmp}/m",)),
        ext("silent/evaluate-tolerance-inf", ["evaluate", "{seq}", "{seq}", "--tolerance", "inf", "--out", "{tmp}/m"],
            brief=BRIEF, names=("--tolerance",), absent=("{tmp}/m",)),
        ext("silent/garment-length-nan", ["garment", "make", "--kind", "skirt", "--length", "nan", "--out",
                                          "{tmp}/g.obj"], brief=BRIEF, names=("--length",), absent=("{tmp}/g.obj",)),
        bad("silent/shape-key-twice", ["body", "--shape", "height=0.1,height=0.9", "--resolution", "low", "--out",
                                       "{tmp}/b.obj"], brief=BRIEF, names=("height",), absent=("{tmp}/b.obj",)),
        ok("silent/report-escapes-a-run-name", ["report", "{store}", "{run}", "{tmp}/r<b>|x`y`", "--no-images",
                                                "--out", "{tmp}/rep"],
           lambda t, s: craft.copy_run(s, t, "r<b>|x`y`"), brief=BRIEF, check=both(wrote("{tmp}/rep/report.md"),
                                                                                   escaped), cost=5),
    ]


def hostile_brief_cases() -> list[Case]:
    return [*overwrite_cases(), *interrupt_cases(), *keep_cases(), *lock_cases(), *hostile_cases(), *silent_cases()]
