"""The per-garment training data: canonical frames, bone transforms, windows."""

import numpy as np
import torch

from loosefit.models.dataset import WindowDataset
from loosefit.models.motion_features import HISTORY_ROOT_FEATURES
from loosefit.motion.heading import to_world
from loosefit.rig.prepared import load_rig
from loosefit.rig.virtual_bones import skin_bones


def test_canonical_data_round_trips_to_the_store(tiny_train):
    store = tiny_train.store
    for s in tiny_train.sequences:
        world = store.sequence(s.name).verts[:]
        assert np.abs(to_world(s.verts, s.frame_rot, s.frame_origin) - world).max() < 1e-5
        assert s.root.shape == (s.num_frames, HISTORY_ROOT_FEATURES) and s.joints.shape == (s.num_frames, 30, 6)
        # Nearest proxy vertex really is the nearest (brute force on one frame).
        d = np.linalg.norm(s.verts[5][:, None] - s.body[5][None], axis=-1)
        assert (d.argmin(1) == s.body_nearest[5]).mean() > 0.999


def test_canonical_bones_skin_the_low_frequency_mesh(tiny_store, tiny_train):
    rig = load_rig(tiny_store, tiny_train.garment_name)
    weights = torch.from_numpy(rig.dense_weights())
    for s in tiny_train.sequences:
        skinned = skin_bones(torch.from_numpy(rig.rest_verts), weights, torch.from_numpy(s.bone_rot), torch.from_numpy(s.bone_trans))
        rmse = np.sqrt(((skinned.numpy() - s.lf) ** 2).sum(-1).mean())
        # The canonical transforms reproduce the canonical low-frequency mesh to the SSDR error (8 bones, coarse).
        assert rmse < 3 * rig.rmse + 2e-3, (rmse, rig.rmse)
        # the split keeps the pinned waist where the simulation put it
        pinned = tiny_train.garment.pinned
        assert pinned.any() and np.abs(s.lf[:, pinned] - s.verts[:, pinned]).max() < 1e-6


def test_held_out_split_follows_the_rig_settings(tiny_test, tiny_train):
    # loaded without bone transforms, the test sequences are still split as the rig was prepared
    assert tiny_test.rig_settings == tiny_train.rig_settings and tiny_test.rig_settings["keep_pinned"]
    pinned = tiny_test.garment.pinned
    for s in tiny_test.sequences:
        assert np.abs(s.lf[:, pinned] - s.verts[:, pinned]).max() < 1e-6
        assert np.abs(s.lf[:, ~pinned] - s.verts[:, ~pinned]).max() > 1e-4  # and the rest is smoothed


def test_windows_cover_each_sequence_with_burn_in(tiny_train):
    ds = WindowDataset(tiny_train, window=24, stride=12, burn_in=6)
    starts = {}
    for i in range(len(ds)):
        item = ds[i]
        assert item["verts"].shape[0] == 24
        assert item["burn_in"] == (0 if item["start"] == 0 else 6)
        s = tiny_train.sequences[item["sequence"]]
        assert torch.equal(item["verts"], torch.from_numpy(s.verts[item["start"] : item["start"] + 24]))
        starts.setdefault(item["sequence"], []).append(item["start"])
    for i, st in starts.items():
        n = tiny_train.sequences[i].num_frames
        assert st[0] == 0 and st[-1] == n - 24  # the first and last frames are both covered


def test_mirrored_sequences_are_the_mirror_image_in_the_heading_frame(tiny_store, tmp_path):
    """The heading frame of a mirrored motion is the mirror of the motion's, so a mirrored sequence's canonical
    garment is the canonical garment mirrored (read through the same correspondence), and its turning is reversed.
    Mirrored sequences come after the originals; bone transforms need a store prepared with ``mirror``."""
    import shutil

    import pytest

    from loosefit.data.mirror import GarmentMirror
    from loosefit.errors import InputError
    from loosefit.models.dataset import GarmentSequences
    from loosefit.rig.prepare import prepare

    with pytest.raises(InputError, match="mirror=true"):
        GarmentSequences(tiny_store, "skirt+average", "train", body=False, mirror=True)
    path = tmp_path / "mirrored.zarr"
    shutil.copytree(tiny_store, path)
    prepare(path, bones=8, mirror=True, progress=False)
    data = GarmentSequences(path, "skirt+average", "train", mirror=True)
    half = len(data.sequences) // 2
    mirror = GarmentMirror.build(data.garment.verts, data.faces)
    for original, image in zip(data.sequences[:half], data.sequences[half:]):
        assert image.name == original.name + "=mirrored" and image.bone_rot.shape == original.bone_rot.shape
        np.testing.assert_allclose(image.verts, mirror(original.verts), atol=2e-5)
        np.testing.assert_allclose(image.root[:, 4], -original.root[:, 4], atol=1e-5)  # heading change
        np.testing.assert_allclose(image.body[:, :, 0].mean(), -original.body[:, :, 0].mean(), atol=2e-3)
