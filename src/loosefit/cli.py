"""The ``loosefit`` command line: argument parsing only; every verb calls a library function."""

from __future__ import annotations

import argparse
import json
import logging
import shlex
import signal
import sys
from pathlib import Path

from loosefit.cli_args import (JOINT_MAP_FORMAT, export_onnx_parser, finite_float, force_option, int_at_least,
                               live_options, motion_file_options, nonnegative_float, piece_choice, positive_float,
                               writable)
from loosefit.errors import InputError, LoosefitError
from loosefit.paths import guard_output
from loosefit.quiet import quiet_third_party


def _body(args):
    """The body for ``--shape`` / ``--smpl``: Anny by default, a SMPL-family file when given."""
    if getattr(args, "smpl", None):
        from loosefit.body.smpl_body import SMPLBody

        betas = [float(b) for b in args.shape.split(",")] if args.shape else None
        return SMPLBody(args.smpl, betas)
    from loosefit.body import AnnyBody, AnnyShape

    return AnnyBody(AnnyShape.parse(args.shape), resolution=getattr(args, "resolution", "full"))


def cmd_body(args):
    import numpy as np

    from loosefit.io.mesh_sequence import MeshSequence
    from loosefit.io.obj import write_obj
    from loosefit.motion.io import load_motion

    writable(args.out, folder=False)
    guard_output(args.out, args.force)
    body = _body(args)
    motion = (load_motion(args.motion, body, joint_map=args.joint_map, keep_first_frame=args.keep_first_frame)
              if args.motion else body.rest_motion(1))
    posed = body.pose(motion)
    out = Path(args.out)
    if out.suffix == ".obj":
        if not 0 <= args.frame < len(posed.verts):
            raise InputError(f"--frame {args.frame} is outside the motion's frames 0..{len(posed.verts) - 1}")
        write_obj(out, posed.verts[args.frame], body.faces, header=f"loosefit body {body.name} frame {args.frame}")
    elif out.suffix == ".npz":
        MeshSequence(posed.verts, body.faces, motion.fps,
                     {"joints": posed.joints, "joint_transforms": posed.joint_transforms,
                      "parents": np.asarray(body.parents)}).save(out)
    else:
        raise LoosefitError(f"{out}: unsupported output, use .obj or .npz")
    print(f"wrote {out}: {body.name}, {posed.verts.shape[0]} frame(s), {body.num_verts} vertices")


def cmd_motion_generate(args):
    from loosefit.motion.procedural import generate

    writable(args.out, folder=False)
    guard_output(args.out, args.force)
    body = _body(args)
    start = args.start or 0.0
    motion = generate(args.kind, start + args.seconds, args.seed, body, fps=args.fps)
    if start:
        motion = motion.cut(start, args.seconds)
    motion.save(args.out)
    print(f"wrote {args.out}: {motion.name}, {motion.num_frames} frames at {motion.fps:g} fps")


def cmd_motion_map(args):
    from loosefit.motion.map_writer import write_joint_map

    writable(args.out, folder=False)
    guard_output(args.out, args.force)
    joint_map, notes = write_joint_map(args.file, _body(args), args.out)
    print(f"wrote {args.out}: {len(joint_map.joints)} joints mapped, {len(joint_map.ignore)} ignored; "
          f"check it, then pass it with --joint-map {args.out}")
    for note in notes:
        print(f"note: {note}")


def cmd_motion_import(args):
    from loosefit.motion.io import load_motion

    writable(args.out, folder=False)
    guard_output(args.out, args.force)
    body = _body(args)
    motion = load_motion(args.file, body, joint_map=args.joint_map, source_fps=args.fps, start=args.start,
                         seconds=args.seconds, keep_first_frame=args.keep_first_frame)
    motion.save(args.out)
    print(f"wrote {args.out}: {motion.num_frames} frames at {motion.fps:g} fps on rig {motion.rig}")


def _garment_params(items: list[str]) -> dict:
    params = {}
    for item in items or []:
        key, sep, val = item.partition("=")
        if not sep:
            raise LoosefitError(f"bad garment parameter {item!r}: expected NAME=VALUE")
        try:
            params[key] = json.loads(val)
        except json.JSONDecodeError:
            params[key] = val
    return params


