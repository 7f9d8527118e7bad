"""JointNet: the grouped GRU, joint neighbourhoods, association, Euler and 6D bones, PSD stages, sizes, streaming,
overfitting."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils.data import Subset, default_collate

from loosefit.config import load_config
from loosefit.errors import InputError
from loosefit.geometry.rotations import axis_angle_to_matrix, euler_to_matrix, matrix_to_euler, matrix_to_sixd
from loosefit.models.dataset import GarmentSequences, WindowDataset
from loosefit.models.jointnet import (Config, JointGRU, JointNet, JointNetConfig, nearby_association, neighbour_table,
                                     select_joints)
from loosefit.models.streams import MemoryWindowConfig
from loosefit.train import StageConfig, TrainConfig, seed_everything, train
from loosefit.train.losses import normal_loss
from loosefit.train.trainer import OPTIMIZERS

CONFIG_FILE = Path(__file__).parents[2] / "configs" / "models" / "jointnet.yaml"
#: The paper's association (``relu(A) psi``, its L1) from a random start and its free PSD basis, so that its tests
#: read the paper's form.
TINY = JointNetConfig(gru_hidden=32, features=32, bone_mlp=[64, 64], psd_mlp=[32, 16], psd_shapes=8, association="l1",
                      association_radius=0.0, lambda_sparse=1e-3, psd_modes=0)
PSD_PARAMS = ("psd_mlp.", "psd_basis")


def _model(data, config=TINY, seed=0) -> JointNet:
    seed_everything(seed)
    return JointNet.from_data(data, config)


def _batch(data, frames: int = 16) -> dict:
    return default_collate([WindowDataset(data, frames, frames, 4)[0]])


@pytest.mark.parametrize("order", ["joint_by_joint", "all_joints_per_frame", "all_joints_by_hand"])
def test_grouped_gru_equals_one_torch_gru_per_joint(order):
    torch.manual_seed(0)
    gru = JointGRU(3, 5, 7)
    x, h0 = torch.randn(2, 6, 3, 5), torch.randn(2, 3, 7)
    out, last = getattr(gru, order)(x, h0)
    (out.square().sum() + last.sum()).backward()
    for g in range(3):
        ref = torch.nn.GRU(5, 7, batch_first=True)
        with torch.no_grad():
            ref.weight_ih_l0.copy_(gru.weight_ih[g])
            ref.weight_hh_l0.copy_(gru.weight_hh[g])
            ref.bias_ih_l0.copy_(gru.bias_ih[g, 0])
            ref.bias_hh_l0.copy_(gru.bias_hh[g, 0])
        expected, expected_last = ref(x[:, :, g], h0[:, g][None])
        assert torch.allclose(out[:, :, g], expected, atol=1e-6)
        assert torch.allclose(last[:, g], expected_last[0], atol=1e-6)
        (expected.square().sum() + expected_last.sum()).backward()
        assert torch.allclose(gru.weight_hh.grad[g], ref.weight_hh_l0.grad, atol=1e-5)
        assert torch.allclose(gru.bias_ih.grad[g, 0], ref.bias_ih_l0.grad, atol=1e-5)
        assert torch.allclose(gru.weight_ih.grad[g], ref.weight_ih_l0.grad, atol=1e-5)
    # forward: training on the CPU by hand; without autograd one frame frame by frame, several joint by joint
    assert torch.equal(gru(x, h0)[0], gru.all_joints_by_hand(x, h0)[0])
    with torch.no_grad():
        assert torch.equal(gru(x, h0)[0], gru.joint_by_joint(x, h0)[0])
        assert torch.equal(gru(x[:, :1], h0)[0], gru.all_joints_per_frame(x[:, :1], h0)[0])


def test_joint_selection_and_skeleton_neighbours(body):
    names, parents = body.joint_names, [int(p) for p in body.parents]
    selected = select_joints(names, JointNetConfig())
    # cmu_mb: 30 non-root joints, 6 of them fingers or thumbs
    assert len(selected) == 24 and not any("Finger" in names[j] or "Thumb" in names[j] for j in selected)
    table = neighbour_table(selected, parents)
    J = len(names)
    rows = {names[j]: list(r) for j, r in zip(selected, table)}
    i = names.index
    assert rows["Spine1"] == [i("Spine1"), i("Spine"), i("LeftShoulder"), i("Neck"), i("RightShoulder")]
    assert rows["LHipJoint"] == [i("LHipJoint"), 0, i("LeftUpLeg"), J, J]  # 0: the root's tilt
    assert rows["LeftHand"] == [i("LeftHand"), i("LeftForeArm"), J, J, J]  # fingers left out: padding
    chosen = select_joints(names, JointNetConfig(joints=["LeftArm", "LeftForeArm"]))
    assert neighbour_table(chosen, parents).tolist() == [[i("LeftArm"), J, i("LeftForeArm")], [i("LeftForeArm"), i("LeftArm"), J]]
    with pytest.raises(InputError, match="Tail"):
        select_joints(names, JointNetConfig(joints=["Tail"]))


def test_sizes_follow_the_data(tiny_train, second_store):
    second = GarmentSequences(second_store, "dress+average", "train", body=False)
    verts = []
    for data, requested in ((tiny_train, 8), (second, 6)):
        model = _model(data)
        V, B = data.garment.verts.shape[0], model.bone_rest.shape[0]
        sizes = model.sizes()
        assert (sizes["num_verts"], sizes["num_joints"]) == (V, 31) and sizes["num_bones"] == B <= requested
        assert model.psd_basis.shape == (24, TINY.psd_shapes, V, 3)
        assert model.association_matrix().shape == (B, 24) and model.skin_weights.shape == (V, B)
        batch = _batch(data, 8)
        out = model(batch["root"], batch["joints"])
        assert out["verts"].shape == (1, 8, V, 3) and out["state"].shape == (1, 24, TINY.gru_hidden)
        assert out["bones"][0].shape == (1, 8, B, 3, 3) and out["displacement"].shape == (1, 8, V, 3)
        # rebuilt from its sizes and state alone (a checkpoint), the model predicts the same
        clone = JointNet(sizes, TINY)
        clone.load_state_dict(model.state_dict())
        assert torch.equal(clone(batch["root"], batch["joints"])["verts"], out["verts"])
        verts.append(V)
    assert verts[0] != verts[1]


def test_streaming_equals_batched(tiny_train):
    model = _model(tiny_train).eval()
    s = tiny_train.sequences[0]
    root, joints = torch.from_numpy(s.root)[None], torch.from_numpy(s.joints)[None]
    with torch.no_grad():
        batched = model(root, joints)["verts"]
        state, frames = None, []
        for t in range(root.shape[1]):
            out = model(root[:, t : t + 1], joints[:, t : t + 1], state)
            state = out["state"]
            frames.append(out["verts"])
    assert (torch.cat(frames, 1) - batched).abs().max() < 1e-5


def test_gradients_reach_every_parameter_of_each_stage(tiny_train):
    model = _model(tiny_train)
    batch = _batch(tiny_train, 8)
    for stage in model.stages():
        model.zero_grad(set_to_none=True)
        model.training_loss(batch, stage)[0].backward()
        trained = {id(p) for p in model.stage_parameters(stage)}
        for name, p in model.named_parameters():
            if id(p) in trained:
                assert p.grad is not None and p.grad.abs().sum() > 0, (stage, name)
            else:  # stage 1: the PSD takes no part
                assert stage == "stage1" and name.startswith(PSD_PARAMS) and p.grad is None, (stage, name)
    assert {n for n, p in model.named_parameters() if id(p) not in {id(q) for q in model.stage_parameters("stage1")}} == {
        n for n, _ in model.named_parameters() if n.startswith(PSD_PARAMS)}


def test_losses_on_sampled_frames_are_the_full_losses_restricted_to_them(tiny_train):
    model = _model(tiny_train, config=JointNetConfig(**{**TINY.__dict__, "loss_frames": 5}))
    batch = default_collate([WindowDataset(tiny_train, 20, 20, 6)[i] for i in range(2)])
    torch.manual_seed(7)
    frames = model.loss_frames(model.mask(batch), 5)
    assert len(set(frames.tolist())) == 5 and frames.min() >= 6
    torch.manual_seed(7)
    _, terms = model.training_loss(batch, "stage2")
    with torch.no_grad():  # the reference: every frame predicted, the losses on the drawn frames only
        pred = model(batch["root"], batch["joints"])["verts"][:, frames]
    target = batch["verts"][:, frames]
    assert terms["l1_mm"] == pytest.approx(float((pred - target).abs().mean()) * 1e3, rel=1e-5)
    assert terms["normal"] == pytest.approx(float(normal_loss(pred, target, model.faces)), rel=1e-5)


def test_stage1_trains_everything_but_the_psd(tiny_train, tmp_path):
    model = _model(tiny_train)
    before = {k: v.clone() for k, v in model.state_dict().items()}
    windows = Subset(WindowDataset(tiny_train, 12, 12, 4), [0, 1])
    config = TrainConfig(optimizer="rmsprop", batch_size=2, progress=False, tensorboard=False,
                         stages={"stage1": StageConfig(epochs=2), "stage2": StageConfig(epochs=0)})
    train(model, windows, None, config, tmp_path / "run")
    for name, value in model.state_dict().items():
        if name.startswith(PSD_PARAMS):
            assert torch.equal(value, before[name]), name
        elif name in dict(model.named_parameters()):
            assert not torch.equal(value, before[name]), name


def test_association_is_non_negative_and_its_l1_is_the_sparsity_loss(tiny_train):
    model = _model(tiny_train)
    with torch.no_grad():
        model.association.copy_(torch.randn(model.association.shape))
        model.association[0] = -1.0  # bone 0 listens to no joint
    A = model.association.detach().numpy()
    relu = model.association_matrix().detach().numpy()
    assert (relu >= 0).all() and np.array_equal(relu, np.maximum(A, 0))
    assert model.sparsity_loss().item() == pytest.approx(np.abs(np.maximum(A, 0)).sum(), rel=1e-6)

    batch = _batch(tiny_train, 8)
    loss, terms = model.training_loss(batch, "stage2")
    pred = model(batch["root"], batch["joints"])
    err = (pred["verts"] - batch["verts"]).detach().numpy()
    assert terms["l1_mm"] == pytest.approx(np.abs(err).mean() * 1e3, rel=1e-5)  # no burn-in in the first window
    normal = normal_loss(pred["verts"], batch["verts"], model.faces).item()
    expected = np.abs(err).mean() + TINY.lambda_norm * normal + TINY.lambda_sparse * np.maximum(A, 0).sum()
    assert loss.item() == pytest.approx(expected, rel=1e-5)
    # without any joint, bone 0 moves the same way in every frame: only its Fourier prior drives it
    R, T = pred["bones"]
    assert torch.allclose(R[0, :, 0], R[0, :1, 0].expand_as(R[0, :, 0]), atol=1e-6)
    assert torch.allclose(T[0, :, 0], T[0, :1, 0].expand_as(T[0, :, 0]), atol=1e-6)
    assert not torch.allclose(R[0, :, 1], R[0, :1, 1].expand_as(R[0, :, 1]), atol=1e-6)


def test_euler_angles_and_offsets_make_the_bone_transforms(tiny_train):
    model = _model(tiny_train)
    last = model.bone_mlp[-1]
    angles, offset = torch.tensor([0.3, -0.2, 0.5]), torch.tensor([0.01, -0.02, 0.03])
    with torch.no_grad():  # constant network output: the standardised Euler angles and offset
        last.weight.zero_()
        last.bias.copy_(torch.cat([(angles - model.euler_mean[2]) / model.euler_std[2],
                                   (offset - model.offset_mean[2]) / model.offset_std[2]]))
    R, T = model.bone_transforms(torch.zeros(1, 1, model.bone_rest.shape[0], model.bone_mlp[0].in_features))
    c, s = math.cos, math.sin
    Rx = torch.tensor([[1, 0, 0], [0, c(0.3), -s(0.3)], [0, s(0.3), c(0.3)]])
    Ry = torch.tensor([[c(-0.2), 0, s(-0.2)], [0, 1, 0], [-s(-0.2), 0, c(-0.2)]])
    Rz = torch.tensor([[c(0.5), -s(0.5), 0], [s(0.5), c(0.5), 0], [0, 0, 1]])
    assert torch.allclose(R[0, 0, 2], Rx @ Ry @ Rz, atol=1e-6)  # intrinsic x, y, z
    centre = model.bone_rest[2]
    assert torch.allclose(R[0, 0, 2] @ centre + T[0, 0, 2], centre + offset, atol=1e-6)  # the rest position moves by the offset
    # the statistics come from the rig's bone transforms, whose Euler angles convert back exactly
    rot = torch.from_numpy(np.concatenate([s.bone_rot for s in tiny_train.sequences])).double()
    euler = matrix_to_euler(rot, "xyz")
    assert torch.allclose(euler_to_matrix(euler, "xyz"), rot, atol=1e-6)
    assert torch.allclose(model.euler_mean.double(), euler.mean(0), atol=1e-5)


def test_sixd_bones_make_the_bone_transforms_and_do_not_wrap(tiny_train):
    model = _model(tiny_train, dataclasses.replace(TINY, rotation="sixd"))
    assert model.sizes()["rotation"] == "sixd" and model.bone_mlp[-1].out_features == 9
    assert "rotation" not in _model(tiny_train).sizes()  # Euler runs keep the sizes they had
    # the statistics: the mean and std of the rig's rotation matrices' first two columns
    rot = torch.from_numpy(np.concatenate([s.bone_rot for s in tiny_train.sequences])).double()
    columns = torch.cat([rot[..., :, 0], rot[..., :, 1]], -1)
    assert torch.allclose(model.sixd_mean.double(), columns.mean(0), atol=1e-5)
    assert torch.allclose(model.sixd_std.double(), columns.std(0, unbiased=False).clamp_min(1e-3), atol=1e-5)
    # a constant network output: the bone turns by the rotation whose columns it gives, about its rest position
    target = axis_angle_to_matrix(torch.tensor([0.4, -1.1, 2.9]))
    offset = torch.tensor([0.01, -0.02, 0.03])
    last = model.bone_mlp[-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.copy_(torch.cat([(matrix_to_sixd(target) - model.sixd_mean[1]) / model.sixd_std[1],
                                   (offset - model.offset_mean[1]) / model.offset_std[1]]))
    R, T = model.bone_transforms(torch.zeros(1, 1, model.bone_rest.shape[0], model.bone_mlp[0].in_features))
    assert torch.allclose(R[0, 0, 1], target, atol=1e-5)
    centre = model.bone_rest[1]
    assert torch.allclose(R[0, 0, 1] @ centre + T[0, 0, 1], centre + offset, atol=1e-6)
    # any output is a rotation (Gram-Schmidt), where Euler angles past half a turn about Z jump by 2 pi
    R, _ = model.bone_outputs(torch.randn(7, model.bone_rest.shape[0], 9))
    assert torch.allclose(R @ R.transpose(-1, -2), torch.eye(3).expand_as(R), atol=1e-5)
    assert torch.allclose(torch.linalg.det(R), torch.ones(R.shape[:-2]), atol=1e-5)
    turns = axis_angle_to_matrix(torch.tensor([[0.0, 0.0, math.pi - 0.01], [0.0, 0.0, -math.pi + 0.01]]))
    assert (matrix_to_euler(turns, "xyz")[0] - matrix_to_euler(turns, "xyz")[1]).abs().max() > 6.0
    assert (matrix_to_sixd(turns)[0] - matrix_to_sixd(turns)[1]).abs().max() < 0.03
    with pytest.raises(InputError, match="rotation"):
        dataclasses.replace(TINY, rotation="quaternion")


#: The joints of the paper-width regression test: the legs and the lower back (the ones that swing a skirt), so that
#: the test runs in seconds; every width is the paper's.
LEGS = ["LeftUpLeg", "RightUpLeg", "LeftLeg", "RightLeg", "LowerBack"]


def _paper_steps(data, test, optimizer: str, steps: int = 12, seed: int = 0):
    """``steps`` optimiser steps of JointNet's first stage at the paper's widths (GRU 600, K 480, F 1024-2048-1024),
    association (its L1 form, a random start) and learning rate (1e-3, batches of 8 windows) with ``optimizer``;
    returns the step losses and the skinned RMSE (mm) of the first test sequence before and after."""
    config = Config()
    model = _model(data, dataclasses.replace(config.model, joints=LEGS, loss_frames=4, association="l1",
                                             association_radius=0.0), seed)
    windows = WindowDataset(data, 8, 6, 2)
    kind, settings = OPTIMIZERS[optimizer]
    optimizer = kind(list(model.stage_parameters("stage1")), lr=config.train.lr, **settings)
    g = torch.Generator().manual_seed(seed)
    whole = _batch(test, test.sequences[0].num_frames)  # the first test sequence from its first frame

    def held_out():
        with torch.no_grad():
            return model.validation_metrics(whole, "stage1")["rmse_mm"]

    before, losses = held_out(), []
    for _ in range(steps):
        batch = default_collate([windows[int(i)] for i in torch.randperm(len(windows), generator=g)[:8]])
        optimizer.zero_grad()
        loss = model.training_loss(batch, "stage1")[0]
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    return losses, before, held_out()


def test_paper_widths_train_stably_with_the_paper_optimiser(tiny_train, tiny_test):
    """The paper's widths, learning rate and optimiser (RMSProp) on the tiny store: no step's loss jumps, the
    loss falls and the held-out error does not blow up. torch's RMSprop, whose squared-gradient average starts
    at zero uncorrected, moves every weight by about 10 lr at once in the first steps: on the same steps its
    loss jumps forty-fold and its held-out error triples (the contrast shows that the bounds can fail)."""
    losses, before, after = _paper_steps(tiny_train, tiny_test, "rmsprop")
    assert all(math.isfinite(v) for v in losses)
    # measured: losses 0.033 .. 0.054, last four 0.041 against 0.046; held-out 66.5 -> 72.9 mm (seed 1: 67.0 ->
    # 79.7). Twelve steps move the held-out error by a few mm either way; the shipped association's start adds
    # its own spread (66.5 -> 77-90 mm at radii 0.2-0.6 on seed 0), so this optimiser test holds the paper's.
    assert max(losses) < 3 * losses[0], losses
    assert np.mean(losses[-4:]) < np.mean(losses[:4]), losses
    assert after < 1.3 * before, (before, after)
    # measured: 0.044 -> 1.79 at the second step; held-out 66.5 -> 203.8 mm
    uncorrected, _, after_uncorrected = _paper_steps(tiny_train, tiny_test, "rmsprop-torch")
    assert max(uncorrected) > 10 * uncorrected[0] and after_uncorrected > 1.3 * before, uncorrected


def test_overfits_a_tiny_sequence(tiny_train):
    """Capacity: the association's L1 is left out, since at ``TINY``'s weight (1e-3) it outweighs a few millimetres
    of vertex error on 8 bones (measured: 6.1 mm after stage 2 with it)."""
    model = _model(tiny_train, dataclasses.replace(TINY, lambda_sparse=0.0))
    batch = _batch(tiny_train, 16)
    start = model.validation_metrics(batch, "stage1")["rmse_mm"]
    rmse = {}
    for stage, steps in (("stage1", 60), ("stage2", 100)):
        optimizer = torch.optim.Adam(list(model.stage_parameters(stage)), lr=5e-3)
        for _ in range(steps):
            optimizer.zero_grad()
            model.training_loss(batch, stage)[0].backward()
            optimizer.step()
        rmse[stage] = model.validation_metrics(batch, stage)["rmse_mm"]
    # measured: 75 mm at the start, 32 mm skinned by 8 bones (stage 1), 3.5 mm with the PSD (stage 2)
    assert rmse["stage1"] < 0.6 * start and rmse["stage2"] < 5.0, (start, rmse)


def test_hoyer_association_is_a_weighted_mean_and_its_penalty_is_scale_free(tiny_train):
    """``association="hoyer"``: rows of ``relu(A)`` normalised to sum 1; the penalty is the rows' L1/L2 - 1
    (brute force per row), 0 for one joint; scaling ``A`` changes neither the penalty nor the garment."""
    model = _model(tiny_train, dataclasses.replace(TINY, association="hoyer"))
    with torch.no_grad():
        model.association.copy_(torch.randn(model.association.shape))
        model.association[0] = -1.0  # bone 0 listens to no joint
        model.association[1] = -1.0
        model.association[1, 3] = 0.7  # bone 1 listens to one joint
    A = np.maximum(model.association.detach().numpy(), 0)
    rows = model.association_matrix().detach().numpy()
    assert np.allclose(rows[2:].sum(-1), 1, atol=1e-6) and (rows[0] == 0).all() and rows[1, 3] == pytest.approx(1)
    expected = sum(r.sum() / np.linalg.norm(r) - 1 for r in A if r.any())
    assert model.sparsity_loss().item() == pytest.approx(expected, rel=1e-5)
    batch = _batch(tiny_train, 8)
    before = model(batch["root"], batch["joints"])["verts"]
    with torch.no_grad():
        model.association.mul_(3.0)
    assert model.sparsity_loss().item() == pytest.approx(expected, rel=1e-5)
    assert torch.allclose(model(batch["root"], batch["joints"])["verts"], before, atol=1e-6)


def test_nearby_association_is_a_normalised_gaussian_of_the_rest_distance():
    bones = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 1.4]], np.float32)
    joints = np.array([[0.1, 0.0, 0.5], [0.0, 0.0, 0.9], [0.2, 0.0, 1.4]], np.float32)
    A = nearby_association(bones, joints, radius=0.2)
    d2 = ((bones[:, None] - joints[None]) ** 2).sum(-1)
    expected = np.exp(-d2 / 0.08)
    np.testing.assert_allclose(A, expected / expected.sum(1, keepdims=True), rtol=1e-5)
    # far from every joint (10 m), a row still sums to 1 instead of underflowing to zeros
    assert nearby_association(bones + 10.0, joints, radius=0.05).sum(1) == pytest.approx([1.0, 1.0])


def test_the_shipped_sparsity_term_prunes_the_association(tiny_train):
    """The shipped association (its form, start and weight) through the ReLU: entries of ``A`` cross zero and stop
    feeding their bone, so a bone listens to fewer joints than without the term (same seed, same steps)."""
    shipped = JointNetConfig()
    batch = _batch(tiny_train, 16)
    nonzero = {}
    for weight in (0.0, shipped.lambda_sparse):
        config = dataclasses.replace(TINY, association=shipped.association, lambda_sparse=weight,
                                     association_radius=shipped.association_radius)
        model = _model(tiny_train, config)
        optimizer = torch.optim.Adam(list(model.stage_parameters("stage1")), lr=5e-3)
        for _ in range(60):
            optimizer.zero_grad()
            model.training_loss(batch, "stage1")[0].backward()
            optimizer.step()
        nonzero[weight] = float((model.association_matrix() > 0).float().mean())
    # measured: 46 % of the entries positive without the term, 20 % with it
    assert 0 < nonzero[shipped.lambda_sparse] < 0.6 * nonzero[0.0], nonzero


def test_config_file_holds_the_defaults():
    config = load_config(Config, CONFIG_FILE)
    assert config == Config()
    assert (config.model.gru_hidden, config.model.features, config.model.bone_mlp) == (600, 480, [1024, 2048, 1024])
    assert (config.train.optimizer, config.train.step_gamma, config.train.step_epochs) == ("rmsprop", 0.7, 30)
    assert config.data == MemoryWindowConfig(window=50, stride=50, burn_in=10, carry_state=True)
    with pytest.raises(InputError, match="even"):
        JointNetConfig(features=31)


# ---------------------------------------------------------------------- the paper's structure


@pytest.mark.parametrize("weight, term", [("lambda_norm", "normal"), ("lambda_sparse", "sparsity")])
def test_each_loss_weight_moves_the_total_by_exactly_its_term(tiny_train, weight, term):
    """JointNet Eq. 6: L1 vertex term plus the weighted normal and association-sparsity terms."""
    model = _model(tiny_train)
    batch = _batch(tiny_train, 8)
    with torch.no_grad():
        loss, terms = model.training_loss(batch, "stage2")
        model.config = JointNetConfig(**{**TINY.__dict__, weight: getattr(TINY, weight) + 0.5})
        moved, moved_terms = model.training_loss(batch, "stage2")
    assert moved_terms == terms and terms[term] > 0
    assert float(moved) - float(loss) == pytest.approx(0.5 * terms[term], rel=1e-4)


def test_psd_deforms_the_rest_mesh_before_the_skinning(tiny_train):
    """JointNet Eq. 5 (Sec. 3.3): the joint-specific displacements live in the canonical (rest) space;
    stage 1 has none."""
    model = _model(tiny_train)
    with torch.no_grad():
        model.psd_basis.normal_(0.0, 1e-3)
        batch = _batch(tiny_train, 8)
        out = model(batch["root"], batch["joints"])
        R, T = out["bones"]
        assert out["displacement"].abs().max() > 1e-4
        assert torch.allclose(out["verts"], model.skin(model.rig_rest + out["displacement"], R, T), atol=1e-6)
        plain = model(batch["root"], batch["joints"], psd=False)
        assert plain["displacement"] is None
        assert torch.allclose(plain["verts"], model.skin(model.rig_rest, R, T), atol=1e-6)


def test_a_bone_listens_only_to_its_associated_joints(tiny_train):
    """JointNet Eqs. 2 and 4: bone features are ``relu(A) psi`` plus the bone's Fourier prior. A bone whose row
    of ``A`` holds one joint moves with that joint's neighbourhood and ignores a joint outside it."""
    model = _model(tiny_train)
    G = len(model.selected)
    table = model.neighbours.numpy()
    J = int(model.joints_mean.shape[0]) + 1
    listened = 0
    reads = {int(r) - 1 for r in table[listened] if 0 < r < J}  # rig joints in its neighbourhood (joints index j-1)
    ignored = next(j for j in model.selected if j - 1 not in reads)  # a joint outside that neighbourhood
    with torch.no_grad():
        model.association.fill_(-1.0)
        model.association[0, listened] = 1.0  # bone 0: one joint
        model.association[1] = 1.0 / G  # bone 1: every joint
        batch = _batch(tiny_train, 8)
        base = model(batch["root"], batch["joints"])["bones"][0]

        def bone_change(joint: int) -> torch.Tensor:
            joints = batch["joints"].clone()
            joints[:, 4, joint - 1] += 0.3
            return (model(batch["root"], joints)["bones"][0] - base).abs().flatten(3).amax(-1)[0, 4]

        own, other = bone_change(model.selected[listened]), bone_change(ignored)
    assert own[0] > 1e-6 and own[1] > 1e-6
    assert other[0] == 0 and other[1] > 1e-6


