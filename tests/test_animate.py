"""Animation from a run folder: batched and streaming agree, world placement follows the body."""

import numpy as np
import pytest

from loosefit.animate import Animator
from loosefit.data import DatasetStore
from loosefit.errors import InputError
from loosefit.motion import Motion
from loosefit.training import train_model


@pytest.fixture(scope="module")
def lbs_run(tiny_store, tmp_path_factory):
    run = tmp_path_factory.mktemp("anim") / "lbs"
    train_model("body-lbs", tiny_store, "skirt+average", run)
    return run


@pytest.fixture(scope="module")
def test_sequence(tiny_store):
    store = DatasetStore.open(tiny_store)
    seq = store.sequence(store.sequence_names(split="test")[0])
    return store.motion(seq.motion), np.asarray(seq.verts[:])


def test_streaming_equals_batched_and_batches_pad_correctly(lbs_run, test_sequence):
    motion, _ = test_sequence
    animator = Animator(lbs_run)
    whole = animator.animate(motion)
    stream = animator.stream()
    frames = np.stack([stream.step(motion.rotations[t], motion.translation[t]) for t in range(motion.num_frames)])
    assert np.abs(frames - whole).max() < 1e-5
    short = motion.slice(0, 20)
    batch = animator.animate_batch([motion, short])  # the short one is padded inside the batch
    assert np.abs(batch[0] - whole).max() < 1e-6 and np.abs(batch[1] - whole[:20]).max() < 1e-5


def test_body_lbs_baseline_follows_the_body(lbs_run, test_sequence):
    motion, gt = test_sequence
    pred = Animator(lbs_run).animate(motion)
    # The skinned skirt stays where the simulated one is, to within a loose garment's swing (decimetres),
    # and the waistband (pinned to the body by skinning in the simulator too) to within centimetres.
    err = np.linalg.norm(pred - gt, axis=-1)
    assert err.mean() < 0.15
    top = gt[0, :, 2] > np.percentile(gt[0, :, 2], 95)
    assert err[:, top].mean() < 0.02


def test_wrong_motion_and_folder(lbs_run, tmp_path):
    animator = Animator(lbs_run)
    with pytest.raises(InputError, match="joints"):
        animator.animate(Motion(np.zeros((3, 5, 3)), np.zeros((3, 3)), rig="x"))
    with pytest.raises(InputError, match="not a loosefit run"):
        Animator(tmp_path)


@pytest.mark.parametrize("text, problem", [
    ('{"method": "body-lbs", "siz', "corrupt or truncated"),
    ("[1, 2]", "expected a JSON object"),
    ('{"method": "no-such-method", "sizes": {}}', "unknown method"),
    ('{"method": "body-lbs", "sizes": {}}', "sizes do not build"),
])
def test_corrupt_run_record_is_a_clear_error(lbs_run, tmp_path, capsys, text, problem):
    """A damaged model.json is refused like a damaged checkpoint: an InputError naming the file, and
    from the command line exit status 2 with that message (no traceback)."""
    import shutil

    from loosefit.cli import main

    run = tmp_path / "run"
    shutil.copytree(lbs_run, run)
    (run / "model.json").write_text(text)
    with pytest.raises(InputError, match=problem) as info:
        Animator(run)
    assert info.value.path == run / "model.json"
    motion = tmp_path / "m.npz"
    Motion(np.zeros((2, 31, 3)), np.zeros((2, 3)) + [0, 0, 0.9], joint_names=[]).save(motion)
    assert main(["animate", str(run), "--motion", str(motion), "--out", str(tmp_path / "a.npz")]) == 2
    err = capsys.readouterr().err
    assert problem in err and str(run / "model.json") in err and "Traceback" not in err


def test_animate_npz_carries_the_posed_body_for_render(lbs_run, test_sequence, tmp_path, body):
    """`loosefit animate --out x.npz` stores the body posed along the motion beside the garment, so
    `loosefit render x.npz` draws both."""
    from loosefit.cli import main
    from loosefit.viz.inputs import load_panels

    motion, _ = test_sequence
    motion.save(tmp_path / "m.npz")
    assert main(["animate", str(lbs_run), "--motion", str(tmp_path / "m.npz"), "--out", str(tmp_path / "a.npz"),
                 "--collision", "none"]) == 0
    with np.load(tmp_path / "a.npz") as z:
        assert np.abs(z["body_verts"] - body.pose(motion).verts).max() < 1e-6
        assert np.array_equal(z["body_faces"], body.faces)
        assert np.abs(z["verts"] - Animator(lbs_run).animate(motion)).max() < 1e-5
    (panel,) = load_panels(tmp_path / "a.npz")
    assert [t.label for t in panel] == ["body", "a"]


