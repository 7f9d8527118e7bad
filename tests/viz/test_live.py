"""``loosefit view --live`` in a real browser (Debian's Chromium driven by Playwright, as the viewer tests).

The garment is the shipped VirtualBones skirt (``pretrained:skirt``), exported once to the ONNX step model. The page
computes it with onnxruntime-web; the references are onnxruntime in Python stepping the same model on the same
inputs, the body posed by :meth:`loosefit.body.base.BodyModel.pose`, and the motion switch recomputed here with
scipy's rotations (slerp of every joint, the new motion turned and moved onto the body's current root).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from loosefit.cli import main
from loosefit.errors import InputError
from loosefit.export_onnx import export_onnx
from loosefit.motion.motion import Motion
from loosefit.viz.live import (build_live_scene, export_step_model, file_motion, pack_live_scene, read_step_model,
                               serve_live_scene, sparse_weights)
from loosefit.viz.viewer import ViewerServer
from tests.viz.test_viewer import page_when

SECONDS = 3.0  # per procedural clip: 90 frames at 30 fps
BLEND = 10  # the page's blend length (live.js BLEND_FRAMES), checked against the page below


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    data, _ = export_step_model("pretrained:skirt")
    path = tmp_path_factory.mktemp("live") / "skirt.onnx"
    path.write_bytes(data)
    return path


@pytest.fixture(scope="module")
def scene(model_file, body):
    return build_live_scene(model_path=model_file, body=body, kinds=("walk", "spin"), seconds=SECONDS)


@pytest.fixture(scope="module")
def server(scene):
    s = ViewerServer(None, port=0)
    serve_live_scene(s, scene)
    with s:
        yield s



def open_live(browser, url: str):
    """The live page at ``url`` (paused: only the tests step it) once ready, and its console errors."""
    page, errors = page_when(browser, url + "live.html?play=0",
                             "window.loosefitLive && (window.loosefitLive.ready || window.loosefitLive.error)",
                             size=(900, 640), timeout=120000)
    assert page.evaluate("loosefitLive.error") is None, errors
    assert page.evaluate("loosefitLive.blendFrames") == BLEND
    return page, errors


class Stepper:
    """onnxruntime (CPU) stepping the step model as the contract says: start from ``initial_state``, feed back
    ``next_state``."""

    def __init__(self, model_file):
        import onnxruntime as ort

        options = ort.SessionOptions()
        options.intra_op_num_threads = 1
        self.session = ort.InferenceSession(str(model_file), options, providers=["CPUExecutionProvider"])
        _, meta = read_step_model(model_file)
        self.state = np.asarray(meta["initial_state"], np.float32)

    def step(self, rotations, root) -> np.ndarray:
        verts, self.state = self.session.run(["vertices", "next_state"], {
            "joint_rotations": np.asarray(rotations, np.float32).reshape(-1, 3),
            "root_position": np.asarray(root, np.float32).reshape(3), "state": self.state})
        return verts


def _motion(scene, name):
    return next(m for m in scene.motions if m.name == name)


def test_manifest_and_data_round_trip(scene, body):
    manifest, data = pack_live_scene(scene)
    assert len(data) == manifest["byteLength"]

    def array(index):
        b = manifest["buffers"][index]
        assert b["offset"] % 4 == 0
        dtype = {"float32": "<f4", "uint32": "<u4"}[b["dtype"]]
        return np.frombuffer(data, dtype, b["bytes"] // 4, b["offset"]).reshape(b["shape"])

    assert [m["name"] for m in manifest["motions"]] == ["walk", "spin"]
    for entry, motion in zip(manifest["motions"], scene.motions):
        assert entry["numFrames"] == round(SECONDS * 30)
        np.testing.assert_array_equal(array(entry["rotations"]), motion.rotations)
        np.testing.assert_array_equal(array(entry["translation"]), motion.translation)
    b = manifest["body"]
    np.testing.assert_array_equal(array(b["restVerts"]), body.rest_verts())
    np.testing.assert_array_equal(array(b["faces"]), body.faces)
    assert b["parents"] == [int(p) for p in body.parents]
    # The sparse influences are the dense weights exactly: no Anny vertex has more than 8 non-zero weights.
    dense = np.zeros_like(body.skinning_weights())
    np.put_along_axis(dense, array(b["skinIndex"]).astype(np.int64), array(b["skinWeight"]), axis=1)
    np.testing.assert_allclose(dense, body.skinning_weights(), atol=1e-6)
    assert manifest["metadata"]["joint_names"] == list(body.joint_names)
    assert json.dumps(manifest)  # JSON-able as served


def test_sparse_weights_keep_the_largest_and_renormalise():
    w = np.array([[0.1, 0.6, 0.3, 0.0], [0.25, 0.25, 0.25, 0.25]], np.float32)
    index, weight = sparse_weights(w, k=2)
    assert index[0].tolist() == [1, 2] and weight[0] == pytest.approx([2 / 3, 1 / 3])
    assert weight[1] == pytest.approx([0.5, 0.5])


def test_bad_model_and_motion_files_name_the_file(tmp_path, model_file, body):
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    with pytest.raises(InputError, match="not an ONNX model") as err:
        build_live_scene(model_path=junk, body=body)
    assert err.value.path == junk
    import onnx

    bare = onnx.load(str(model_file))
    del bare.metadata_props[:]
    onnx.save(bare, str(tmp_path / "bare.onnx"))
    with pytest.raises(InputError, match="no 'loosefit' metadata") as err:
        build_live_scene(model_path=tmp_path / "bare.onnx", body=body)
    assert err.value.path == tmp_path / "bare.onnx"
    with pytest.raises(InputError, match="motion file not found") as err:
        build_live_scene(model_path=model_file, body=body, kinds=(), motions=[tmp_path / "missing.bvh"])
    assert err.value.path == tmp_path / "missing.bvh"
    assert main(["view", "--live", str(tmp_path / "no-run")]) == 2
    assert main(["view", "--live", str(model_file), str(model_file)]) == 2


def test_an_int8_model_is_served_with_a_warning(tmp_path, model_file, caplog):
    """onnxruntime-web runs ``--int8`` models several times slower: the page still takes one, and says so once."""
    assert read_step_model(model_file)[0] == model_file.read_bytes() and not caplog.records
    small = tmp_path / "int8.onnx"
    export_onnx("pretrained:skirt", small, int8=True)
    data, meta = read_step_model(small)
    assert data == small.read_bytes() and meta["weights"]["storage"] == "int8"
    warned = [r for r in caplog.records if r.levelname == "WARNING"]
    assert len(warned) == 1 and str(small) in warned[0].getMessage() and "without --int8" in warned[0].getMessage()


def test_a_motion_file_is_offered_as_it_is(tmp_path, body, scene):
    walk = _motion(scene, "walk")
    path = tmp_path / "mine.npz"
    Motion(walk.rotations, walk.translation, 30.0, body.rig, body.joint_names, "mine").save(path)
    clip = file_motion(path, body, 30.0)
    assert clip.name == "mine"
    np.testing.assert_array_equal(clip.rotations, walk.rotations)
    np.testing.assert_array_equal(clip.translation, walk.translation)


def test_page_garment_and_body_match_python(browser, server, scene, model_file, body):
    """After N frames of walk stepped in the page, its garment is onnxruntime's in Python within 0.5 mm, and its
    body is the body posed by loosefit within 0.5 mm."""
    page, errors = open_live(browser, server.url)
    n = 40
    assert page.evaluate(f"loosefitLive.step({n - 1})") == n  # the page showed frame 0 when it became ready
    walk = _motion(scene, "walk")
    stepper = Stepper(model_file)
    for t in range(n):
        ref = stepper.step(walk.rotations[t], walk.translation[t])
    shown = np.asarray(page.evaluate("loosefitLive.garment()"), np.float32).reshape(-1, 3)
    assert shown.shape == ref.shape
    print(f"page vs onnxruntime after {n} frames: {1000 * np.abs(shown - ref).max():.4f} mm")
    assert np.abs(shown - ref).max() < 5e-4
    # the garment moved since frame 0 (so matching it means something): the walk carried it forward
    first = Stepper(model_file).step(walk.rotations[0], walk.translation[0])
    assert np.linalg.norm(ref - first, axis=1).min() > 0.05
    np.testing.assert_allclose(page.evaluate("loosefitLive.state()"), stepper.state, atol=1e-3)
    posed = body.pose(Motion(walk.rotations[n - 1: n], walk.translation[n - 1: n], 30.0, body.rig,
                             body.joint_names)).verts[0]
    shown_body = np.asarray(page.evaluate("loosefitLive.body()"), np.float32).reshape(-1, 3)
    assert np.abs(shown_body - posed).max() < 5e-4
    assert not errors
    page.close()


def _heading(rot: Rotation) -> float:
    front = rot.apply([0.0, -1.0, 0.0])
    return float(np.arctan2(front[1], front[0]))


def expected_switch(scene, s: int, name_from: str, name_to: str):
    """The inputs the page feeds at frames ``s .. s + BLEND - 1`` after switching from ``name_from`` (shown
    untouched up to frame ``s - 1``) to ``name_to``: ``(rotations (BLEND, J, 3) as Rotation list, roots (BLEND, 3))``.
    Joint rotations: slerp with weight smoothstep((k + 1) / BLEND), the new root turned to the body's heading; root:
    moved on by the same blend of the two motions' horizontal steps, its height blended."""
    old, new = _motion(scene, name_from), _motion(scene, name_to)
    last_root = Rotation.from_rotvec(old.rotations[s - 1, 0])
    yaw = _heading(last_root) - _heading(Rotation.from_rotvec(new.rotations[0, 0]))
    turn = Rotation.from_rotvec([0.0, 0.0, yaw])
    old_t, new_t = old.translation.astype(np.float64), new.translation.astype(np.float64)
    root = old_t[s - 1].copy()
    rots, roots = [], []
    for k in range(BLEND):
        x = (k + 1) / BLEND
        w = x * x * (3 - 2 * x)
        r_old = Rotation.from_rotvec(old.rotations[s + k])
        r_new = Rotation.from_rotvec(new.rotations[k])
        r_new = Rotation.concatenate([turn * r_new[0], r_new[1:]])
        rots.append(Rotation.concatenate([Slerp([0, 1], Rotation.concatenate([r_old[j], r_new[j]]))(w)
                                          for j in range(len(r_old))]))
        # the root moves by the blend of the two motions' steps (the new one's first step for its frame 0)
        step_old = old_t[s + k, :2] - old_t[s + k - 1, :2]
        f = max(k, 1)
        step_new = turn.apply(np.r_[new_t[f, :2] - new_t[f - 1, :2], 0.0])[:2]
        root[:2] += (1 - w) * step_old + w * step_new
        root[2] = (1 - w) * old_t[s + k, 2] + w * new_t[k, 2]
        roots.append(root.copy())
    return rots, np.asarray(roots)