def test_fourier_prior_of_the_bone_rest_positions(tiny_train):
    """JointNet Eq. 3: ``[alpha cos(2 pi c . p), alpha sin(2 pi c . p)]`` of each bone's rest position ``p``,
    added to the bone features: a bone that listens to no joint still gets its own transform."""
    model = _model(tiny_train)
    p, c, a = model.bone_rest.double(), model.fourier_freqs.double(), model.fourier_alpha.detach().double()
    phase = 2 * math.pi * p @ c.T
    expected = torch.cat([a * torch.cos(phase), a * torch.sin(phase)], -1)
    assert torch.allclose(model.fourier_features().detach().double(), expected, atol=1e-5)
    with torch.no_grad():
        model.association.fill_(-1.0)  # no joint at all: the bones differ only through their prior
        batch = _batch(tiny_train, 8)
        R, T = model(batch["root"], batch["joints"], psd=False)["bones"]
        offsets = (R @ model.bone_rest[:, :, None])[..., 0] + T - model.bone_rest
        assert (offsets[0, 0, 0] - offsets[0, 0, 1]).abs().max() > 1e-5
        model.fourier_alpha.zero_()
        R, T = model(batch["root"], batch["joints"], psd=False)["bones"]
        standardised = (matrix_to_euler(R, "xyz") - model.euler_mean) / model.euler_std
        assert torch.allclose(standardised[0, 0, 0], standardised[0, 0, 1], atol=1e-4)  # the same MLP input


