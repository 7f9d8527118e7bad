"""Look at the predictions: frames of a test sequence, the simulation beside SwinGar and body-LBS (from the
garment's rest mesh alone), FitGar's coarse and detail meshes, and per-garment runs (VirtualBones, JointNet:
``--run LABEL=RUN``), on the sequence's body. ``--mean-reference`` adds the mean of the sequence's base and
reference runs (what a deterministic model can reach, :mod:`loosefit.metrics.reference`).

Each row of the PNG is one frame; each column one mesh, drawn with the posed body, from the same camera.
The per-vertex error to the simulation (mm) colours the predictions, on one scale for the whole image.

With ``--collision SDF_RUN`` (and ``--margin``) SwinGar's meshes are also shown after the neural collision
correction (SwinGar Eq. 10, :func:`~loosefit.models.collision.handle_motion_collisions`).

Run: .venv/bin/python benchmarks/experiments/graph_renders.py --data DATA.zarr --sequence NAME [--swingar RUN]
         [--collision SDF_RUN [--margin 0.01|auto]] [--fitgar RUN] [--run VirtualBones=RUN ...] [--mean-reference]
         [--frames 45,120] [--name graph-render-NAME]
(writes benchmarks/results/<name>.png)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common and the standing scripts
from _common import RESULTS  # noqa: E402

from loosefit.animate import Animator  # noqa: E402
from loosefit.animate_any import AnyGarmentAnimator  # noqa: E402
from loosefit.body import AnnyBody, AnnyShape  # noqa: E402
from loosefit.data.store import DatasetStore  # noqa: E402
from loosefit.errors import InputError  # noqa: E402
from loosefit.metrics.reference import References  # noqa: E402
from loosefit.models.collision import SDF_FILE, collision_margin, handle_motion_collisions, load_body_sdf  # noqa: E402
from loosefit.sim.attach import body_lbs  # noqa: E402
from loosefit.viz.render import render_frames, save_png  # noqa: E402
from loosefit.viz.scene import BODY_COLOR, MeshTrack  # noqa: E402

ERROR_RANGE_MM = (0.0, 100.0)


def predictions(store: DatasetStore, name: str, swingar: Path | None, fitgar: Path | None,
                collision: Path | None = None, margin: float = 0.0, runs: dict[str, Path] | None = None,
                mean_reference: bool = False) -> tuple[dict, object, object, np.ndarray]:
    """``({label: (T, V, 3)}, body, motion, faces (F, 3))``: the simulation first, then each method's meshes."""
    seq = store.sequence(name)
    motion = store.motion(seq.motion)
    body = AnnyBody(AnnyShape.from_array(store.body(seq.body)), rig=motion.rig)
    garment = store.garment(seq.garment)
    meshes = {"simulation": np.asarray(seq.verts[:], np.float32)}
    if mean_reference:
        refs = References(meshes["simulation"], store.references(name))
        meshes[f"mean of {refs.count + 1} runs"] = refs.mean.astype(np.float32)
    for label, run in (runs or {}).items():
        meshes[label] = Animator(run).animate(motion)
    if swingar is not None:
        meshes["SwinGar"] = Animator(swingar, garment=garment, body=body).animate(motion)
        if collision is not None:
            net = load_body_sdf(collision / SDF_FILE)
            label = "SwinGar + Eq. 10" + (f", {margin * 1e3:.1f} mm margin" if margin else "")
            meshes[label] = handle_motion_collisions(meshes["SwinGar"], garment.faces, body, motion, "neural", net,
                                                     margin=margin)
    meshes["body-LBS"] = body_lbs(garment.verts, body, motion)
    if fitgar is not None:
        animator = AnyGarmentAnimator(fitgar)
        out = animator.animate_outputs(animator.pair(garment.verts, garment.faces, body), motion)
        meshes["FitGar coarse"], meshes["FitGar detail"] = out["coarse"], out["verts"]
    return meshes, body, motion, garment.faces


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, required=True)
    p.add_argument("--sequence", required=True)
    p.add_argument("--swingar", type=Path, default=None, help="a SwinGar run")
    p.add_argument("--collision", type=Path, default=None, help="a body SDF run: SwinGar corrected by it too")
    p.add_argument("--margin", default="0", help="the correction's margin, metres, or 'auto' (the SDF run's calibrated one)")
    p.add_argument("--fitgar", type=Path, default=None, help="a FitGar run")
    p.add_argument("--run", action="append", default=[], metavar="LABEL=RUN",
                   help="a per-garment run (VirtualBones, JointNet) trained on the sequence's garment")
    p.add_argument("--mean-reference", action="store_true", help="also the mean of the base and reference runs")
    p.add_argument("--frames", default="45,120")
    p.add_argument("--size", default="360,480", help="W,H pixels of one panel")
    p.add_argument("--name", default=None)
    args = p.parse_args()
    store = DatasetStore.open(args.data)
    if args.collision is not None and args.swingar is None:
        p.error("--collision corrects SwinGar's meshes: give --swingar")
    try:
        margin = collision_margin(args.collision, args.margin) if args.collision is not None else 0.0
    except InputError as e:
        p.error(str(e))
    if any("=" not in text for text in args.run):
        p.error("--run takes LABEL=RUN, e.g. VirtualBones=runs/skirt/virtualbones")
    runs = {label: Path(run) for label, run in (text.split("=", 1) for text in args.run)}
    meshes, body, motion, faces = predictions(store, args.sequence, args.swingar, args.fitgar, args.collision, margin,
                                              runs, args.mean_reference)
    frames = [int(f) for f in args.frames.split(",")]
    posed = body.pose(motion).verts
    gt = meshes["simulation"]
    panels, titles = [], []
    for label, verts in meshes.items():
        error = None if label == "simulation" else np.linalg.norm(verts - gt, axis=-1) * 1e3
        garment = MeshTrack(verts, faces, scalars=error, clim=ERROR_RANGE_MM if error is not None else None,
                            cmap="inferno", label=label, scalar_name="error (mm)" if error is not None else "")
        panels.append([MeshTrack(posed[: len(gt)], body.faces, BODY_COLOR, label="body"), garment])
        rmse = "" if error is None else f" {np.sqrt((error[frames] ** 2).mean()):.0f} mm"
        titles.append(label + rmse)
    size = tuple(int(v) for v in args.size.split(","))
    rows = render_frames(panels, size=size, frames=frames, titles=titles)
    name = args.name or f"graph-render-{args.sequence.replace('+', '-')}"
    path = RESULTS / f"{name}.png"
    save_png(path, np.concatenate(list(rows), axis=0))
    print(path)


if __name__ == "__main__":
    main()