def test_animate_handles_collisions_by_default_and_reports_what_is_inside(lbs_run, tmp_path, body, capsys):
    """By default the animation is corrected for collisions (exact distance, SwinGar Eq. 10): what the
    uncorrected one leaves more than 5 mm inside the body is pushed out, and every animation prints the share
    of vertices inside, as :func:`inside_body_report` measures it."""
    from loosefit.cli import main
    from loosefit.metrics.collision import inside_body_report
    from loosefit.models.collision import handle_motion_collisions

    from loosefit.motion.procedural import generate

    motion = generate("spin", 1.0, 0, body)  # body-LBS leaves a few skirt vertices inside the turning legs
    motion.save(tmp_path / "m.npz")
    args = ["animate", str(lbs_run), "--motion", str(tmp_path / "m.npz")]
    assert main(args + ["--out", str(tmp_path / "raw.npz"), "--collision", "none"]) == 0
    raw_line = capsys.readouterr().out
    assert main(args + ["--out", str(tmp_path / "fixed.npz")]) == 0
    line = capsys.readouterr().out
    with np.load(tmp_path / "raw.npz") as z:
        raw = z["verts"]
    with np.load(tmp_path / "fixed.npz") as z:
        fixed = z["verts"]
    expected = handle_motion_collisions(raw, Animator(lbs_run).faces, body, motion, "exact")
    assert np.abs(fixed - expected).max() < 1e-6
    faces = Animator(lbs_run).faces
    before, after = (inside_body_report(v, body, motion, faces=faces) for v in (raw, fixed))
    assert before["mean_percent"] > 0.1 and after["mean_percent"] < 0.5 * before["mean_percent"]
    assert f"{before['mean_percent']:.1f} % of the vertices" in raw_line and "collision handling none" in raw_line
    assert f"{after['mean_percent']:.1f} % of the vertices" in line and "collision handling exact" in line
    # and on the surface between the vertices (edge midpoints, centroids), with the deepest point
    for report, text in ((before, raw_line), (after, line)):
        assert (f"{report['surface_mean_percent']:.1f} % of surface points between them (worst "
                f"{report['surface_worst_percent']:.1f} %), deepest {report['deepest_mm']:.0f} mm") in text
    assert before["surface_mean_percent"] > 0 and before["deepest_mm"] > 5.0  # measured 0.09 %, 34 mm


def test_inside_body_report_counts_what_is_deeper_than_the_depth(body):
    """Vertices of the posed full-resolution body moved along their inward normals by 2 and 8 mm: at a 5 mm depth
    exactly the 8 mm ones count; frames are evenly spaced and capped."""
    from loosefit.geometry.normals import vertex_normals
    from loosefit.metrics.collision import inside_body_report
    from loosefit.motion.procedural import generate

    motion = generate("walk", 1.0, 0, body)
    posed = body.pose(motion).verts
    picked = np.arange(0, body.num_verts, 29)
    depth = np.where(np.arange(len(picked)) % 4 == 0, 0.008, 0.002)  # a quarter deep, the rest shallow
    normals = np.stack([vertex_normals(v, body.faces) for v in posed])[:, picked]
    garment = posed[:, picked] - depth[None, :, None] * normals
    report = inside_body_report(garment, body, motion, max_frames=10)
    assert report["frames"] == 10 and report["of_frames"] == motion.num_frames
    deep = 100.0 * (depth > 0.005).mean()  # 25 %; fewer where 8 mm along the normal crosses a thin part (fingers)
    assert 0.7 * deep < report["mean_percent"] <= deep and report["worst_percent"] >= report["mean_percent"]
    assert inside_body_report(garment, body, motion, depth=0.001, max_frames=10)["mean_percent"] > 2 * deep
    shallow = posed[:, picked] - 0.002 * normals
    assert inside_body_report(shallow, body, motion, max_frames=10)["mean_percent"] < 1.0



