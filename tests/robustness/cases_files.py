"""Cases of the verbs that read one input file onto the body: ``body`` (and SMPL-family model files),
``motion generate / import / map`` (BVH, AMASS, motion ``.npz``, joint-map YAML) and ``garment make /
import`` (OBJ, PLY)."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np

from tests.robustness import craft
from tests.robustness.harness import MARKER, Case
from tests.robustness.kit import bad, ext, ok, wrote

OUT = "{tmp}/out.npz"
PROC = "/proc/loosefit-robustness/out"  # never writable, even by root


def parent_file(tmp: Path, sh) -> None:
    """``{tmp}/file`` is a regular file, so ``{tmp}/file/x`` cannot be created."""
    craft.write(tmp / "file", "a file, not a folder\n")


def _smpl_model(tmp: Path) -> dict:
    with open(craft.smpl_pkl(tmp / "model.pkl"), "rb") as f:
        return pickle.load(f, encoding="latin1")  # our own file, written just above


def smpl_without(key: str, suffix: str):
    def setup(tmp, sh):
        model = _smpl_model(tmp)
        del model[key]
        if suffix == ".pkl":
            craft.write(tmp / "SMPL_NEUTRAL.pkl", pickle.dumps(model, protocol=2))
        else:
            model["J_regressor"] = model["J_regressor"].toarray()
            np.savez(tmp / "SMPL_NEUTRAL.npz", **{k: np.asarray(v) for k, v in model.items()})
    return setup


def smpl_payload_pkl(where: str):
    """A SMPL-looking pickle with the payload as the whole file, or in place of ``v_template``."""
    def setup(tmp, sh):
        if where == "file":
            data = craft.payload_pickle(tmp)
        else:
            def wrap(payload):
                model = _smpl_model(tmp)
                model[where] = payload
                return model
            data = craft.payload_pickle(tmp, wrap)
        craft.write(tmp / "SMPL_NEUTRAL.pkl", data)
    return setup


def _eval_payload(tmp: Path, sh) -> None:
    class Evil:
        def __reduce__(self):
            return (eval, (f"open({str(tmp / MARKER)!r}, 'w')",))
    craft.write(tmp / "SMPL_NEUTRAL.pkl", pickle.dumps({"v_template": Evil()}, protocol=2))


def body_cases() -> list[Case]:
    b = ["body", "--out", "{tmp}/b.obj"]
    smpl = ["body", "--out", "{tmp}/b.obj", "--smpl"]
    return [
        ok("body/rest-obj", b, check=wrote("{tmp}/b.obj")),
        ok("body/motion-npz", ["body", "--motion", "{motion}", "--out", OUT], check=wrote(OUT)),
        bad("body/shape-unknown-key", b + ["--shape", "tallness=2"], names=("tallness",), absent=("{tmp}/b.obj",)),
        bad("body/shape-out-of-range", b + ["--shape", "height=5"], names=("height",)),
        bad("body/shape-not-a-number", b + ["--shape", "height=tall"], names=("height",)),
        ext("body/shape-nan", b + ["--shape", "height=nan"], names=("height",)),
        bad("body/unsupported-output", ["body", "--out", "{tmp}/b.txt"], names=("b.txt",), absent=("{tmp}/b.txt",)),
        bad("body/motion-missing", b + ["--motion", "{tmp}/none.npz"], names=("none.npz",)),
        bad("body/frame-out-of-range", b + ["--motion", "{motion}", "--frame", "999"], brief="inputs",
            names=("frame", "999"), absent=("{tmp}/b.obj",)),
        bad("body/out-parent-is-file", ["body", "--out", "{tmp}/file/b.obj"], parent_file, brief="inputs",
            names=("file/b.obj",)),
        bad("body/out-in-proc", ["body", "--out", PROC + ".obj"], brief="inputs", names=("/proc",)),
        # SMPL-family model files (--smpl): pickles must never run code
        ok("smpl/pkl", smpl + ["{tmp}/SMPL_NEUTRAL.pkl"], lambda t, s: craft.smpl_pkl(t / "SMPL_NEUTRAL.pkl"),
           brief="inputs", defect=True, check=wrote("{tmp}/b.obj")),  # a legit pickle still loads
        ok("smpl/npz", smpl + ["{tmp}/SMPL_NEUTRAL.npz"], lambda t, s: craft.smpl_npz(t / "SMPL_NEUTRAL.npz"),
           check=wrote("{tmp}/b.obj")),
        bad("smpl/npz-object-array-payload", smpl + ["{tmp}/SMPL_NEUTRAL.npz"],
            lambda t, s: craft.npz_payload(t / "SMPL_NEUTRAL.npz", t, "v_template", f=np.zeros((1, 3), np.int64)),
            brief="inputs", defect=True, names=("SMPL_NEUTRAL.npz",)),
        bad("smpl/pkl-payload", smpl + ["{tmp}/SMPL_NEUTRAL.pkl"], smpl_payload_pkl("file"), brief="inputs",
            defect=True, names=("SMPL_NEUTRAL.pkl",)),
        bad("smpl/pkl-payload-in-model", smpl + ["{tmp}/SMPL_NEUTRAL.pkl"], smpl_payload_pkl("v_template"),
            brief="inputs", names=("SMPL_NEUTRAL.pkl",)),
        bad("smpl/pkl-eval-payload", smpl + ["{tmp}/SMPL_NEUTRAL.pkl"], _eval_payload, brief="inputs",
            names=("SMPL_NEUTRAL.pkl",)),
        bad("smpl/pkl-garbage", smpl + ["{tmp}/SMPL_NEUTRAL.pkl"], lambda t, s: craft.garbage(t / "SMPL_NEUTRAL.pkl"),
            names=("SMPL_NEUTRAL.pkl",)),
        bad("smpl/pkl-truncated", smpl + ["{tmp}/SMPL_NEUTRAL.pkl"],
            lambda t, s: craft.truncate(craft.smpl_pkl(t / "SMPL_NEUTRAL.pkl")), names=("SMPL_NEUTRAL.pkl",)),
        bad("smpl/pkl-missing-weights", smpl + ["{tmp}/SMPL_NEUTRAL.pkl"], smpl_without("weights", ".pkl"),
            names=("SMPL_NEUTRAL.pkl",)),
        bad("smpl/npz-missing-faces", smpl + ["{tmp}/SMPL_NEUTRAL.npz"], smpl_without("f", ".npz"),
            names=("SMPL_NEUTRAL.npz",)),
        bad("smpl/pkl-a-list", smpl + ["{tmp}/SMPL_NEUTRAL.pkl"],
            lambda t, s: craft.write(t / "SMPL_NEUTRAL.pkl", pickle.dumps([1, 2, 3], protocol=2)),
            names=("SMPL_NEUTRAL.pkl",)),
        bad("smpl/missing-file", smpl + ["{tmp}/SMPL_NONE.pkl"], names=("SMPL_NONE.pkl",)),
    ]


# ---------------------------------------------------------------------------------------------- motions


def motion_edit(name: str = "m.npz", **changes):
    return lambda t, s: craft.npz_edit(s.motion, t / name, **changes)


def bvh(edit=None, frames: int = 30, name: str = "clip.bvh"):
    return lambda t, s: craft.bvh_cut(t / name, frames, edit)


def _set(index: int, value: str):
    def edit(header, data):
        data[index] = " ".join([value] + data[index].split()[1:])
    return edit


def _header(prefix: str, line: str):
    def edit(header, data):
        i = next(k for k, h in enumerate(header) if h.startswith(prefix))
        header[i] = line
    return edit


def _no_frames(header, data):
    data.clear()
    header[-2] = "Frames: 0"


def _latin1_bvh(tmp: Path, sh) -> None:
    """A byte that is not UTF-8 (Latin-1 e-acute) in a joint name."""
    data = craft.bvh_cut(tmp / "c.bvh").read_bytes()
    craft.write(tmp / "clip.bvh", data.replace(b"CC_Base_Hip", b"CC_Base_H\xe9p", 1))


def _rename_joints(header, data):
    header[:] = [h.replace("CC_Base_", "bone_") for h in header]


def joint_map(text_edit):
    """The built-in ``cc`` joint map of the measured tree, edited by ``text_edit(text) -> text``."""
    def setup(tmp, sh):
        src = Path(sh.src) if sh.src else Path(__file__).resolve().parents[2] / "src"
        craft.write(tmp / "map.yaml", text_edit((src / "loosefit/motion/joint_maps/cc.yaml").read_text()))
        craft.bvh_cut(tmp / "clip.bvh")
    return setup


def motion_cases() -> list[Case]:
    gen = ["motion", "generate", "--kind", "walk", "--seconds", "0.5", "--out"]
    imp = ["motion", "import", "--out", OUT]
    clip = imp + ["{tmp}/clip.bvh"]
    amass = imp + ["{tmp}/amass.npz"]
    npz = imp + ["{tmp}/m.npz"]
    jm = clip + ["--joint-map", "{tmp}/map.yaml"]
    return [
        ok("motion-generate/walk", gen + [OUT], check=wrote(OUT)),
        bad("motion-generate/unknown-kind", ["motion", "generate", "--kind", "moonwalk", "--out", OUT], names=("moonwalk",)),
        bad("motion-generate/zero-seconds", gen[:-3] + ["--seconds", "0", "--out", OUT], names=("seconds",)),
        bad("motion-generate/negative-seconds", gen[:-3] + ["--seconds", "-1", "--out", OUT], names=("seconds",)),
        bad("motion-generate/zero-fps", gen + [OUT, "--fps", "0"], names=("fps",)),
        ext("motion-generate/nan-fps", gen + [OUT, "--fps", "nan"], names=("fps",)),
        ext("motion-generate/inf-seconds", gen[:-3] + ["--seconds", "inf", "--out", OUT], names=("seconds",)),
        bad("motion-generate/negative-start", gen + [OUT, "--start", "-1"], names=("start",)),
        bad("motion-generate/out-in-proc", gen + [PROC + ".npz"], brief="inputs", names=("/proc",)),
        bad("motion-generate/out-parent-is-file", gen + ["{tmp}/file/m.npz"], parent_file, brief="inputs",
            names=("file/m.npz",)),
        # BVH (a real clip: Character Creator skeleton, Y up, centimetres, 60 fps)
        ok("motion-import/bvh", clip, bvh(), check=wrote(OUT)),
        bad("motion-import/bvh-truncated-hierarchy", clip,
            lambda t, s: craft.write(t / "clip.bvh", "\n".join(craft.mocap_clip().read_text()
                                                                .splitlines()[:100]) + "\n"), names=("clip.bvh",)),
        bad("motion-import/bvh-no-motion-section", clip,
            lambda t, s: craft.write(t / "clip.bvh", craft.mocap_clip().read_text().split("MOTION")[0]),
            names=("clip.bvh",)),
        bad("motion-import/bvh-zero-frames", clip, bvh(_no_frames), names=("clip.bvh",)),
        bad("motion-import/bvh-frame-time-zero", clip, bvh(_header("Frame Time", "Frame Time: 0")), names=("clip.bvh",)),
        bad("motion-import/bvh-frame-time-negative", clip, bvh(_header("Frame Time", "Frame Time: -0.016667")),
            names=("clip.bvh",)),
        bad("motion-import/bvh-frame-count-mismatch", clip, bvh(_header("Frames", "Frames: 100")), names=("clip.bvh",)),
        ext("motion-import/bvh-nan-value", clip, bvh(_set(5, "nan")), names=("clip.bvh",)),
        ext("motion-import/bvh-inf-value", clip, bvh(_set(5, "inf")), names=("clip.bvh",)),
        bad("motion-import/bvh-text-value", clip, bvh(_set(5, "abc")), names=("clip.bvh",)),
        bad("motion-import/bvh-short-frame-line",
            clip, bvh(lambda h, d: d.__setitem__(3, " ".join(d[3].split()[:-5]))), names=("clip.bvh",)),
        bad("motion-import/bvh-garbage", clip, lambda t, s: craft.garbage(t / "clip.bvh"), names=("clip.bvh",)),
        bad("motion-import/bvh-empty", clip, lambda t, s: craft.write(t / "clip.bvh", ""), names=("clip.bvh",)),
        bad("motion-import/bvh-not-utf8", clip, _latin1_bvh, names=("clip.bvh",)),
        bad("motion-import/bvh-unknown-skeleton", clip, bvh(_rename_joints), names=("clip.bvh",)),
        # joint maps (YAML)
        bad("motion-import/joint-map-duplicate-key", jm, joint_map(lambda t: t + "calibration: rest\n"),
            brief="inputs", defect=True, names=("map.yaml",)),
        bad("motion-import/joint-map-duplicate-joint", jm,
            joint_map(lambda t: t.replace("  LeftLeg: CC_Base_L_Calf\n",
                                          "  LeftLeg: CC_Base_L_Calf\n  LeftLeg: CC_Base_L_Foot\n")),
            brief="inputs", names=("map.yaml",)),
        bad("motion-import/joint-map-yaml-syntax", jm, joint_map(lambda t: t + "joints: [unclosed\n"), names=("map.yaml",)),
        bad("motion-import/joint-map-unknown-key", jm, joint_map(lambda t: t + "up_axis: y\n"), names=("map.yaml",)),
        bad("motion-import/joint-map-a-list", jm, joint_map(lambda t: "- Hips\n- Spine\n"), names=("map.yaml",)),
        bad("motion-import/joint-map-python-tag", jm,
            joint_map(lambda t: t + f"extra: !!python/object/apply:builtins.open [{MARKER}, w]\n"), names=("map.yaml",)),
        bad("motion-import/joint-map-missing", clip + ["--joint-map", "{tmp}/none.yaml"], bvh(), names=("none.yaml",)),
        bad("motion-import/joint-map-for-npz", imp + ["{motion}", "--joint-map", "cc"], names=("joint map", "bvh")),
        # AMASS / SMPL-H .npz
        ok("motion-import/amass", amass, lambda t, s: craft.amass(t / "amass.npz"), check=wrote(OUT)),
        bad("motion-import/amass-no-trans", amass, lambda t, s: craft.amass(t / "amass.npz", trans=None),
            names=("amass.npz",)),
        bad("motion-import/amass-poses-shape", amass, lambda t, s: craft.amass(t / "amass.npz", poses=np.zeros((60, 10))),
            names=("amass.npz",)),
        ext("motion-import/amass-nan-poses", amass,
            lambda t, s: craft.amass(t / "amass.npz", poses=np.full((60, 156), np.nan)), names=("amass.npz",)),
        bad("motion-import/amass-zero-rate", amass, lambda t, s: craft.amass(t / "amass.npz", mocap_framerate=np.float64(0)),
            names=("amass.npz",)),
        bad("motion-import/amass-negative-rate", amass,
            lambda t, s: craft.amass(t / "amass.npz", mocap_framerate=np.float64(-60)), names=("amass.npz",)),
        bad("motion-import/amass-no-rate", amass, lambda t, s: craft.amass(t / "amass.npz", fps=None), names=("amass.npz",)),
        bad("motion-import/amass-truncated", amass, lambda t, s: craft.truncate(craft.amass(t / "amass.npz")),
            brief="inputs", names=("amass.npz",)),
        bad("motion-import/amass-flipped-byte", amass, lambda t, s: craft.flip_byte(craft.amass(t / "amass.npz")),
            brief="inputs", names=("amass.npz",)),
        bad("motion-import/amass-object-array-payload", amass, lambda t, s: craft.npz_payload(
            t / "amass.npz", t, "poses", trans=np.zeros((60, 3)), mocap_framerate=np.float64(60)), names=("amass.npz",)),
        # loosefit motion .npz
        bad("motion-import/npz-truncated", npz, lambda t, s: craft.truncate(craft.npz_edit(s.motion, t / "m.npz")),
            brief="inputs", defect=True, names=("m.npz",)),
        bad("motion-import/npz-flipped-byte", npz, lambda t, s: craft.flip_byte(craft.npz_edit(s.motion, t / "m.npz")),
            brief="inputs", defect=True, names=("m.npz",)),
        bad("motion-import/npz-empty-file", npz, lambda t, s: craft.write(t / "m.npz", b""), brief="inputs",
            names=("m.npz",)),
        bad("motion-import/npz-is-npy", npz, lambda t, s: np.save(open(t / "m.npz", "wb"), np.zeros(3)), names=("m.npz",)),
        bad("motion-import/npz-wrong-joint-count", npz, motion_edit(rotations=lambda r: r[:, :10]), names=("m.npz",)),
        ext("motion-import/npz-nan-rotations", npz, motion_edit(rotations=lambda r: r * np.nan), names=("m.npz",)),
        ext("motion-import/npz-inf-translation", npz, motion_edit(translation=lambda x: x + np.inf), names=("m.npz",)),
        bad("motion-import/npz-zero-fps", npz, motion_edit(fps=np.float64(0)), names=("m.npz",)),
        bad("motion-import/npz-negative-fps", npz, motion_edit(fps=np.float64(-30)), names=("m.npz",)),
        bad("motion-import/fps-disagrees", imp + ["{motion}", "--fps", "60"], names=("fps",)),
        bad("motion-import/start-past-end", imp + ["{motion}", "--start", "100"], names=("motion", "100")),
        bad("motion-import/negative-seconds", imp + ["{motion}", "--seconds", "-1"], names=("seconds",)),
        bad("motion-import/text-file", imp + ["{tmp}/m.txt"], lambda t, s: craft.write(t / "m.txt", "walk\n"),
            names=("m.txt",)),
        bad("motion-import/a-folder", imp + ["{tmp}"], names=("{tmp}",)),
        bad("motion-import/out-in-proc", ["motion", "import", "{motion}", "--out", PROC + ".npz"], brief="inputs",
            names=("/proc",)),
        # motion map
        ok("motion-map/bvh", ["motion", "map", "{tmp}/clip.bvh", "--out", "{tmp}/map.yaml"], bvh(_rename_joints),
           check=wrote("{tmp}/map.yaml")),
        bad("motion-map/npz", ["motion", "map", "{motion}", "--out", "{tmp}/map.yaml"], names=("npz", "bvh")),
        bad("motion-map/garbage-bvh", ["motion", "map", "{tmp}/clip.bvh", "--out", "{tmp}/map.yaml"],
            lambda t, s: craft.garbage(t / "clip.bvh"), names=("clip.bvh",)),
        bad("motion-map/out-parent-is-file", ["motion", "map", "{tmp}/clip.bvh", "--out", "{tmp}/file/map.yaml"],
            lambda t, s: (parent_file(t, s), craft.bvh_cut(t / "clip.bvh")), brief="inputs", names=("file/map.yaml",)),
    ]


# ---------------------------------------------------------------------------------------------- garments


def obj(edit=None, name: str = "g.obj", scale: float = 1.0):
    """The shared garment's mesh as a plain OBJ (no sidecar: it is imported), ``edit(verts, faces)`` returning
    new ones."""
    def setup(tmp, sh):
        verts, faces = craft.garment_mesh(sh)
        if edit is not None:
            verts, faces = edit(verts.copy(), faces.copy())
        craft.write(tmp / name, craft.obj_text(verts * scale, faces))
    return setup


def _vertex_7(v, value):
    """The vertices with the 8th one's coordinates set to ``value``."""
    v[7] = value
    return v