def test_switch_blends_the_motion_and_keeps_the_garment_continuous(browser, server, scene, model_file):
    page, errors = open_live(browser, server.url)
    s = 30  # frames of walk before the switch
    page.evaluate("loosefitLive.record = true; loosefitLive.log = []")
    page.evaluate(f"loosefitLive.step({s - 1})")
    page.evaluate("loosefitLive.switchTo('spin')")
    page.evaluate(f"loosefitLive.step({BLEND + 5})")
    log = page.evaluate("loosefitLive.log")
    assert [e["frame"] for e in log] == list(range(1, s + BLEND + 5))
    rot = np.asarray([e["joint_rotations"] for e in log], np.float32).reshape(len(log), -1, 3)
    root = np.asarray([e["root_position"] for e in log], np.float64)
    verts = np.asarray([e["vertices"] for e in log], np.float32).reshape(len(log), -1, 3)
    walk = _motion(scene, "walk")
    # before the switch: the walk as it is
    np.testing.assert_array_equal(rot[: s - 1], walk.rotations[1:s])
    # during the blend: scipy's slerp of every joint onto the turned, moved spin
    want_rot, want_root = expected_switch(scene, s, "walk", "spin")
    for k in range(BLEND):
        got = Rotation.from_rotvec(rot[s - 1 + k])
        assert (got.inv() * want_rot[k]).magnitude().max() < 1e-4, k
    np.testing.assert_allclose(root[s - 1: s - 1 + BLEND], want_root, atol=1e-5)
    # the page's garment is onnxruntime's on the page's own inputs, the state carried across the switch
    stepper = Stepper(model_file)
    ref = [stepper.step(walk.rotations[0], walk.translation[0])]
    ref += [stepper.step(r, p) for r, p in zip(rot, root)]
    assert np.abs(verts - np.asarray(ref[1:])).max() < 5e-4
    # Continuity: the largest vertex jump across the switch frame is at most 3x the largest per-frame vertex motion
    # of the 10 walk frames before it (the blend's first frame moves the pose 2.8% of the way, smoothstep(1/10)).
    steps = np.linalg.norm(np.diff(verts, axis=0), axis=2).max(axis=1)  # steps[i]: log frame i -> i + 1
    switch = s - 2  # from frame s - 1 (last walk) to frame s (first blended)
    bound = 3.0 * steps[switch - 10: switch].max()
    print(f"switch: jump {1000 * steps[switch]:.2f} mm, blend max {1000 * steps[switch: switch + BLEND].max():.2f} mm, "
          f"bound {1000 * bound:.2f} mm; page vs onnxruntime {1000 * np.abs(verts - np.asarray(ref[1:])).max():.4f} mm")
    assert steps[switch] <= bound, (steps[switch], bound)
    assert steps[switch: switch + BLEND].max() <= bound
    # the root continues: no step larger than the walk's own
    root_steps = np.linalg.norm(np.diff(root, axis=0), axis=1)
    assert root_steps[switch: switch + BLEND].max() <= 3.0 * root_steps[switch - 10: switch].max()
    # Control: the same switch without blending, spin restarted where it was recorded, state reset as a fresh load
    # would do; its jump breaks the bound, so the bound tells a continuous switch from a restart.
    spin = _motion(scene, "spin")
    restart = Stepper(model_file).step(spin.rotations[0], spin.translation[0])
    assert np.linalg.norm(restart - verts[s - 2], axis=1).max() > bound
    assert page.evaluate("loosefitLive.current()") == {"motion": "spin", "frame": BLEND + 5, "blending": False}
    assert not errors
    page.close()


