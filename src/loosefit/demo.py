"""``make demo`` / ``loosefit demo``: the whole pipeline on the embedded default data, from nothing.

simulate the training and validation motions of ``configs/datasets/demo.yaml`` (a skirt on short procedural
motions and, when ``../shared/mocap`` is beside the project, pieces of CMU capture) -> prepare (virtual bones) ->
train VirtualBones and JointNet briefly, choosing their checkpoints on the validation motions, while the held-out
motions (a spin and a capture walk on uneven terrain of a subject nothing trains on) are simulated on the other core -> animate them
with both and the body-LBS baseline -> a metrics table per held-out motion (the report is built beside it) ->
``demo_out/``: a side-by-side MP4 of the capture walk (the spin without the capture files: ground truth |
VirtualBones | JointNet, coloured by error), a PNG of one frame, the metrics as CSV / JSON per motion, the JointNet
animation as ``.usdc`` and ``.glb``, every prediction as a mesh-sequence ``.npz`` (``predictions/``), and last the
comparison report (``report/index.html``, ``loosefit report``) with the ``loosefit view`` command that plays the
simulation beside the predictions. Each held-out motion is simulated five times (four runs with 10 micrometres of
start noise): the metrics give each method's RMSE against the mean of the five and the floor, their spread about
it, below which no deterministic model can score against one run. Every stage resumes: running the demo again
reuses what is already there.
"""

from __future__ import annotations

import json
import multiprocessing
import shutil
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from loosefit.errors import InputError

#: The repository's configs (the demo runs from a source checkout, as ``make demo`` does).
CONFIGS = Path(__file__).resolve().parents[2] / "configs"

#: Short training for the demo, in minutes on 2 cores: the paper's layer sizes for VirtualBones (its global
#: layer factorised through 64 channels), a narrower JointNet (its paper sizes need a GPU to train). Every 3 s
#: motion is one training window from the zero state, as animation starts (90 frames, no warm-up), four to a
#: batch. These settings were chosen on the spin of seed 11, a validation motion of the plan
#: (benchmarks/experiments/LOG.md, "The demo's training"): VirtualBones' rate 2e-3 over 1e-3 and then 150 low-frequency epochs; the high-frequency
#: loss on 30 random frames of a window (the same error, that stage 2.6x faster); not taken: GRUs of 256 units,
#: batches of 8 (both worse on it). The held-out motions never chose anything.
WHOLE_SEQUENCES = ["data.window=90", "data.stride=90", "data.burn_in=0", "train.batch_size=4", "train.progress=false"]
DEMO_TRAINING = {
    "body-lbs": [],
    "virtualbones": ["train.stages.low.epochs=150", "train.stages.high.epochs=10", "train.lr=2e-3",
                     "model.global_rank=64", "model.hf_loss_frames=30", *WHOLE_SEQUENCES],
    "jointnet": ["model.gru_hidden=128", "model.features=128", "model.bone_mlp=[256,256]", "model.psd_mlp=[128]",
                 "model.psd_shapes=16", "train.optimizer=adam", "train.stages.stage1.epochs=32",
                 "train.stages.stage2.epochs=12", *WHOLE_SEQUENCES],
}
#: Models trained at once (one process each, one thread each) and Blender simulations at once (Ray workers).
TRAIN_PROCESSES = 2
SIM_WORKERS = 2


class _Stages:
    """Prints each stage's title and keeps its wall-clock seconds (``seconds``: stage key -> s)."""

    def __init__(self):
        self.seconds: dict[str, float] = {}
        self._key, self._start = None, 0.0

    def __call__(self, key: str, message: str) -> float:
        self.stop()
        print(f"\n== {message}", flush=True)
        self._key, self._start = key, time.perf_counter()
        return self._start

    def stop(self) -> None:
        if self._key is not None:
            self.seconds[self._key] = round(time.perf_counter() - self._start, 1)
            self._key = None