def _at_model_rate(motion, path):
    """``motion`` at the frame rate garment models learn at (30 fps, as every dataset is simulated): a motion file
    at another rate is resampled (its duration kept), and a line says so."""
    from loosefit.motion.motion import DEFAULT_FPS
    from loosefit.motion.resample import resample

    if abs(motion.fps - DEFAULT_FPS) <= 1e-6 * DEFAULT_FPS:
        return motion
    resampled = resample(motion, DEFAULT_FPS)
    print(f"{path}: {motion.num_frames} frames at {motion.fps:g} fps, resampled to the model's {DEFAULT_FPS:g} fps "
          f"({resampled.num_frames} frames)", file=sys.stderr)
    return resampled


def _shape_text(shape: dict) -> str:
    return ",".join(f"{k}={v:g}" for k, v in shape.items())


def _refit_line(path, fitted: dict) -> str:
    """What :func:`loosefit.garment.body_fit.refit` did to the garment file ``path``, for people."""
    return (f"{path}: made on the body {_shape_text(fitted['from_shape'])}, draped onto "
            f"{_shape_text(fitted['to_shape'])}: {fitted['inside_before_percent']:g}% of vertices more than 2 mm "
            f"inside the body before, {fitted['inside_after_percent']:g}% after")


def _garment_out(args) -> None:
    """Check a garment's output and its JSON sidecar (``G.obj`` writes ``G.json`` beside it) before the work."""
    from loosefit.garment import Garment

    writable(args.out, folder=False)
    for path in (args.out, Garment.sidecar_path(args.out)):
        guard_output(path, args.force)


def cmd_garment_make(args):
    from loosefit.garment import make_garment

    _garment_out(args)
    params = _garment_params(args.param)
    if args.length is not None:
        params["length"] = args.length
    if args.flare is not None:
        params["flare"] = args.flare
    garment = make_garment(args.kind, _body(args), seed=args.seed, edge_length=args.edge_length, **params)
    garment.save(args.out)
    print(f"wrote {args.out}: {garment.kind}, {len(garment.verts)} vertices, {len(garment.faces)} faces, "
          f"{int(garment.pinned.sum())} pinned")


def cmd_garment_import(args):
    from loosefit.garment import import_garment

    _garment_out(args)
    garment = import_garment(args.file, _body(args), unit=args.unit, up=args.up, fit=True if args.fit else None,
                             piece=args.piece, repair=args.repair)
    garment.save(args.out)
    p = garment.params
    if args.repair:  # one line per kind of change
        for line in p["repair"]["changes"] or ["nothing to change"]:
            print(f"repair: {line}")
    if "fit" in p:  # made for another body: say so, what it was made for, and what is left inside
        f = p["fit"]
        print(f"fitted as a garment made for another body ({f['why']}): it fits the body "
              f"{f.get('shape_option') or _shape_text(f['shape'])} best, "
              f"draped from there onto this body; {f['inside_percent']:g}% of vertices more than 2 mm inside it")
    repaired = {k: v for k, v in p["repairs"].items() if v}
    print(f"wrote {args.out}: {len(garment.verts)} vertices, {len(garment.faces)} faces; {p['unit']}, {p['up']} up, "
          f"attachment {p['attachment']}, top at {p['top_z']:.3f} m (moved by {p['offset']} m); pushed out of the body "
          f"by {p['pushed_out']['max_mm']:g} mm at most (mean {p['pushed_out']['mean_mm']:g} mm over "
          f"{p['pushed_out']['moved_percent']:g}% of vertices)" + (f"; repaired {repaired}" if repaired else ""))


def cmd_info(args):
    from loosefit.data import DatasetStore, format_info, format_repair

    if args.repair:
        with DatasetStore.open(args.data, mode="a") as store:
            dropped = store.repair()
        print(json.dumps({"dropped": dropped}, indent=2) if args.json else format_repair(args.data, dropped))
        return
    info = DatasetStore.open(args.data, mode="r").info()
    print(json.dumps(info, indent=2, default=str) if args.json else format_info(info))


