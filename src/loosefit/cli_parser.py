"""The ``loosefit`` command line's arguments: one subcommand per verb, each bound to its handler in
:mod:`loosefit.cli_commands`."""

from __future__ import annotations

import argparse

from loosefit.cli_args import (JOINT_MAP_FORMAT, finite_float, force_option, int_at_least, live_options,
                               motion_file_options, nonnegative_float, piece_choice, positive_float)
from loosefit.cli_commands import (
    cmd_animate,
    cmd_body,
    cmd_demo,
    cmd_evaluate,
    cmd_export_onnx,
    cmd_export_rig,
    cmd_garment_import,
    cmd_garment_make,
    cmd_info,
    cmd_motion_generate,
    cmd_motion_import,
    cmd_motion_map,
    cmd_prepare,
    cmd_quantize,
    cmd_render,
    cmd_report,
    cmd_simulate,
    cmd_train,
    cmd_view,
)
from loosefit.export_onnx import add_arguments as onnx_arguments
from loosefit.quantize import add_arguments as quantize_arguments


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="loosefit",
        description="Learning-based animation of loose-fitting garments: simulate, prepare, train, animate, evaluate.")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="log progress details, and let libraries print their own start-up lines (Warp's banner)")
    sub = p.add_subparsers(dest="command", required=True)

    def body_options(sp, resolution=False):
        sp.add_argument("--shape", default=None, help="Anny: gender=0.8,weight=0.3 (values in [0,1]); SMPL: betas b0,b1,...")
        sp.add_argument("--smpl", default=None, help="SMPL / SMPL-H / SMPL-X model file to use instead of Anny")
        if resolution:
            sp.add_argument("--resolution", choices=["full", "low"], default="full", help="Anny mesh resolution")

    sp = sub.add_parser("body", help="pose the body along a motion and write it")
    body_options(sp, resolution=True)
    sp.add_argument("--motion", default=None, help="motion .npz / .bvh (default: the rest pose)")
    motion_file_options(sp)
    sp.add_argument("--frame", type=int, default=0, help="frame written to an .obj")
    sp.add_argument("--out", required=True, help="body.obj (one frame) or body.npz (mesh sequence)")
    force_option(sp)
    sp.set_defaults(func=cmd_body)

    motion = sub.add_parser("motion", help="generate or import motions").add_subparsers(dest="motion_command", required=True)
    sp = motion.add_parser("generate", help="a procedural motion by kind and seed")
    sp.add_argument("--kind", required=True, help="walk, run, turn, spin, jump, kick, squat, bow, arm_raise, wave, sway, mix")
    sp.add_argument("--seconds", type=positive_float, default=8.0, help="length of the motion written")
    sp.add_argument("--start", type=nonnegative_float, default=None,
                    help="skip the first START seconds of the generated motion")
    sp.add_argument("--seed", type=int, default=0)
    sp.add_argument("--fps", type=positive_float, default=30.0)
    body_options(sp)
    sp.add_argument("--out", required=True)
    force_option(sp)
    sp.set_defaults(func=cmd_motion_generate)
    sp = motion.add_parser(
        "map", help="write a starting joint map for a BVH skeleton (YAML, to check and pass with --joint-map)",
        description="Write a starting joint map for a BVH file's skeleton, found from its shape (hips, legs, "
                    "spine, arms; left and right) and joint names, for you to check.\n\n" + JOINT_MAP_FORMAT,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    sp.add_argument("file", help="the BVH file")
    body_options(sp)
    sp.add_argument("--out", required=True, help="MAP.yaml")
    force_option(sp)
    sp.set_defaults(func=cmd_motion_map)
    sp = motion.add_parser("import", help="import a BVH or AMASS file onto the body rig",
                           description="Import a BVH or AMASS (SMPL-H .npz) motion onto the body's rig.\n\n"
                                       + JOINT_MAP_FORMAT, formatter_class=argparse.RawDescriptionHelpFormatter)
    sp.add_argument("file")
    motion_file_options(sp)
    sp.add_argument("--fps", type=positive_float, default=None, help="the file's frame rate, for AMASS / SMPL-H files "
                    "that store none (mocap_framerate); the motion is written at 30 fps")
    sp.add_argument("--start", type=nonnegative_float, default=None, help="keep the motion from START seconds on")
    sp.add_argument("--seconds", type=positive_float, default=None, help="keep SECONDS seconds (default: to the end)")
    body_options(sp)
    sp.add_argument("--out", required=True)
    force_option(sp)
    sp.set_defaults(func=cmd_motion_import)

    garment = sub.add_parser("garment", help="make or import garments").add_subparsers(dest="garment_command", required=True)
    sp = garment.add_parser("make", help="a garment template fitted to the body")
    sp.add_argument("--kind", required=True, choices=["skirt", "dress", "long_shirt", "jumpsuit"])
    sp.add_argument("--length", type=finite_float, default=None)
    sp.add_argument("--flare", type=finite_float, default=None)
    sp.add_argument("--seed", type=int, default=0)
    sp.add_argument("--edge-length", type=positive_float, default=0.02,
                    help="target edge length, metres (sets the resolution)")
    sp.add_argument("--param", action="append", help="any other template parameter, NAME=VALUE (repeatable)")
    body_options(sp)
    sp.add_argument("--out", required=True)
    force_option(sp)
    sp.set_defaults(func=cmd_garment_make)
    sp = garment.add_parser("import", help="validate, repair and align an OBJ / PLY garment")
    sp.add_argument("file")
    sp.add_argument("--unit", choices=["m", "cm", "mm"], default=None, help="file unit (default: detected from size)")
    sp.add_argument("--up", choices=["y", "z"], default=None, help="file up axis (default: detected by fitting)")
    sp.add_argument("--fit", action="store_true",
                    help="a garment made for another body: find the Anny shape it fits (all six keys; said in one "
                         "line), drape it from there onto this body (--shape) with Blender cloth (done anyway when it "
                         "has no plausible placement here)")
    sp.add_argument("--piece", type=piece_choice, default=None, metavar="largest|N",
                    help="keep one connected piece (1 is the largest); default: every piece, when each is attached")
    sp.add_argument("--repair", action="store_true",
                    help="repair a messy mesh by dropping what breaks it (faces on non-manifold edges, duplicates, "
                         "degenerate faces, loose pieces; the largest wearable piece, or --piece, is kept) and "
                         "print what changed")
    body_options(sp)
    sp.add_argument("--out", required=True)
    force_option(sp)
    sp.set_defaults(func=cmd_garment_import)

    sp = sub.add_parser("info", help="summarise a dataset store")
    sp.add_argument("data")
    sp.add_argument("--json", action="store_true", help="print the summary as JSON")
    sp.add_argument("--repair", action="store_true",
                    help="drop the damaged sequences (and entries) that info lists as problems, keeping the rest as is")
    sp.set_defaults(func=cmd_info)

    sp = sub.add_parser("render", help="render a mesh sequence, dataset sequence, motion or garment to MP4 / GIF / PNG")
    sp.add_argument("input", nargs="+", help="mesh-sequence .npz, motion .npz, DATA.zarr with --sequence, or a garment "
                    ".obj / .ply on the body (at rest, or along --motion); several side by side")
    sp.add_argument("--sequence", default=None, help="sequence name inside a dataset store")
    sp.add_argument("--motion", default=None, metavar="FILE",
                    help="pose the body along this motion (.npz / .bvh) and a garment .obj / .ply with it (skinned to "
                         "the body, as the body-LBS baseline); choose a frame for a .png with --frame")
    motion_file_options(sp)
    sp.add_argument("--out", required=True, help="out.mp4, out.gif, out.png or a folder")
    force_option(sp)
    sp.add_argument("--frame", type=int_at_least(0), action="append", default=None,
                    help="render only frame K (0 is the first; repeat for several); a .png output needs exactly one")
    sp.add_argument("--fps", type=positive_float, default=30.0)
    sp.add_argument("--width", type=int_at_least(1), default=640)
    sp.add_argument("--height", type=int_at_least(1), default=480)
    sp.add_argument("--backend", choices=["auto", "pyvista", "matplotlib"], default="auto")
    sp.set_defaults(func=cmd_render)

    sp = sub.add_parser("simulate", help="simulate ground truth with Blender cloth: one sequence or a plan")
    sp.add_argument("plan", nargs="?", default=None, help="a plan YAML (configs/datasets/*.yaml)")
    sp.add_argument("--out", required=True, help="DATA.zarr for a plan; seq.npz for one sequence")
    force_option(sp)
    sp.add_argument("--garment", default=None, help="garment .obj (one sequence)")
    sp.add_argument("--motion", default=None, help="motion .npz / .bvh (one sequence)")
    sp.add_argument("--params", default=None, help="simulation parameters YAML")
    sp.add_argument("--set", action="append", help="simulation parameter override, e.g. bending=1e-4 (repeatable)")
    sp.add_argument("--shape", default=None, help="Anny shape, e.g. height=0.8; a loosefit garment made on another "
                    "shape is draped onto this one first")
    sp.add_argument("--fit", action="store_true",
                    help="a garment mesh made for another body: find the Anny shape it fits and drape it onto --shape "
                         "(done anyway when it has no plausible placement on it)")
    motion_file_options(sp)
    sp.add_argument("--workers", type=int_at_least(1), default=1, help="parallel Blender workers (Ray) for a plan")
    sp.add_argument("--address", default=None, help="an existing Ray cluster's address")
    sp.add_argument("--splits", nargs="+", choices=["train", "val", "test"], default=None,
                    help="a plan's sequences of these splits only (reference runs only with test)")
    sp.add_argument("--garments", nargs="+", default=None, metavar="NAME",
                    help="a plan's sequences of these garments only (one garment finished before the next)")
    sp.set_defaults(func=cmd_simulate)

    sp = sub.add_parser("prepare", help="virtual bones, descriptors, fit attributes and statistics of a dataset")
    sp.add_argument("data")
    sp.add_argument("--bones", type=int, default=None,
                    help="virtual bones per garment (default: PrepareSettings.bones, 80)")
    sp.add_argument("--force", action="store_true", help="redo garments already prepared")
    sp.add_argument("--set", action="append", help="prepare setting override, e.g. influences=6 (repeatable; "
                    "see PrepareSettings)")
    sp.set_defaults(func=cmd_prepare)

    sp = sub.add_parser("train", help="train a garment model")
    sp.add_argument("--method", required=True, help="virtualbones, jointnet, body-lbs, fitgar, swingar or collision "
                    "(the body SDF of SwinGar's collision handling)")
    sp.add_argument("--data", required=True, help="a prepared DATA.zarr")
    sp.add_argument("--garment", default=None, help="garment name in the dataset (see loosefit info); none for fitgar, "
                    "which trains on all; for swingar a comma-separated list, or none for every training garment")
    sp.add_argument("--out", required=True, help="run folder")
    sp.add_argument("--config", default=None, help="method config YAML (configs/models/<method>.yaml)")
    sp.add_argument("--set", action="append", help="config override, e.g. train.epochs=5 (repeatable)")
    sp.add_argument("--resume", action="store_true", help="continue an interrupted run")
    sp.add_argument("--val-split", choices=["val", "test", "none"], default="val",
                    help="what selects checkpoints/best.pt: the store's val split (default; none there: no validation), "
                    "test (model selection then sees the test motions: warned) or none")
    sp.add_argument("--val-motions", default=None, metavar="NAME,...",
                    help="validate on these training motions instead of training on them (never a test motion)")
    sp.add_argument("--val-fraction", type=positive_float, default=None,
                    help="validate on this share of the training motions, chosen by name (e.g. 0.2)")
    sp.add_argument("--train-fraction", type=positive_float, default=None,
                    help="train on this share (0-1] of the training motions of each kind, nested by name: a learning "
                    "curve (per-garment methods)")
    sp.add_argument("--device", choices=["cpu", "cuda", "auto"], default=None,
                    help="where to train (default: the config's train.device); an error when CUDA is asked but absent")
    sp.add_argument("--nproc", type=int, default=1, help="training processes on this machine (DistributedDataParallel: "
                    "gloo on CPU, one GPU each with NCCL on CUDA); train.batch_size is the global batch")
    sp.set_defaults(func=cmd_train)

    sp = sub.add_parser("animate", help="animate a trained garment on new motions")
    sp.add_argument("run", help="run folder written by loosefit train, or a shipped garment: pretrained:skirt, "
                    "pretrained:dress/jointnet (loosefit.pretrained)")
    sp.add_argument("--motion", required=True, action="append", help="motion .npz / .bvh / AMASS .npz (repeatable)")
    motion_file_options(sp)
    sp.add_argument("--fps", type=positive_float, default=None,
                    help="the frame rate of motion files that store none (a loosefit .npz without 'fps', AMASS "
                         "without mocap_framerate); a file that stores one must agree. Any rate is resampled to "
                         "the model's 30 fps")
    sp.add_argument("--garment", default=None, help="fitgar and swingar runs: the garment .obj to animate (any vertex "
                    "count), in the rest pose of --shape; a loosefit garment made on another shape is draped onto it")
    body_options(sp)
    sp.add_argument("--out", required=True, help="anim.npz|.usdc|.glb|.abc|.pc2 or an OBJ folder; a folder for several motions")
    force_option(sp)
    sp.add_argument("--format", default=".npz", help="file suffix per motion when animating several motions")
    sp.add_argument("--with-body", action="store_true", help="export the posed body too (always in an .npz)")
    sp.add_argument("--checkpoint", default="best", help="best (by validation; last when the run validated on "
                    "nothing), last or a checkpoint path")
    sp.add_argument("--threads", type=int_at_least(1), default=1, help="torch CPU threads")
    sp.add_argument("--device", choices=["cpu", "cuda", "auto"], default="cpu", help="where the model runs")
    sp.add_argument("--collision", default="exact", help="collision handling after the network (SwinGar Eq. 10): "
                    "'exact' (the default: libigl's distance to the posed body), a body SDF run folder (loosefit train "
                    "--method collision: the neural field), 'pushout' (fixed-distance baseline) or 'none'")
    sp.add_argument("--collision-margin", default="0",
                    help="with a body SDF network: correct where the network puts a vertex less than this many "
                         "metres outside the body too (its surface moved out; default 0, as in SwinGar); 'auto': "
                         "the margin measured for the network when it was trained (its model.json)")
    sp.set_defaults(func=cmd_animate)

    sp = sub.add_parser("export-rig", help="a virtualbones / jointnet garment as an engine-ready skinned rig "
                        "(its virtual bones animated along a motion) with the skinned body: .glb or .usdc")
    sp.add_argument("run", help="run folder written by loosefit train (virtualbones or jointnet)")
    sp.add_argument("--motion", required=True, help="motion .npz / .bvh / AMASS .npz")
    motion_file_options(sp)
    body_options(sp)
    sp.add_argument("--out", required=True, help="dress.glb (skinned glTF) or dress.usdc / .usda (UsdSkel)")
    force_option(sp)
    sp.add_argument("--influences", type=int, choices=[4, 8], default=4, help="skinning weights kept per vertex")
    sp.add_argument("--no-body", action="store_true", help="write the garment only")
    sp.add_argument("--checkpoint", default="best", help="best (by validation; last when the run validated on "
                    "nothing), last or a checkpoint path")
    sp.add_argument("--threads", type=int_at_least(1), default=1, help="torch CPU threads")
    sp.set_defaults(func=cmd_export_rig)

    sp = sub.add_parser("export-onnx", help="a body-lbs / virtualbones / jointnet garment as one ONNX model that "
                        "animates one frame per call (onnxruntime, onnxruntime-web)")
    onnx_arguments(sp)
    force_option(sp)
    sp.set_defaults(func=cmd_export_onnx)

    sp = sub.add_parser("quantize", help="a copy of a run with its weights rounded as export-onnx --int8 rounds them: "
                        "it animates as its int8 model does")
    quantize_arguments(sp)
    sp.set_defaults(func=cmd_quantize)

    sp = sub.add_parser("evaluate", help="compare predicted and ground-truth mesh sequences")
    sp.add_argument("pred", help="predicted .npz mesh sequence, or a folder of them named like the ground truth")
    sp.add_argument("gt", help="ground-truth .npz / folder, or DATA.zarr (predictions read from PRED/<sequence>.npz)")
    sp.add_argument("--body", default=None, help="body mesh-sequence .npz for the collision ratio (else body_verts in GT)")
    sp.add_argument("--sequence", action="append", default=None, help="dataset sequence to evaluate (repeatable)")
    sp.add_argument("--split", default="test", help="dataset split evaluated when no --sequence is given")
    sp.add_argument("--out", default=".", help="folder for metrics.csv and metrics.json")
    sp.add_argument("--sted-rings", type=int, default=None, help="STED neighbourhood rings (default in loosefit.metrics.sted)")
    sp.add_argument("--sted-dt", type=finite_float, default=None, help="STED temporal distance")
    sp.add_argument("--sted-c", type=finite_float, default=None, help="STED temporal weight")
    sp.add_argument("--tolerance", type=finite_float, default=None, help="collision tolerance, metres (default 1 mm)")
    sp.add_argument("--surface-depth", type=nonnegative_float, default=None,
                    help="depth inside the body, metres, beyond which a point of the garment's surface (edge midpoint, "
                         "triangle centroid) counts in the surface column (default 5 mm)")
    force_option(sp)
    sp.set_defaults(func=cmd_evaluate)

    sp = sub.add_parser("report", help="compare trained runs on a dataset: HTML + Markdown report with metrics, "
                        "error maps, error over time, speed and paper claims")
    sp.add_argument("data", help="a dataset store DATA.zarr (ground truth)")
    sp.add_argument("run", nargs="+", help="run folders written by loosefit train")
    sp.add_argument("--out", required=True, help="report folder (index.html, report.md, metrics.json, figures/)")
    force_option(sp)
    sp.add_argument("--sequence", action="append", default=None, help="dataset sequence to report on (repeatable)")
    sp.add_argument("--split", default="test", help="split reported when no --sequence is given")
    sp.add_argument("--results", default=None, help="benchmark results folder (default: the checkout's benchmarks/results)")
    sp.add_argument("--device", choices=["cpu", "cuda", "auto"], default="cpu", help="where the models run")
    sp.add_argument("--no-images", action="store_true", help="leave out the rendered error maps")
    sp.add_argument("--collision", choices=["exact", "pushout", "none"], default="exact",
                    help="collision handling of the animations, as loosefit animate (default exact)")
    sp.add_argument("--measure-speed", action="store_true", help="also time each run's own model on this machine")
    sp.set_defaults(func=cmd_report)

    sp = sub.add_parser("view", help="play the simulation and predictions side by side in the browser (or animations "
                        "alone: --no-reference)")
    sp.add_argument("input", nargs="+", help="SEQ.npz (mesh sequence), DATA.zarr:SEQUENCE or RUN:MOTION; the first "
                    "is the simulation, the others predictions compared with it (--no-reference: animations alone)")
    sp.add_argument("--no-reference", action="store_true",
                    help="no simulation: show each input by itself (animations on your own motions, any garments), "
                         "without errors against the first")
    sp.add_argument("--port", type=int_at_least(0, 65535), default=8000,
                    help="port of the local server (127.0.0.1; 0: any free port)")
    sp.add_argument("--export", default=None, metavar="DIR", help="write the page as static files to DIR instead "
                    "of serving it (opens from disk)")
    sp.add_argument("--collision", choices=["exact", "pushout", "none"], default="exact",
                    help="collision handling of the runs' animations, as loosefit animate (default exact)")
    motion_file_options(sp)
    live_options(sp)
    sp.add_argument("--no-collisions", action="store_true", help="skip the per-frame collision ratio")
    sp.add_argument("--collision-frames", type=int_at_least(0), default=100, help="compute the collision ratio at this many "
                    "evenly spaced frames (0: every frame; ~0.5 s a frame for a 13.7k-vertex body)")
    sp.set_defaults(func=cmd_view)

    sp = sub.add_parser("demo", help="the main job on the embedded default data")
    sp.add_argument("--out", default="demo_out")
    sp.set_defaults(func=cmd_demo)
    return p