def run_demo(out: Path, plan: Path | None = None, bones: int = 32) -> dict:
    """Run the demo into ``out``; returns the metric rows of every held-out motion per method,
    ``{motion: {method: row}}`` (:func:`loosefit.metrics.report.evaluate_sequence`'s rows)."""
    from loosefit.animate import Animator
    from loosefit.body import AnnyBody
    from loosefit.data import DatasetStore
    from loosefit.io.export import export_animation
    from loosefit.metrics.report import SequencePair, evaluate
    from loosefit.models.collision import handle_motion_collisions
    from loosefit.rig.prepare import prepare
    from loosefit.simulate import run_plan
    from loosefit.sim.plan import load_plan
    from loosefit.viz.render import render_video, save_png, render_frames
    from loosefit.viz.scene import BODY_COLOR, MeshTrack

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    plan = plan or CONFIGS / "datasets" / "demo.yaml"
    data = out / "demo.zarr"
    started = time.perf_counter()

    loaded = load_plan(plan)
    held_out = [job for job in loaded.jobs if job.split == "test"]
    if not held_out:
        raise InputError("the plan has no test sequence to animate", plan)
    if loaded.missing_motions:
        print(f"   the motion capture files of {', '.join(loaded.missing_motions)} are not here "
              f"(../shared/mocap beside the project): the demo runs on its procedural motions only")

    _step = _Stages()
    t = _step("simulate", f"simulate the training and validation motions of {loaded.name} with Blender cloth")
    summary = run_plan(plan, data, workers=SIM_WORKERS, splits=("train", "val"))
    print(f"   {summary['ok']} ok, {summary['failed']} failed, {summary['skipped']} already done ({time.perf_counter() - t:.0f} s)")

    t = _step("prepare", f"prepare: {bones} virtual bones per garment (SSDR)")
    prepared = prepare(data, bones=bones)
    for g, entry in prepared["garments"].items():
        if "bones" in entry:
            print(f"   {g}: low-frequency SSDR RMSE {entry['rmse_lf_mm']:.2f} mm ({time.perf_counter() - t:.0f} s)")

    t = _step("train", f"train {', '.join(DEMO_TRAINING)} ({TRAIN_PROCESSES} at a time, one thread each), and simulate "
                       "the held-out motions with their reference runs beside VirtualBones")
    # One process per job, each on one thread, so that two share the two cores of a small machine. VirtualBones
    # trains longest: the held-out simulations (only the evaluation reads them), body-LBS and JointNet take turns
    # on the other core.
    garment_name = held_out[0].garment_entry
    context = multiprocessing.get_context("spawn")  # a fresh interpreter: no torch state forked mid-use
    with ProcessPoolExecutor(TRAIN_PROCESSES, mp_context=context) as pool:
        def train(m):
            return pool.submit(_train, m, data, garment_name, out / "runs" / m, DEMO_TRAINING[m])

        jobs = {"virtualbones": train("virtualbones")}  # submitted first: the pool starts jobs in order
        simulated = pool.submit(run_plan, plan, data, workers=1, splits=("test",), progress=False)
        jobs.update({m: train(m) for m in DEMO_TRAINING if m != "virtualbones"})
        summary = simulated.result()
        print(f"   the held-out motions: {summary['ok']} ok, {summary['failed']} failed, with "
              f"{summary['references']['ok']} reference runs ok", flush=True)
        for method, job in jobs.items():
            print(f"   {method}: trained in {job.result():.0f} s", flush=True)

    store = DatasetStore.open(data)
    test = [job.id for job in held_out if job.id in store.sequence_names(split="test", status="ok")]
    if not test:
        raise InputError("the held-out motions failed the simulation's quality gate: nothing to evaluate", data)
    garment = store.garment(store.sequence(test[0]).garment)
    from loosefit.report import build_report

    # The report animates and evaluates every run again, with collision handling: built on the other core meanwhile.
    reporter = ProcessPoolExecutor(1, mp_context=context)
    try:
        report = reporter.submit(build_report, data, [out / "runs" / m for m in DEMO_TRAINING], out / "report")
        animators = {m: Animator(out / "runs" / m) for m in DEMO_TRAINING}
        t = _step("evaluate", f"evaluate on the held-out motions {', '.join(store.sequence(n).motion for n in test)} "
                              "(collision handling exact)")
        results, shown = {}, None
        for name in test:
            seq = store.sequence(name)
            motion = store.motion(seq.motion)
            body = AnnyBody(_shape(store, seq.body))
            # with the collision handling `loosefit animate` applies by default (exact, against the posed body)
            predictions = {m: handle_motion_collisions(a.animate(motion), garment.faces, body, motion, "exact",
                                                       rest=garment.verts)
                           for m, a in animators.items()}
            posed = body.pose(motion)
            # the reference runs (start noise): RMSE against the mean of the runs and their spread, the floor
            references = store.references(seq.name)
            gt = np.asarray(seq.verts[:])
            pairs = [SequencePair(m, p, gt, garment.faces, posed.verts, body.faces, references)
                     for m, p in predictions.items()]
            result = evaluate(pairs, progress=False)
            print(f"   {seq.motion}:\n{result.table(overall=False)}")  # rows are methods: pooling them means nothing
            result.write_csv(out / f"metrics-{seq.motion}.csv")
            result.write_json(out / f"metrics-{seq.motion}.json")
            results[seq.motion] = {row["name"]: row for row in result.rows}
            if shown is None or ":seed=" not in motion.name:  # the capture clip when there is one
                shown = (seq, motion, posed, body, gt, predictions)

        seq, motion, posed, body, gt, predictions = shown
        t = _step("render and export", f"render and export {seq.motion}")
        err = {m: np.linalg.norm(predictions[m] - gt, axis=-1) * 1e3 for m in ("virtualbones", "jointnet")}
        clim = (0.0, float(max(np.percentile(e, 95) for e in err.values())))  # one colour scale for both

        def panel(verts, label, scalars=None):
            body_track = MeshTrack(posed.verts, body.faces, color=BODY_COLOR, label="body")
            garment_track = MeshTrack(verts, garment.faces, scalars=scalars, cmap="inferno", clim=clim,
                                      label=label, scalar_name="error (mm)")
            return [body_track, garment_track]

        panels = [panel(gt, "simulation (Blender)"), panel(predictions["virtualbones"], "VirtualBones", err["virtualbones"]),
                  panel(predictions["jointnet"], "JointNet", err["jointnet"])]
        titles = ["simulation", "VirtualBones", "JointNet"]
        render_video(panels, out / "demo.mp4", fps=motion.fps, size=(480, 540), titles=titles)
        middle = motion.num_frames // 2
        save_png(out / "demo.png", render_frames(panels, size=(480, 540), frames=[middle], titles=titles)[0])
        export_animation(out / "jointnet.usdc", predictions["jointnet"], garment.faces, motion.fps, posed.verts, body.faces)
        export_animation(out / "jointnet.glb", predictions["jointnet"], garment.faces, motion.fps)
        for method, verts in predictions.items():
            export_animation(out / "predictions" / f"{method}.npz", verts, garment.faces, motion.fps)
        print(f"   wrote {out}/demo.mp4, demo.png, metrics-*.csv, metrics-*.json, jointnet.usdc, jointnet.glb, "
              f"predictions/ ({seq.motion})")

        t = _step("report", "report: every method on the held-out sequences (built beside the evaluation)")
        index = report.result()
    finally:
        reporter.shutdown(cancel_futures=True)
    view = " ".join(["loosefit view", f"{data}:{seq.name}"] + [str(out / "predictions" / f"{m}.npz") for m in predictions])
    _step.stop()
    total = time.perf_counter() - started
    (out / "timings.json").write_text(json.dumps({"total_s": round(total, 1), "stages_s": _step.seconds}, indent=1))
    print(f"\ndemo finished in {total:.0f} s ({', '.join(f'{k} {v:.0f} s' for k, v in _step.seconds.items())})")
    print(f"report: {index}")
    print(f"look at it in the browser: {view}")
    return results


def _train(method: str, data: Path, garment: str, run: Path, overrides: list[str]) -> float:
    """Train (or resume) ``method`` with the config ``overrides`` into ``run``; seconds taken. Runs in a worker
    process."""
    from loosefit.training import StaleRunError, train_model

    started = time.perf_counter()
    settings = {"config": CONFIGS / "models" / f"{method}.yaml", "overrides": overrides}
    try:
        train_model(method, data, garment, run, resume=True, **settings)
    except StaleRunError as e:  # the demo's data or settings changed since: its old run is out of date
        print(f"   {e}: training again", flush=True)
        shutil.rmtree(run)
        train_model(method, data, garment, run, **settings)
    return time.perf_counter() - started


def _shape(store, name: str):
    from loosefit.body import AnnyShape

    return AnnyShape.from_array(store.body(name))