def test_grouped_gru_takes_a_strided_hidden_state():
    """A hidden state that is a transposed view (as a stream passes it back in) gives the same output as a
    contiguous copy; CUDA's GRU kernel refuses a strided one, so the grouped GRU makes it contiguous."""
    torch.manual_seed(0)
    gru = JointGRU(3, 5, 7)
    x, h0 = torch.randn(2, 4, 3, 5), torch.randn(3, 2, 7).transpose(0, 1)
    assert not h0.is_contiguous()
    with torch.no_grad():
        assert torch.equal(gru.joint_by_joint(x, h0)[0], gru.joint_by_joint(x, h0.contiguous())[0])


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
@pytest.mark.parametrize("frames", [1, 6])
def test_grouped_gru_on_cuda_equals_cpu(frames):
    """Streaming (one frame) and batched calls on CUDA give the CPU's numbers (cuDNN's TF32 GRU, 2e-5 off on an
    H100, is not used)."""
    torch.manual_seed(0)
    gru = JointGRU(3, 5, 7)
    x, h0 = torch.randn(2, frames, 3, 5), torch.randn(3, 2, 7).transpose(0, 1)
    with torch.no_grad():
        expected = gru(x, h0)
        got = gru.cuda()(x.cuda(), h0.cuda())
    assert all((g.cpu() - e).abs().max() < 5e-6 for g, e in zip(got, expected))


