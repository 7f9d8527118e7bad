"""Cases of the verbs that write or read a dataset store and run folders: ``info`` (and ``--repair``),
``simulate`` (plan and single sequence, plan YAML, simulation parameters), two writers on one store,
``prepare`` and ``train`` (config YAML, overrides, checkpoints)."""

from __future__ import annotations

import json
import socket
from pathlib import Path

from tests.robustness import craft
from tests.robustness.cases_files import PROC, parent_file
from tests.robustness.harness import Case
from tests.robustness.kit import also, bad, both, ext, gone, lists_problem, ok, reads_back, repaired_store, wrote
from tests.robustness.live import then, two_writers

#: A plan small enough to simulate in seconds (a coarse skirt, 0.3 s of walk); ``{seed}`` of the walk.
QUICK_PLAN = """\
name: quick
garments:
  skirt: {{template: skirt, seed: 0, edge_length: 0.06, params: {{length: 0.4, flare: 20}}}}
motions:
  walk: {{procedural: walk, seconds: 0.3, seed: {seed}}}
sim_params:
  default: {{preroll: 0.2}}
"""
#: Tiny networks and two epochs per stage: a training run of seconds on the shared store (as benchmarks/tiny_run.py).
TINY_TRAIN = ["--set", "model.lf_hidden=16", "--set", "model.hf_hidden=16", "--set", "model.edge_channels=[8]",
              "--set", "train.stages.low.epochs=2", "--set", "train.stages.high.epochs=2", "--set", "train.progress=false",
              "--set", "train.tensorboard=false", "--set", "data.window=20", "--set", "data.stride=20",
              "--set", "data.burn_in=4"]
GARMENT = "skirt+average"


def _two_more_motions(text: str) -> str:
    """The quick plan with two more motions of a second: its writer holds the store for many seconds, long
    enough for a second writer to start (several seconds of imports) while it runs."""
    return text.replace("sim_params:", "  spin: {procedural: spin, seconds: 1.0, seed: 1}\n"
                                       "  sway: {procedural: sway, seconds: 1.0, seed: 2}\nsim_params:")


def plan(text: str, name: str = "plan.yaml"):
    return lambda t, s: craft.write(t / name, text)


def quick(seed: int = 0, name: str = "plan.yaml", edit=None):
    text = QUICK_PLAN.format(seed=seed)
    return plan(edit(text) if edit else text, name)


def store_copy(damage=None, split: str = "train"):
    """A copy of the shared store as ``{tmp}/d.zarr``, ``damage(store, sequence of split, tmp)`` applied."""
    def setup(tmp, sh):
        store = craft.copy_store(sh, tmp)
        if damage is not None:
            damage(store, craft.sequence_named(store, split), tmp)
    return setup


def truncated(store, seq, tmp):
    craft.truncate(craft.first_chunk(store, seq))


def flipped(store, seq, tmp):
    craft.flip_byte(craft.first_chunk(store, seq))


def chunk_deleted(store, seq, tmp):
    craft.first_chunk(store, seq).unlink()


def zattrs_garbage(store, seq, tmp):
    craft.write(store / "sequences" / seq / ".zattrs", "{not json")


def zarray_garbage(store, seq, tmp):
    craft.write(store / "sequences" / seq / "verts" / ".zarray", "\x00garbage")


def pickle_codec(store, seq, tmp):
    craft.pickle_codec_array(store, seq, tmp)


def creating_litter(tmp: Path, sh) -> None:
    """A stale creation leftover beside the store (its creator's pid is dead)."""
    litter = tmp / f".d.zarr.creating-{craft.dead_pid()}"
    (litter / "garments").mkdir(parents=True)
    craft.write(litter / ".zgroup", '{"zarr_format": 2}')


def stale_lock(tmp: Path, sh) -> None:
    craft.write(tmp / "d.zarr" / ".lock", json.dumps({"pid": craft.dead_pid(), "host": socket.gethostname(),
                                                      "since": "2020-01-01T00:00:00+00:00"}))


def single_motion(tmp: Path, sh) -> None:
    """The first 9 frames of the shared motion (0.3 s)."""
    craft.npz_edit(sh.motion, tmp / "m.npz", rotations=lambda r: r[:9], translation=lambda x: x[:9])


