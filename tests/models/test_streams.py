"""Stateful training windows: a sequence shorter than a window trains alike in both modes; the state carried
over consecutive windows reproduces the whole-sequence forward pass; the batches keep each sequence in order."""

from __future__ import annotations

import pytest
import torch
from torch.utils.data import default_collate

from loosefit.models.dataset import WindowDataset
from loosefit.models.jointnet import JointNet, JointNetConfig
from loosefit.models.streams import MemoryWindowConfig, StreamWindows
from loosefit.models.virtualbones import VirtualBones, VirtualBonesConfig
from loosefit.train import StageConfig, TrainConfig, seed_everything, train

VB = VirtualBonesConfig(lf_hidden=24, hf_hidden=24, global_channels=4, edge_channels=(8,),
                        pose_noise=0.0)  # the losses compared are of the same draw-free inputs
JN = JointNetConfig(gru_hidden=24, features=16, bone_mlp=[32], psd_mlp=[16], psd_shapes=4)
#: (model class, config, stages)
MODELS = {"virtualbones": (VirtualBones, VB, ("low", "high")), "jointnet": (JointNet, JN, ("stage1", "stage2"))}
#: the losses are float32 means over about 10^5 values: summed in another order they differ in the last bits
ROUND_OFF = 1e-6


def _model(method, data):
    cls, config, _ = MODELS[method]
    seed_everything(0)
    return cls.from_data(data, config)


def _whole_sequences(data) -> dict:
    """Every sequence (all of one length here) as one batch, straight from the arrays, from the zero state."""
    items = []
    for i, s in enumerate(data.sequences):
        item = {k: torch.from_numpy(getattr(s, k)) for k in ("root", "joints", "verts", "lf", "bone_rot",
                                                             "bone_trans", "body", "body_normals", "body_nearest")}
        items.append({**item, "burn_in": 0, "sequence": i, "start": 0})
    return default_collate(items)


def _lengths(data) -> int:
    lengths = {s.num_frames for s in data.sequences}
    assert len(lengths) == 1, lengths  # the fixture's motions share one duration
    return lengths.pop()


@pytest.mark.parametrize("method", sorted(MODELS))
def test_a_sequence_shorter_than_a_window_gives_the_same_loss_either_way(tiny_train, method):
    frames = _lengths(tiny_train)
    window = frames + 19  # longer than every sequence: one window each, from frame 0
    model = _model(method, tiny_train)
    whole = _whole_sequences(tiny_train)
    windowed = default_collate([WindowDataset(tiny_train, window, 32, 16)[k] for k in range(2)])
    streamed = StreamWindows(tiny_train, window)
    assert len(streamed) == 2 and streamed.length == frames
    streamed = default_collate([streamed[k] for k in range(2)])
    for stage in MODELS[method][2]:
        with torch.no_grad():
            reference, _ = model.training_loss(whole, stage)
            a, _ = model.training_loss(windowed, stage)
            b, _ = model.training_loss(streamed, stage)
        assert reference > 0
        assert abs(float(a) - float(reference)) <= ROUND_OFF * float(reference)
        assert abs(float(b) - float(reference)) <= ROUND_OFF * float(reference)


@pytest.mark.parametrize("method", sorted(MODELS))
def test_carried_state_over_consecutive_windows_is_the_whole_sequence_forward_pass(tiny_train, method):
    frames = _lengths(tiny_train)
    window = 10  # 45 frames: windows of 10, 10, 10, 10 and 5 (padded)
    model = _model(method, tiny_train).eval()
    whole = _whole_sequences(tiny_train)
    dataset = StreamWindows(tiny_train, window)
    batches = dataset.batch_sampler(2, torch.Generator().manual_seed(3), shuffle=True)
    assert len(batches) == -(-frames // window) and all(len(b) == 2 for b in batches)

    with torch.no_grad():
        expected = model(whole["root"], whole["joints"])
        for stage in MODELS[method][2]:
            reference, _ = model.training_loss(whole, stage)
            total, counted = 0.0, 0.0
            for indices in batches:
                batch = default_collate([dataset[k] for k in indices])
                loss, _ = model.training_loss(batch, stage)  # carries the state as training does
                n = float(model.mask(batch).sum())
                total, counted = total + float(loss) * n, counted + n
            assert not model.carry.saved  # every carried state was taken up by the next window
            # the loss's means over frames, accumulated window by window, are the whole sequences' means
            assert abs(total / counted - float(reference)) <= 10 * ROUND_OFF * float(reference)
        pieces = {i: [] for i in range(len(tiny_train.sequences))}
        for indices in batches:
            batch = default_collate([dataset[k] for k in indices])
            out = model(batch["root"], batch["joints"], model.carry.initial(batch))
            model.carry.keep(batch, out["state"])
            for row, (i, f) in enumerate(zip(batch["sequence"].tolist(), batch["frames"].tolist())):
                pieces[i].append(out["verts"][row, :f])
    streamed = torch.stack([torch.cat(pieces[i]) for i in sorted(pieces)])
    assert streamed.shape == expected["verts"].shape
    torch.testing.assert_close(streamed, expected["verts"], atol=1e-6, rtol=0)
    # from the zero state at every window instead, the prediction differs: the carried state matters
    with torch.no_grad():
        restarted = model(whole["root"][:, window:], whole["joints"][:, window:])["verts"]
    assert (restarted - expected["verts"][:, window:]).abs().max() > 1e-4


def test_batches_keep_each_sequence_in_order_and_cover_every_window_once(tiny_train):
    dataset = StreamWindows(tiny_train, 8)
    for shuffle in (False, True):
        batches = dataset.batch_sampler(4, torch.Generator().manual_seed(0), shuffle)
        flat = [k for b in batches for k in b]
        assert sorted(flat) == list(range(len(dataset)))
        for i in range(len(tiny_train.sequences)):
            starts = [dataset.index[k][1] for k in flat if dataset.index[k][0] == i]
            assert starts == list(range(0, tiny_train.sequences[i].num_frames, 8))
    item = dataset[dataset.windows_of[0][-1]]  # 45 frames: the last window has 5 real frames, 3 padded
    assert item["frames"] == 5 and item["last"] and item["verts"].shape[0] == 8
    assert torch.equal(item["verts"][5:], item["verts"][4:5].expand(3, -1, -1))


def test_a_window_out_of_order_is_refused(tiny_train):
    model = _model("jointnet", tiny_train)
    dataset = StreamWindows(tiny_train, 10)
    batch = default_collate([dataset[dataset.windows_of[0][1]]])  # frame 10 before frame 0
    with pytest.raises(RuntimeError, match="in order"):
        model.training_loss(batch, "stage1")


def test_stateful_training_runs_through_the_trainer_and_repeats_exactly(tiny_train, tmp_path):
    config = MemoryWindowConfig(window=16, carry_state=True)
    dataset = config.dataset(tiny_train)
    assert isinstance(dataset, StreamWindows)
    settings = TrainConfig(batch_size=2, progress=False, tensorboard=False, lr=3e-3, schedule="none",
                           stages={"stage1": StageConfig(epochs=2), "stage2": StageConfig(epochs=0)})
    runs = [train(_model("jointnet", tiny_train), dataset, dataset, settings, tmp_path / f"run{k}") for k in range(2)]
    losses = [[row["train_loss"] for row in r.history] for r in runs]
    assert losses[0][-1] < losses[0][0]
    assert losses[0] == losses[1]
    assert runs[0].val_metrics == runs[1].val_metrics