def _split_panels(v, f):
    """Every face gets its own three vertices (a triangle soup: seams written as separate panels)."""
    return v[f.ravel()], np.arange(3 * len(f)).reshape(-1, 3)


def _moebius(v, f):
    n, w = 60, 0.15
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    verts = []
    for s in (-w, w):
        r = 0.3 + s * np.cos(t / 2)
        verts.append(np.stack([r * np.cos(t), r * np.sin(t), 1.0 + s * np.sin(t / 2)], 1))
    verts = np.concatenate(verts)
    faces = []
    for i in range(n):
        j = (i + 1) % n
        a, b = i, n + i
        c, d = (j, n + j) if j else (n + j, j)  # the half twist joins the ends crosswise
        faces += [[a, c, b], [b, c, d]]
    return verts, np.array(faces)


def ply(edit=None):
    def setup(tmp, sh):
        verts, faces = craft.garment_mesh(sh)
        text = craft.ply_text(verts, faces)
        craft.write(tmp / "g.ply", edit(text) if edit else text)
    return setup


def garment_cases() -> list[Case]:
    make = ["garment", "make", "--kind", "skirt", "--edge-length", "0.05", "--out"]
    g = "{tmp}/g.obj"
    imp = ["garment", "import", "--out", "{tmp}/out.obj"]
    tri = np.array([[0.0, 0.0, 1.0], [0.3, 0.0, 1.0], [0.0, 0.0, 0.7]]), np.array([[0, 1, 2]])
    return [
        ok("garment-make/skirt", make + [g], check=wrote(g, "{tmp}/g.json")),
        bad("garment-make/unknown-kind", ["garment", "make", "--kind", "cape", "--out", g], names=("cape", "--kind")),
        bad("garment-make/zero-edge-length", make[:-3] + ["--edge-length", "0", "--out", g], names=("edge",)),
        bad("garment-make/negative-edge-length", make[:-3] + ["--edge-length", "-0.01", "--out", g], names=("edge",)),
        bad("garment-make/negative-length", make + [g, "--length", "-1"], names=("length",)),
        ext("garment-make/nan-length", make + [g, "--length", "nan"], names=("length",)),
        ext("garment-make/inf-flare", make + [g, "--flare", "inf"], names=("flare",)),
        bad("garment-make/unknown-param", make + [g, "--param", "bogus=1"], names=("bogus",)),
        bad("garment-make/param-not-a-number", make + [g, "--param", "length=abc"], names=("length",)),
        bad("garment-make/param-without-value", make + [g, "--param", "length"], names=("length",)),
        bad("garment-make/out-ply", make + ["{tmp}/g.ply"], names=("g.ply",)),
        bad("garment-make/out-in-proc", make + [PROC + ".obj"], brief="inputs", defect=True, names=("/proc",)),
        bad("garment-make/out-parent-is-file", make + ["{tmp}/file/g.obj"], parent_file, brief="inputs",
            names=("file/g.obj",)),
        ok("garment-import/obj", imp + [g], obj(), check=wrote("{tmp}/out.obj")),
        ok("garment-import/ply", imp + ["{tmp}/g.ply"], ply(), check=wrote("{tmp}/out.obj")),
        bad("garment-import/split-panels", imp + [g], obj(_split_panels), report=("repaired", "merged")),
        bad("garment-import/degenerate-faces", imp + [g], obj(lambda v, f: (v, np.vstack([f, [[0, 0, 1], [2, 2, 2]]]))),
            report=("repaired", "degenerate")),
        bad("garment-import/duplicate-faces", imp + [g], obj(lambda v, f: (v, np.vstack([f, f[:20]]))),
            report=("repaired", "duplicate")),
        bad("garment-import/one-triangle", imp + [g], obj(lambda v, f: tri), brief="inputs", defect=True, names=("g.obj",),
            absent=("{tmp}/out.obj",)),
        bad("garment-import/two-triangles-1cm", imp + [g],
            obj(lambda v, f: (np.array([[0, 0, 1.0], [0.01, 0, 1.0], [0, 0, 0.99], [0.01, 0, 0.99]]),
                              np.array([[0, 1, 2], [1, 3, 2]]))),
            brief="inputs", names=("g.obj",)),
        ext("garment-import/nan-vertex", imp + [g], obj(lambda v, f: (_vertex_7(v, np.nan), f)),
            names=("g.obj",)),
        ext("garment-import/inf-vertex", imp + [g], obj(lambda v, f: (_vertex_7(v, np.inf), f)),
            names=("g.obj",)),
        ext("garment-import/scale-1e6", imp + [g], obj(scale=1e6), names=("g.obj",)),
        ext("garment-import/scale-1e-6", imp + [g], obj(scale=1e-6), names=("g.obj",)),
        bad("garment-import/face-index-out-of-range", imp + [g], obj(lambda v, f: (v, np.vstack([f, [[0, 1, len(v) + 5]]]))),
            names=("g.obj",)),
        bad("garment-import/face-index-zero", imp + [g], lambda t, s: (obj()(t, s), craft.write(
            t / "g.obj", (t / "g.obj").read_text() + "f 0 1 2\n")), names=("g.obj",)),
        bad("garment-import/not-numbers", imp + [g], lambda t, s: craft.write(t / "g.obj", "v a b c\nv 1 2 3\nf 1 2 3\n"),
            names=("g.obj",)),
        bad("garment-import/empty", imp + [g], lambda t, s: craft.write(t / "g.obj", ""), names=("g.obj",)),
        bad("garment-import/vertices-only", imp + [g], obj(lambda v, f: (v, np.zeros((0, 3), int))), names=("g.obj",)),
        bad("garment-import/garbage", imp + [g], lambda t, s: craft.garbage(t / "g.obj"), names=("g.obj",)),
        bad("garment-import/ply-truncated", imp + ["{tmp}/g.ply"], lambda t, s: (ply()(t, s), craft.truncate(t / "g.ply")),
            names=("g.ply",)),
        bad("garment-import/ply-garbage-header", imp + ["{tmp}/g.ply"],
            ply(lambda x: x.replace("format ascii", "format wobbly")),
            names=("g.ply",)),
        bad("garment-import/ply-too-few-vertices", imp + ["{tmp}/g.ply"],
            ply(lambda x: x.replace("element vertex ", "element vertex 9")), names=("g.ply",)),
        bad("garment-import/stl", imp + ["{tmp}/g.stl"], obj(name="g.stl"), names=("g.stl",)),
        bad("garment-import/two-far-pieces", imp + [g],
            obj(lambda v, f: (np.vstack([v, v + [3.0, 0, 0]]), np.vstack([f, f + len(v)]))), names=("g.obj",)),
        bad("garment-import/moebius-strip", imp + [g], obj(_moebius), names=("g.obj",)),
        bad("garment-import/missing", imp + ["{tmp}/none.obj"], names=("none.obj",)),
        bad("garment-import/a-folder", imp + ["{tmp}"], names=("{tmp}",)),
        bad("garment-import/out-in-proc", ["garment", "import", g, "--out", PROC + ".obj"], obj(), brief="inputs",
            names=("/proc",)),
    ]