def test_motion_list_speed_control_and_looping(browser, server, scene, body):
    """The list switches motion, the speed control sets the page's speed, and a motion at its end starts again
    from where the body is (root continuous), the body posed as loosefit poses the page's own inputs."""
    page, errors = open_live(browser, server.url)
    page.select_option("#motions", label="spin")
    page.evaluate("loosefitLive.step(3)")
    assert page.evaluate("loosefitLive.current()") == {"motion": "spin", "frame": 3, "blending": True}
    page.select_option("#speed", "2")
    assert page.evaluate("loosefitLive.speed()") == 2
    page.select_option("#motions", label="walk")
    frames = round(SECONDS * 30)
    page.evaluate("loosefitLive.record = true; loosefitLive.log = []")
    page.evaluate(f"loosefitLive.step({frames + 5})")  # past the walk's end: it starts again, continuing
    assert page.evaluate("loosefitLive.current()") == {"motion": "walk", "frame": 5, "blending": True}
    log = page.evaluate("loosefitLive.log")
    root = np.asarray([e["root_position"] for e in log])
    steps = np.linalg.norm(np.diff(root[:, :2], axis=0), axis=1)
    walk = _motion(scene, "walk")
    walk_steps = np.linalg.norm(np.diff(walk.translation[:, :2], axis=0), axis=1)
    assert steps.max() <= 1.5 * walk_steps.max()  # no jump back to the walk's start at the loop
    assert np.linalg.norm(root[-1, :2] - walk.translation[4, :2]) > 0.5  # it walks on from where it was
    rot = np.asarray(log[-1]["joint_rotations"], np.float32).reshape(1, -1, 3)
    posed = body.pose(Motion(rot, root[-1:].astype(np.float32), 30.0, body.rig, body.joint_names)).verts[0]
    shown_body = np.asarray(page.evaluate("loosefitLive.body()"), np.float32).reshape(-1, 3)
    assert np.abs(shown_body - posed).max() < 5e-4
    assert not errors
    page.close()