def planted_litter(tmp: Path, sh) -> None:
    """A copy of the shared run with the temp files a killed checkpoint / record write leaves."""
    run = craft.copy_run(sh, tmp)
    craft.write(run / "checkpoints" / ".last.pt.k3j9x2ab.pt", b"half a checkpoint")
    craft.write(run / ".model.json.q8w1e4rt.json", '{"method": "virtu')


def store_cases() -> list[Case]:
    info = ["info", "{tmp}/d.zarr"]
    kept = ("{tmp}/d.zarr",)
    clean_after = then(["info", "{tmp}/d.zarr"],
                       lambda r: None if "problems: none" in r.stdout else "`info` still finds problems after the repair")
    sim_resume = ["simulate", "{plan}", "--out", "{tmp}/d.zarr"]
    return [
        ok("info/store", ["info", "{store}"], check=lambda c: None if "problems: none" in c.result.stdout
           else "the shared store is not reported clean"),
        ok("info/json", ["info", "{store}", "--json"], check=lambda c: json.loads(c.result.stdout) and None),
        bad("info/missing", ["info", "{tmp}/none.zarr"], names=("none.zarr",)),
        bad("info/a-file", ["info", "{tmp}/d.zarr"], lambda t, s: craft.write(t / "d.zarr", "x"), names=("d.zarr",)),
        bad("info/empty-folder", ["info", "{tmp}/d.zarr"], lambda t, s: (t / "d.zarr").mkdir(), names=("d.zarr",)),
        bad("info/root-attributes-garbage", info, store_copy(lambda st, q, t: craft.write(st / ".zattrs", "{oops")),
            names=("d.zarr",), keep=kept),
        bad("info/newer-format", info, store_copy(lambda st, q, t: craft.write(
            st / ".zattrs", json.dumps({**json.loads((st / ".zattrs").read_text()), "format_version": 99}))),
            names=("d.zarr",), keep=kept),
        bad("info/truncated-chunk", info, store_copy(truncated), brief="store", defect=True, report=("problem",),
            check=lists_problem(), keep=kept),
        bad("info/flipped-byte-chunk", info, store_copy(flipped), brief="store", defect=True, report=("problem",),
            check=lists_problem(), keep=kept),
        bad("info/deleted-chunk", info, store_copy(chunk_deleted), brief="store", report=("problem",),
            check=lists_problem(), keep=kept),
        bad("info/garbage-sequence-attributes", info, store_copy(zattrs_garbage), brief="store", defect=True,
            report=("problem",), check=lists_problem(), keep=kept),
        bad("info/garbage-array-metadata", info, store_copy(zarray_garbage), brief="store", report=("problem",),
            check=lists_problem(), keep=kept),
        bad("info/pickle-codec-array", info, store_copy(pickle_codec), brief="store", defect=True, report=("problem",),
            check=lists_problem(), keep=kept),
        bad("info/repair-truncated-chunk", info + ["--repair"], store_copy(truncated), brief="store", defect=True,
            fixes=True, check=repaired_store(), runner=clean_after),
        bad("info/repair-pickle-codec-array", info + ["--repair"], store_copy(pickle_codec), brief="store", fixes=True,
            check=repaired_store(), runner=clean_after),
        # writers: resume, litter, locks
        bad("store/resume-resimulates-truncated-chunk", sim_resume, store_copy(truncated), brief="store", defect=True,
            fixes=True, check=reads_back(), timeout=400, cost=8),
        bad("store/creating-litter-cleaned", sim_resume, also(store_copy(), creating_litter), brief="store", defect=True,
            fixes=True, check=gone(".d.zarr.creating-*"), cost=3),
        ok("store/stale-lock-taken-over", sim_resume, also(store_copy(), stale_lock), cost=3),
        bad("store/failed-plan-leaves-no-store", ["simulate", "{tmp}/plan.yaml", "--out", "{tmp}/s.zarr"],
            quick(edit=lambda t: t.replace("{procedural: walk, seconds: 0.3, seed: 0}", "{file: none.npz}")),
            brief="store", defect=True, names=("none.npz",), absent=("{tmp}/s.zarr",), cost=2),
        bad("store/two-writers", [], also(quick(0, "a.yaml", _two_more_motions), quick(5, "b.yaml")), brief="store",
            defect=True, names=("pid",), cost=12,
            runner=two_writers(["simulate", "{tmp}/a.yaml", "--out", "{tmp}/s.zarr"],
                               ["simulate", "{tmp}/b.yaml", "--out", "{tmp}/s.zarr"], wait_for="{tmp}/s.zarr")),
        bad("store/two-creators", [], also(quick(0, "a.yaml", _two_more_motions), quick(5, "b.yaml")), brief="store",
            defect=True, names=("s.zarr",), cost=12,
            runner=two_writers(["simulate", "{tmp}/a.yaml", "--out", "{tmp}/s.zarr"],
                               ["simulate", "{tmp}/b.yaml", "--out", "{tmp}/s.zarr"], wait_for=None)),
    ]


