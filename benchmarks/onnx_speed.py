"""Speed of the exported step model: frames per second of ``loosefit export-onnx`` models in onnxruntime on one
CPU thread, beside PyTorch eager (:meth:`loosefit.animate.AnimationStream.step`, one torch thread), for
VirtualBones and JointNet at the papers' sizes, at the CPU sizes the other benchmarks share, and body-LBS.

The networks are untrained: each is built at its size (``configs/models/<method>.yaml``, the papers': VirtualBones'
600-unit GRUs and per-vertex global layer, JointNet's 600-unit GRU per joint, 480 features, (1024, 2048, 1024)
bone MLP and 64 PSD shapes per joint; ``-rank64`` and ``-reduced``: ``_common.CPU_MODEL`` on top) on the dress of
``configs/datasets/bench.yaml`` (about 4.2k vertices) and on the same template remeshed to about ``--vertices``
vertices, with ``--bones`` virtual bones placed on the garment, 8-bone skinning weights and random network weights:
the time per frame does not depend on their values. Each is written as a run folder (``model.json``,
``method.yaml``, a checkpoint) and exported by :func:`loosefit.export_onnx.export_onnx`: the timed file is the one
a user gets.

Per garment and variant: the model file's size, milliseconds per frame (mean, median, 95th percentile of the wall
clock, and the process's CPU time per frame) over ``--frames`` frames of a procedural motion after ``--warmup``
untimed ones, feeding ``next_state`` back, for onnxruntime (``intra_op_num_threads = inter_op_num_threads = 1``)
and for PyTorch eager, and the largest vertex difference between the two. The machine is shared: the load average
is recorded, and the CPU time (which leaves out the time spent waiting for a core) is the steadier figure.

Every variant can also be timed exported with ``--int8`` (``<variant>-int8``: the run quantized by
:func:`loosefit.quantize.quantize_run`, then its large matrices in int8 blocks, :mod:`loosefit.io.onnx_int8`; the
difference is from the quantized run, and ``weight_rounding_mm`` from the original). With ``--runs``, trained run
folders (``pretrained:skirt``, the garments loosefit ships; ``RUN-int8`` exported with ``--int8``) are timed the
same way.

Run: .venv/bin/python benchmarks/onnx_speed.py [--vertices 12000] [--frames 200] [--warmup 20] [--bones 80]
         [--variants body-lbs,virtualbones,...] [--runs RUN,...] [--profile] [--name onnx-speed]
     (writes benchmarks/results/<name>.json; --profile: onnxruntime's profile of each model, the ten slowest
     operator types, in the results). The shipped garments: --variants '' --runs
     pretrained:skirt,pretrained:skirt/jointnet --name onnx-speed-shipped
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import CPU_MODEL, save_results  # noqa: E402
from speed import bench_dress  # noqa: E402

import onnxruntime as ort  # noqa: E402
import torch  # noqa: E402

from loosefit.animate import Animator  # noqa: E402
from loosefit.body import AnnyBody  # noqa: E402
from loosefit.config import load_config  # noqa: E402
from loosefit.export_onnx import export_onnx, read_metadata  # noqa: E402
from loosefit.models.layers.edge_conv import neighbour_table  # noqa: E402
from loosefit.models.motion_features import HISTORY_FRAMES, HISTORY_ROOT_FEATURES  # noqa: E402
from loosefit.models.registry import model_class, run_config_class  # noqa: E402
from loosefit.motion.procedural import generate  # noqa: E402
from loosefit.quantize import quantize_run  # noqa: E402
from loosefit.train.protocol import parameter_count  # noqa: E402
from loosefit.training import METHOD_CONFIG, MODEL_META  # noqa: E402

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
#: Variants: name -> (method, config overrides on ``configs/models/<method>.yaml``): the papers' sizes, and the
#: CPU-sized networks the speed and accuracy benchmarks share (``_common.CPU_MODEL``).
VARIANTS = {
    "body-lbs": ("body-lbs", []),
    "virtualbones": ("virtualbones", []),
    "jointnet": ("jointnet", []),
    "virtualbones-rank64": ("virtualbones", CPU_MODEL["virtualbones"]),
    "jointnet-reduced": ("jointnet", CPU_MODEL["jointnet"]),
    "jointnet-psd-modes": ("jointnet", ["model.psd_modes=256"]),  # its PSD in the garment's 256 smoothest modes
}
#: ``<variant>-int8``: the same model exported with ``--int8`` (large matrices in int8 blocks).
INT8 = "-int8"
#: Skinning weights per vertex of the stand-in rig (the rig's own setting, ``prepare``'s default).
INFLUENCES = 8
TARGET_FPS = 100.0


def paper_model(method: str, garment, body, bones: int, overrides=(), seed: int = 0):
    """An untrained ``method`` model at the sizes of ``configs/models/<method>.yaml`` for ``garment`` on ``body``,
    its rig buffers filled with a stand-in virtual-bone rig (bones at garment vertices far apart, each vertex
    skinned to its ``INFLUENCES`` nearest bones by inverse distance) and body-LBS' with the body's own."""
    from loosefit.sim.attach import garment_weights

    rng = np.random.default_rng(seed)
    verts, faces = garment.verts.astype(np.float32), garment.faces.astype(np.int64)
    V, J = len(verts), body.num_joints
    sizes = {"num_verts": V, "num_joints": J, "num_faces": len(faces), "root_features": HISTORY_ROOT_FEATURES,
             "history_frames": list(HISTORY_FRAMES), "history_vertical": False, "num_bones": bones,
             "max_degree": int(neighbour_table(faces, V).shape[1]), "joint_names": list(body.joint_names),
             "parents": [int(p) for p in body.parents]}
    cfg = load_config(run_config_class(method), CONFIGS / "models" / f"{method}.yaml", overrides)
    if method == "jointnet":  # its PSD in the garment's smoothest modes, as JointNet.from_data sizes it
        sizes["psd_modes"] = min(cfg.model.psd_modes, V - 1)
    torch.manual_seed(seed)
    model = model_class(method)(sizes, cfg.model)
    chosen = [int(rng.integers(V))]  # farthest-point bone centres
    dist = np.linalg.norm(verts - verts[chosen[0]], axis=1)
    for _ in range(bones - 1):
        chosen.append(int(dist.argmax()))
        dist = np.minimum(dist, np.linalg.norm(verts - verts[chosen[-1]], axis=1))
    centres = verts[chosen]
    d = np.linalg.norm(verts[:, None] - centres[None], axis=-1)
    near = np.argsort(d, 1)[:, :INFLUENCES]
    w = 1.0 / (np.take_along_axis(d, near, 1) + 1e-3)
    weights = np.zeros((V, bones), np.float32)
    np.put_along_axis(weights, near, (w / w.sum(1, keepdims=True)).astype(np.float32), 1)
    buffers = {"faces": faces, "template": verts, "rest_verts": verts, "rig_rest": verts, "skin_weights": weights,
               "bone_rest": centres}
    if method == "virtualbones":  # (JointNet's own ``neighbours`` is its joint table)
        buffers["neighbours"] = neighbour_table(faces, V)
    if method == "body-lbs":
        buffers.update(rest_joints=body.rest_joints(), weights=garment_weights(verts, body))
    with torch.no_grad():
        for name, value in buffers.items():
            if hasattr(model, name) and isinstance(getattr(model, name), torch.Tensor):
                getattr(model, name).copy_(torch.from_numpy(np.asarray(value)))
    return model, cfg


def write_run(model, cfg, folder: Path) -> Path:
    """``model`` as a run folder (``model.json``, ``method.yaml``, ``checkpoints/last.pt``), as training writes one."""
    from loosefit.config import save_config
    from loosefit.train.run import RunDir
    from loosefit.training import _save_weights

    folder.mkdir(parents=True, exist_ok=True)
    (folder / MODEL_META).write_text(json.dumps({"method": model.method, "garment": "dress", "data": "",
                                                 "sizes": model.sizes(), "train_sequences": []}))
    save_config(folder / METHOD_CONFIG, cfg)
    _save_weights(model, RunDir(folder), ["fixed"])
    return folder


def onnx_session(path: Path, profile: Path | None = None) -> ort.InferenceSession:
    options = ort.SessionOptions()
    options.intra_op_num_threads, options.inter_op_num_threads = 1, 1
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    if profile is not None:
        options.enable_profiling, options.profile_file_prefix = True, str(profile)
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def timing(times: list[float], cpu_seconds: float) -> dict:
    """Wall-clock statistics of per-frame ``times`` (seconds) and the process's CPU time per frame: on a machine
    shared with other jobs the wall clock also counts the time the process waited for a core."""
    ms = 1000.0 * np.asarray(times)
    cpu_ms = 1000.0 * cpu_seconds / len(ms)
    return {"frames": len(ms), "ms_mean": float(ms.mean()), "ms_median": float(np.median(ms)),
            "ms_p95": float(np.percentile(ms, 95)), "fps": float(1000.0 / ms.mean()), "cpu_ms_per_frame": cpu_ms,
            "fps_by_cpu_time": 1000.0 / cpu_ms}


def run_onnx(sess, meta: dict, motion, warmup: int):
    """Vertices of every frame and the timing of the frames after ``warmup``."""
    state = np.asarray(meta["initial_state"], np.float32)
    rot, trans = motion.rotations.astype(np.float32), motion.translation.astype(np.float32)
    verts, times, cpu = [], [], 0.0
    for t in range(motion.num_frames):
        start, cpu_start = time.perf_counter(), time.process_time()
        v, state = sess.run(None, {"joint_rotations": rot[t], "root_position": trans[t], "state": state})[:2]
        if t >= warmup:
            times.append(time.perf_counter() - start)
            cpu += time.process_time() - cpu_start
        verts.append(v)
    return np.stack(verts), timing(times, cpu)


def run_torch(run, motion, warmup: int, checkpoint: str = "best"):
    stream = Animator(run, checkpoint=checkpoint, threads=1).stream()
    verts, times, cpu = [], [], 0.0
    for t in range(motion.num_frames):
        start, cpu_start = time.perf_counter(), time.process_time()
        verts.append(stream.step(motion.rotations[t], motion.translation[t]))
        if t >= warmup:
            times.append(time.perf_counter() - start)
            cpu += time.process_time() - cpu_start
    return np.stack(verts), timing(times, cpu)


def profile_summary(path: Path, top: int = 10) -> list[dict]:
    """The ``top`` operator types by total time in an onnxruntime profile (JSON trace)."""
    per_op = defaultdict(float)
    for event in json.loads(path.read_text()):
        if event.get("cat") == "Node" and event.get("name", "").endswith("_kernel_time"):
            per_op[event.get("args", {}).get("op_name", "?")] += event.get("dur", 0)
    total = sum(per_op.values()) or 1.0
    ranked = sorted(per_op.items(), key=lambda kv: -kv[1])[:top]
    return [{"op": op, "share": us / total, "us_total": us} for op, us in ranked]


def time_run(run, path: Path, motion, args, checkpoint: str = "best", int8: bool = False) -> dict:
    """Export ``run`` to ``path`` and time it in onnxruntime and in torch eager along ``motion``;
    ``max_vertex_difference_mm`` is the exported model's largest difference from torch. With ``int8`` the run is
    quantized first (``loosefit quantize``) and exported with ``--int8``: the difference is from the quantized run's
    own animation, and ``weight_rounding_mm`` is how far the quantized run's vertices are from the original's."""
    start = time.perf_counter()
    original, original_checkpoint = run, checkpoint
    if int8:
        run = Path(quantize_run(run, path.with_name(path.stem + "-quantized"), checkpoint=checkpoint)["path"])
        checkpoint = "best"
    export_onnx(run, path, checkpoint=checkpoint, int8=int8)
    export_s = time.perf_counter() - start
    meta = read_metadata(path)
    with torch.no_grad():
        ort_verts, ort_time = run_onnx(onnx_session(path), meta, motion, args.warmup)
    torch_verts, torch_time = run_torch(run, motion, args.warmup, checkpoint)
    entry = {"vertices": meta["vertex_count"], "model_bytes": path.stat().st_size,
             "model_mb": path.stat().st_size / 2**20, "export_s": export_s, "onnxruntime": ort_time,
             "torch_eager": torch_time, "speedup_over_torch": torch_time["ms_mean"] / ort_time["ms_mean"],
             "max_vertex_difference_mm": float(np.abs(ort_verts - torch_verts).max() * 1e3)}
    if int8:
        float_verts = run_torch(original, motion, args.warmup, original_checkpoint)[0]
        entry["weight_rounding_mm"] = float(np.abs(torch_verts - float_verts).max() * 1e3)
    if args.profile:
        sess = onnx_session(path, profile=path.with_suffix(""))
        run_onnx(sess, meta, motion.slice(0, args.warmup + 20), args.warmup)
        entry["profile"] = profile_summary(Path(sess.end_profiling()))
    return entry


def summary_line(e: dict) -> str:
    o, t = e["onnxruntime"], e["torch_eager"]
    return (f"onnxruntime {o['fps']:.0f} fps ({o['ms_mean']:.2f} ms, CPU {o['cpu_ms_per_frame']:.2f} ms), torch eager "
            f"{t['fps']:.0f} fps ({t['ms_mean']:.2f} ms, CPU {t['cpu_ms_per_frame']:.2f} ms), {e['model_mb']:.1f} MB, "
            f"max difference {e['max_vertex_difference_mm']:.2e} mm")


def bench_garment(body, garment, motion, args, folder: Path) -> dict:
    out = {"vertices": len(garment.verts), "faces": len(garment.faces), "methods": {}}
    for variant in [v for v in args.variants.split(",") if v]:
        int8 = variant.endswith(INT8)
        method, overrides = VARIANTS[variant.removesuffix(INT8)]
        model, cfg = paper_model(method, garment, body, args.bones, overrides)
        run = write_run(model, cfg, folder / f"{variant}-{len(garment.verts)}")
        entry = {"method": method, "overrides": overrides, "int8": int8, "parameters": parameter_count(model),
                 **time_run(run, folder / f"{variant}-{len(garment.verts)}.onnx", motion, args, "last", int8)}
        out["methods"][variant] = entry
        print(f"{len(garment.verts)} vertices, {variant}: {summary_line(entry)}", flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--vertices", type=int, default=12000, help="the denser dress (0: the bench dress only)")
    parser.add_argument("--frames", type=int, default=200, help="timed frames")
    parser.add_argument("--warmup", type=int, default=20, help="untimed frames first")
    parser.add_argument("--bones", type=int, default=80, help="virtual bones (the rig's default)")
    parser.add_argument("--profile", action="store_true", help="onnxruntime's per-operator profile")
    parser.add_argument("--name", default="onnx-speed", help="results file name")
    parser.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated variants (VARIANTS, each "
                        "also as <variant>-int8; '' none)")
    parser.add_argument("--runs", default="", help="comma-separated trained runs timed too (pretrained:skirt ...; "
                        "RUN-int8 exported with --int8)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    body = AnnyBody()
    motion = generate("mix", (args.frames + args.warmup) / 30.0, 0, body)
    results = {"load_average_at_start": os.getloadavg(), "settings": vars(args), "onnxruntime": ort.__version__,
               "torch": torch.__version__, "target_fps": TARGET_FPS,
               "note": "untrained networks at the papers' sizes (time per frame does not depend on the weights); "
                       "onnxruntime and torch eager on one CPU thread each, on a shared 2-core machine",
               "garments": []}
    with tempfile.TemporaryDirectory() as tmp:
        garments = [] if not args.variants else [bench_dress(body)[0]] + (
            [bench_dress(body, args.vertices)[0]] if args.vertices else [])
        for garment in garments:
            results["garments"].append(bench_garment(body, garment, motion, args, Path(tmp)))
        results["runs"] = {}
        for i, run in enumerate(r for r in args.runs.split(",") if r):
            int8 = run.endswith(INT8)
            results["runs"][run] = time_run(run.removesuffix(INT8), Path(tmp) / f"run-{i}.onnx", motion, args,
                                            int8=int8)
            print(f"{run}: {summary_line(results['runs'][run])}", flush=True)
    first = results["garments"][0]["methods"] if results["garments"] else {}
    results["targets"] = {m: {"fps": first[m]["onnxruntime"]["fps"], "fps_by_cpu_time": first[m]["onnxruntime"][
        "fps_by_cpu_time"], "pass": first[m]["onnxruntime"]["fps"] >= TARGET_FPS}
        for m in ("virtualbones", "jointnet", "virtualbones" + INT8, "jointnet" + INT8) if m in first}
    results["load_average_at_end"] = os.getloadavg()
    save_results(args.name, results)


if __name__ == "__main__":
    main()
