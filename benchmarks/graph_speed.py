"""Speed of the multi-garment graph methods at their papers' network sizes: SwinGar and FitGar.

Weights are untrained (the time of a pass does not depend on their values); garments are dresses of the
average Anny body remeshed to about the requested vertex count (:func:`dress`). Every row carries the
1-minute load average read right after its timing: the machines are shared, so compare rows only at
similar loads.

1. :func:`matmul_rate`: the best dense float32 matrix product rate (GFLOP/s) over a few square sizes, per
   torch thread count: the ceiling the networks' FLOPs are compared with.
2. :func:`swingar_speed`: SwinGar (the paper's sizes, ``SwinGarConfig()``) bound to one dress, streaming (one
   frame per call with the recurrent state, the median of ``frames`` calls after ``warmup``) and batch 16
   (16 frames of one motion in one call from a cold start). The paper: about 26 ms a frame (38.1 fps)
   streaming and 307.8 fps in batches of 10 for a 10k-vertex garment on an RTX 4090 (SwinGar Sec. V-D,
   Table V). On the CPU the streaming frames run with GAT-LN's fused kernel (:mod:`loosefit.models.layers.native`)
   and again without it (``stream_no_kernel_*``: torch's eager passes), with the largest vertex difference.
3. :func:`fitgar_speed`: FitGar (``configs/models/fitgar.yaml``) one frame per pass, inputs collated
   beforehand. The paper: about 21 ms a frame (8 ms coarse, 13 ms detail) for 3-4k vertices on an RTX
   2080 Ti (FitGar Sec. 5.4); SwinGar's Table V lists it at 47.6 fps.

FLOPs per frame are counted with :class:`torch.utils.flop_counter.FlopCounterMode`, which counts the matrix
products (``mm``, ``addmm``, ``bmm``, convolutions) and nothing else: gathers and scatters (the graph
neighbourhoods, PyG's message passing), softmaxes, normalisations and elementwise operations are left out,
and so is a CPU LSTM (``mkldnn_rnn_layer``: SwinGar's motion encoder, added analytically and reported
apart). The achieved rate is the counted FLOPs over the measured time, and its ``fraction`` of
:func:`matmul_rate` at the same thread count says how far the network is from being bound by its products.

On CUDA both models also stream through their captured CUDA graphs (:mod:`loosefit.models.cuda_graph`), timed beside
the eager frames: SwinGar's ``stream_ms_per_frame`` (eager) and ``stream_graph_ms_per_frame`` (graph replay), FitGar's
``ms_per_frame`` (eager, PyG's edge list) and ``graph_ms_per_frame``, each with the largest vertex difference from the
eager frames (``*_max_abs_diff_m``) and whether the capture took (``*_captured``). FitGar's ``tables_ms_per_frame``
is the captured step run eagerly (:class:`~loosefit.models.fitgar_stream.FitGarStream`: fixed neighbour tables, no
scatter), on any device.

Thread counts matter on these machines: PyG's scatter (FitGar's GATConv, its pooling) runs many times slower
with 2 torch threads than with 1 (see the design notes), so every measurement runs at each of ``--threads``.
With ``--device cuda`` (where CUDA is available) the same runs on the GPU, synchronised around every timing.

Run: PYTHONPATH=src .venv/bin/python benchmarks/graph_speed.py [--swingar-vertices 10000]
         [--fitgar-vertices 4000,10000] [--threads 1,2] [--device cpu] [--frames 8] [--fitgar-frames 20]
         [--skip matmul,swingar,fitgar] [--profile] [--name graph-speed]
(writes benchmarks/results/<name>.json; ``--profile`` adds the top operators of SwinGar's streaming frames)
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Callable
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import save_results  # noqa: E402

import torch  # noqa: E402
from torch.utils.flop_counter import FlopCounterMode  # noqa: E402

from loosefit.models.layers import native  # noqa: E402
from loosefit.threads import torch_threads  # noqa: E402

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "models"
#: The papers' timings (GPU), kept beside every row.
PAPER = {
    "swingar": {"ms_per_frame": 26.0, "fps": 38.1, "batch_fps": 307.8, "batch": 10, "vertices": 10000,
                "hardware": "RTX 4090, i9-13900K"},
    "fitgar": {"ms_per_frame": 21.0, "coarse_ms": 8.0, "detail_ms": 13.0, "vertices": "3000-4000",
               "hardware": "RTX 2080 Ti", "fps_in_swingar_table_v": 47.6},
}
MATMUL_SIZES = {"cpu": (256, 512, 1024, 2048), "cuda": (1024, 2048, 4096, 8192)}


def load_average() -> float:
    return float(os.getloadavg()[0])


def _device(device: str | torch.device) -> torch.device:
    device = torch.device(device)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise RuntimeError("--device cuda: CUDA is not available on this machine")
    return device


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def _timed(fn: Callable[[], object], device: torch.device) -> tuple[float, object]:
    """Seconds of ``fn()`` (synchronised before and after on CUDA) and its result."""
    _sync(device)
    start = time.perf_counter()
    out = fn()
    _sync(device)
    return time.perf_counter() - start, out


def _to(value, device: torch.device):
    if isinstance(value, torch.Tensor):
        return value.to(device)
    if isinstance(value, dict):
        return {k: _to(v, device) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(_to(v, device) for v in value)
    return value


def count_flops(fn: Callable[[], object]) -> tuple[int, dict[str, int]]:
    """FLOPs of ``fn()`` that :class:`FlopCounterMode` counts (matrix products), in total and per operator."""
    with FlopCounterMode(display=False) as counter:
        fn()
    by_op = {str(k).replace("aten.", ""): int(v) for k, v in counter.get_flop_counts().get("Global", {}).items()}
    return int(counter.get_total_flops()), by_op


# ---------------------------------------------------------------------- the machine's ceiling

def _matmul_row(threads: int, device: torch.device, sizes, seconds: float) -> dict:
    rates, medians = {}, {}
    with torch_threads(threads):
        for n in sizes:
            a, b = torch.randn(n, n, device=device), torch.randn(n, n, device=device)
            _timed(lambda: a @ b, device)  # warm-up
            times: list[float] = []
            while sum(times) < seconds or len(times) < 3:
                times.append(_timed(lambda: a @ b, device)[0])
            rates[n] = 2.0 * n ** 3 / min(times) / 1e9
            medians[n] = 2.0 * n ** 3 / statistics.median(times) / 1e9
    size = max(rates, key=rates.get)
    return {"threads": threads, "device": device.type, "gflops": rates[size], "best_size": size,
            "gflops_by_size": {str(k): v for k, v in rates.items()},
            "median_gflops_by_size": {str(k): v for k, v in medians.items()}, "load_average": load_average()}


def matmul_rate(threads: list[int] = (1, 2), device: str = "cpu", sizes=None, seconds: float = 0.5) -> list[dict]:
    """The measured dense float32 matmul rate: per thread count, the best GFLOP/s of ``a @ b`` over square
    sizes ``sizes`` (each timed for about ``seconds``, the fastest product kept), and the size that gave it;
    the median product's rate per size beside (on a busy machine the best is what a free core gives, the
    median what a run can expect).
    On CUDA the thread count does not change the product; it is measured once (``threads: None``) at
    torch's default float32 precision (no TF32)."""
    dev = _device(device)
    sizes = sizes or MATMUL_SIZES[dev.type]
    if dev.type == "cuda":
        row = _matmul_row(1, dev, sizes, seconds)
        row["threads"] = None
        row["float32_matmul_precision"] = torch.get_float32_matmul_precision()
        return [row]
    return [_matmul_row(t, dev, sizes, seconds) for t in threads]