def test_view_animates_runs_with_collision_handling_like_animate(lbs_run, tmp_path, body):
    """`loosefit view RUN:MOTION` shows the animation `loosefit animate` writes: collision-handled by default."""
    from loosefit.models.collision import handle_motion_collisions
    from loosefit.motion.procedural import generate
    from loosefit.viz.viewer_scene import build_scene

    motion = generate("spin", 1.0, 0, body)
    motion.save(tmp_path / "m.npz")
    spec = [f"{lbs_run}:{tmp_path / 'm.npz'}"]
    raw = build_scene(spec, body=body, collisions=False, handling="none").panels[0].garment.verts
    fixed = build_scene(spec, body=body, collisions=False).panels[0].garment.verts
    expected = handle_motion_collisions(raw, Animator(lbs_run).faces, body, motion, "exact")
    assert np.abs(fixed - expected).max() < 1e-6 and np.abs(fixed - raw).max() > 1e-4
    with pytest.raises(InputError, match="exact, pushout or none"):
        build_scene(spec, body=body, handling="sdf")


def test_view_takes_the_joint_map_of_a_bvh_motion(lbs_run, tmp_path, body):
    """A BVH of a skeleton without a built-in map: `view RUN:clip.bvh` refuses it naming `loosefit motion map`;
    with `--joint-map` it shows what `animate --joint-map` writes."""
    from loosefit.cli import main
    from loosefit.motion.bvh import write_bvh
    from loosefit.viz.viewer_scene import build_scene
    from tests.motion.test_retarget import smooth_motion, to_bvh

    bvh, joint_map = tmp_path / "odd.bvh", tmp_path / "map.yaml"
    names = [f"bone{j:02d}" for j in range(body.num_joints)]
    write_bvh(bvh, to_bvh(body, smooth_motion(body, 30.0, seconds=0.5), names=names, up="y", scale=100.0))
    assert main(["motion", "map", str(bvh), "--out", str(joint_map)]) == 0
    with pytest.raises(InputError, match="loosefit motion map"):
        build_scene([f"{lbs_run}:{bvh}"], body=body, collisions=False, handling="none")
    shown = build_scene([f"{lbs_run}:{bvh}"], body=body, collisions=False, handling="none",
                        joint_map=str(joint_map)).panels[0].garment.verts
    assert main(["animate", str(lbs_run), "--motion", str(bvh), "--joint-map", str(joint_map), "--collision", "none",
                 "--out", str(tmp_path / "a.npz")]) == 0
    with np.load(tmp_path / "a.npz") as z:
        assert np.abs(shown - z["verts"]).max() < 1e-6


def test_animate_fps_gives_the_rate_of_a_motion_file_without_one(lbs_run, test_sequence, tmp_path, capsys):
    """A motion ``.npz`` without ``fps`` is refused naming the file and the option; ``--fps`` gives its rate (any
    rate is resampled to the model's 30 fps, as a file's own rate is); a file whose own rate disagrees is refused."""
    from loosefit.cli import main

    motion, _ = test_sequence
    bare = tmp_path / "bare.npz"
    np.savez(bare, rotations=motion.rotations, translation=motion.translation)  # no fps, as some tools write
    args = ["animate", str(lbs_run), "--motion", str(bare), "--collision", "none", "--out"]
    assert main(args + [str(tmp_path / "none.npz")]) == 2
    err = capsys.readouterr().err
    assert str(bare) in err and "no frame rate" in err and "--fps" in err and "Traceback" not in err
    assert not (tmp_path / "none.npz").exists()

    assert main(args + [str(tmp_path / "a30.npz"), "--fps", "30"]) == 0
    with np.load(tmp_path / "a30.npz") as z:
        assert z["verts"].shape[0] == motion.num_frames and float(z["fps"]) == 30.0
        assert np.abs(z["verts"] - Animator(lbs_run).animate(motion)).max() < 1e-5
    capsys.readouterr()
    assert main(args + [str(tmp_path / "a60.npz"), "--fps", "60"]) == 0  # played twice as fast
    assert "resampled to the model's 30 fps" in capsys.readouterr().err
    with np.load(tmp_path / "a60.npz") as z:
        assert z["verts"].shape[0] == (motion.num_frames + 1) // 2

    motion.save(tmp_path / "own.npz")  # stores 30 fps
    assert main(["animate", str(lbs_run), "--motion", str(tmp_path / "own.npz"), "--fps", "60", "--out",
                 str(tmp_path / "b.npz")]) == 2
    err = capsys.readouterr().err
    assert str(tmp_path / "own.npz") in err and "frame rate is 30 fps, --fps says 60" in err
