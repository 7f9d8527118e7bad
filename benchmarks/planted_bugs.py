"""Planted structural bugs: how many the model tests catch.

Each planted bug rewires or removes one structural element of a method as its paper describes it
(a loss term left out of the total, a module reading the wrong mesh, a displacement added in the wrong
space). For each one this script copies ``src/``, ``tests/`` and ``configs/`` of a revision into a
scratch folder, edits the copy (never the repository), runs that method's test file with ``pytest -x``
and records whether a test failed (caught) or all passed (missed).

    python benchmarks/planted_bugs.py                  # the working tree's tests
    python benchmarks/planted_bugs.py --rev main       # the tests of another revision (before/after)
    python benchmarks/planted_bugs.py --only vb-      # the bugs whose name starts with vb-

Writes ``benchmarks/results/planted-bugs-<label>.json``. An edit may list a text for each revision (the
ones that do not occur are skipped); a bug none of whose texts occur, or one occurring twice, is reported
as ``not planted`` (the source moved on): edit its entry.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import save_results  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
VB, JN, LBS, FG, SG = (f"src/loosefit/models/{m}.py" for m in ("virtualbones", "jointnet", "body_lbs", "fitgar", "swingar"))
T_VB, T_JN, T_LBS, T_FG, T_SG = (f"tests/models/test_{m}.py"
                                 for m in ("virtualbones", "jointnet", "body_lbs", "fitgar", "swingar"))

#: name -> (file, [(text, replacement)...], test file, what the bug breaks)
BUGS = {
    "vb-hf-reads-rest-mesh": (VB, [("local = (lf - self.lf_mean) / self.lf_std",
                                    "local = (self.rest_verts.expand_as(lf) - self.lf_mean) / self.lf_std")], T_VB,
                              "the high-frequency EdgeConv reads the rest mesh, not the predicted low-frequency mesh"),
    "vb-forward-hf-on-rest": (VB, [("offsets, h_high = self.high_frequency(raw, lf, h_high)",
                                    "offsets, h_high = self.high_frequency(raw, self.rest_verts.expand_as(lf), h_high)")],
                              T_VB, "forward gives the high-frequency module the rest mesh"),
    "vb-laplacian-dropped": (VB, [("loss = vertex + c.laplacian_weight * lap", "loss = vertex")], T_VB,
                             "the Laplacian term of VirtualBones Eq. 2 is logged but not in the total"),
    "vb-laplacian-unweighted": (VB, [("loss = vertex + c.laplacian_weight * lap", "loss = vertex + lap")], T_VB,
                                "lambda_Lap ignored"),
    "vb-collision-unweighted": (VB, [("loss = loss + c.collision_weight * coll", "loss = loss + coll")], T_VB,
                                "the collision weight ignored"),
    "vb-bone-unweighted": (VB, [("loss = loss + c.bone_weight * bone", "loss = loss + bone")], T_VB,
                           "the bone supervision weight ignored"),
    "vb-hf-gru-reads-nothing": (VB, [("out, h = self.high_gru(raw.flatten(-2), h)",
                                      "out, h = self.high_gru(torch.zeros_like(raw.flatten(-2)), h)")], T_VB,
                                "the high-frequency GRU does not read the predicted bone motion"),
    "vb-no-hf": (VB, [('"verts": lf + offsets', '"verts": lf + 0 * offsets')], T_VB,
                 "the output lacks the high-frequency offsets"),
    "jn-normal-unweighted": (JN, [("self.config.lambda_norm * normal", "normal")], T_JN, "lambda_norm ignored"),
    "jn-sparsity-dropped": (JN, [(" + self.config.lambda_sparse * sparse", "")], T_JN,
                            "the L1 of the association (JointNet Eq. 8) not in the total"),
    "jn-psd-posed-space": (JN, [("            rest = rest + displacement\n", ""),
                                *[(f"verts = self.skin(rest, R, {t})",  # the translation's name before and after
                                   f"verts = self.skin(rest, R, {t}) + (0 if displacement is None else displacement)")
                                  for t in ("T", "trans")]],
                           T_JN, "the PSD displacement added after the skinning, not in the canonical rest space"),
    "jn-no-fourier": (JN, [("association @ psi + self.fourier_features()", "association @ psi")], T_JN,
                      "the garment prior (Fourier features of the bone rest positions) left out"),
    "jn-association-ignored": (JN, [("association @ psi + self.fourier_features()",
                                     "association.mean() * 0 + psi.mean(2, keepdim=True) + self.fourier_features()")],
                               T_JN, "every bone reads the mean of all joint features: no joint-to-bone association"),
    "jn-no-relu": (JN, [("return torch.relu(self.association)", "return self.association")], T_JN,
                   "the association may go negative"),
    "lbs-root-height-ignored": (LBS, [("torch.zeros_like(height), height], -1)",
                                       "torch.zeros_like(height), 0 * height], -1)")], T_LBS,
                                "the root height feature does not move the skeleton"),
    "lbs-weights-all-root": (LBS, [("skinning_transforms(world, self.rest_joints))",
                                    "skinning_transforms(world, self.rest_joints)[:, :1].expand_as("
                                    "skinning_transforms(world, self.rest_joints)))")], T_LBS,
                             "every vertex follows the root joint"),
    "fg-detail-reads-anchor": (FG, [("detail_disp = self.detail_displacement(batch, coarse)",
                                     'detail_disp = self.detail_displacement(batch, batch["anchor"])')], T_FG,
                               "the detail generator reads the body anchor, not the predicted coarse mesh"),
    "fg-detail-normals-of-anchor": (FG, [("vertex_normals_torch(coarse, batch[\"faces\"])",
                                          "vertex_normals_torch(batch[\"anchor\"], batch[\"faces\"])")], T_FG,
                                    "the detail graph's normals are those of the anchor, not of the coarse mesh"),
    "fg-no-parser-product": (FG, [("h = h * self.encoding(batch)[idx]  # FitGar Eq. 7",
                                   "h = h + 0 * self.encoding(batch)[idx]")], T_FG,
                             "the attribute parser's encoding is not infused (FitGar Eq. 7)"),
    "sg-blend-posed-space": (SG, [('rest = g["rest"] + blend  #', 'rest = g["rest"] + 0 * blend  #'),
                                  ("Mc = (M[..., :3] @ rest[..., None])[..., 0] + M[..., 3]",
                                   "Mc = (M[..., :3] @ rest[..., None])[..., 0] + M[..., 3] + blend")], T_SG,
                             "the blend shapes added after the skinning, not to the unposed garment"),
    "sg-corrective-reads-rest": (SG, [('"nodes": torch.cat([Mc, dist], -1)',
                                       '"nodes": torch.cat([g["rest"].expand_as(Mc), dist], -1)')], T_SG,
                                 "the corrective predictor reads the rest garment, not the coarse mesh M_c"),
    "sg-weights-ignore-shape": (SG, [("self.weight_out(self.weight_state(S) * shape)",
                                      "self.weight_out(self.weight_state(S))")], T_SG,
                                "the dynamic skinning weights ignore the garment's shape features"),
}


def checkout(rev: str | None, dest: Path) -> None:
    """``src``, ``tests``, ``configs`` of ``rev`` (None: the working tree) under ``dest``."""
    if rev is None:
        for part in ("src", "tests", "configs"):
            shutil.copytree(ROOT / part, dest / part, ignore=shutil.ignore_patterns("__pycache__"))
        return
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "src", "tests", "configs"],
                             check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)


def plant(root: Path, path: str, edits: list[tuple[str, str]]) -> bool:
    """Apply the edits to ``root / path``; an edit whose text does not occur is skipped (an alternative
    for another revision); False when no edit applies or a text occurs more than once."""
    file = root / path
    text = file.read_text()
    applied = 0
    for old, new in edits:
        if text.count(old) > 1:
            return False
        if text.count(old) == 1:
            text = text.replace(old, new)
            applied += 1
    file.write_text(text)
    return applied > 0


def run_bug(rev: str | None, name: str, timeout: float) -> dict:
    path, edits, tests, what = BUGS[name]
    with tempfile.TemporaryDirectory(prefix="planted-") as tmp:
        root = Path(tmp)
        checkout(rev, root)
        if not plant(root, path, edits):
            return {"what": what, "result": "not planted"}
        env = {**os.environ, "PYTHONPATH": str(root / "src"), "PYTHONDONTWRITEBYTECODE": "1"}
        start = time.perf_counter()
        try:
            proc = subprocess.run([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", tests],
                                  cwd=root, env=env, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return {"what": what, "result": "timeout", "seconds": timeout}
        seconds = round(time.perf_counter() - start, 1)
        failed = [line.split(" ")[1] for line in proc.stdout.splitlines() if line.startswith(("FAILED", "ERROR"))]
        result = {0: "missed", 1: "caught"}.get(proc.returncode, f"pytest rc {proc.returncode}")
        return {"what": what, "tests": tests, "result": result, "by": failed[:1], "seconds": seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rev", help="git revision whose src/tests/configs to use (default: the working tree)")
    parser.add_argument("--only", default="", help="only the bugs whose name starts with this")
    parser.add_argument("--label", help="results name suffix (default: the revision or 'worktree')")
    parser.add_argument("--timeout", type=float, default=900.0, help="seconds per bug")
    args = parser.parse_args()
    results = {}
    for name in BUGS:
        if name.startswith(args.only):
            results[name] = run_bug(args.rev, name, args.timeout)
            print(name, results[name]["result"], results[name].get("by", ""), flush=True)
    counts = {k: sum(r["result"] == k for r in results.values()) for k in ("caught", "missed", "not planted")}
    print(counts)
    save_results(f"planted-bugs-{args.label or args.rev or 'worktree'}", {"counts": counts, "bugs": results})


if __name__ == "__main__":
    main()
