"""The ``simulate`` stage: one sequence from files, or a whole plan into a dataset store (resumable, in parallel
with Ray). It sits above the simulator (:mod:`loosefit.sim`), the garments that drape with it
(:mod:`loosefit.garment`) and the store (:mod:`loosefit.data`).

A plan run adds the plan's body shapes, garments and motions to the store, then simulates every
job whose sequence is not already stored with the same content hash. Each finished sequence is
written atomically, so an interrupted run loses at most the sequences in flight; running the
plan again redoes only those. A job that raises (a crash, not a quality failure) is stored as
failed with a reason starting with ``"crashed:"`` and retried by the next run; the other jobs go on.

With the plan's ``references`` (:class:`loosefit.sim.plan.ReferencePlan`), the reference runs of every test
sequence stored ok are simulated after the test sequences and before the others: run ``k`` is the base's job
with the garment's start moved by :func:`perturb_start` (seed ``k``) and the base's solver steps a frame, stored
with the sequence (:meth:`loosefit.data.store.DatasetStore.write_reference`) as it finishes, ok or failed by the
gate like sequences; a crashed one is retried by the next run, and so is one whose plan entry changed (its hash).
Runs beyond ``count`` are dropped. A sequence that failed the gate gets none (it is never evaluated).

Workers: ``workers=1`` without ``address`` simulates in this process; otherwise every job is a Ray
task (one CPU each), on a local Ray started with ``workers`` CPUs or on the cluster at ``address``.
Each Ray worker is its own process with its own Blender.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import signal
import threading
import time
import traceback
from pathlib import Path
from typing import Any, Callable

import numpy as np
from tqdm import tqdm

from loosefit.errors import InputError
from loosefit.extras import require
from loosefit.interrupts import held_signals
from loosefit.sim.params import SimParams
from loosefit.sim.plan import Plan, ProceduralMotion, SequenceJob, TemplateGarment, load_plan
from loosefit.sim.quality import QualityGate
from loosefit.sim.sequence import SimResult, backend_run_cloth, check_backend, save_result, simulate_sequence

log = logging.getLogger(__name__)

CRASHED = "crashed:"
#: Object store of a local Ray: results (a few tens of MB each) pass through it.
_OBJECT_STORE_BYTES = 300 * 1024**2
#: Ray's logger that announces, at every local start, the token authentication it turns on by itself (a notice about
#: Ray's defaults that a user of loosefit cannot act on; the authentication stays on).
RAY_AUTH_NOTICE_LOGGER = "ray._private.authentication.authentication_token_setup"


@functools.lru_cache(maxsize=8)
def plan_body(shape_values: tuple[float, ...]):
    """The full-resolution Anny body of a shape, built once per process."""
    from loosefit.body import AnnyBody, AnnyShape

    return AnnyBody(AnnyShape(*shape_values))


def simulate_file(
    garment_path: str | Path,
    motion_path: str | Path,
    out_path: str | Path,
    params: SimParams | None = None,
    shape: str | None = None,
    joint_map: str | None = None,
    fit: bool | None = None,
    keep_first_frame: bool = False,
) -> SimResult:
    """Simulate one garment file on one motion file and write a mesh-sequence ``.npz``.

    Args:
        garment_path: a garment ``.obj`` with its sidecar (:meth:`Garment.load`), or any mesh for
            :func:`loosefit.garment.import_garment`.
        motion_path: any motion file :func:`loosefit.motion.io.load_motion` reads.
        out_path: the ``.npz`` to write (garment ``verts``/``faces``, ``body_verts``/``body_faces``,
            ``stats`` JSON, ``status``, ``reason``); written even when the quality gate fails.
        params: simulation parameters (defaults when ``None``).
        shape: body shape as ``"gender=0.8,height=0.3"`` (the average when ``None``).
        joint_map: joint map for BVH files (see :func:`loosefit.motion.bvh.import_bvh`).
        fit: for a mesh without a sidecar, :func:`~loosefit.garment.import_garment`'s ``fit``: ``None`` fits it
            as a garment made for another body when the direct placement is refused, ``True`` always.
        keep_first_frame: keep a BVH / AMASS file's first frame when it is far from the motion (a rest pose
            put before it), which :func:`~loosefit.motion.io.load_motion` drops by default.

    A loosefit garment made on another Anny shape is draped onto this one first
    (:func:`loosefit.garment.body_fit.refit`); the result's ``stats["garment_fit"]`` says what was done to the
    garment (the refit, or the import's fit), and is absent when nothing was.
    """
    from loosefit.body import AnnyShape
    from loosefit.garment import Garment, import_garment
    from loosefit.garment.body_fit import refit
    from loosefit.motion.io import load_motion

    backend_run_cloth((params or SimParams()).backend)  # the simulator is installed ([sim] extra)
    body = plan_body(tuple(AnnyShape.parse(shape).to_array().tolist()))
    garment_path = Path(garment_path)
    if Garment.sidecar_path(garment_path).is_file():
        garment, fitted = refit(Garment.load(garment_path), body, garment_path, params)
    else:
        garment = import_garment(garment_path, body, fit=fit)
        fitted = garment.params.get("fit")
    motion = load_motion(motion_path, body, joint_map=joint_map, keep_first_frame=keep_first_frame)
    result = simulate_sequence(garment, body, motion, params)
    if fitted is not None:
        result.stats["garment_fit"] = fitted
    save_result(out_path, result, garment.faces, body.faces, motion.fps)
    return result


def perturb_start(garment, seed: int, sigma: float):
    """``garment`` with every rest vertex (the start state the simulation skins from) moved by Gaussian noise of
    ``sigma`` metres per axis, from ``numpy.random.default_rng(seed)``: a reference run's start
    (:mod:`loosefit.metrics.reference`), the same for the same seed on every machine."""
    import dataclasses

    noise = np.random.default_rng(seed).normal(0.0, sigma, np.shape(garment.verts))
    return dataclasses.replace(garment, verts=(np.asarray(garment.verts, np.float64) + noise).astype(np.float32))


def load_plan_garment(plan: Plan, name: str, shape_values: tuple[float, ...]):
    """Garment ``name`` of ``plan`` (a template made, or a file loaded) on the body of ``shape_values``."""
    from loosefit.garment import Garment, import_garment, make_garment

    spec = plan.garment_spec(name)
    body = plan_body(shape_values)
    if isinstance(spec, TemplateGarment):
        return make_garment(spec.template, body, **spec.make_kwargs())
    path = plan.resolve(spec.file)
    if Garment.sidecar_path(path).is_file():
        from loosefit.garment.body_fit import refit

        return refit(Garment.load(path), body, path)[0]
    return import_garment(path, body)


def load_plan_motion(plan: Plan, name: str):
    """Motion ``name`` of ``plan`` (procedural, or a file with its start and frame count) on the average body,
    slowed down and held as its entry says."""
    from loosefit.motion.hold import hold_poses

    spec = plan.motion_spec(name)
    motion = _plan_motion_played(plan, name, spec)
    if spec.hold is None:
        return motion
    return hold_poses(motion, spec.hold.every, spec.hold.transition, spec.hold.frames, spec.hold.in_place,
                      spec.hold.from_rest, spec.hold.order_seed)


def _plan_motion_played(plan: Plan, name: str, spec):
    """Motion ``name`` as generated or read, cut and slowed down (before any hold).

    A file is read with every frame it has (``keep_first_frame``): a plan's ``start`` counts the frames of
    the file as imported (at 30 fps, after ``slowdown``), frame 0 included, whatever it holds, so that a
    plan selects the same frames whatever the importer's default; ``start: 1`` skips a rest pose a
    converter put at frame 0. A root jump left in the frames selected is warned about, naming the frames."""
    from loosefit.body import AnnyShape
    from loosefit.motion.resample import slow_down

    body = plan_body(tuple(AnnyShape().to_array().tolist()))  # motions are made on the average body
    if isinstance(spec, ProceduralMotion):
        from loosefit.motion.procedural import DEFAULT_FPS, generate

        if spec.slowdown == 1:
            return generate(spec.procedural, spec.seconds, spec.seed, body)
        # a frame more than needed, so that the slowed motion covers ``seconds`` whatever the rounding
        motion = generate(spec.procedural, spec.seconds / spec.slowdown + 1.0 / DEFAULT_FPS, spec.seed, body)
        return slow_down(motion, spec.slowdown).slice(0, int(round(spec.seconds * motion.fps)))
    from loosefit.motion.io import read_motion
    from loosefit.motion.jumps import warn_jumps

    path = plan.resolve(spec.file)
    motion = slow_down(read_motion(path, body, joint_map=spec.joint_map, keep_first_frame=True), spec.slowdown)
    start, frames = spec.start, spec.frames
    motion = motion.slice(start, None if frames is None else start + frames)
    if motion.num_frames == 0:
        raise InputError(f"motion {name!r}: no frames left after start={start}", path)
    warn_jumps(motion, f"{path} (plan motion {name!r}, from start={start})")
    return motion


def simulate_job(payload: dict[str, Any]) -> dict[str, Any]:
    """Simulate one job (runs in a worker). ``payload``: ``garment``, ``motion``, ``shape`` values,
    ``params`` and ``gate`` dicts. Returns ``verts``, ``stats``, ``status``, ``reason``; an exception
    is returned as a ``"crashed: ..."`` failure."""
    try:
        result = simulate_sequence(
            payload["garment"],
            plan_body(payload["shape"]),
            payload["motion"],
            SimParams.from_dict(payload["params"]),
            gate=QualityGate.from_dict(payload["gate"]),
        )
        return {"verts": result.verts, "stats": result.stats, "status": result.status, "reason": result.reason}
    except Exception as e:  # one sequence's crash must not stop the others
        where = traceback.extract_tb(e.__traceback__)[-1]
        reason = f"{CRASHED} {type(e).__name__}: {e} (at {Path(where.filename).name}:{where.lineno})"
        return {"verts": None, "stats": {}, "status": "failed", "reason": reason}


def _done(store, job: SequenceJob) -> bool:
    """Whether the job's sequence is stored, reads back as written (every chunk is checked: a
    damaged one is simulated again), has the job's hash and did not crash."""
    if not store.has_sequence(job.id):
        return False
    problem = store.verify_sequence(job.id)
    if problem:
        log.warning("%s: sequence %s is damaged (%s); simulating it again", store.path, job.id, problem)
        return False
    seq = store.sequence(job.id)
    return seq.stats.get("job_hash") == job.hash and not seq.reason.startswith(CRASHED)


