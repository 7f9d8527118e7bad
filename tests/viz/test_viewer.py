"""``loosefit view`` in a real browser: Debian's Chromium driven by Playwright (``make test`` installs it).

The scene is known in closed form: a body sphere (an icosphere of radius 0.2 m around (0, 0, 1)) and a
cylindrical garment around it that stays still over frames 0-1, then slides along +X through the sphere.
The prediction is the simulation lifted along +Z by ``a_i * (t + 1) / T`` with ``a_i`` from 1 to 20 mm over the
vertices, so its per-vertex error is ``a_i (t + 1) / T`` and its per-frame RMSE the root mean square of that;
the collision ratio is the share of garment vertices inside the sphere (none lies within the tessellation
band of the sphere's surface, checked).
"""

from __future__ import annotations

import os
import shutil
import socket
from pathlib import Path

import imageio.v3 as iio
import matplotlib
import numpy as np
import pytest
import trimesh

from loosefit.cli import main
from loosefit.errors import InputError
from loosefit.io.mesh_sequence import MeshSequence
from loosefit.viz.viewer import ViewerServer, export_scene, pack_scene
from loosefit.viz.viewer_scene import COLORMAP, ViewerScene, build_scene, collision_frame_indices

T = 6
CENTER = np.array([0.0, 0.0, 1.0])
RADIUS = 0.2
SHIFTS = [0.0, 0.0, 0.06, 0.12, 0.18, 0.24]  # garment X offset per frame, metres


def cylinder(rings: int = 6, segments: int = 24, radius: float = 0.25):
    theta = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    z = np.linspace(0.8, 1.2, rings)
    verts = np.stack(np.broadcast_arrays(radius * np.cos(theta)[None], radius * np.sin(theta)[None], z[:, None]), -1)
    faces = []
    for r in range(rings - 1):
        for s in range(segments):
            a, b = r * segments + s, r * segments + (s + 1) % segments
            faces += [[a, b, b + segments], [a, b + segments, a + segments]]
    return verts.reshape(-1, 3), np.array(faces)


class Known:
    """The scene's arrays and its closed-form errors, RMSE and collision ratio."""

    def __init__(self, root: Path):
        sphere = trimesh.creation.icosphere(subdivisions=4, radius=RADIUS)
        self.body_faces = np.asarray(sphere.faces)
        self.body = np.repeat((sphere.vertices + CENTER)[None], T, 0).astype(np.float32)
        base, self.faces = cylinder()
        self.sim = np.stack([base + [s, 0, 0] for s in SHIFTS]).astype(np.float32)
        V = len(base)
        lift = (1.0 + 19.0 * np.arange(V) / (V - 1)) * 1e-3  # metres
        self.errors_mm = 1000.0 * lift[None] * ((np.arange(T) + 1) / T)[:, None]  # (T, V)
        self.pred = self.sim.copy()
        self.pred[:, :, 2] += (self.errors_mm / 1000.0).astype(np.float32)
        self.rmse_mm = np.sqrt((self.errors_mm ** 2).mean(1))
        # Inside the sphere by more than the 1 mm collision tolerance; no vertex within the band between the
        # icosphere's faces (inradius) and its vertices (radius), where the closed form would be ambiguous.
        inradius = np.abs(np.einsum("ij,ij->i", sphere.face_normals, sphere.triangles[:, 0])).min()
        self.inradius = inradius

        def inside(g):
            d = np.linalg.norm(g.astype(np.float64) - CENTER, axis=-1)
            assert not ((d > inradius - 1e-3 - 1e-4) & (d < RADIUS - 1e-3 + 1e-4)).any()
            return 100.0 * (d < inradius - 1e-3).mean(1)

        self.sim_collision = inside(self.sim)
        self.pred_collision = inside(self.pred)
        body = {"body_verts": self.body, "body_faces": self.body_faces}
        self.sim_path, self.pred_path = root / "sim.npz", root / "pred.npz"
        MeshSequence(self.sim, self.faces, 30.0, body).save(self.sim_path)
        MeshSequence(self.pred, self.faces, 30.0, body).save(self.pred_path)
        self.inputs = [str(self.sim_path), str(self.pred_path)]


@pytest.fixture(scope="module")
def known(tmp_path_factory):
    return Known(tmp_path_factory.mktemp("view"))


