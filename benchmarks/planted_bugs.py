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
as ``not planted`` (the source moved on): edit its entry. A bug's file may be a tuple of paths, the first
that exists in the revision taken (a module that moved). The ``sign-`` bugs flip a sign, drop or change a
constant of a paper's equation, or swap what a gate reads; each names the ``*_signs.py`` test file that pins
it. The ``stat-`` bugs compute a normalisation statistic or buffer from the wrong quantity, the ``grad-`` bugs cut
or widen the gradient path of one loss term (its value unchanged), the ``metric-`` bugs average per frame what is
pooled (or the reverse) in a reported number; each names its ``*_statistics.py`` or ``*_gradients.py`` test file.
At a revision without a bug's test file, the module's own older test files run instead (:data:`EARLIER_TESTS`),
so that ``--rev`` of a revision before those tests measures what the tests caught then.
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
GAT, LGL = (f"src/loosefit/models/layers/{m}.py" for m in ("gat_ln", "lstm_gat_ln"))
#: The collision module before and after its split into a package.
RESOLVER = ("src/loosefit/models/collision/resolver.py", "src/loosefit/models/collision.py")
SDF_NET = ("src/loosefit/models/collision/network.py", "src/loosefit/models/collision.py")
SDF_TRAIN = ("src/loosefit/models/collision/training.py", "src/loosefit/models/collision.py")
S_VB, S_JN, S_FG, S_SG, S_COL = (f"tests/models/test_{m}_signs.py"
                                 for m in ("virtualbones", "jointnet", "fitgar", "swingar", "collision"))
S_GAT, S_LGL = (f"tests/models/layers/test_{m}_signs.py" for m in ("gat_ln", "lstm_gat_ln"))
DS, MG, FGD, LOSSES = ("src/loosefit/models/dataset.py", "src/loosefit/models/multi_garment.py",
                       "src/loosefit/models/fitgar_data.py", "src/loosefit/train/losses.py")
PREP, REPORT, REF, STED = ("src/loosefit/rig/prepare.py", "src/loosefit/metrics/report.py",
                          "src/loosefit/metrics/reference.py", "src/loosefit/metrics/sted.py")
#: The statistics, gradient and metric test files (``stat-``, ``grad-``, ``metric-`` bugs).
D_DS, D_VB, D_JN, D_FG = (f"tests/models/test_{m}_statistics.py" for m in ("dataset", "virtualbones", "jointnet", "fitgar"))
G_VB, G_JN, G_FG, G_SG = (f"tests/models/test_{m}_gradients.py" for m in ("virtualbones", "jointnet", "fitgar", "swingar"))
G_LOSS, D_PREP = "tests/train/test_losses_gradients.py", "tests/rig/test_prepare_statistics.py"
D_REPORT, D_REF, D_STED, D_COL = (f"tests/metrics/test_{m}_statistics.py"
                                  for m in ("report", "reference", "sted", "collision"))