def cmd_render(args):
    from loosefit.viz.inputs import load_panels
    from loosefit.viz.render import render_video
    from loosefit.viz.scene import check_panels

    writable(args.out)  # a path without a suffix is a folder of PNGs
    guard_output(args.out, args.force)
    meshes = [p for p in args.input if Path(p).suffix.lower() in (".obj", ".ply")]
    if args.motion and not meshes:
        raise InputError("--motion poses a garment mesh (.obj / .ply input); the inputs have their own frames",
                         args.motion)
    panels = [panel for path in args.input for panel in load_panels(
        path, sequence=args.sequence, motion=args.motion if path in meshes else None, joint_map=args.joint_map,
        keep_first_frame=args.keep_first_frame)]
    if args.frame is None and Path(args.out).suffix.lower() == ".png":
        frames = check_panels(panels)
        if frames != 1:
            raise InputError(f"a .png output holds one frame and the input has {frames}: choose one with --frame K "
                             "(0 is the first) or write a .mp4, .gif or a folder", args.out)
    render_video(panels, args.out, fps=args.fps, size=(args.width, args.height), backend=args.backend,
                 frames=args.frame)
    print(f"wrote {args.out}")


def cmd_evaluate(args):
    from loosefit.metrics.report import EvaluationSettings, evaluate, load_pairs

    given = dict(sted_rings=args.sted_rings, sted_dt=args.sted_dt, sted_c=args.sted_c, collision_tolerance=args.tolerance,
                 surface_depth=args.surface_depth)
    settings = EvaluationSettings(**{k: v for k, v in given.items() if v is not None})
    writable(args.out, folder=True)
    out = Path(args.out)
    guard_output(out, args.force, names=("metrics.csv", "metrics.json"))  # a run folder's metrics.csv is its log
    result = evaluate(load_pairs(args.pred, args.gt, args.body, args.sequence, args.split), settings)
    print(result.table())
    result.write_csv(out / "metrics.csv")
    result.write_json(out / "metrics.json")
    print(f"wrote {out / 'metrics.csv'} and {out / 'metrics.json'}")


def cmd_simulate(args):
    from loosefit.sim import SimParams, run_plan, simulate_file
    from loosefit.sim.runner import summary_line

    if args.plan is not None:
        if args.garment or args.motion:
            raise LoosefitError("give either PLAN.yaml or --garment and --motion, not both")
        # These options shape one sequence; a plan says the same things itself, under these keys.
        in_plan = {"--set": "sim_params (a named set, e.g. sim_params: {default: {bending: 1.0e-4}})",
                   "--params": "sim_params", "--shape": "shapes (e.g. shapes: {tall: {height: 0.8}})",
                   "--fit": "a garment file made on another shape (its sidecar's body_shape; drape happens anyway)",
                   "--joint-map": "the joint_map of a file motion (motions: {clip: {file: ..., joint_map: cc}})",
                   "--keep-first-frame": "start (a plan reads every frame of a file; start: 1 skips its frame 0)"}
        given = [option for option in in_plan if getattr(args, option[2:].replace("-", "_"))]
        if given:
            where = "; ".join(f"{option} -> {in_plan[option]}" for option in given)
            raise InputError(f"options for one sequence (--garment, --motion), not for a plan: {', '.join(given)}; "
                             f"write them into the plan instead: {where}", args.plan)
        if args.force:
            raise InputError("--force applies to one sequence's --out; a plan resumes in its store (finished "
                             "sequences are kept)", args.plan)
        writable(args.out, folder=True)
        summary = run_plan(args.plan, args.out, workers=args.workers, address=args.address,
                           splits=tuple(args.splits) if args.splits else None,
                           garments=tuple(args.garments) if args.garments else None)
        print(json.dumps({k: v for k, v in summary.items() if k != "sequences"}, indent=2))
        print(summary_line(summary, args.out))
        return
    if not (args.garment and args.motion):
        raise LoosefitError("simulate needs PLAN.yaml, or --garment G.obj and --motion M.npz")
    if args.splits or args.garments:
        raise LoosefitError("--splits and --garments choose sequences of a plan; give PLAN.yaml")
    sets = args.set or []
    params = SimParams.load(args.params, sets) if args.params else SimParams().with_overrides(sets)
    writable(args.out, folder=False)  # before the simulation, not after it
    guard_output(args.out, args.force)
    result = simulate_file(args.garment, args.motion, args.out, params=params, shape=args.shape,
                           joint_map=args.joint_map, fit=True if args.fit else None,
                           keep_first_frame=args.keep_first_frame)
    print(json.dumps(result.stats, indent=2, default=str))
    fitted = result.stats.get("garment_fit")
    if fitted is not None and "from_shape" in fitted:
        print(_refit_line(args.garment, fitted))
    elif fitted is not None:
        print(f"{args.garment}: fitted as a garment made for another body ({fitted['why']}): it fits the body "
              f"{fitted.get('shape_option') or _shape_text(fitted['shape'])} best; {fitted['inside_percent']:g}% of "
              "vertices more than 2 mm inside this body")
    if result.status != "ok":
        raise LoosefitError(f"{args.out}: the simulation failed the quality gate: {result.reason}")
    print(f"{args.out}: simulated ok ({result.verts.shape[0]} frames, passed the quality gate)")