def test_psd_in_the_smoothest_modes(tiny_train):
    """psd_modes k: D_j = Phi C_j, Phi the rig rest mesh's k smoothest modes; the displacement is Phi times the
    blended coefficients (JointNet Eq. 5 in the modes' basis), and the model round-trips through its state."""
    from loosefit.geometry.laplacian import cotangent_laplacian, mass_matrix, smoothest_modes

    model = _model(tiny_train, dataclasses.replace(TINY, psd_modes=6))
    rest, faces = model.rig_rest.double().numpy(), model.faces.numpy()
    phi, buffer = smoothest_modes(rest, faces, 6), model.psd_modes.double().numpy()
    # the same modes up to a basis of equal-frequency pairs: mass-orthonormal, the same frequencies
    M, L = mass_matrix(rest, faces), -cotangent_laplacian(rest, faces)
    np.testing.assert_allclose(buffer.T @ (M @ buffer), np.eye(6), atol=1e-5)
    np.testing.assert_allclose(np.linalg.eigvalsh(buffer.T @ (L @ buffer)), np.einsum("vk,vk->k", phi, L @ phi),
                               rtol=1e-3, atol=1e-6)
    assert model.psd_basis.shape == (len(model.joint_names), TINY.psd_shapes, 6, 3)
    batch = _batch(tiny_train, 8)
    with torch.no_grad():
        model.psd_basis.normal_(0.0, 1e-3)
        seen = []
        hook = model.psd_mlp.register_forward_hook(lambda module, args, output: seen.append(output))
        out = model(batch["root"], batch["joints"])
        hook.remove()
        # brute force: every joint, every shape, every mode
        expected = torch.einsum("ntjx,jxkc,vk->ntvc", seen[0].double(), model.psd_basis.double(),
                                model.psd_modes.double())
        assert expected.abs().max() > 1e-5
        torch.testing.assert_close(out["displacement"].double(), expected, atol=1e-7, rtol=1e-4)  # float32 sums
        again = JointNet(model.sizes(), model.config)
        again.load_state_dict(model.state_dict())
        torch.testing.assert_close(again(batch["root"], batch["joints"])["verts"], out["verts"])
    with pytest.raises(InputError, match="psd_modes must be >= 0"):
        dataclasses.replace(TINY, psd_modes=-1)