@pytest.fixture(scope="module")
def scene(known):
    return build_scene(known.inputs)



@pytest.fixture(scope="module")
def shots(tmp_path_factory):
    """Where the screenshots go to be looked at: $LOOSEFIT_SCREENSHOTS, else pytest's temporary folder."""
    where = os.environ.get("LOOSEFIT_SCREENSHOTS")
    if where:
        Path(where).mkdir(parents=True, exist_ok=True)
        return Path(where)
    return tmp_path_factory.mktemp("viewer-screenshots")


@pytest.fixture(scope="module")
def server(scene):
    with ViewerServer(scene, port=0) as s:
        yield s


def page_when(browser, url: str, ready: str, size=(1100, 620), timeout: float = 20000):
    """A page at ``url`` once the JavaScript condition ``ready`` holds, and the list collecting its console errors."""
    page = browser.new_page(viewport={"width": size[0], "height": size[1]})
    errors = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url)
    page.wait_for_function(ready, timeout=timeout)
    return page, errors


def open_page(browser, url: str):
    """A page at ``url`` once the viewer is ready, and the list collecting its console errors."""
    return page_when(browser, url, "window.loosefitViewer && window.loosefitViewer.ready")


def positions(page, panel: int, track: int) -> np.ndarray:
    return np.asarray(page.evaluate(f"loosefitViewer.positions({panel}, {track})"), np.float32).reshape(-1, 3)


def test_scene_metrics_match_the_closed_form(known, scene):
    sim, pred = scene.panels
    np.testing.assert_allclose(pred.garment.errors, known.errors_mm, atol=2e-3)
    np.testing.assert_allclose(pred.metrics["rmse_mm"], known.rmse_mm, atol=2e-3)
    np.testing.assert_allclose(sim.metrics["collision_pct"], known.sim_collision)
    np.testing.assert_allclose(pred.metrics["collision_pct"], known.pred_collision)
    assert 0 < known.sim_collision[-1] < 100 and "rmse_mm" not in sim.metrics
    # The heat map spans 0 to the 99th percentile of the errors; the largest error is kept beside it.
    assert scene.error_range == (0.0, pytest.approx(np.percentile(known.errors_mm, 99), abs=2e-3))
    assert scene.error_max == pytest.approx(20.0, abs=2e-3) and scene.error_range[1] < 19.9