def cmd_prepare(args):
    from loosefit.config import apply_overrides, config_to_dict
    from loosefit.rig.prepare import prepare, prepare_settings

    settings = apply_overrides(prepare_settings({} if args.bones is None else {"bones": args.bones}), args.set or [])
    summary = prepare(args.data, force=args.force, **config_to_dict(settings))
    for name, g in summary["garments"].items():
        rig = f"{g['bones']} bones, LF RMSE {g['rmse_lf_mm']:.2f} mm" if "bones" in g else "no training sequences"
        print(f"{name}: {rig}")
    print(f"fit attribute: {summary['fit_attribute'].get('status', summary['fit_attribute'])}")


def cmd_train(args):
    from loosefit.training import train_model

    writable(args.out, folder=True)
    guard_output(args.out, None, stores_only=True)  # a run folder is train's own output; a store is not

    if args.method == "collision":
        if args.nproc != 1 or args.device not in (None, "cpu"):
            raise InputError("the body SDF (--method collision) trains in one CPU process: drop --nproc / --device")
        from loosefit.config import load_config
        from loosefit.models.collision import SDFRunConfig, train_sdf_run

        summary = train_sdf_run(args.data, args.out, load_config(SDFRunConfig, args.config, args.set or ()))
        print(json.dumps(summary, indent=2, default=str))
        return

    from loosefit.train.distributed import is_main, launch

    from loosefit.models.registry import run_config_class
    from loosefit.train.run import RunDir
    from loosefit.training import METHOD_CONFIG

    run = RunDir(args.out)
    if args.resume and not (run.has_checkpoint() or (run.path / METHOD_CONFIG).is_file()):
        raise InputError(f"--resume: this folder holds no run to resume (no {METHOD_CONFIG}, no checkpoints/last.pt); "
                         "drop --resume to start a new run here", args.out)

    overrides = list(args.set or ())
    if args.device and hasattr(run_config_class(args.method)(), "train"):  # body-lbs has nothing to train
        overrides.append(f"train.device={args.device}")
    result = launch(train_model, args.nproc, args.method, args.data, args.garment, args.out, config=args.config,
                    overrides=overrides, resume=args.resume, val_split=args.val_split,
                    val_motions=args.val_motions, val_fraction=args.val_fraction, train_fraction=args.train_fraction)
    if not is_main():  # under torchrun every process runs this command: rank 0 reports
        return
    if result is None:
        print(f"{args.method} has no trainable parameters: wrote its fixed weights to {args.out}")
    else:
        print(json.dumps(result.summary(), indent=2, default=str))