def simulate_cases() -> list[Case]:
    p = ["simulate", "{tmp}/plan.yaml", "--out", "{tmp}/s.zarr"]
    no_store = ("{tmp}/s.zarr",)
    single = ["simulate", "--garment", "{tmp}/g.obj", "--motion", "{tmp}/m.npz", "--out"]
    sgl = also(lambda t, s: craft.copy_garment(s, t), single_motion)
    return [
        ok("simulate/single", single + ["{tmp}/s.npz"], sgl, check=wrote("{tmp}/s.npz"), cost=5),
        bad("simulate/plan-with-set", p + ["--set", "backend=foo"], quick(), brief="inputs", defect=True,
            names=("--set",), absent=no_store, cost=4),
        bad("simulate/plan-with-params", p + ["--params", "{tmp}/p.yaml"],
            also(quick(), plan("bending: 1.0e-3\n", "p.yaml")), brief="inputs", defect=True, names=("--params",),
            absent=no_store, cost=4),
        bad("simulate/plan-with-shape", p + ["--shape", "height=0.8"], quick(), brief="inputs", defect=True,
            names=("--shape",), absent=no_store, cost=4),
        bad("simulate/plan-with-joint-map", p + ["--joint-map", "cc"], quick(), brief="inputs", defect=True,
            names=("--joint-map",), absent=no_store, cost=4),
        bad("simulate/plan-duplicate-key", p, quick(edit=lambda t: t.replace(
            "sim_params:", "  walk: {procedural: spin, seconds: 0.3, seed: 1}\nsim_params:")), brief="inputs",
            defect=True, names=("plan.yaml",), absent=no_store, cost=4),
        bad("simulate/plan-yaml-syntax", p, quick(edit=lambda t: t + "motions: [unclosed\n"), names=("plan.yaml",),
            absent=no_store),
        bad("simulate/plan-unknown-key", p, quick(edit=lambda t: t + "garmets: {}\n"), names=("plan.yaml",),
            absent=no_store),
        bad("simulate/plan-unknown-template", p, quick(edit=lambda t: t.replace("template: skirt", "template: cape")),
            brief="store", names=("plan.yaml", "cape"), absent=no_store),
        bad("simulate/plan-bad-garment-parameter", p,
            quick(edit=lambda t: t.replace("edge_length: 0.06", "edge_length: 0.5")),
            brief="inputs", names=("plan.yaml",), absent=no_store),
        bad("simulate/plan-a-list", p, plan("- walk\n- spin\n"), names=("plan.yaml",), absent=no_store),
        bad("simulate/plan-python-tag", p, quick(edit=lambda t: t.replace(
            "name: quick", "name: !!python/object/apply:builtins.open [PAYLOAD-RAN, w]")), names=("plan.yaml",),
            absent=no_store),
        bad("simulate/plan-missing", p, names=("plan.yaml",), absent=no_store),
        bad("simulate/plan-negative-seconds", p, quick(edit=lambda t: t.replace("seconds: 0.3", "seconds: -1")),
            names=("plan.yaml", "seconds"), absent=no_store),
        bad("simulate/plan-out-in-proc", ["simulate", "{tmp}/plan.yaml", "--out", PROC + ".zarr"], quick(),
            brief="inputs", defect=True, names=("/proc",)),
        bad("simulate/plan-out-parent-is-file", ["simulate", "{tmp}/plan.yaml", "--out", "{tmp}/file/s.zarr"],
            also(quick(), parent_file), brief="inputs", names=("file/s.zarr",)),
        bad("simulate/plan-workers-zero", p + ["--workers", "0"], quick(), names=("--workers",), absent=no_store,
            timeout=300),
        bad("simulate/single-out-parent-is-file", single + ["{tmp}/file/s.npz"], also(sgl, parent_file),
            brief="inputs", defect=True, names=("file/s.npz",), cost=4),
        bad("simulate/single-out-in-proc", single + [PROC + ".npz"], sgl, brief="inputs", names=("/proc",), cost=4),
        bad("simulate/single-one-triangle", single + ["{tmp}/s.npz"], also(single_motion, lambda t, s: craft.write(
            t / "g.obj", "v 0 0 1\nv 0.3 0 1\nv 0 0 0.7\nf 1 2 3\n")), brief="inputs", defect=True, names=("g.obj",),
            absent=("{tmp}/s.npz",), cost=3),
        bad("simulate/single-set-unknown-backend", single + ["{tmp}/s.npz", "--set", "backend=foo"], sgl,
            names=("backend", "foo"), absent=("{tmp}/s.npz",)),
        bad("simulate/single-set-negative-bending", single + ["{tmp}/s.npz", "--set", "bending=-1"], sgl,
            names=("bending",), absent=("{tmp}/s.npz",)),
        bad("simulate/single-set-unknown-key", single + ["{tmp}/s.npz", "--set", "bendy=1"], sgl, names=("bendy",),
            absent=("{tmp}/s.npz",)),
        bad("simulate/single-params-duplicate-key", single + ["{tmp}/s.npz", "--params", "{tmp}/p.yaml"],
            also(sgl, plan("bending: 1.0e-5\nbending: 1.0e-3\n", "p.yaml")), brief="inputs", defect=True,
            names=("p.yaml",), absent=("{tmp}/s.npz",), cost=4),
        bad("simulate/single-truncated-motion", single + ["{tmp}/s.npz"],
            also(sgl, lambda t, s: craft.truncate(t / "m.npz")), brief="inputs", names=("m.npz",)),
        ext("simulate/single-nan-motion", single + ["{tmp}/s.npz"], also(sgl, lambda t, s: craft.npz_edit(
            t / "m.npz", t / "m.npz", rotations=lambda r: r * float("nan"))), names=("m.npz",)),
        bad("simulate/plan-and-garment", p + ["--garment", "{garment}"], quick(), names=("plan", "garment")),
        bad("simulate/nothing-to-simulate", ["simulate", "--out", "{tmp}/s.npz"], names=("garment", "plan")),
    ]


