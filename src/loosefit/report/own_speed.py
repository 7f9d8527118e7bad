"""The speed of the reported runs' own models, measured on this machine when the report is asked to
(``loosefit report --measure-speed``), beside the table copied from ``benchmarks/results/speed.json``.

Each run animates the first reported sequence it can: streaming (:class:`loosefit.animate.AnimationStream`, one
frame per call, as a game would) and batched (the whole clip in one call), on ``threads`` CPU threads, without
collision handling (the network's own cost; the handling is timed by ``benchmarks/surface_collision.py``).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from loosefit.report.predictions import Method, Sequence

#: Frames streamed after the warm-up, and the warm-up frames (first-call allocations and lazy set-up).
FRAMES, WARMUP = 120, 5


def _animator(run: Path, seq: Sequence, threads: int):
    """The run's animator bound to ``seq``'s garment (a multi-garment run) or its own garment."""
    from loosefit.animate import Animator, read_run_meta

    meta = read_run_meta(run)
    if meta.get("garment") is None and "garments" in meta:
        return Animator(run, threads=threads, garment=seq.garment_mesh, body=seq.body)
    return Animator(run, threads=threads)


def _seconds(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def measure_run_speed(run: str | Path, seq: Sequence, threads: int = 1, frames: int = FRAMES) -> dict:
    """Streaming and batched frames per second of ``run`` on ``seq``'s motion (its first ``frames`` frames
    after :data:`WARMUP`; a shorter clip is looped), on ``threads`` CPU threads.

    Returns ``{"stream_fps", "batch_fps", "frames", "threads", "parameters"}``; ``stream_fps`` is None for a
    static (frame-by-frame, stateless) method, which has no stream.
    """
    from loosefit.animate_any import AnyGarmentAnimator, is_static_run

    run = Path(run)
    motion = seq.motion
    n = WARMUP + frames
    index = np.arange(n) % motion.num_frames
    rotations, translation = motion.rotations[index], motion.translation[index]
    if is_static_run(run):
        animator = AnyGarmentAnimator(run, threads=threads)
        pair = animator.pair(seq.garment_mesh.verts, seq.faces, seq.body)
        clip = motion.slice(0, min(frames, motion.num_frames))
        animator.animate(pair, motion.slice(0, WARMUP))
        batch = _seconds(lambda: animator.animate(pair, clip))
        return {"stream_fps": None, "batch_fps": clip.num_frames / batch, "frames": clip.num_frames,
                "threads": threads, "parameters": sum(p.numel() for p in animator.model.parameters())}
    animator = _animator(run, seq, threads)
    stream = animator.stream()
    for f in range(WARMUP):
        stream.step(rotations[f], translation[f])
    streamed = _seconds(lambda: [stream.step(rotations[f], translation[f]) for f in range(WARMUP, n)])
    clip = motion.slice(0, min(frames, motion.num_frames))
    animator.animate(motion.slice(0, WARMUP))
    batch = _seconds(lambda: animator.animate(clip))
    return {"stream_fps": frames / streamed, "batch_fps": clip.num_frames / batch, "frames": frames,
            "threads": threads, "parameters": sum(p.numel() for p in animator.model.parameters())}


def own_speed_rows(methods: list[Method], sequences: list[Sequence], threads: int = 1) -> list[dict]:
    """One row per run, in the shape of :func:`loosefit.report.claims.speed_table`'s rows plus ``source``
    and ``run``: the run measured on the first of ``sequences`` it animated."""
    rows = []
    for m in methods:
        seq = next(s for s in sequences if s.name in m.predictions)
        speed = measure_run_speed(m.run, seq, threads)
        rows.append({"garment": seq.garment, "vertices": int(seq.gt.shape[1]), "method": m.label,
                     "parameters": speed["parameters"], "simulator_ms": None, "stream_fps": speed["stream_fps"],
                     "batch_fps": speed["batch_fps"], "stream_speedup": None, "batch_speedup": None,
                     "run": str(m.run), "source": f"measured now: {seq.name}, {speed['frames']} frames, "
                                                  f"{threads} thread{'s' if threads > 1 else ''}"})
    return rows