def cmd_animate(args):
    from loosefit.animate import Animator
    from loosefit.animate_any import AnyGarmentAnimator, is_static_run
    from loosefit.io.export import export_animation
    from loosefit.metrics.collision import inside_body_report
    from loosefit.motion.io import load_motion

    from loosefit.io.export import export_files

    writable(args.out, folder=True if len(args.motion) > 1 else None)
    if len(args.motion) > 1:
        written = [f.name for p in args.motion for f in export_files(f"{Path(p).stem}{args.format}", args.with_body)]
        guard_output(args.out, args.force, names=written)
    else:
        for path in export_files(args.out, args.with_body):
            guard_output(path, args.force)
    body = _body(args)
    motions = [_at_model_rate(load_motion(path, body, joint_map=args.joint_map, source_fps=args.fps,
                                          keep_first_frame=args.keep_first_frame), path) for path in args.motion]
    if is_static_run(args.run):
        from loosefit.garment import Garment
        from loosefit.garment.body_fit import refit

        if not args.garment:
            raise InputError("this run animates any garment: give --garment (in the rest pose of --shape)", args.run)
        animator = AnyGarmentAnimator(args.run, checkpoint=args.checkpoint, threads=args.threads, device=args.device)
        garment, fitted = refit(Garment.load(args.garment), body, args.garment)
        if fitted is not None:
            print(_refit_line(args.garment, fitted))
        pair = animator.pair(garment.verts, garment.faces, body)
        results, faces = [animator.animate(pair, m) for m in motions], garment.faces
    else:
        animator = Animator(args.run, checkpoint=args.checkpoint, threads=args.threads, garment=args.garment,
                            body=body if args.garment else None, device=args.device)
        results, faces = animator.animate_batch(motions), animator.faces
    for path, motion in zip(args.motion, motions):  # root motion the run never saw: the garment may lag behind
        for line in animator.range_warnings(motion, path):
            print(f"loosefit animate: warning: {line}", file=sys.stderr)
    if args.collision != "none":
        from loosefit.models.collision import SDF_FILE, collision_margin, handle_motion_collisions, load_body_sdf

        mode, net = args.collision, None
        if mode not in ("exact", "pushout"):
            mode, net = "neural", load_body_sdf(Path(args.collision) / SDF_FILE)
        margin = collision_margin(args.collision if net is not None else None, args.collision_margin)
        if margin and net is None:
            raise InputError("--collision-margin applies to a body SDF network, not to --collision " + mode)
        results = [handle_motion_collisions(v, faces, body, m, mode, net, margin=margin)
                   for v, m in zip(results, motions)]
    outs = [Path(args.out)] if len(motions) == 1 else [Path(args.out) / f"{Path(p).stem}{args.format}" for p in args.motion]
    for motion, verts, out in zip(motions, results, outs):
        # A mesh-sequence .npz always carries the body, so `loosefit render` shows what the garment is on.
        posed = body.pose(motion) if args.with_body or out.suffix.lower() == ".npz" else None
        export_animation(out, verts, faces, fps=motion.fps,
                         body_verts=None if posed is None else posed.verts, body_faces=None if posed is None else body.faces)
        inside = inside_body_report(verts, body, motion, faces=faces)
        print(f"wrote {out}: {verts.shape[0]} frames, {verts.shape[1]} vertices ({animator.method}, collision handling "
              f"{args.collision}); inside the body by more than {inside['depth_m'] * 1e3:g} mm: {inside['mean_percent']:.1f} % "
              f"of the vertices (worst frame {inside['worst_percent']:.1f} %), {inside['surface_mean_percent']:.1f} % of "
              f"surface points between them (worst {inside['surface_worst_percent']:.1f} %), deepest "
              f"{inside['deepest_mm']:.0f} mm (measured on {inside['frames']} of {inside['of_frames']} frames)")


def cmd_report(args):
    from loosefit.report import build_report
    from loosefit.report.build import DEFAULT_RESULTS

    writable(args.out, folder=True)  # before the runs are evaluated
    guard_output(args.out, args.force, names=("index.html", "report.md", "metrics.json", "figures"))
    index = build_report(args.data, args.run, args.out, sequences=args.sequence, split=args.split,
                         results_dir=args.results or DEFAULT_RESULTS, device=args.device, images=not args.no_images,
                         handling=args.collision)
    print(f"wrote {index} (and report.md, metrics.json, figures/)")