def test_projecting_a_free_psd_keeps_its_smooth_part(tiny_train):
    """project_psd: C_j = Phi^T M D_j. A free basis already in the modes' span comes back exactly (same
    garment); a random one becomes Phi Phi^T M D (numpy), everything else unchanged."""
    from loosefit.geometry.laplacian import mass_matrix, smoothest_modes
    from loosefit.models.jointnet_psd import project_psd

    model = _model(tiny_train)
    rest, faces = model.rig_rest.double().numpy(), model.faces.numpy()
    phi, m = smoothest_modes(rest, faces, 5), mass_matrix(rest, faces).diagonal()
    G, X = model.psd_basis.shape[:2]
    batch = _batch(tiny_train, 8)
    with torch.no_grad():
        coeff = torch.randn(G, X, 5, 3, dtype=torch.float64) * 1e-3
        model.psd_basis.copy_(torch.einsum("vk,gxkc->gxvc", torch.from_numpy(phi), coeff).float())
        projected = project_psd(model, 5)
        torch.testing.assert_close(projected.psd_basis.double(), coeff, atol=1e-7, rtol=1e-4)
        torch.testing.assert_close(projected(batch["root"], batch["joints"])["verts"],
                                   model(batch["root"], batch["joints"])["verts"], atol=1e-6, rtol=0)
        model.psd_basis.normal_(0.0, 1e-3)
        projected = project_psd(model, 5)
        dense = model.psd_basis.double().numpy()
        smooth = np.einsum("vk,wk,w,gxwc->gxvc", phi, phi, m, dense)
        got = np.einsum("vk,gxkc->gxvc", projected.psd_modes.double().numpy(), projected.psd_basis.double().numpy())
        np.testing.assert_allclose(got, smooth, atol=1e-9)
        assert all(torch.equal(v, model.state_dict()[k]) for k, v in projected.state_dict().items()
                   if k not in ("psd_basis", "psd_modes"))
    with pytest.raises(InputError, match="already in 5 modes"):
        project_psd(projected, 5)