def run_plan(
    plan_path: str | Path,
    out: str | Path,
    workers: int = 1,
    address: str | None = None,
    progress: bool = True,
    splits: tuple[str, ...] | None = None,
    garments: tuple[str, ...] | None = None,
) -> dict[str, Any]:
    """Simulate a plan into a dataset store, resuming what an earlier run left.

    Args:
        plan_path: the plan YAML (:mod:`loosefit.sim.plan`).
        out: the dataset store (``.zarr`` directory), created when missing.
        workers: parallel simulations on a local Ray (1: in this process, no Ray).
        address: address of an existing Ray cluster (``"auto"``, ``"ray://host:10001"``...).
        progress: show a progress bar and a line per finished sequence.
        splits: simulate only the sequences of these splits (``None``: all); the reference runs only with
            ``"test"`` among them. The demo simulates the training motions first and the held-out one while
            it trains.
        garments: simulate only the sequences of these plan garments (``None``: all), so that one garment of a
            long plan is complete, its reference runs included, before the next starts.

    Returns:
        Summary: ``jobs``, ``skipped`` (already done), ``ok``, ``failed``, ``crashed``, ``wall_s``
        and per sequence ``{id: {status, reason, ms_per_frame, wall_s}}``; ``references``: the same counts
        for the reference runs (``jobs`` 0 without the plan key) and per run ``{"<id>#<k>": {...}}``.
    """
    from loosefit.data.store import DatasetStore

    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"workers must be a positive integer, got {workers!r}")
    start = time.perf_counter()
    plan = load_plan(plan_path)
    unknown = sorted(set(garments or ()) - set(plan.garments))
    if unknown:
        raise InputError(f"no garment {', '.join(map(repr, unknown))} in the plan (it has {', '.join(plan.garments)})",
                         plan_path)
    in_process = workers == 1 and address is None
    for params in plan.sim_params.values():  # a missing simulator is an error, not a crashed sequence each
        if in_process:
            backend_run_cloth(params.backend)
        else:  # never imported here: bpy would shadow itself in the processes this one spawns
            check_backend(params.backend)
    if not in_process:
        require("ray", "parallel simulation (--workers / --address)")
    store = DatasetStore.open_or_create(Path(out))  # holds the store's write lock until the run ends
    try:
        return _run_jobs(plan, store, workers, address, progress, start, splits, garments)
    except BaseException:
        if store.created:  # a first run that fails before storing any sequence leaves no store behind
            store.remove_if_empty()
        raise
    finally:
        store.close()