def cmd_export_rig(args):
    from loosefit.export_rig import export_rig
    from loosefit.motion.io import load_motion

    writable(args.out, folder=False)
    guard_output(args.out, args.force)
    body = _body(args)
    motion = _at_model_rate(load_motion(args.motion, body, joint_map=args.joint_map,
                                        keep_first_frame=args.keep_first_frame), args.motion)
    summary = export_rig(args.run, motion, args.out, body=None if args.no_body else body, influences=args.influences,
                         checkpoint=args.checkpoint, threads=args.threads)
    print(f"wrote {args.out}: {summary['bytes']} bytes, {summary['frames']} frames at {summary['fps']:g} fps, "
          f"{args.influences} influences per vertex")
    for name in ("garment", "body"):
        if name in summary:
            m = summary[name]
            print(f"  {name}: {m['vertices']} vertices, {m['joints']} joints; {m['vertices_truncated']} vertices had more "
                  f"influences: moved {m['rms_mm']:.2f} mm RMS, {m['max_mm']:.2f} mm at most")


def cmd_view(args):
    from loosefit.viz.viewer import view

    if args.live:
        from loosefit.viz.live import view_live_command

        return view_live_command(args)
    if args.export is not None:
        writable(args.export, folder=True)  # before the scene is built
        guard_output(args.export, None)  # no --force: an export folder is a new one or an earlier export
    result = view(args.input, port=args.port, export=args.export, collisions=not args.no_collisions,
                  collision_frames=args.collision_frames, handling=args.collision, joint_map=args.joint_map,
                  keep_first_frame=args.keep_first_frame, reference=not args.no_reference)
    if args.export is not None:
        print(f"wrote {result}: open it in a browser (from disk or any web server)")


def cmd_demo(args):
    from loosefit.demo import run_demo

    writable(args.out, folder=True)
    guard_output(args.out, None)  # no --force: the demo resumes in its own folder
    run_demo(Path(args.out))


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
    export_onnx_parser(sub)

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


class Stopped(KeyboardInterrupt):
    """SIGTERM, raised where Ctrl-C raises :class:`KeyboardInterrupt` (so that what is running keeps its work).

    ``Stopped.seen`` says that a SIGTERM arrived even when the exception reaches :func:`main` as a plain
    :class:`KeyboardInterrupt` (Ray's ``wait`` turns any exception of a signal handler into one)."""

    seen = False


def _on_sigterm(signum, frame):
    Stopped.seen = True
    raise Stopped()


def _kept(args, argv: list[str]) -> str:
    """What an interrupted verb kept, and the command that resumes it, in words."""
    again = shlex.join(["loosefit", *argv])
    if args.command == "simulate" and args.plan is not None:
        out = Path(args.out)
        try:
            from loosefit.data import DatasetStore

            done = len(DatasetStore.open(out, mode="r").sequence_names(status="ok"))
        except Exception:  # noqa: BLE001 - no store (nothing was stored) or one that cannot be read now
            return f"nothing was stored in {out}; run again: {again}"
        return f"{done} finished sequence(s) are kept in {out}; resume (finished ones are skipped): {again}"
    if args.command == "simulate":  # one sequence: its file is written only when the simulation is finished
        return f"nothing was written to {args.out} (a sequence is written when its simulation ends); run again: {again}"
    if args.command == "prepare":
        return (f"what was prepared is kept in {args.data} (a garment cut short is marked writing and redone); "
                f"resume: {again}")
    if args.command == "train":
        last = Path(args.out) / "checkpoints" / "last.pt"
        if args.method == "collision" or not last.is_file():
            return f"no training epoch was completed in {args.out}; run again: {again}"
        resume = again if args.resume else shlex.join(["loosefit", *argv, "--resume"])
        return f"the last completed epoch is kept in {last}; resume: {resume}"
    return f"run again: {again}"


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    Stopped.seen = False
    try:
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread: leave SIGTERM alone
        previous = None
    try:
        with quiet_third_party(quiet=not args.verbose):  # Warp's start-up banner and load timings: with -v only
            args.func(args)
    except LoosefitError as e:
        print(f"loosefit {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:  # Ctrl-C or SIGTERM: one line, no traceback
        term = isinstance(e, Stopped) or Stopped.seen
        print(f"loosefit {args.command}: interrupted ({'SIGTERM' if term else 'SIGINT'}): {_kept(args, argv)}",
              file=sys.stderr)
        return 143 if term else 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return 0


if __name__ == "__main__":
    sys.exit(main())