def test_packed_buffers_round_trip_and_share_the_body(known, scene):
    manifest, data = pack_scene(scene)
    assert len(data) == manifest["byteLength"]

    def array(index):
        b = manifest["buffers"][index]
        assert b["offset"] % 4 == 0
        dtype = {"float32": "<f4", "uint32": "<u4"}[b["dtype"]]
        return np.frombuffer(data, dtype, b["bytes"] // 4, b["offset"]).reshape(b["shape"])

    (sim_body, sim_garment), (pred_body, pred_garment) = (p["tracks"] for p in manifest["panels"])
    np.testing.assert_array_equal(array(sim_garment["verts"]), known.sim)
    np.testing.assert_array_equal(array(pred_garment["verts"]), known.pred)
    np.testing.assert_array_equal(array(sim_garment["faces"]), known.faces)
    np.testing.assert_array_equal(array(sim_body["verts"]), known.body)
    assert pred_body["verts"] == sim_body["verts"]  # the same body array is sent once
    np.testing.assert_allclose(array(pred_garment["errors"]), known.errors_mm, atol=2e-3)


def test_bad_inputs_name_the_file(known, tmp_path):
    with pytest.raises(InputError, match="no such file") as err:
        build_scene([str(known.sim_path), str(tmp_path / "missing.npz")])
    assert err.value.path == tmp_path / "missing.npz"
    other, other_faces = cylinder(segments=20)
    MeshSequence(np.repeat(other[None], T, 0), other_faces).save(tmp_path / "other.npz")
    with pytest.raises(InputError, match=r"120 vertices but the simulation \(.*sim.npz, the first input\) has 144") as err:
        build_scene([str(known.sim_path), str(tmp_path / "other.npz")])
    assert err.value.path == tmp_path / "other.npz"
    with pytest.raises(InputError, match="DATA.zarr:SEQUENCE or RUN:MOTION"):
        build_scene([str(tmp_path)])


def test_port_in_use_is_a_clear_error(scene, known, capsys):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(InputError, match=f"port {port} on 127.0.0.1 is in use"):
            ViewerServer(scene, port=port)
        # The port is checked before the inputs are loaded (here one is missing).
        assert main(["view", str(known.sim_path), "missing.npz", "--port", str(port)]) == 2
    err = capsys.readouterr().err
    assert f"port {port} on 127.0.0.1 is in use" in err and "missing.npz" not in err


def test_export_never_overwrites_other_files(scene, tmp_path):
    (tmp_path / "notes.txt").write_text("keep me")
    with pytest.raises(InputError, match="not empty"):
        export_scene(scene, tmp_path)
    assert (tmp_path / "notes.txt").read_text() == "keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_page_shows_the_vertices_of_each_frame(browser, server, known):
    page, errors = open_page(browser, server.url)
    try:
        assert page.evaluate("loosefitViewer.numFrames") == T
        for k in (0, 3, 5, 2):
            page.evaluate(f"loosefitViewer.setFrame({k})")
            assert page.evaluate("loosefitViewer.renderedFrame") == k
            np.testing.assert_array_equal(positions(page, 0, 1), known.sim[k])
            np.testing.assert_array_equal(positions(page, 1, 1), known.pred[k])
            np.testing.assert_array_equal(positions(page, 1, 0), known.body[k])
        assert errors == []
    finally:
        page.close()


def test_heat_map_colour_follows_the_legend(browser, server, known, scene):
    cmap = matplotlib.colormaps[COLORMAP].resampled(256)
    lo, hi = scene.error_range
    page, errors = open_page(browser, server.url)
    try:
        k = 4
        page.evaluate(f"loosefitViewer.setFrame({k})")
        e = known.errors_mm[k]
        for i in (0, int(np.argmin(np.abs(e - np.median(e)))), len(e) - 1):
            shown = page.evaluate(f"loosefitViewer.errorAt(1, 1, {i})")
            assert shown == pytest.approx(e[i], abs=2e-3)
            expected = np.asarray(cmap((e[i] - lo) / (hi - lo))[:3])
            colour = np.asarray(page.evaluate(f"loosefitViewer.vertexColor(1, 1, {i})"))
            np.testing.assert_allclose(colour, expected, atol=1.5 / 255)
            legend = np.asarray(page.evaluate(f"loosefitViewer.legendColorAt({e[i]})")) / 255
            np.testing.assert_allclose(legend, expected, atol=1.5 / 255)
        assert page.evaluate("loosefitViewer.vertexColor(0, 1, 0)") is None  # the simulation has no error
        low, mid, high = page.evaluate("loosefitViewer.legendLabels()")
        assert high.startswith("\u2265 ")  # larger errors exist: they take the top colour
        assert [float(low), float(mid), float(high[2:])] == pytest.approx([0, hi / 2, hi], abs=0.05)
        # An error above the range (the last vertex at the last frame) takes the top colour of the map.
        page.evaluate(f"loosefitViewer.setFrame({T - 1})")
        i = len(e) - 1
        assert known.errors_mm[T - 1, i] > hi and page.evaluate(f"loosefitViewer.vertexColor(1, 1, {i})") == pytest.approx(
            np.asarray(cmap(1.0)[:3]), abs=1.5 / 255)
        page.evaluate("loosefitViewer.setHeat(false)")
        assert page.evaluate("loosefitViewer.vertexColor(1, 1, 0)") is None
        assert errors == []
    finally:
        page.close()


def test_metric_plot_and_its_cursor(browser, server, known):
    page, errors = open_page(browser, server.url)
    try:
        labels = page.evaluate("loosefitViewer.plotSeries()")
        assert labels == ["frame", "sim collision %", "pred RMSE mm", "pred collision %"]
        data = page.evaluate("loosefitViewer.plotData()")
        np.testing.assert_array_equal(data[0], np.arange(T))
        np.testing.assert_allclose(data[1], known.sim_collision, atol=1e-9)
        np.testing.assert_allclose(data[2], known.rmse_mm, atol=2e-3)
        np.testing.assert_allclose(data[3], known.pred_collision, atol=1e-9)
        for k in (1, 4):
            page.evaluate(f"loosefitViewer.setFrame({k})")
            assert page.evaluate("loosefitViewer.plotCursorFrame") == k
            # The cursor line is drawn where the frame axis puts frame k.
            x = page.evaluate("loosefitViewer.plotCursorX")
            rgb = page.evaluate(f"""(() => {{ const c = document.querySelector('#plot canvas');
                const d = c.getContext('2d').getImageData({x}, Math.round(c.height / 3), 1, 1).data;
                return [d[0], d[1], d[2]]; }})()""")
            assert rgb == [255, 59, 48]
        assert errors == []
    finally:
        page.close()


def test_screenshots_change_when_the_garment_moves(browser, server, shots):
    page, errors = open_page(browser, server.url)
    try:
        images = []
        for k in (0, 1, 2):
            page.evaluate(f"loosefitViewer.setFrame({k})")
            path = shots / f"viewer-frame{k}.png"
            page.locator("#gl").screenshot(path=str(path))
            images.append(iio.imread(path).astype(np.float64) / 255)
        page.screenshot(path=str(shots / "viewer-page.png"))
        # The simulation's panel (left half; the prediction's heat map changes with its error) shows
        # the same picture for frames 0 and 1, where nothing moves, and another one at frame 2.
        sim = [im[:, : im.shape[1] // 2] for im in images]
        assert np.array_equal(sim[0], sim[1])
        changed = np.abs(sim[2] - sim[1]).max(-1) > 0.05
        assert changed.mean() > 0.01  # the garment slid 6 cm
        assert errors == []
    finally:
        page.close()


def test_play_advances_frames(browser, server):
    page, errors = open_page(browser, server.url)
    try:
        page.evaluate("loosefitViewer.setSpeed(4)")
        page.evaluate("loosefitViewer.play()")
        page.wait_for_function("loosefitViewer.frame >= 3", timeout=5000)
        page.evaluate("loosefitViewer.pause()")
        assert not page.evaluate("loosefitViewer.isPlaying()")
        assert errors == []
    finally:
        page.close()


def test_export_opens_from_disk(browser, known, tmp_path, capsys, shots):
    out = tmp_path / "share"
    assert main(["view", *known.inputs, "--export", str(out)]) == 0
    assert "index.html" in capsys.readouterr().out
    assert (out / "vendor" / "LICENSE.three").is_file() and (out / "data" / "chunk-000.js").is_file()
    page, errors = open_page(browser, (out / "index.html").as_uri())
    try:
        page.evaluate("loosefitViewer.setFrame(5)")
        np.testing.assert_array_equal(positions(page, 1, 1), known.pred[5])
        assert page.evaluate("loosefitViewer.errorAt(1, 1, 0)") == pytest.approx(known.errors_mm[5, 0], abs=2e-3)
        page.screenshot(path=str(shots / "viewer-export-file.png"))
        assert errors == []
    finally:
        page.close()
    # A second export into the same folder replaces the first one.
    assert main(["view", str(known.sim_path), "--export", str(out), "--no-collisions"]) == 0
    page, errors = open_page(browser, (out / "index.html").as_uri())
    try:
        assert page.evaluate("window.LOOSEFIT_MANIFEST.panels.length") == 1 and errors == []
    finally:
        page.close()
    shutil.rmtree(out)


def test_collision_ratio_at_evenly_spaced_frames(known):
    assert collision_frame_indices(6, 0).tolist() == [0, 1, 2, 3, 4, 5]
    assert collision_frame_indices(300, 100)[[0, -1]].tolist() == [0, 299]
    assert len(collision_frame_indices(300, 100)) == 100
    sim, pred = build_scene(known.inputs, collision_frames=3).panels
    frames = collision_frame_indices(T, 3)
    assert frames.tolist() == [0, 2, 5]
    for panel, expected in ((sim, known.sim_collision), (pred, known.pred_collision)):
        np.testing.assert_allclose(panel.metrics["collision_pct"][frames], expected[frames])
        assert np.isnan(np.delete(panel.metrics["collision_pct"], frames)).all()
    manifest, _ = pack_scene(ViewerScene([pred], 30.0, T, (0.0, 1.0), np.zeros((256, 3), np.uint8)))
    assert manifest["panels"][0]["metrics"]["collision_pct"][1] is None  # JSON null: a gap in the plot


def test_dataset_sequence_and_run_inputs(tmp_path, body):
    from loosefit.data.store import DatasetStore
    from loosefit.garment import Garment
    from tests.viz.test_inputs import bent_motion, grid

    verts, faces = grid(frames=2)
    store = DatasetStore.create(tmp_path / "data.zarr")
    store.add_garment("g", Garment(verts=verts[0], faces=faces, pinned=np.zeros(16, bool), kind="skirt", params={}, name="g"))
    store.add_body("b", np.full(6, 0.5, np.float32))
    motion = bent_motion(body)
    motion.fps = 24.0
    store.add_motion("m", motion)
    store.write_sequence("s1", verts, "g", "b", "m", sim_params={}, stats={}, split="train")
    pred = verts + np.float32([0.0, 0.003, 0.004])  # 5 mm everywhere
    MeshSequence(pred, faces).save(tmp_path / "pred.npz")
    scene = build_scene([f"{tmp_path / 'data.zarr'}:s1", str(tmp_path / "pred.npz")], body=body, collisions=False)
    sim, prediction = scene.panels
    assert scene.fps == 24.0 and sim.title == "s1" and [t.role for t in sim.tracks] == ["body", "garment"]
    np.testing.assert_array_equal(sim.garment.verts, verts)
    assert sim.body.verts.shape == (2, body.num_verts, 3)
    np.testing.assert_allclose(prediction.garment.errors, 5.0, atol=1e-3)
    np.testing.assert_allclose(prediction.metrics["rmse_mm"], [5.0, 5.0], atol=1e-3)
    with pytest.raises(InputError, match="s2") as err:
        build_scene([f"{tmp_path / 'data.zarr'}:s2"], body=body)
    assert err.value.path == tmp_path / "data.zarr"
    # A folder that is neither a store nor a run, given a motion: named as not a run folder.
    (tmp_path / "run").mkdir()
    motion.save(tmp_path / "walk.npz")
    with pytest.raises(InputError, match="not a loosefit run folder") as err:
        build_scene([f"{tmp_path / 'run'}:{tmp_path / 'walk.npz'}"], body=body)
    with pytest.raises(InputError, match="no such motion file"):
        build_scene([f"{tmp_path / 'run'}:{tmp_path / 'missing.npz'}"], body=body)


def test_inputs_of_other_lengths_play_their_own_frames(browser, known, tmp_path, capsys):
    """A prediction 2 frames shorter and one 2 frames longer than the 6-frame simulation: each plays its own
    frames and the shorter ones hold their last; errors, RMSE and the heat map only where both exist."""
    long_pred = np.concatenate([known.pred, known.pred[-1:] + [[0.0, 0.0, 0.01]], known.pred[-1:] + [[0.0, 0.0, 0.02]]])
    body = np.concatenate([known.body, known.body[-2:]])
    extra = {"body_verts": body, "body_faces": known.body_faces}
    MeshSequence(known.pred[:4], known.faces, 30.0, {"body_verts": known.body[:4], "body_faces": known.body_faces}
                 ).save(tmp_path / "short.npz")
    MeshSequence(long_pred.astype(np.float32), known.faces, 30.0, extra).save(tmp_path / "long.npz")
    inputs = [str(known.sim_path), str(tmp_path / "short.npz"), str(tmp_path / "long.npz")]
    scene = build_scene(inputs)
    sim, short, long = scene.panels
    assert scene.num_frames == T + 2
    np.testing.assert_allclose(short.garment.errors, known.errors_mm[:4], atol=2e-3)
    np.testing.assert_allclose(short.metrics["rmse_mm"], known.rmse_mm[:4], atol=2e-3)
    np.testing.assert_allclose(long.garment.errors, known.errors_mm, atol=2e-3)
    np.testing.assert_allclose(long.metrics["rmse_mm"], known.rmse_mm, atol=2e-3)
    assert len(long.metrics["collision_pct"]) == T + 2 and len(short.metrics["collision_pct"]) == 4
    np.testing.assert_allclose(long.metrics["collision_pct"][:T], known.pred_collision)
    assert any("4 frames, the simulation" in w and "first 4 frames" in w for w in short.warnings)
    assert any("8 frames, the simulation" in w and "first 6 frames" in w for w in long.warnings)
    with ViewerServer(scene, port=0) as server:
        page, errors = open_page(browser, server.url)
        try:
            assert page.evaluate("loosefitViewer.numFrames") == T + 2
            page.evaluate("loosefitViewer.setFrame(3)")  # every input has frame 3: heat maps on both
            np.testing.assert_array_equal(positions(page, 1, 1), known.pred[3])
            assert page.evaluate("loosefitViewer.errorAt(1, 1, 0)") == pytest.approx(known.errors_mm[3, 0], abs=2e-3)
            assert page.evaluate("loosefitViewer.vertexColor(2, 1, 0)") is not None
            page.evaluate("loosefitViewer.setFrame(5)")  # the short one holds its frame 3, without an error
            np.testing.assert_array_equal(positions(page, 1, 1), known.pred[3])
            np.testing.assert_array_equal(positions(page, 1, 0), known.body[3])
            assert page.evaluate("loosefitViewer.errorAt(1, 1, 0)") is None
            assert page.evaluate("loosefitViewer.vertexColor(1, 1, 0)") is None
            assert page.evaluate("loosefitViewer.errorAt(2, 1, 0)") == pytest.approx(known.errors_mm[5, 0], abs=2e-3)
            page.evaluate(f"loosefitViewer.setFrame({T + 1})")  # past the simulation: it holds its last frame
            np.testing.assert_array_equal(positions(page, 0, 1), known.sim[T - 1])
            np.testing.assert_array_equal(positions(page, 2, 1), long_pred[T + 1].astype(np.float32))
            assert page.evaluate("loosefitViewer.errorAt(2, 1, 0)") is None
            assert page.evaluate("loosefitViewer.vertexColor(2, 1, 0)") is None
            data = page.evaluate("loosefitViewer.plotData()")
            assert len(data[0]) == T + 2
            assert errors == []
        finally:
            page.close()
    # The CLI prints the difference as a warning and exports the page.
    assert main(["view", *inputs, "--export", str(tmp_path / "page"), "--no-collisions"]) == 0
    assert "4 frames, the simulation" in capsys.readouterr().err


def test_animations_alone_without_a_simulation(browser, known, tmp_path, capsys):
    """Two animations on a user's own motion, of different garments (144 and 120 vertices) and lengths, one
    with its body and one without: no simulation, so nothing is compared; each plays its own frames."""
    other, other_faces = cylinder(segments=20)
    other_verts = np.stack([other + [0.0, 0.0, 0.02 * t] for t in range(T + 2)]).astype(np.float32)
    MeshSequence(other_verts, other_faces, 30.0).save(tmp_path / "other.npz")
    inputs = [str(known.pred_path), str(tmp_path / "other.npz")]
    with pytest.raises(InputError, match="120 vertices but the simulation"):
        build_scene(inputs)  # by default the first is the simulation
    scene = build_scene(inputs, reference=False)
    first, second = scene.panels
    assert scene.num_frames == T + 2 and [len(p.tracks) for p in scene.panels] == [2, 1]
    assert all(t.errors is None for p in scene.panels for t in p.tracks)
    assert "rmse_mm" not in first.metrics and "rmse_mm" not in second.metrics and not first.warnings
    np.testing.assert_allclose(first.metrics["collision_pct"], known.pred_collision)
    with ViewerServer(scene, port=0) as server:
        page, errors = open_page(browser, server.url)
        try:
            assert page.evaluate("window.LOOSEFIT_MANIFEST.panels.length") == 2
            assert page.evaluate("loosefitViewer.numFrames") == T + 2
            for k in (0, 3, T + 1):
                page.evaluate(f"loosefitViewer.setFrame({k})")
                np.testing.assert_array_equal(positions(page, 0, 1), known.pred[min(k, T - 1)])
                np.testing.assert_array_equal(positions(page, 0, 0), known.body[min(k, T - 1)])
                np.testing.assert_array_equal(positions(page, 1, 0), other_verts[k])
                assert page.evaluate("loosefitViewer.errorAt(0, 1, 0)") is None
                assert page.evaluate("loosefitViewer.vertexColor(0, 1, 0)") is None  # plain colour: no heat map
            assert page.evaluate("loosefitViewer.plotSeries()") == ["frame", "pred collision %"]
            assert errors == []
        finally:
            page.close()
    assert main(["view", *inputs, "--no-reference", "--export", str(tmp_path / "page"), "--no-collisions"]) == 0
    assert "index.html" in capsys.readouterr().out