def test_server_answers_the_runtime_with_its_types(server, scene):
    """The page's ES modules must come as JavaScript and the WebAssembly as application/wasm (browsers refuse a
    module of another type); the served files are the vendored ones and the scene's."""
    import urllib.request

    from loosefit.viz.viewer import STATIC_DIR

    def get(path):
        with urllib.request.urlopen(server.url + path) as r:
            return r.headers["Content-Type"], r.read()

    for name, kind in [("vendor/ort.webgpu.min.mjs", "text/javascript"), ("live.js", "text/javascript"),
                       ("vendor/ort-wasm-simd-threaded.asyncify.wasm", "application/wasm")]:
        ctype, body = get(name)
        assert ctype.split(";")[0] == kind, (name, ctype)
        assert body == (STATIC_DIR / name).read_bytes()
    assert get("live/model.onnx")[1] == scene.model
    manifest = json.loads(get("live/manifest.json")[1])
    assert len(get("live/data.bin")[1]) == manifest["byteLength"]


def test_an_exported_viewer_page_leaves_the_live_page_out(tmp_path):
    """``loosefit view --export`` copies the viewer's files, not the live page or onnxruntime-web (28 MB it
    cannot use from disk)."""
    from loosefit.viz.viewer import STATIC_DIR, export_scene
    from loosefit.viz.viewer_scene import ViewerPanel, ViewerScene, ViewerTrack, colormap_table

    tri = ViewerTrack("garment", np.zeros((2, 3, 3), np.float32), np.array([[0, 1, 2]]), (0.5, 0.5, 0.5))
    scene = ViewerScene([ViewerPanel("t", "t", [tri])], 30.0, 2, (0.0, 1.0), colormap_table())
    index = export_scene(scene, tmp_path / "out")
    copied = {p.relative_to(index.parent).as_posix() for p in index.parent.rglob("*") if p.is_file()}
    assert {"index.html", "viewer.js", "vendor/three.min.js"} <= copied
    assert not {n for n in copied if n.startswith(("live.", "vendor/ort"))}
    assert (STATIC_DIR / "live.html").is_file() and list((STATIC_DIR / "vendor").glob("ort*.wasm"))