def _rate_for(rates: list[dict], threads: int) -> float | None:
    for r in rates:
        if r["threads"] in (threads, None):
            return r["gflops"]
    return None


def _achieved(row: dict, flops: int, seconds: float, rates: list[dict] | None, prefix: str) -> None:
    row[f"{prefix}gflop_per_frame"] = flops / 1e9
    row[f"{prefix}achieved_gflops"] = flops / seconds / 1e9
    rate = _rate_for(rates or [], row["threads"])
    row[f"{prefix}fraction_of_matmul_rate"] = row[f"{prefix}achieved_gflops"] / rate if rate else None


# ---------------------------------------------------------------------- garments

def dress(body, vertices: int, seed: int = 0):
    """A dress of about ``vertices`` vertices: cloth holds about ``1 / h^2`` vertices per unit area at edge
    length ``h``, so ``h`` is scaled from a coarse dress's count (clipped to 6-60 mm)."""
    from loosefit.garment import make_garment

    coarse = make_garment("dress", body, seed=seed, edge_length=0.04)
    h = float(np.clip(0.04 * np.sqrt(len(coarse.verts) / vertices), 0.006, 0.06))
    return make_garment("dress", body, seed=seed, edge_length=h)


# ---------------------------------------------------------------------- SwinGar

def _swingar(body, garment, device: torch.device):
    """SwinGar at the paper's sizes, bound to ``garment`` on ``body``, on ``device``."""
    from loosefit.models.multi_garment import garment_graph
    from loosefit.models.swingar import BoundSwinGar, SwinGar, SwinGarConfig

    config = SwinGarConfig()
    torch.manual_seed(0)
    model = SwinGar({"num_joints": body.num_joints, "parents": body.parents.tolist(), "shape_values": 6}, config).eval()
    graph = garment_graph("dress", garment.verts, garment.faces, body.collision_proxy(), body.shape.to_array(),
                          config.descriptor_samples)
    bound = BoundSwinGar(model, graph)  # built on the CPU, then moved with its garment tensors and features
    if device.type != "cpu":
        bound.to(device)
        bound.g, bound.features = _to(bound.g, device), _to(bound.features, device)
    return bound