COLLISION, ATTACH = "src/loosefit/metrics/collision.py", "src/loosefit/sim/attach.py"
D_LBS = "tests/models/test_body_lbs_statistics.py"
INT8, T_INT8 = "src/loosefit/io/onnx_int8.py", "tests/io/test_onnx_int8.py"
#: The test files of each module before its ``*_signs.py``, ``*_statistics.py`` or ``*_gradients.py`` file
#: existed (a tuple: all of them run).
EARLIER_TESTS = {S_VB: T_VB, S_JN: T_JN, S_FG: T_FG, S_SG: T_SG, S_COL: "tests/models/test_collision.py",
                 S_GAT: "tests/models/layers/test_gat_ln.py", S_LGL: "tests/models/layers/test_lstm_gat_ln.py",
                 D_DS: ("tests/models/test_dataset.py", T_SG), D_VB: (T_VB, S_VB), G_VB: (T_VB, S_VB),
                 D_JN: (T_JN, S_JN), G_JN: (T_JN, S_JN), D_FG: (T_FG, "tests/models/test_fitgar_train.py"),
                 G_FG: (T_FG, S_FG), G_SG: (T_SG, S_SG), G_LOSS: "tests/train/test_losses.py",
                 D_PREP: "tests/rig/test_prepare.py", D_REPORT: "tests/metrics/test_report.py",
                 D_REF: ("tests/metrics/test_reference.py", "tests/data/test_run_spread.py"),
                 D_STED: "tests/metrics/test_sted.py",
                 D_COL: "tests/metrics/test_collision.py", D_LBS: (T_LBS, "tests/sim/test_attach.py")}

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
    "jn-no-fourier": (JN, [("association @ psi + self.fourier_features()", "association @ psi"),
                           ("prior = self.fourier_features()", "prior = 0 * self.fourier_features()")], T_JN,
                      "the garment prior (Fourier features of the bone rest positions) left out"),
    "jn-association-ignored": (JN, [("association @ psi + self.fourier_features()",
                                     "association.mean() * 0 + psi.mean(2, keepdim=True) + self.fourier_features()"),
                                    ("self.join_prior(association @ psi)",
                                     "self.join_prior(association.mean() * 0 + psi.mean(2, keepdim=True)"
                                     ".expand(-1, -1, association.shape[0], -1))")],
                               T_JN, "every bone reads the mean of all joint features: no joint-to-bone association"),
    "jn-no-relu": (JN, [("return torch.relu(self.association)", "return self.association"),
                        ("A = torch.relu(self.association)\n        if self.config.association == \"hoyer\":\n"
                         "            return A / A.sum(", "A = self.association\n        if self.config.association == "
                         "\"hoyer\":\n            return A / A.sum(")], T_JN,
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
                                       '"nodes": torch.cat([g["rest"].expand_as(Mc), dist], -1)'),
                                      ("nodes = [Mc, dist]", 'nodes = [g["rest"].expand_as(Mc), dist]')], T_SG,
                                 "the corrective predictor reads the rest garment, not the coarse mesh M_c"),
    "sg-weights-ignore-shape": (SG, [("self.weight_out(self.weight_state(S) * shape)",
                                      "self.weight_out(self.weight_state(S))")], T_SG,
                                "the dynamic skinning weights ignore the garment's shape features"),
    # ---- signs and constants of the papers' equations
    "sign-jn-fourier-scale-dropped": (JN, [("torch.randn(K // 2, 3) * config.fourier_scale", "torch.randn(K // 2, 3)")],
                                      S_JN, "the Fourier frequencies ignore fourier_scale (JointNet Eq. 3)"),
    "sign-jn-association-init-scale": (JN, [("torch.rand(B, G) * (2.0 / G)", "torch.rand(B, G) * 2.0")], S_JN,
                                       "the association starts with rows summing to J_s, not 1"),
    "sign-sg-gravity-flipped": (SG, [('GRAVITY * (g["mass"] * (pred[..., 2] - target[..., 2]))',
                                      'GRAVITY * (g["mass"] * (target[..., 2] - pred[..., 2]))')], S_SG,
                                "gravity's sign flipped: raising the garment lowers the loss (SwinGar Eq. 13)"),
    "sign-sg-bend-laplacian-sign": (SG, [(".index_add_(-2, pairs[:, 1], -diff)", ".index_add_(-2, pairs[:, 1], diff)")],
                                    S_SG, "the face-normal Laplacian adds n_b - n_a at face b (SwinGar Eq. 12)"),
    "sign-sg-vert-not-squared": (SG, [('terms = {"vert": ((pred - target) ** 2).sum(-1).mean()}',
                                       'terms = {"vert": (pred - target).norm(dim=-1).mean()}')], S_SG,
                                 "the vertex term is the mean distance, not squared (SwinGar Eq. 11)"),
    "sign-lgl-forget-reads-input-peephole": (LGL, [("f = torch.sigmoid(gf + self.peephole[1] * c)",
                                                    "f = torch.sigmoid(gf + self.peephole[0] * c)")], S_LGL,
                                             "the forget gate reads the input gate's peephole w_i (SwinGar Eq. 6)"),
    "sign-lgl-output-reads-forget-peephole": (LGL, [("o = torch.sigmoid(go + self.peephole[2] * c)",
                                                     "o = torch.sigmoid(go + self.peephole[1] * c)")], S_LGL,
                                              "the output gate reads the forget gate's peephole w_f (SwinGar Eq. 6)"),
    "sign-lgl-output-peeks-new-cell": (LGL, [("        o = torch.sigmoid(go + self.peephole[2] * c)\n"
                                              "        c = i * torch.tanh(gg) + f * c\n",
                                              "        c = i * torch.tanh(gg) + f * c\n"
                                              "        o = torch.sigmoid(go + self.peephole[2] * c)\n"),
                                             ("        o = torch.sigmoid(go + self.peephole[2] * c)\n"
                                              "        c = i * _tanh(gg) + f * c\n",
                                              "        c = i * _tanh(gg) + f * c\n"
                                              "        o = torch.sigmoid(go + self.peephole[2] * c)\n")], S_LGL,
                                       "the output gate's peephole reads C^t, not C^{t-1} (SwinGar Eq. 6)"),
    "sign-gat-alpha-dropped": (GAT, [("s = self.alpha * s / torch.maximum(row, feat * lip)[:, None, None]",
                                      "s = s / torch.maximum(row, feat * lip)[:, None, None]"),
                                     ("scale = (self.alpha / norm)[..., None]", "scale = (1.0 / norm)[..., None]")], S_GAT,
                               "the normalised scores are not scaled by alpha (SwinGar Eq. 4)"),
    "sign-gat-smaller-norm": (GAT, [("s = self.alpha * s / torch.maximum(row, feat * lip)[:, None, None]",
                                     "s = self.alpha * s / torch.minimum(row, feat * lip)[:, None, None]"),
                                    ("return torch.maximum(rows, feat[..., None] * lip)",
                                     "return torch.minimum(rows, feat[..., None] * lip)")], S_GAT,
                              "the scores are divided by the smaller of the two norms (SwinGar Eq. 4)"),
    "sign-gat-heads-summed": (GAT, [("/ self.heads + self.bias", "+ self.bias"),
                                    ("self.out_channels) / self.heads\n", "self.out_channels)\n")], S_GAT,
                              "the heads' outputs are summed, not averaged"),
    "sign-gat-score-slope": (GAT, [("SCORE_SLOPE = 0.2", "SCORE_SLOPE = 0.02")], S_GAT,
                             "GAT's LeakyReLU slope on the scores is 0.02, not 0.2"),
    "sign-col-weights-include-inside": (RESOLVER, [("w = np.exp(-d2 / (2 * self.sigma**2)) * free",
                                                    "w = np.exp(-d2 / (2 * self.sigma**2))")], S_COL,
                                        "delta_i's weights count the inside neighbours too (SwinGar Eq. 10)"),
    "sign-col-eikonal-weight": (SDF_TRAIN, [("EIKONAL_WEIGHT = 0.15", "EIKONAL_WEIGHT = 1.5")], S_COL,
                                "mu_e is 1.5, not 0.15 (SwinGar Eq. 8)"),
    "sign-col-softplus-beta": (SDF_NET, [("SOFTPLUS_BETA = 100.0", "SOFTPLUS_BETA = 10.0")], S_COL,
                               "the SDF network's Softplus has beta 10, not 100 (SwinGar Sec. IV)"),
    "sign-vb-rest-6d-not-identity": (VB, [("IDENTITY_6D = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)",
                                           "IDENTITY_6D = (1.0, 0.0, 0.0, 0.0, 0.0, 1.0)")], S_VB,
                                     "a zero output is a quarter turn about x, not the rest rotation"),
    "sign-vb-pivot-at-origin": (VB, [("return rot, position - (rot @ self.bone_rest[:, :, None])[..., 0]",
                                      "return rot, position - self.bone_rest")], S_VB,
                                "a bone rotates about the origin, not its rest centroid"),
    "sign-fg-coarse-reads-last-factor": (FG, [('batch["alpha"][:, :1] - self.alpha_mean[:1]) / self.alpha_std[:1]',
                                               'batch["alpha"][:, -1:] - self.alpha_mean[-1:]) / self.alpha_std[-1:]')],
                                         S_FG, "the coarse graph reads the last fit factor, not a_1 (FitGar Sec. 4.3)"),
    "sign-fg-loss-scale-not-squared": (FG, [("/ self.coarse.output.scale ** 2}", "/ self.coarse.output.scale}")],
                                       S_FG, "the coarse loss is divided by its output scale, not its square"),
    "sign-fg-parser-added": (FG, [("h = h * self.encoding(batch)[idx]  # FitGar Eq. 7",
                                   "h = h + self.encoding(batch)[idx]  # FitGar Eq. 7")], S_FG,
                             "the parser's encoding is added to the first detail block, not multiplied (FitGar Eq. 7)"),
    # ---- normalisation statistics and buffers computed from the wrong quantity
    "stat-feature-std-over-all-features": (DS, [("np.maximum(x.std(0), STD_FLOOR[key])", "np.maximum(x.std(), STD_FLOOR[key])")],
                                           D_DS, "one std over every motion feature together, not one per feature"),
    "stat-feature-stats-first-sequence": (DS, [("x = np.concatenate([getattr(s, key) for s in self.sequences]).astype(np.float64)",
                                                "x = getattr(self.sequences[0], key).astype(np.float64)")], D_DS,
                                          "the motion statistics of the first training sequence only"),
    "stat-sg-stats-first-garment": (MG, [("for d in self.sequences for s in d.sequences]",
                                          "for s in self.sequences[0].sequences]")], D_DS,
                                    "SwinGar's motion statistics from the first garment's sequences only"),
    "stat-vb-position-is-translation": (VB, [("positions.update((s.bone_rot @ rig.bone_rest_positions[:, :, None])[..., 0] + s.bone_trans)",
                                              "positions.update(s.bone_trans)")], D_VB,
                                        "the bone position statistics of the translations, not of where the centroids went"),
    "stat-vb-position-std-mean-of-stds": (VB, [("pooled = np.sqrt((positions.std**2).mean(0))", "pooled = positions.std.mean(0)")],
                                          D_VB, "the pooled position std is the mean of the bones' stds, not their RMS"),
    "stat-vb-offset-std-of-vertices": (VB, [("offsets.update(s.verts - s.lf)", "offsets.update(s.verts)")], D_VB,
                                       "the high-frequency output scale is the std of the vertices, not of the offsets"),
    "stat-jn-offset-is-position": (JN, [("np.einsum(\"tbij,bj->tbi\", rot, centre) + trans - centre",
                                         "np.einsum(\"tbij,bj->tbi\", rot, centre) + trans")], D_JN,
                                   "JointNet's offset statistics of the bone positions, not of their displacements"),
    "stat-jn-std-pooled-over-bones": (JN, [("np.maximum(values.std(0), MIN_OUTPUT_STD)",
                                            "np.maximum(values.std((0, 1)), MIN_OUTPUT_STD)")], D_JN,
                                      "one output std per axis for every bone, not one per bone"),
    "stat-fg-detail-scale-of-full": (FGD, [("\"detail_scale\": f32(max(np.sqrt(detail.mean()), 1e-4))",
                                            "\"detail_scale\": f32(max(np.sqrt(full.mean()), 1e-4))")], D_FG,
                                     "the detail output scale is that of the whole displacement"),
    "stat-fg-rel-of-body-only": (FGD, [("np.concatenate([np.concatenate([it[\"body_rel\"], it[\"garment_rel\"]]) for it in items])",
                                        "np.concatenate([it[\"body_rel\"] for it in items])")], D_FG,
                                 "the relative-feature statistics leave the garment's vertices out"),
    "stat-fg-dist-to-anchor": (FGD, [("np.linalg.norm(it[\"smooth\"][:, None] - it[\"joints\"][None], axis=-1)",
                                      "np.linalg.norm(it[\"anchor\"][:, None] - it[\"joints\"][None], axis=-1)")], D_FG,
                               "the joint-distance statistics from the body anchors, not the coarse target"),
    "stat-prepare-hf-offset-of-full": (PREP, [("stats.add(\"hf_offset\", hf, (3,))", "stats.add(\"hf_offset\", full, (3,))")],
                                       D_PREP, "the stored high-frequency offset statistics are those of the vertices"),
    "stat-lbs-weights-of-nearest-joint": (ATTACH, [("cKDTree(body.rest_verts(shape))", "cKDTree(body.rest_joints(shape))")],
                                          D_LBS, "body-LBS takes the weights of the body vertex numbered as the nearest joint"),
    # ---- the gradient path of one loss term
    "grad-laplacian-pred-detached": (LOSSES, [("vertex_distance(apply_laplacian(L, pred), apply_laplacian(L, target), mask)",
                                               "vertex_distance(apply_laplacian(L, pred.detach()), apply_laplacian(L, target), mask)")],
                                     G_LOSS, "the Laplacian term (VirtualBones Eq. 2) has its value but trains nothing"),
    "grad-collision-pred-detached": (LOSSES, [("depth = margin - ((pred - b) * n).sum(-1)",
                                               "depth = margin - ((pred.detach() - b) * n).sum(-1)")], G_LOSS,
                                     "the collision penalty never pushes a vertex out"),
    "grad-normal-pred-detached": (LOSSES, [("cos = (face_normals_torch(pred, faces) * face_normals_torch(target, faces)).sum(-1)",
                                            "cos = (face_normals_torch(pred.detach(), faces) * face_normals_torch(target, faces)).sum(-1)")],
                                  G_LOSS, "JointNet's normal term has its value but no gradient"),
    "grad-vb-high-stage-reaches-low": (VB, [("with torch.no_grad():  # the low-frequency module is frozen in this stage",
                                             "if True:  # the low-frequency module is frozen in this stage")], G_VB,
                                       "the high-frequency stage's loss back-propagates into the low-frequency module"),
    "grad-sg-edge-lengths-detached": (SG, [("((lengths(pred) - lengths(target)) ** 2).mean()",
                                            "((lengths(pred).detach() - lengths(target)) ** 2).mean()")], G_SG,
                                      "SwinGar's edge term (Eq. 12) trains nothing"),
    "grad-sg-bend-normals-detached": (SG, [("n = face_normals_torch(pred, g[\"faces\"])",
                                            "n = face_normals_torch(pred.detach(), g[\"faces\"])")], G_SG,
                                      "SwinGar's bending term (Eq. 12) trains nothing"),
    "grad-jn-sparsity-detached": (JN, [("return A.sum()", "return A.detach().sum()")], G_JN,
                                  "JointNet's sparsity term (Eq. 8) does not sparsify the association"),
    "grad-fg-parser-encoding-detached": (FG, [("h = h * self.encoding(batch)[idx]  # FitGar Eq. 7",
                                               "h = h * self.encoding(batch)[idx].detach()  # FitGar Eq. 7")], G_FG,
                                         "the attribute parser gets no gradient through FitGar Eq. 7's product"),
    # ---- diagnostic numbers and pooled averages
    "metric-masked-rmse-per-frame": (LOSSES, [("float(((sq * mask).sum() / n).sqrt() * 1e3)",
                                               "float(((sq.sqrt() * mask).sum() / n) * 1e3)")], G_LOSS,
                                     "the validation RMSE averages the frames' RMS values instead of pooling squares"),
    "metric-report-rmse-per-frame": (REPORT, [("\"rmse_mm\": float(1000 * np.sqrt(np.mean(err * err)))",
                                               "\"rmse_mm\": float(1000 * np.sqrt(np.mean(err * err, 1)).mean())")],
                                     D_REPORT, "a sequence's RMSE is the mean of its frames' RMS values"),
    "metric-report-hausdorff-worst-frame": (REPORT, [("\"hausdorff_mm\": float(1000 * hausdorff_per_frame(pred, gt).mean())",
                                                      "\"hausdorff_mm\": float(1000 * hausdorff_per_frame(pred, gt).max())")],
                                            D_REPORT, "a sequence's Hausdorff distance is its worst frame's, not the mean"),
    "metric-overall-rmse-by-frames": (REPORT, [("ms = _weighted([{**r, \"ms\": r[\"rmse_mm\"] ** 2} for r in rows], \"ms\", tv)",
                                                "ms = _weighted([{**r, \"ms\": r[\"rmse_mm\"] ** 2} for r in rows], \"ms\", "
                                                "lambda r: r[\"frames\"])")], D_REPORT,
                                      "the overall RMSE weighs sequences by frames, not frames x vertices"),
    "metric-overall-collision-by-frames": (REPORT, [("\"collision_pct\": _weighted(rows, \"collision_pct\", tv)",
                                                     "\"collision_pct\": _weighted(rows, \"collision_pct\", lambda r: r[\"frames\"])")],
                                           D_REPORT, "the overall collision share weighs sequences by frames only"),
    "metric-floor-mean-of-run-rms": (("src/loosefit/data/run_spread.py", REF),
                                     [(f"float(np.sqrt(np.mean([{ms}(run, mean) for run in runs])))",
                                       f"float(np.mean([np.sqrt({ms}(run, mean)) for run in runs]))")
                                      for ms in ("_mean_square", "mean_square_distance")], D_REF,
                                     "the floor averages the runs' RMS spreads instead of pooling squares"),
    "metric-sted-temporal-over-prediction": (STED, [("np.mean(np.abs(lt_p - lt) / lt))", "np.mean(np.abs(lt_p - lt) / lt_p))")],
                                             D_STED, "temporal STED relative to the prediction's edge lengths"),
    "metric-surface-share-of-queried": (COLLISION, [("100.0 * (inside > depth).sum() / (len(e) + len(f))",
                                                     "100.0 * (inside > depth).sum() / max(len(inside), 1)")], D_COL,
                                        "the surface share counts over the samples queried, not over all of them"),
    "metric-prepare-rmse-per-frame": (PREP, [("\"rmse_lf_mm\": float(np.sqrt(np.concatenate(err_lf).mean()) * 1e3)",
                                              "\"rmse_lf_mm\": float(np.sqrt(np.concatenate(err_lf)).mean() * 1e3)")],
                                      D_PREP, "the rig's reported RMSE is the mean of its frames' RMS values"),
    # ---- int8 weights of the exported model
    "int8-zero-point-127": (INT8, [("return (q + 128).astype(np.uint8)", "return (q + 127).astype(np.uint8)")], T_INT8,
                            "the stored blocks are off by one step from MatMulNBits' zero point"),
    "int8-blocks-scrambled": (INT8, [("w = padded.T.reshape(N, blocks, block_size)",
                                      "w = padded.reshape(N, blocks, block_size)")], T_INT8,
                              "the blocks run along the wrong axis of the weights"),
    "int8-columns-one-scale": (INT8, [("scales = (np.abs(weight).max(0) / 127.0).astype(np.float32)",
                                       "scales = np.full(weight.shape[1], np.abs(weight).max() / 127.0, np.float32)")],
                               T_INT8, "one scale for the whole matrix where each column has its own"),
    "int8-split-first-group": (INT8, [("products = [block_product(p, w[g]) for g, p in enumerate(parts)]",
                                       "products = [block_product(p, w[0]) for g, p in enumerate(parts)]")], T_INT8,
                               "every group of a batched product multiplies the first group's weights"),
    "int8-residual-floor": (INT8, [('node("Round", [node("Mul", [x, inverse])])',
                                    'node("Floor", [node("Mul", [x, inverse])])')], T_INT8,
                            "the residual of the input's rounding taken against its floor, not its nearest step"),
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