def summary_line(summary: dict[str, Any], store) -> str:
    """One line saying how a plan run (:func:`run_plan`'s summary) ended, for people: how many sequences are ok,
    how many failed the quality gate or crashed (the first few named, with their reason), how many were done
    before."""
    done = summary["ok"] + summary["failed"] + summary["crashed"]
    line = f"{summary['plan']}: {summary['ok']} of {done} sequences simulated ok"
    if summary["skipped"]:
        line += f" ({summary['skipped']} of {summary['jobs']} were done before)"
    refs = summary.get("references") or {}
    if refs.get("jobs") and not refs["ok"] + refs["failed"] + refs["crashed"]:
        line += f"; reference runs: all {refs['jobs']} done before"
    elif refs.get("jobs"):
        made = refs["ok"] + refs["failed"] + refs["crashed"]
        line += f"; {refs['ok']} of {made} reference runs ok"
        if refs["failed"] or refs["crashed"]:
            line += f" ({refs['failed']} failed the gate, {refs['crashed']} crashed)"
        if refs["skipped"]:
            line += f" ({refs['skipped']} of {refs['jobs']} were done before)"
    bad = [(name, s["reason"]) for name, s in summary["sequences"].items() if s["status"] != "ok"]
    if bad:
        shown = "; ".join(f"{name}: {reason}" for name, reason in bad[:3])
        more = f"; and {len(bad) - 3} more" if len(bad) > 3 else ""
        line += (f", {summary['failed']} failed the quality gate and {summary['crashed']} crashed ({shown}{more}); "
                 f"they are kept in {store} with status failed (loosefit info lists them)")
    return line