def _motion(body, frames: int, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    from loosefit.models.motion_features import motion_features
    from loosefit.motion.procedural import generate

    feats = motion_features(generate("walk", frames / 30.0 + 0.1, 0, body))
    return (torch.from_numpy(feats["root"])[None, :frames].to(device),
            torch.from_numpy(feats["joints"])[None, :frames].to(device))


def lstm_flops(model, windows: int) -> int:
    """Analytic FLOPs of SwinGar's motion encoder over ``windows`` windows (the counter sees neither the CPU's
    fused LSTM nor cuDNN's):
    per step ``2 * 4H (P + H)`` multiply-adds for the gates."""
    lstm = model.motion_encoder
    H, P = lstm.hidden_size, lstm.input_size
    return int(windows * model.config.motion_frames * 2 * 4 * H * (P + H))


def swingar_speed(vertices: list[int] = (10000,), threads: list[int] = (1, 2), device: str = "cpu",
                  frames: int = 8, warmup: int = 2, batch: int = 16, repeats: int = 2,
                  rates: list[dict] | None = None, body=None) -> list[dict]:
    """SwinGar frames per second, streaming and in batches of ``batch``, per vertex count and thread count.

    Streaming: ``warmup`` frames, then ``frames`` calls of one frame each with the previous call's state
    (motion history and the corrective's input maps), the median. Batch: one call of ``batch`` frames from a
    cold start, the fastest of ``repeats`` after an untimed one. ``rates``: :func:`matmul_rate`'s rows for the
    achieved fraction. FLOPs: one streaming call with a state, and the batch call over ``batch``."""
    from loosefit.body import AnnyBody

    dev = _device(device)
    body = body or AnnyBody()
    root, joints = _motion(body, warmup + frames + batch, dev)
    rows = []
    for n in vertices:
        garment = dress(body, n)
        bound = _swingar(body, garment, dev)
        for t in threads:
            with torch_threads(t), torch.no_grad():
                bound.use_graphs = False  # eager first; the CUDA graph's frames after
                stream, times, eager_verts, state = _swingar_stream(bound, root, joints, warmup, frames, dev)
                stream_load = load_average()
                kernel = dev.type == "cpu" and native.library() is not None
                if kernel:  # the same frames with GAT-LN's fused CPU kernel off: torch's eager passes
                    with native_off():
                        no_kernel, no_kernel_times, plain_verts, _ = _swingar_stream(
                            bound, root, joints, warmup, frames, dev)
                    kernel_diff = max(float((a - b).abs().max()) for a, b in zip(eager_verts, plain_verts))
                graph = None
                if dev.type == "cuda":
                    bound.use_graphs = True
                    graph, graph_times, graph_verts, _ = _swingar_stream(bound, root, joints, warmup, frames, dev)
                    captured = any(g is not None for g in bound._graphs.values())
                    graph_diff = max(float((a - b).abs().max()) for a, b in zip(eager_verts, graph_verts))
                    bound.use_graphs = False
                k = warmup + frames
                stream_flops, stream_ops = count_flops(lambda: bound(root[:, k:k + 1], joints[:, k:k + 1], state))
                if kernel:  # the eager passes multiply more: the kernel takes the scores' centre as a mean
                    with native_off():
                        no_kernel_flops, _ = count_flops(lambda: bound(root[:, k:k + 1], joints[:, k:k + 1], state))
                whole = lambda: bound(root[:, :batch], joints[:, :batch])  # noqa: E731
                _timed(whole, dev)
                batch_s = min(_timed(whole, dev)[0] for _ in range(repeats)) / batch
                batch_load = load_average()
                batch_flops, _ = count_flops(whole)
            row = {"model": "swingar", "vertices": garment.num_verts, "threads": t, "device": dev.type,
                   "stream_ms_per_frame": stream * 1e3, "stream_fps": 1.0 / stream,
                   "stream_ms_all": [x * 1e3 for x in times[warmup:]], "stream_load_average": stream_load,
                   f"batch{batch}_ms_per_frame": batch_s * 1e3, f"batch{batch}_fps": 1.0 / batch_s,
                   "batch_load_average": batch_load, "load_average": batch_load}
            _achieved(row, stream_flops, stream, rates, "stream_")
            row["native_kernel"] = kernel
            if kernel:
                row.update({"stream_no_kernel_ms_per_frame": no_kernel * 1e3,
                            "stream_no_kernel_ms_all": [x * 1e3 for x in no_kernel_times[warmup:]],
                            "stream_kernel_max_abs_diff_m": kernel_diff, "stream_kernel_speedup": no_kernel / stream})
                _achieved(row, no_kernel_flops, no_kernel, rates, "stream_no_kernel_")
            if graph is not None:
                row.update({"stream_graph_ms_per_frame": graph * 1e3, "stream_graph_fps": 1.0 / graph,
                            "stream_graph_ms_all": [x * 1e3 for x in graph_times[warmup:]],
                            "stream_graph_captured": captured, "stream_graph_max_abs_diff_m": graph_diff,
                            "stream_graph_speedup": stream / graph})
                _achieved(row, stream_flops, graph, rates, "stream_graph_")
            _achieved(row, batch_flops // batch, batch_s, rates, f"batch{batch}_")
            row["stream_counted_flops_by_op"] = stream_ops
            row["motion_lstm_gflop_per_frame_uncounted"] = lstm_flops(bound.model, 1) / 1e9
            row["paper"] = PAPER["swingar"]
            rows.append(row)
            print({k: v for k, v in row.items() if k not in ("stream_ms_all", "stream_graph_ms_all",
                                                             "stream_no_kernel_ms_all", "stream_counted_flops_by_op",
                                                             "paper")},
                  flush=True)
    return rows


def native_off():
    """GAT-LN's fused CPU kernel switched off (``LOOSEFIT_NATIVE=0``) while inside."""
    return mock.patch.dict(os.environ, {"LOOSEFIT_NATIVE": "0"})


def _swingar_stream(bound, root, joints, warmup: int, frames: int, device: torch.device):
    """Stream ``warmup + frames`` frames one call each from a cold start: the median seconds of the last
    ``frames``, every call's seconds, each frame's vertices and the last state. On CUDA with ``bound.use_graphs``
    the second call (the first with a state) captures the CUDA graph, inside the warm-up."""
    state, times, verts = None, [], []
    for k in range(warmup + frames):
        dt, out = _timed(lambda: bound(root[:, k:k + 1], joints[:, k:k + 1], state), device)
        state = out["state"]
        times.append(dt)
        verts.append(out["verts"])
    return statistics.median(times[warmup:]), times, verts, state


def profile_swingar(vertices: int = 10000, threads: int = 1, frames: int = 3, top: int = 15, body=None) -> dict:
    """The top operators (self CPU time per frame) of SwinGar's streaming frames on the CPU, and the time per
    frame of each GAT-LN layer (by its sizes), from :mod:`torch.profiler` over ``frames`` frames after two."""
    from torch.profiler import ProfilerActivity, profile, record_function

    from loosefit.body import AnnyBody
    from loosefit.models.layers.gat_ln import GATLN

    body = body or AnnyBody()
    dev = torch.device("cpu")
    bound = _swingar(body, dress(body, vertices), dev)
    root, joints = _motion(body, frames + 2, dev)
    original = GATLN.forward

    def labelled(self, x, table, valid):
        with record_function(f"GATLN {self.in_channels}->{self.out_channels} x{self.heads} heads"):
            return original(self, x, table, valid)

    GATLN.forward = labelled
    try:
        with torch_threads(threads), torch.no_grad():
            state = None
            for k in range(2):
                state = bound(root[:, k:k + 1], joints[:, k:k + 1], state)["state"]
            with profile(activities=[ProfilerActivity.CPU]) as prof:
                for k in range(2, 2 + frames):
                    state = bound(root[:, k:k + 1], joints[:, k:k + 1], state)["state"]
    finally:
        GATLN.forward = original
    events = prof.key_averages()
    total = sum(e.self_cpu_time_total for e in events)
    ops = sorted((e for e in events if not e.key.startswith("GATLN")), key=lambda e: -e.self_cpu_time_total)[:top]
    layers = sorted((e for e in events if e.key.startswith("GATLN")), key=lambda e: -e.cpu_time_total)
    return {"vertices": bound.g["rest"].shape[0], "threads": threads, "frames": frames, "load_average": load_average(),
            "ms_per_frame_profiled": total / 1e3 / frames,
            "top_ops": [{"op": e.key, "self_ms_per_frame": e.self_cpu_time_total / 1e3 / frames,
                         "share": e.self_cpu_time_total / total, "calls_per_frame": e.count / frames} for e in ops],
            "gat_ln_layers": [{"layer": e.key, "ms_per_frame": e.cpu_time_total / 1e3 / frames,
                               "calls_per_frame": e.count / frames} for e in layers]}


# ---------------------------------------------------------------------- FitGar

def fitgar_speed(vertices: list[int] = (4000, 10000), threads: list[int] = (1, 2), device: str = "cpu",
                 frames: int = 20, config: Path = CONFIGS / "fitgar.yaml", rates: list[dict] | None = None,
                 body=None) -> list[dict]:
    """FitGar frames per second, one frame per pass (the network alone: inputs built and collated
    beforehand), per vertex count and thread count: the median and mean of ``frames`` frames after one
    untimed frame. FLOPs: one frame."""
    from loosefit.body import AnnyBody
    from loosefit.config import load_config
    from loosefit.models.fitgar import Config, FitGar
    from loosefit.models.fitgar_data import collate_frames, frame_items
    from loosefit.models.fitgar_inputs import GarmentBodyPair
    from loosefit.models.fitgar_stream import FitGarStream
    from loosefit.motion.procedural import generate

    dev = _device(device)
    body = body or AnnyBody()
    motion = generate("walk", (frames + 1) / 30.0 + 0.1, 0, body)
    torch.manual_seed(0)
    model = FitGar({"num_joints": body.num_joints, "num_shape": 6, "num_fit_factors": 3,
                    "pose_features": 6 * body.num_joints, "fit_length": 8}, load_config(Config, config).model).eval().to(dev)
    rows = []
    for n in vertices:
        garment = dress(body, n)
        pair = GarmentBodyPair.build(garment.verts, garment.faces, body, body.shape.to_array(), np.zeros(3))
        batches = [_to(collate_frames([it]), dev) for it in frame_items(pair, pair.frames(motion))[:frames + 1]]
        for t in threads:
            with torch_threads(t), torch.no_grad():
                model.use_graphs = False  # FitGar.forward's eager pass on the edge list
                _timed(lambda: model(batches[0]), dev)  # warm-up
                times = [_timed(lambda: model(b), dev)[0] for b in batches[1:]]
                eager = [model(b)["verts"] for b in batches[1:]]
                load = load_average()
                flops, by_op = count_flops(lambda: model(batches[0]))
                # the same frames over fixed tables (FitGarStream), eagerly; on CUDA also as a CUDA graph
                stream = FitGarStream(model, batches[0], use_graphs=False)
                _timed(lambda: stream(batches[0]), dev)
                stream_times = [_timed(lambda: stream(b), dev)[0] for b in batches[1:]]
                stream_diff = max(float((stream(b)["verts"] - e).abs().max()) for b, e in zip(batches[1:], eager))
                if dev.type == "cuda":
                    model.use_graphs = True  # FitGar.forward's own path on CUDA
                    _timed(lambda: model(batches[0]), dev)  # captures
                    graph_times = [_timed(lambda: model(b), dev)[0] for b in batches[1:]]
                    graph_diff = max(float((model(b)["verts"] - e).abs().max()) for b, e in zip(batches[1:], eager))
                    captured = model._stream._graph is not None
                    model.use_graphs = False
            per_frame = statistics.median(times)
            row = {"model": "fitgar", "vertices": garment.num_verts, "threads": t, "device": dev.type,
                   "ms_per_frame": per_frame * 1e3, "fps": 1.0 / per_frame, "mean_ms_per_frame": float(np.mean(times)) * 1e3,
                   "load_average": load}
            _achieved(row, flops, per_frame, rates, "")
            per_frame = statistics.median(stream_times)
            row.update({"tables_ms_per_frame": per_frame * 1e3, "tables_max_abs_diff_m": stream_diff})
            _achieved(row, flops, per_frame, rates, "tables_")
            if dev.type == "cuda":
                per_frame = statistics.median(graph_times)
                row.update({"graph_ms_per_frame": per_frame * 1e3, "graph_fps": 1.0 / per_frame,
                            "graph_captured": captured, "graph_max_abs_diff_m": graph_diff,
                            "graph_speedup": row["ms_per_frame"] / 1e3 / per_frame})
                _achieved(row, flops, per_frame, rates, "graph_")
            row["counted_flops_by_op"] = by_op
            row["paper"] = PAPER["fitgar"]
            rows.append(row)
            print({k: v for k, v in row.items() if k not in ("counted_flops_by_op", "paper")}, flush=True)
    return rows


# ---------------------------------------------------------------------- script

def _ints(text: str) -> list[int]:
    return [int(v) for v in text.split(",") if v]


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--swingar-vertices", default="10000", help="comma-separated dress vertex counts for SwinGar")
    p.add_argument("--fitgar-vertices", default="4000,10000", help="comma-separated dress vertex counts for FitGar")
    p.add_argument("--threads", default="1,2", help="comma-separated torch thread counts")
    p.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    p.add_argument("--frames", type=int, default=8, help="SwinGar streaming frames timed (after 2 of warm-up)")
    p.add_argument("--batch", type=int, default=16, help="SwinGar frames per batched call")
    p.add_argument("--repeats", type=int, default=2, help="SwinGar batched calls timed (the fastest is kept)")
    p.add_argument("--fitgar-frames", type=int, default=20)
    p.add_argument("--fitgar-config", type=Path, default=CONFIGS / "fitgar.yaml")
    p.add_argument("--skip", default="", help="comma-separated parts to leave out: matmul, swingar, fitgar")
    p.add_argument("--profile", action="store_true", help="add the top operators of SwinGar's streaming frames "
                                                          "(CPU, the first --swingar-vertices, one thread)")
    p.add_argument("--name", default="graph-speed")
    args = p.parse_args(argv)
    if args.device == "cuda" and not torch.cuda.is_available():
        p.error("--device cuda: CUDA is not available on this machine")
    threads, skip = _ints(args.threads), set(args.skip.split(","))
    from loosefit.body import AnnyBody

    body = AnnyBody()
    results: dict = {"device": args.device, "threads": threads, "load_average_at_start": load_average(),
                     "counted": "matrix products only (FlopCounterMode): gathers, scatters, softmax and elementwise "
                                "operations are not counted, nor a CPU LSTM (added analytically apart)"}
    rates: list[dict] = []
    if "matmul" not in skip:
        rates = matmul_rate(threads, args.device)
        for r in rates:
            print(r, flush=True)
        results["matmul"] = rates
    if "swingar" not in skip:
        results["swingar"] = swingar_speed(_ints(args.swingar_vertices), threads, args.device, frames=args.frames,
                                           batch=args.batch, repeats=args.repeats, rates=rates, body=body)
    if "fitgar" not in skip:
        results["fitgar"] = fitgar_speed(_ints(args.fitgar_vertices), threads, args.device, frames=args.fitgar_frames,
                                         config=args.fitgar_config, rates=rates, body=body)
    if args.profile:
        results["swingar_profile"] = profile_swingar(_ints(args.swingar_vertices)[0], 1, body=body)
        for r in results["swingar_profile"]["top_ops"] + results["swingar_profile"]["gat_ln_layers"]:
            print(r, flush=True)
    results["load_average_at_end"] = load_average()
    save_results(args.name, results)


if __name__ == "__main__":
    main()