def train_cases() -> list[Case]:
    t = ["train", "--method", "virtualbones", "--garment", GARMENT, *TINY_TRAIN]
    on_copy = t + ["--data", "{tmp}/d.zarr", "--out", "{tmp}/r"]
    kept = ("{tmp}/d.zarr",)
    prep = ["prepare", "{tmp}/d.zarr", "--force", "--bones", "6"]
    prep_kept = ("{tmp}/d.zarr/sequences", "{tmp}/d.zarr/garments", "{tmp}/d.zarr/motions")
    out = ["--data", "{store}", "--out", "{tmp}/r"]
    return [
        ok("prepare/force", prep, store_copy(), cost=4),
        bad("prepare/missing-store", ["prepare", "{tmp}/none.zarr"], names=("none.zarr",)),
        bad("prepare/a-file", ["prepare", "{tmp}/d.zarr"], lambda t, s: craft.write(t / "d.zarr", "x"), names=("d.zarr",)),
        bad("prepare/zero-bones", prep[:-1] + ["0"], store_copy(), defect=True, names=("bones",), keep=kept),
        bad("prepare/negative-bones", prep[:-1] + ["-3"], store_copy(), names=("bones",), keep=kept),
        bad("prepare/unknown-setting", ["prepare", "{tmp}/d.zarr", "--set", "bone=3"], store_copy(), names=("bone",),
            keep=kept),
        bad("prepare/truncated-chunk", prep, store_copy(truncated), brief="store", defect=True, names=("d.zarr",),
            keep=prep_kept, cost=2),
        bad("prepare/garbage-sequence-attributes", prep, store_copy(zattrs_garbage), brief="store", defect=True,
            names=("d.zarr",), keep=prep_kept, cost=2),
        bad("prepare/pickle-codec-array", prep, store_copy(pickle_codec), brief="store",
            names=("d.zarr",), keep=prep_kept, cost=2),
        ok("train/body-lbs", ["train", "--method", "body-lbs", "--garment", GARMENT, *out],
           check=wrote("{tmp}/r/model.json"), cost=2),
        bad("train/unknown-method", ["train", "--method", "vbones", "--garment", GARMENT, *out], names=("vbones",)),
        bad("train/missing-store", ["train", "--method", "virtualbones", "--garment", GARMENT, "--data", "{tmp}/none.zarr",
                                    "--out", "{tmp}/r"], names=("none.zarr",), absent=("{tmp}/r",)),
        bad("train/unknown-garment", ["train", "--method", "virtualbones", "--garment", "cape", *out], names=("cape",),
            absent=("{tmp}/r",)),
        bad("train/config-duplicate-key", t + out + ["--config", "{tmp}/c.yaml"],
            plan("train:\n  lr: 1.0e-3\n  lr: 1.0e-1\n", "c.yaml"), brief="inputs", defect=True, names=("c.yaml",),
            absent=("{tmp}/r",), cost=3),
        bad("train/config-yaml-syntax", t + out + ["--config", "{tmp}/c.yaml"], plan("train: [lr\n", "c.yaml"),
            names=("c.yaml",), absent=("{tmp}/r",)),
        bad("train/config-python-tag", t + out + ["--config", "{tmp}/c.yaml"],
            plan("train: !!python/object/apply:builtins.open [PAYLOAD-RAN, w]\n", "c.yaml"), names=("c.yaml",),
            absent=("{tmp}/r",)),
        bad("train/set-unknown-key", t + out + ["--set", "train.epoch=3"], names=("epoch",), absent=("{tmp}/r",)),
        bad("train/set-not-a-number", t + out + ["--set", "train.lr=fast"], names=("lr",), absent=("{tmp}/r",)),
        bad("train/set-negative-epochs", t + out + ["--set", "train.epochs=-1"], names=("epochs",), absent=("{tmp}/r",)),
        bad("train/nproc-zero", t + out + ["--nproc", "0"], names=("nproc",), absent=("{tmp}/r",)),
        bad("train/out-is-a-file", t + ["--data", "{store}", "--out", "{tmp}/runfile"],
            lambda t_, s: craft.write(t_ / "runfile", "my notes\n"), brief="inputs", defect=True, names=("runfile",),
            keep=("{tmp}/runfile",)),
        bad("train/out-in-proc", t + ["--data", "{store}", "--out", PROC], brief="inputs", names=("/proc",)),
        bad("train/out-parent-is-file", t + ["--data", "{store}", "--out", "{tmp}/file/r"], parent_file, brief="inputs",
            names=("file/r",)),
        bad("train/truncated-chunk", on_copy, store_copy(truncated), brief="store", defect=True, names=("d.zarr",),
            keep=kept, absent=("{tmp}/r/checkpoints/last.pt",), cost=2),
        bad("train/garbage-sequence-attributes", on_copy, store_copy(zattrs_garbage), brief="store", defect=True,
            names=("d.zarr",), keep=kept, absent=("{tmp}/r/checkpoints/last.pt",), cost=2),
        bad("train/pickle-codec-array", on_copy, store_copy(pickle_codec), brief="store", defect=True,
            names=("d.zarr",), keep=kept, absent=("{tmp}/r/checkpoints/last.pt",), cost=2),
        bad("train/resume-truncated-checkpoint", t + ["--data", "{store}", "--out", "{tmp}/run", "--resume"],
            lambda t_, s: craft.truncate(craft.copy_run(s, t_) / "checkpoints" / "last.pt"), names=("last.pt",)),
        bad("train/existing-run-without-resume", t + ["--data", "{store}", "--out", "{tmp}/run"],
            lambda t_, s: craft.copy_run(s, t_), names=("run",), keep=("{tmp}/run",)),
        bad("train/resume-cleans-temp-files", ["train", "--method", "virtualbones", "--garment", GARMENT, "--data",
                                               "{store}", "--out", "{tmp}/run", "--resume"], planted_litter,
            brief="inputs", defect=True, fixes=True, check=both(gone("run/checkpoints/.last.pt.*", "run/.model.json.*"),
                                                                 wrote("{tmp}/run/checkpoints/last.pt")), cost=3),
    ]