def _run_jobs(plan: Plan, store, workers: int, address: str | None, progress: bool, start: float,
              splits: tuple[str, ...] | None = None, garments: tuple[str, ...] | None = None) -> dict[str, Any]:
    """Simulate the plan's jobs (of ``splits`` and ``garments``) that are not done into the open ``store``; see
    :func:`run_plan`."""
    jobs = [job for job in plan.jobs if (splits is None or job.split in splits)
            and (garments is None or job.garment in garments)]
    todo = [job for job in jobs if not _done(store, job)]
    summary: dict[str, Any] = {"plan": plan.name, "jobs": len(jobs), "skipped": len(jobs) - len(todo),
                               "ok": 0, "failed": 0, "crashed": 0, "sequences": {}}
    payloads = _inputs(plan, store, todo)  # made before simulating: a bad garment or motion stops the run at once
    bar = tqdm(total=len(jobs), initial=summary["skipped"], desc=plan.name, unit="seq", disable=not progress)

    def record(job: SequenceJob, result: dict[str, Any]) -> None:
        stats = {**result["stats"], "job_hash": job.hash}
        store.write_sequence(
            job.id, _stored_verts(store, job, result), garment=job.garment_entry, body=job.shape, motion=job.motion,
            sim_params=plan.sim_params[job.sim_params].to_dict(), stats=stats, split=job.split,
            status=result["status"], reason=result["reason"],
        )
        _count(summary, result)
        summary["sequences"][job.id] = {"status": result["status"], "reason": result["reason"],
                                        "ms_per_frame": stats.get("ms_per_frame"), "wall_s": stats.get("wall_s")}
        if progress:
            timing = f"{stats['ms_per_frame']:.0f} ms/frame, {stats['wall_s']:.1f} s" if "ms_per_frame" in stats else ""
            bar.write(f"{job.id}: {result['status']} {timing} {result['reason']}".rstrip())
        bar.update(1)

    # The test sequences first, then their reference runs, then the rest: a long plan stopped part way has
    # its held-out sequences with their floors (the plans list the held-out motions first too).
    test = [k for k, job in enumerate(todo) if job.split == "test"] if plan.reference_jobs() else []
    rest = sorted(set(range(len(todo))) - set(test))
    try:
        _dispatch([todo[k] for k in test], [payloads[k] for k in test], workers, address, record)
        if splits is None or "test" in splits:
            summary["references"] = _run_references(plan, store, workers, address, progress, garments)
        _dispatch([todo[k] for k in rest], [payloads[k] for k in rest], workers, address, record)
    finally:
        bar.close()
    summary["wall_s"] = time.perf_counter() - start
    return summary


def _stored_verts(store, job: SequenceJob, result: dict[str, Any]) -> np.ndarray:
    """A simulation's vertices ``(T, V, 3)`` as stored: no frames (``(0, V, 3)``) for a run that crashed."""
    if result["verts"] is None:
        return np.zeros((0, store.garment_num_verts(job.garment_entry), 3), np.float32)
    return result["verts"]


