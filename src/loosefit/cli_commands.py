"""The verbs of the ``loosefit`` command line: each handler takes the parsed arguments
(:func:`loosefit.cli_parser.build_parser`), checks its outputs and calls a library function."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from loosefit.cli_args import writable
from loosefit.errors import InputError, LoosefitError
from loosefit.paths import guard_output


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
    from loosefit.sim import SimParams
    from loosefit.simulate import run_plan, simulate_file, summary_line

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
        results, faces, rest = [animator.animate(pair, m) for m in motions], garment.faces, garment.verts
    else:
        animator = Animator(args.run, checkpoint=args.checkpoint, threads=args.threads, garment=args.garment,
                            body=body if args.garment else None, device=args.device)
        results, faces, rest = animator.animate_batch(motions), animator.faces, animator.rest_garment
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
        results = [handle_motion_collisions(v, faces, body, m, mode, net, margin=margin, rest=rest)
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
                         handling=args.collision, measure_speed=args.measure_speed)
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


def cmd_export_onnx(args):
    from loosefit.export_onnx import export_onnx

    writable(args.out, folder=False)
    guard_output(args.out, args.force)
    s = export_onnx(args.run, args.out, checkpoint=args.checkpoint, bones=args.bones, int8=args.int8)
    bones = f", {s['bones']} bone transforms" if s["bones"] else ""
    print(f"wrote {s['path']}: {s['bytes']} bytes, {s['method']}, {s['joints']} joints in, {s['vertices']} vertices "
          f"out, state of {s['state_size']} floats{bones}")
    if args.int8 and not s["weights"]["run_on_int8_grid"]:
        print("  its weights are rounded to int8 here, not in the run: its vertices differ from loosefit animate's "
              "by what that rounding does (about 1 mm at most); `loosefit quantize RUN --out RUN-int8` makes a run "
              "that animates as this model does")


def cmd_quantize(args):
    from loosefit.quantize import quantize_run

    writable(args.out, folder=True)
    s = quantize_run(args.run, args.out, checkpoint=args.checkpoint)
    print(f"wrote {s['path']}: {s['method']}, {s['weights_rounded']} weights of {s['matrices']} matrices "
          f"({len(s['parameters'])} parameters) rounded to int8, the largest change {s['largest_change']:.2e}; "
          f"export it with export-onnx --int8")


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