def test_pose_noise_offsets_each_joint_rotation_per_window_in_training_only(tiny_train):
    model = _model(tiny_train, dataclasses.replace(TINY, pose_noise=0.3))
    batch = _batch(tiny_train, frames=16)
    clean = model.joint_inputs(batch["root"], batch["joints"])
    torch.manual_seed(0)
    offset = model.joint_inputs(batch["root"], batch["joints"], 0.3) - clean  # (N, T, J_s, R + 6 (2 + C))
    R = model.root_features
    assert offset[..., :R].abs().max() == 0  # the root's features are not a pose
    assert (offset - offset[:, :1]).abs().max() < 1e-6  # the same in every frame of the window
    own = offset[:, 0, :, R:R + 6]  # each selected joint's own rotation
    assert own.std().item() == pytest.approx(0.3, rel=0.2)
    # a joint's offset is the one its neighbours read for it: its parent row in a child's input is the same draw
    torch.manual_seed(0)
    _, joints = model.normalise(batch["root"], batch["joints"], 0.3)
    _, plain = model.normalise(batch["root"], batch["joints"])
    drawn = (joints - plain)[:, 0]  # (N, J-1, 6)
    assert torch.allclose(own, drawn[:, [j - 1 for j in model.selected]], atol=1e-6)
    losses = []
    for seed in (0, 0, 1):
        torch.manual_seed(seed)
        losses.append(model.training_loss(batch, "stage1")[0].item())
    assert losses[0] == losses[1] != losses[2]
    with torch.no_grad():  # validation and prediction read the pose as it is
        assert model.validation_metrics(batch, "stage1") == model.validation_metrics(batch, "stage1")