def _count(summary: dict[str, Any], result: dict[str, Any]) -> None:
    """One more ``ok``, ``failed`` (the gate) or ``crashed`` run in ``summary``."""
    summary["crashed" if result["reason"].startswith(CRASHED) else result["status"]] += 1


def _dispatch(keys: list, payloads: list[dict[str, Any]], workers: int, address: str | None, record) -> None:
    """Simulate every payload in this process or on Ray, calling ``record(key, result)`` as each finishes."""
    if workers == 1 and address is None:
        for key, payload in zip(keys, payloads):
            record(key, simulate_job(payload))
    elif keys:
        _run_ray(keys, payloads, workers, address, record)


def _reference_done(store, job: SequenceJob, index: int, run_hash: str) -> bool:
    """Whether reference run ``index`` of ``job`` is stored with hash ``run_hash``, did not crash and reads back
    as written (every chunk is checked)."""
    run = store.reference_runs(job.id).get(index)
    if run is None or run.get("run_hash") != run_hash or run["reason"].startswith(CRASHED):
        return False
    try:
        store.reference(job.id, index)
    except InputError as e:
        log.warning("%s: reference run %d of %s is damaged (%s); simulating it again", store.path, index, job.id, e)
        return False
    return True


def _run_references(plan: Plan, store, workers: int, address: str | None, progress: bool,
                    garments: tuple[str, ...] | None = None) -> dict[str, Any]:
    """Simulate the reference runs the plan asks for and the store lacks (of ``garments``, ``None``: all; see the
    module docstring); their summary."""
    refs = plan.references
    todo, total = [], 0
    for job in plan.reference_jobs():
        if garments is not None and job.garment not in garments:
            continue
        if not store.has_sequence(job.id):
            continue
        base = store.sequence(job.id)
        if base.status != "ok" or base.stats.get("job_hash") != job.hash:
            continue
        total += refs.count
        for index in [k for k in store.reference_runs(job.id) if k > refs.count]:
            store.delete_reference(job.id, index)
        for index in range(1, refs.count + 1):
            run_hash = refs.run_hash(job, index)
            if not _reference_done(store, job, index, run_hash):
                todo.append((job, index, run_hash, base.stats.get("quality")))
    summary: dict[str, Any] = {"jobs": total, "skipped": total - len(todo), "ok": 0, "failed": 0, "crashed": 0,
                               "runs": {}}
    if not todo:
        return summary
    jobs = list(dict.fromkeys(job for job, *_ in todo))
    bases = dict(zip((job.id for job in jobs), _inputs(plan, store, jobs)))
    payloads = []
    for job, index, _, steps in todo:
        payload = bases[job.id]
        params = payload["params"]
        if steps is not None:  # the base's steps exactly (the noise could move the adaptive choice)
            params = {**params, "quality": int(steps), "adaptive_quality": False}
        payloads.append({**payload, "garment": perturb_start(payload["garment"], index, refs.noise), "params": params})
    bar = tqdm(total=total, initial=summary["skipped"], desc=f"{plan.name} references", unit="run",
               disable=not progress)

    def record(key: tuple, result: dict[str, Any]) -> None:
        job, index, run_hash, steps = key
        info = {"noise_seed": index, "noise_m": refs.noise, "run_hash": run_hash, "quality": steps,
                "stats": result["stats"]}
        store.write_reference(job.id, index, _stored_verts(store, job, result), status=result["status"],
                              reason=result["reason"], info=info)
        _count(summary, result)
        summary["runs"][f"{job.id}#{index}"] = {"status": result["status"], "reason": result["reason"],
                                                "wall_s": result["stats"].get("wall_s")}
        if progress:
            bar.write(f"{job.id} reference {index}: {result['status']} {result['reason']}".rstrip())
        bar.update(1)

    try:
        _dispatch(todo, payloads, workers, address, record)
    finally:
        bar.close()
    return summary