def plant(root: Path, path: str | tuple[str, ...], edits: list[tuple[str, str]]) -> bool:
    """Apply the edits to ``root / path`` (the first of several paths that exists); an edit whose text does
    not occur is skipped (an alternative for another revision); False when no edit applies or a text occurs
    more than once."""
    paths = (path,) if isinstance(path, str) else path
    file = next((root / p for p in paths if (root / p).exists()), None)
    if file is None:
        return False
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
        if not (root / tests).exists() and tests in EARLIER_TESTS:
            tests = EARLIER_TESTS[tests]  # a revision before the test file: the module's own tests then
        files = [tests] if isinstance(tests, str) else [t for t in tests if (root / t).exists()]
        if not files:  # pytest without a path would run the whole suite
            return {"what": what, "tests": tests, "result": "no test file", "by": [], "seconds": 0.0}
        env = {**os.environ, "PYTHONPATH": str(root / "src"), "PYTHONDONTWRITEBYTECODE": "1"}
        start = time.perf_counter()
        try:
            proc = subprocess.run([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *files],
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
    parser.add_argument("--only", default="", help="only the bugs whose name starts with this (several: comma-separated)")
    parser.add_argument("--label", help="results name suffix (default: the revision or 'worktree')")
    parser.add_argument("--timeout", type=float, default=900.0, help="seconds per bug")
    args = parser.parse_args()
    results = {}
    for name in BUGS:
        if name.startswith(tuple(args.only.split(","))):
            results[name] = run_bug(args.rev, name, args.timeout)
            print(name, results[name]["result"], results[name].get("by", ""), flush=True)
    counts = {k: sum(r["result"] == k for r in results.values()) for k in ("caught", "missed", "not planted")}
    print(counts)
    save_results(f"planted-bugs-{args.label or args.rev or 'worktree'}", {"counts": counts, "bugs": results})


if __name__ == "__main__":
    main()