def _area_weighted_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit vertex normals: the sum of the cross products of each vertex's triangles (twice their areas times their
    normals), brute force in float64."""
    v = verts.astype(np.float64)
    normals = np.zeros_like(v)
    for a, b, c in faces:
        n = np.cross(v[b] - v[a], v[c] - v[a])
        normals[a] += n
        normals[b] += n
        normals[c] += n
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def test_the_drawn_normals_are_the_area_weighted_ones(browser, server, scene, body):
    """The page's own normals (typed arrays, not three.js's) on the drawn garment and body: each within 1e-4 of the
    brute-force area-weighted normal of the positions drawn."""
    page, errors = open_live(browser, server.url)
    page.evaluate("loosefitLive.step(7, true)")
    garment_faces = np.asarray(scene.metadata["faces"], np.int64).reshape(-1, 3)
    for which, faces in (("garment", garment_faces), ("body", np.asarray(body.faces))):
        verts = np.asarray(page.evaluate(f"loosefitLive.{which}()"), np.float32).reshape(-1, 3)
        drawn = np.asarray(page.evaluate(f"loosefitLive.normals('{which}')"), np.float64).reshape(-1, 3)
        used = np.unique(faces)
        expected = _area_weighted_normals(verts, faces)
        assert np.abs(drawn[used] - expected[used]).max() < 1e-4, which
    assert not errors
    page.close()


def test_playing_draws_fewer_pixels_while_the_garment_falls_behind(browser, server):
    """Stepping renders each frame once. Each second of playing, a garment rate under 90 % of the motion's lowers the
    drawing resolution by a fifth (never under 35 %); three seconds of keeping up raise it by a tenth, up to every
    pixel; a paused page draws every pixel; the drawn canvas follows the scale."""
    page, errors = open_live(browser, server.url)
    L = "loosefitLive"
    # one render a frame: the camera following the walking body must not render the frame again
    before = page.evaluate(f"{L}.renders")
    page.evaluate(f"{L}.step(5, true)")
    assert page.evaluate(f"{L}.renders") - before == 5
    scales = [page.evaluate(f"{L}.adaptRenderScale(12, 30)") for _ in range(8)]
    expected = [max(0.35, 0.8 ** (i + 1)) for i in range(8)]
    np.testing.assert_allclose(scales, expected, rtol=1e-12)
    climbing = [page.evaluate(f"{L}.adaptRenderScale(30, 30)") for _ in range(9)]
    np.testing.assert_allclose(climbing, [0.35, 0.35, 0.385, 0.385, 0.385, 0.4235, 0.4235, 0.4235, 0.46585], rtol=1e-12)
    assert page.evaluate(f"{L}.adaptRenderScale(27.5, 30)") == pytest.approx(0.46585)  # within 90 %: held
    ratio = page.evaluate("window.devicePixelRatio || 1")

    def drawn_share():  # drawn pixels per CSS pixel of the last draw, across and down
        width, height, client_width, client_height = page.evaluate(f"{L}.drawingBuffer()")
        return width / (client_width * ratio), height / (client_height * ratio), client_width

    assert drawn_share()[:2] == (1, 1)
    page.evaluate(f"{L}.setRenderScale(0.5); {L}.play()")
    page.wait_for_function(f"{L}.drawingBuffer()[0] < {L}.drawingBuffer()[2]", timeout=20000)
    across, down, client_width = drawn_share()
    assert abs(across - 0.5) <= 1 / client_width and abs(down - 0.5) <= 0.01
    page.evaluate(f"{L}.pause(); {L}.step(1, true)")
    assert drawn_share()[:2] == (1, 1)
    assert not errors
    page.close()