def _inputs(plan: Plan, store, jobs: list[SequenceJob]) -> list[dict[str, Any]]:
    """Make the bodies, garments and motions the jobs use and add them to the store (once each;
    identical entries are left as they are); return each job's payload."""
    from loosefit.body import AnnyShape

    shapes = {name: tuple(AnnyShape(**spec).to_array().tolist()) for name, spec in plan.shapes.items()}
    garments: dict[str, Any] = {}
    motions: dict[str, Any] = {}
    payloads = []
    # a garment or motion whose plan changed may be replaced only if every sequence using it is simulated again
    rewritten = {job.id for job in jobs}
    for job in jobs:
        shape = shapes[job.shape]
        if job.garment_entry not in garments:
            store.add_body(job.shape, np.asarray(shape, np.float32))
            garments[job.garment_entry] = load_plan_garment(plan, job.garment, shape)
            store.add_garment(job.garment_entry, garments[job.garment_entry], rewritten=rewritten)
        if job.motion not in motions:
            motions[job.motion] = load_plan_motion(plan, job.motion)
            store.add_motion(job.motion, motions[job.motion], rewritten=rewritten)
        payloads.append({
            "garment": garments[job.garment_entry],
            "motion": motions[job.motion],
            "shape": shape,
            "params": plan.sim_params[job.sim_params].to_dict(),
            "gate": vars(plan.gate),
        })
    return payloads


def _run_ray(
    jobs: list[SequenceJob],
    payloads: list[dict[str, Any]],
    workers: int,
    address: str | None,
    record: Callable[[SequenceJob, dict[str, Any]], None],
) -> None:
    """Run the jobs as Ray tasks, at most twice the worker count in flight, recording results in order of completion."""
    import ray

    started = not ray.is_initialized()
    pending: dict[Any, SequenceJob] = {}
    try:
        if started:
            _start_ray(ray, workers, address)
        task = ray.remote(num_cpus=1, max_retries=0)(_simulate_parts)
        capacity = 2 * (workers if address is None else max(1, int(ray.cluster_resources().get("CPU", workers))))
        refs: dict[int, Any] = {}  # one object-store copy per garment / motion
        for job, payload in zip(jobs, payloads):
            for key in ("garment", "motion"):
                if id(payload[key]) not in refs:
                    refs[id(payload[key])] = ray.put(payload[key])
            garment, motion = refs[id(payload["garment"])], refs[id(payload["motion"])]
            rest = {k: v for k, v in payload.items() if k not in ("garment", "motion")}
            pending[task.remote(garment, motion, rest)] = job
            while len(pending) >= capacity:
                _collect(ray, pending, record)
        while pending:
            _collect(ray, pending, record)
    except BaseException:  # Ctrl-C, SIGTERM or an error: no task of this run goes on simulating (on a cluster too)
        for ref in pending:
            with contextlib.suppress(Exception):
                ray.cancel(ref, force=True)
        raise
    finally:
        if started:  # a local Ray stops with its worker processes (also one cut short while starting)
            ray.shutdown()


def _start_ray(ray, workers: int, address: str | None) -> None:
    """``ray.init`` (the cluster at ``address``, else a local one of ``workers`` CPUs), keeping the caller's
    signal handlers: Ray puts in one that exits at once on SIGTERM, which would say nothing of what is kept."""
    handler = signal.getsignal(signal.SIGTERM) if threading.current_thread() is threading.main_thread() else None
    try:
        with held_signals():  # a Ctrl-C while Ray starts acts once it has started (and can be shut down)
            if address is not None:
                ray.init(address=address, log_to_driver=False)
            else:
                logging.getLogger(RAY_AUTH_NOTICE_LOGGER).setLevel(logging.ERROR)
                ray.init(num_cpus=workers, include_dashboard=False, object_store_memory=_OBJECT_STORE_BYTES,
                         log_to_driver=False)
    except SystemExit as e:  # Ray's own SIGTERM handler ran while it started: act as the caller's would have
        if not callable(handler) or e.code != signal.SIGTERM:
            raise
        handler(signal.SIGTERM, None)
        raise


def _simulate_parts(garment, motion, payload: dict[str, Any]) -> dict[str, Any]:
    """Ray task: Ray resolves object refs passed as top-level arguments (garment, motion), not nested ones."""
    return simulate_job({**payload, "garment": garment, "motion": motion})


def _collect(ray, pending: dict, record) -> None:
    (ready,), _ = ray.wait(list(pending), num_returns=1)
    job = pending.pop(ready)
    try:
        result = ray.get(ready)
    except Exception as e:  # the worker process died (Blender crash, out of memory)
        reason = f"{CRASHED} worker lost: {type(e).__name__}: {e}"
        result = {"verts": None, "stats": {}, "status": "failed", "reason": reason}
    record(job, result)
