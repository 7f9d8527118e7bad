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
    assert main(["animate", str(lbs_run), "--motion", str(tmp_path / "m.npz"), "--out", str(tmp_path / "a.npz")]) == 0
    with np.load(tmp_path / "a.npz") as z:
        assert np.abs(z["body_verts"] - body.pose(motion).verts).max() < 1e-6
        assert np.array_equal(z["body_faces"], body.faces)
        assert np.abs(z["verts"] - Animator(lbs_run).animate(motion)).max() < 1e-5
    (panel,) = load_panels(tmp_path / "a.npz")
    assert [t.label for t in panel] == ["body", "a"]
