"""VirtualBones: overfitting a simulated sequence, gradients per stage, sizes from the data, streaming."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch

from loosefit.config import load_config
from loosefit.errors import InputError
from loosefit.models.body_lbs import training_body
from loosefit.models.dataset import GarmentSequences, WindowDataset
from loosefit.models.motion_features import HISTORY_FRAMES, HISTORY_ROOT_FEATURES, ROOT_FEATURES, MotionHistory
from loosefit.models.virtualbones import Config, VirtualBones, VirtualBonesConfig
from loosefit.rig.prepared import load_rig
from loosefit.train import StageConfig, TrainConfig, seed_everything, train

#: The exact pose in (the training's pose noise has its own test), so that a tiny network can be held to a fit.
TINY = VirtualBonesConfig(lf_hidden=32, hf_hidden=32, global_channels=8, edge_channels=(16, 16), pose_noise=0.0)


def _model(data, seed=0, config=TINY):
    seed_everything(seed)
    return VirtualBones.from_data(data, config)


def _batch(dataset) -> dict:
    return torch.utils.data.default_collate([dataset[i] for i in range(len(dataset))])


def _one_sequence(data: GarmentSequences, index: int) -> GarmentSequences:
    one = copy.copy(data)
    one.sequences = [data.sequences[index]]
    return one


def _rmse_mm(a: torch.Tensor, b: torch.Tensor) -> float:
    return float(((a - b) ** 2).sum(-1).mean().sqrt() * 1e3)


def test_overfits_one_sequence_low_then_high(tiny_train, tmp_path):
    one = _one_sequence(tiny_train, 0)
    frames = one.sequences[0].num_frames
    windows = WindowDataset(one, window=frames, stride=frames, burn_in=0)
    batch = _batch(windows)
    model = _model(one)

    # the best the rig can do on this sequence: the SSDR bone transforms, skinned
    ssdr = load_rig(tiny_train.store, tiny_train.garment_name).skin(batch["bone_rot"], batch["bone_trans"])
    ssdr_mm = _rmse_mm(ssdr, batch["lf"])
    with torch.no_grad():
        lf0 = _rmse_mm(model(batch["root"], batch["joints"])["lf"], batch["lf"])

    common = dict(batch_size=1, schedule="none", progress=False, tensorboard=False,
                  checkpoint_every=1000, validate_every=1000)
    low = TrainConfig(lr=1e-2, stages={"low": StageConfig(epochs=100), "high": StageConfig(epochs=0)}, **common)
    result = train(model, windows, windows, low, tmp_path / "low")
    lf_mm = result.val_metrics["lf_target_rmse_mm"]
    after_low = {k: v.clone() for k, v in model.state_dict().items()}
    full0 = result.val_metrics["rmse_mm"]  # the low-frequency mesh against the simulated one
    assert result.val_metrics["lf_rmse_mm"] == full0

    high = TrainConfig(lr=2e-2, stages={"low": StageConfig(epochs=0), "high": StageConfig(epochs=60)}, **common)
    result = train(model, windows, windows, high, tmp_path / "high")
    full_mm = result.val_metrics["rmse_mm"]

    print(f"SSDR {ssdr_mm:.2f} mm; LF {lf0:.1f} -> {lf_mm:.2f} mm; full {full0:.1f} -> {full_mm:.2f} mm")
    assert lf0 > 10 * ssdr_mm
    assert lf_mm < ssdr_mm + 2.0
    assert full_mm < full0 / 4
    # stage "high" leaves the low-frequency module as it was, and trains the high-frequency one
    state = model.state_dict()
    low_names = [n for n in state if n.startswith("low.")]
    assert low_names and all(torch.equal(state[n], after_low[n]) for n in low_names)
    assert not torch.equal(state["head.0.weight"], after_low["head.0.weight"])
    assert result.val_metrics["lf_target_rmse_mm"] == pytest.approx(lf_mm, abs=1e-4)
    assert result.val_metrics["lf_rmse_mm"] == pytest.approx(full0, abs=1e-4)  # the offsets are what improved


@pytest.mark.parametrize("stage, rank", [("low", 0), ("high", 0), ("high", 3)])
def test_gradients_reach_every_parameter_of_the_stage(tiny_train, stage, rank):
    model = _model(tiny_train, config=VirtualBonesConfig(**{**TINY.__dict__, "global_rank": rank}))
    batch = _batch(WindowDataset(tiny_train, window=20, stride=20, burn_in=5))
    loss, terms = model.training_loss(batch, stage)
    loss.backward()
    active = {id(p) for p in model.stage_parameters(stage)}
    assert active
    for name, p in model.named_parameters():
        if id(p) in active:
            assert p.grad is not None and p.grad.abs().sum() > 0, name
        else:
            assert p.grad is None, name
    expected = {"low": {"vertex", "laplacian"}, "high": {"vertex", "collision"}}[stage]
    assert set(terms) == expected and all(np.isfinite(v) and v >= 0 for v in terms.values())


@pytest.mark.parametrize("target", ["residual", "simulation"])
def test_high_frequency_loss_on_sampled_frames_is_the_full_loss_restricted_to_them(tiny_train, target):
    model = _model(tiny_train, config=VirtualBonesConfig(**{**TINY.__dict__, "hf_loss_frames": 4, "hf_target": target}))
    batch = _batch(WindowDataset(tiny_train, window=20, stride=20, burn_in=5))
    torch.manual_seed(3)
    frames = model.loss_frames(model.mask(batch), 4)
    assert len(frames) == 4 and len(set(frames.tolist())) == 4 and frames.min() >= 5
    torch.manual_seed(3)
    _, terms = model.training_loss(batch, "high")
    with torch.no_grad():
        out = model(batch["root"], batch["joints"])
    # the reference: every frame predicted, then the vertex and collision terms on the drawn ones only
    pred = out["verts"][:, frames]
    if target == "residual":  # the offsets against the simulation's high-frequency part
        vertex = ((pred - out["lf"][:, frames]) - (batch["verts"] - batch["lf"])[:, frames]).norm(dim=-1).mean()
    else:
        vertex = (pred - batch["verts"][:, frames]).norm(dim=-1).mean()
    idx = batch["body_nearest"][:, frames, :, None].expand(-1, -1, -1, 3)
    depth = -((pred - torch.gather(batch["body"][:, frames], 2, idx))
              * torch.gather(batch["body_normals"][:, frames], 2, idx)).sum(-1)
    assert terms["vertex"] == pytest.approx(float(vertex), rel=1e-5)
    assert terms["collision"] == pytest.approx(float(torch.relu(depth).mean()), rel=1e-4, abs=1e-9)


def test_bone_supervision_term_is_zero_at_the_ssdr_bones(tiny_train):
    model = _model(tiny_train, config=VirtualBonesConfig(**{**TINY.__dict__, "bone_weight": 1.0}))
    batch = _batch(WindowDataset(tiny_train, window=20, stride=20, burn_in=5))
    raw = model.encode_bones(batch["bone_rot"], batch["bone_trans"])
    rot, trans = model.decode_bones(raw)
    assert torch.allclose(rot, batch["bone_rot"], atol=1e-5) and torch.allclose(trans, batch["bone_trans"], atol=1e-5)
    loss, terms = model.training_loss(batch, "low")
    assert terms["bone"] > 0
    loss.backward()
    assert model.low.out.weight.grad.abs().sum() > 0


def test_sizes_follow_the_data(tiny_train, second_store):
    second = GarmentSequences(second_store, "dress+average", "train", body=False)
    a, b = _model(tiny_train), _model(second)
    for model, data in ((a, tiny_train), (b, second)):
        rig = load_rig(data.store, data.garment_name)
        sizes = model.sizes()
        assert sizes["num_verts"] == len(data.garment.verts) == rig.num_verts
        assert sizes["num_bones"] == rig.num_bones
        seq = data.sequences[0]
        out = model(torch.from_numpy(seq.root)[None, :7], torch.from_numpy(seq.joints)[None, :7])
        assert out["verts"].shape == out["lf"].shape == (1, 7, sizes["num_verts"], 3)
        assert out["bones"][0].shape == (1, 7, rig.num_bones, 3, 3) and out["bones"][1].shape == (1, 7, rig.num_bones, 3)
    assert a.sizes()["num_verts"] != b.sizes()["num_verts"] and a.sizes()["num_bones"] != b.sizes()["num_bones"]
    # a checkpoint rebuilds the model from its sizes alone
    rebuilt = VirtualBones(b.sizes(), TINY)
    rebuilt.load_state_dict(b.state_dict())
    seq = second.sequences[0]
    x = torch.from_numpy(seq.root)[None, :5], torch.from_numpy(seq.joints)[None, :5]
    assert torch.equal(rebuilt(*x)["verts"], b(*x)["verts"])


def test_runs_from_before_the_history_read_eleven_root_features(tiny_train):
    """A run recorded before the history features (no ``root_features`` in its sizes) reads the first 11 of the
    features it is given, so it animates as it did; a model given fewer than it reads is refused."""
    model = _model(tiny_train)
    assert model.sizes()["root_features"] == HISTORY_ROOT_FEATURES
    old_sizes = {k: v for k, v in model.sizes().items() if k != "root_features" and not k.startswith("history_")}
    old = _perturbed(VirtualBones(old_sizes, TINY))
    seq = tiny_train.sequences[0]
    root, joints = torch.from_numpy(seq.root)[None, :6], torch.from_numpy(seq.joints)[None, :6]
    assert root.shape[-1] == HISTORY_ROOT_FEATURES
    with torch.no_grad():
        assert torch.equal(old(root, joints)["verts"], old(root[..., :ROOT_FEATURES], joints)["verts"])
        with pytest.raises(InputError, match="reads 20 root features, got 11"):
            model(root[..., :ROOT_FEATURES], joints)
    plain = GarmentSequences(tiny_train.store, tiny_train.garment_name, "train", body=False, history=None)
    assert _model(plain).sizes()["root_features"] == ROOT_FEATURES and _model(plain).history is None


def test_the_motion_history_travels_with_the_model(tiny_train):
    """A model records its data's motion history, and its animator computes its features with it; a run recorded
    before the history was a setting (20 root features, neither ``history_frames`` nor ``history_vertical``)
    reads the default history; sizes whose count and history disagree are refused."""
    from loosefit.animate import Animator

    history = MotionHistory((4.0, 60.0), vertical=True)
    data = GarmentSequences(tiny_train.store, tiny_train.garment_name, "train", body=False, history=history)
    model = _model(data)
    assert model.sizes()["history_frames"] == [4.0, 60.0] and model.sizes()["history_vertical"] is True
    assert model.history == history and Animator.from_model(model).history == history
    assert model.root_features == ROOT_FEATURES + 8 == data.sequences[0].root.shape[1]
    old = {k: v for k, v in _model(tiny_train).sizes().items() if not k.startswith("history_")}
    assert VirtualBones(old, TINY).history == MotionHistory(HISTORY_FRAMES)
    with pytest.raises(InputError, match="do not match"):
        VirtualBones({**old, "history_vertical": True}, TINY)


def test_streaming_equals_batched(tiny_test, tiny_train):
    model = _model(tiny_train)
    with torch.no_grad():  # move the networks off their near-rest start
        for p in model.parameters():
            p.add_(0.05 * torch.randn_like(p))
    seq = tiny_test.sequences[0]
    root, joints = torch.from_numpy(seq.root)[None], torch.from_numpy(seq.joints)[None]
    with torch.no_grad():
        whole = model(root, joints)
        state, frames = None, []
        for t in range(seq.num_frames):
            out = model(root[:, t:t + 1], joints[:, t:t + 1], state)
            state = out["state"]
            frames.append(out["verts"])
    streamed = torch.cat(frames, 1)
    assert (streamed - whole["verts"]).abs().max() < 1e-5
    assert (whole["verts"][0, 1:] - whole["verts"][0, :-1]).norm(dim=-1).max() > 1e-3  # it does move
    assert (whole["verts"] - whole["lf"]).norm(dim=-1).max() > 1e-4  # with a high-frequency part


def test_batched_animation_in_chunks_equals_one_pass(tiny_test, tiny_train):
    from loosefit.animate import Animator

    model = _model(tiny_train)
    with torch.no_grad():
        for p in model.parameters():
            p.add_(0.05 * torch.randn_like(p))
    motion = tiny_test.sequences[0].motion
    animator = Animator.from_model(model)
    animator.chunk_frames = 7  # carries both recurrent states across chunk boundaries
    chunked = [animator.animate_batch([motion, motion.slice(0, 12)], output=o) for o in ("verts", "lf")]
    animator.chunk_frames = motion.num_frames
    whole = [animator.animate_batch([motion, motion.slice(0, 12)], output=o) for o in ("verts", "lf")]
    for a, b in zip(chunked, whole):
        assert np.abs(a[0] - b[0]).max() < 1e-5 and np.abs(a[1] - b[1]).max() < 1e-5
    assert np.abs(chunked[0][0] - chunked[1][0]).max() > 1e-4  # two different outputs


def test_yaml_config_mirrors_the_defaults():
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "configs" / "models" / "virtualbones.yaml"
    assert load_config(Config, path) == Config()
    assert Config().train.stage("low").epochs == Config().train.stage("high").epochs == 50


# ---------------------------------------------------------------------- the paper's structure


def _perturbed(model):
    """The model with its networks moved off their near-rest start (outputs depend on every layer)."""
    torch.manual_seed(1)
    with torch.no_grad():
        for p in model.parameters():
            p.add_(0.05 * torch.randn_like(p))
    return model


def _with(model, **change):
    """The same weights under another config (loss weights are read at each call)."""
    model.config = VirtualBonesConfig(**{**model.config.__dict__, **change})
    return model


@pytest.mark.parametrize("stage, weight, term", [("low", "laplacian_weight", "laplacian"),
                                                 ("low", "bone_weight", "bone"),
                                                 ("high", "collision_weight", "collision")])
def test_each_loss_weight_moves_the_total_by_exactly_its_term(tiny_train, stage, weight, term):
    """VirtualBones Eq. 2 and Sec. 4.3: the total is the vertex term plus each weighted term."""
    model = _model(tiny_train, config=VirtualBonesConfig(**{**TINY.__dict__, "bone_weight": 1.0,
                                                            "collision_margin": 0.05}))
    batch = _batch(WindowDataset(tiny_train, window=20, stride=20, burn_in=5))
    with torch.no_grad():
        loss, terms = model.training_loss(batch, stage)
        assert terms[term] > 0
        weighted = [getattr(model.config, f"{k}_weight") * terms[k] for k in terms if k != "vertex"]
        expected = terms["vertex"] + sum(weighted)
        assert float(loss) == pytest.approx(expected, rel=1e-6)
        moved, moved_terms = _with(model, **{weight: getattr(model.config, weight) + 2.5}).training_loss(batch, stage)
    assert moved_terms == terms
    assert float(moved) - float(loss) == pytest.approx(2.5 * terms[term], rel=1e-4)


def test_high_frequency_module_reads_the_predicted_low_frequency_mesh(tiny_train):
    """VirtualBones Sec. 4.3: the EdgeConv layers run on the low-frequency mesh the first module predicts
    (not the rest mesh), the GRU on the predicted bone motion, and the output is that mesh plus the offsets."""
    model = _perturbed(_model(tiny_train))
    seq = tiny_train.sequences[0]
    root, joints = torch.from_numpy(seq.root)[None, :10], torch.from_numpy(seq.joints)[None, :10]
    with torch.no_grad():
        out = model(root, joints)
        raw, rot, trans, lf, _ = model.low_frequency(model._inputs(root, joints))
        assert torch.equal(lf, out["lf"])
        assert torch.equal(lf, model.skin(model.rest_verts, rot, trans))
        offsets, _ = model.high_frequency(raw, lf)
        assert torch.allclose(out["verts"], lf + offsets, atol=1e-6)
        # the offsets follow the mesh they are given, frame by frame ...
        bent = lf.clone()
        bent[:, 4] += 0.02 * torch.randn_like(bent[:, 4])
        moved = (model.high_frequency(raw, bent)[0] - offsets).norm(dim=-1).amax(-1)[0]
        assert moved[4] > 1e-4 and moved[:4].max() == 0 and moved[5:].max() == 0
        # ... and the bone motion (through the GRU: this frame and the later ones, never the earlier)
        shaken = raw.clone()
        shaken[:, 6] += 0.1
        moved = (model.high_frequency(shaken, lf)[0] - offsets).norm(dim=-1).amax(-1)[0]
        assert moved[:6].max() == 0 and moved[6:].min() > 1e-5
        # the rest mesh reaches the offsets only through the predicted mesh
        model.rest_verts.add_(0.03)
        assert torch.equal(model.high_frequency(raw, lf)[0], offsets)
        shifted = model(root, joints)
        assert (shifted["lf"] - lf).abs().max() > 1e-3
        assert torch.allclose(shifted["verts"], shifted["lf"] + model.high_frequency(raw, shifted["lf"])[0], atol=1e-6)


def test_every_motion_feature_moves_the_bones_and_only_later_frames(tiny_train):
    """VirtualBones Sec. 4.2: the low-frequency GRU reads the root height, the root displacement and
    heading change, the root tilt and every joint rotation; a recurrent network is causal."""
    model = _perturbed(_model(tiny_train))
    seq = tiny_train.sequences[0]
    root, joints = torch.from_numpy(seq.root)[None, :8], torch.from_numpy(seq.joints)[None, :8]
    groups = {"height": (slice(0, 1), None), "displacement": (slice(1, 3), None), "heading": (slice(3, 5), None),
              "tilt": (slice(5, 11), None), "history": (slice(11, 20), None), "first joint": (None, 0),
              "last joint": (None, joints.shape[2] - 1)}
    with torch.no_grad():
        base = model(root, joints)
        for name, (cols, joint) in groups.items():
            r, j = root.clone(), joints.clone()
            if cols is not None:
                r[:, 5, cols] += 0.2 * root[0, :, cols].std(0).clamp_min(0.05)
            else:
                j[:, 5, joint] += 0.2
            out = model(r, j)
            bones = (out["bones"][0] - base["bones"][0]).abs().flatten(2).amax(-1)[0]
            assert bones[:5].max() == 0 and bones[5] > 1e-6, name
            assert torch.equal(out["verts"][:, :5], base["verts"][:, :5]), name


# ---------------------------------------------------------------------- the garment's own state fed back (ours)

FED = VirtualBonesConfig(**{**TINY.__dict__, "feedback_frames": 2, "feedback_noise": 0.3})


def test_fed_back_outputs_are_the_two_previous_frames_and_stream_like_a_whole_pass(tiny_train):
    """Holden et al. 2019's departure: frame t reads the low-frequency module's outputs of t-1 and t-2 (zeros
    before the first frame); the carried state is exactly those outputs, so streaming equals one pass."""
    model = _perturbed(_model(tiny_train, config=FED))
    seq = tiny_train.sequences[0]
    root, joints = torch.from_numpy(seq.root)[None, :12], torch.from_numpy(seq.joints)[None, :12]
    with torch.no_grad():
        x = model._inputs(root, joints)
        raw, _, _, _, (h, fed) = model.low_frequency(x)
        assert torch.equal(fed, torch.cat([raw[:, -1].flatten(1), raw[:, -2].flatten(1)], -1))
        whole = model(root, joints)
        state, frames = None, []
        for t in range(12):
            out = model(root[:, t:t + 1], joints[:, t:t + 1], state)
            state, frames = out["state"], frames + [out["verts"]]
        assert (torch.cat(frames, 1) - whole["verts"]).abs().max() < 1e-5
        # the weights reading the fed-back outputs act from frame 1 on, never on frame 0 (which sees zeros)
        fed_columns = slice(x.shape[-1], None)
        model.low.gru.weight_ih_l0[:, fed_columns] = 0
        cut = model(root, joints)
    assert torch.equal(cut["lf"][:, 0], whole["lf"][:, 0])
    assert (cut["lf"][:, 1:] - whole["lf"][:, 1:]).abs().amax((0, 2, 3)).min() > 1e-6


def test_noise_on_the_fed_back_outputs_is_drawn_in_training_only(tiny_train):
    model = _perturbed(_model(tiny_train, config=FED))
    batch = _batch(WindowDataset(tiny_train, window=16, stride=16, burn_in=4))
    losses = []
    for seed in (0, 0, 1):
        torch.manual_seed(seed)
        losses.append(model.training_loss(batch, "low")[0])
    assert losses[0].item() == losses[1].item() != losses[2].item()  # the noise is drawn, from torch's generator
    losses[2].backward()
    fed_grad = model.low.gru.weight_ih_l0.grad[:, model.low.gru.input_size - 2 * 9 * model.bone_rest.shape[0]:]
    assert fed_grad.abs().sum() > 0  # the rollout carries gradients into the fed-back weights
    with torch.no_grad():  # prediction and validation feed back without noise
        a = model(batch["root"], batch["joints"])["verts"]
        torch.manual_seed(5)
        b = model(batch["root"], batch["joints"])["verts"]
        assert torch.equal(a, b)
        quiet = []
        for seed in (0, 1):
            torch.manual_seed(seed)
            quiet.append(_with(model, feedback_noise=0.0).training_loss(batch, "low")[0].item())
    assert quiet[0] == quiet[1] != losses[0].item()


def test_the_rollout_is_torchs_gru_when_nothing_is_fed_back(tiny_train):
    """The frame-by-frame low-frequency GRU of the fed-back model follows torch's GRU equations: with the weights
    that read the fed-back outputs at zero it equals ``nn.GRU`` over the motion features alone."""
    model = _perturbed(_model(tiny_train, config=FED))
    seq = tiny_train.sequences[0]
    root, joints = torch.from_numpy(seq.root)[None, :10], torch.from_numpy(seq.joints)[None, :10]
    with torch.no_grad():
        x = model._inputs(root, joints)
        plain = _model(tiny_train)
        plain.low.load_state_dict({**model.low.state_dict(),
                                   "gru.weight_ih_l0": model.low.gru.weight_ih_l0[:, :x.shape[-1]]})
        model.low.gru.weight_ih_l0[:, x.shape[-1]:] = 0
        rolled, _, _, _, (h, _) = model.low_frequency(x)
        fused, _, _, _, h_fused = plain.low_frequency(x)
    assert (rolled - fused).abs().max() < 1e-5 and (h - h_fused).abs().max() < 1e-5
    assert rolled.abs().max() > 1e-3


def test_ignored_joints_move_nothing_and_the_others_still_do(tiny_train):
    model = _perturbed(_model(tiny_train, config=VirtualBonesConfig(**{**TINY.__dict__,
                                                                       "exclude_joints": ("Arm", "Hand")})))
    names = training_body(tiny_train).joint_names[1:]
    ignored = [i for i, n in enumerate(names) if "Arm" in n or "Hand" in n]
    assert model.joint_read[:, 0].tolist() == [0.0 if i in ignored else 1.0 for i in range(len(names))]
    assert ignored and len(ignored) < len(names)
    seq = tiny_train.sequences[0]
    root, joints = torch.from_numpy(seq.root)[None, :8], torch.from_numpy(seq.joints)[None, :8]
    with torch.no_grad():
        base = model(root, joints)["verts"]
        for j, changes in ((ignored[0], False), (names.index("LeftUpLeg"), True)):
            moved = joints.clone()
            moved[:, 2:, j] += 0.5
            diff = (model(root, moved)["verts"] - base).abs().max()
            assert (diff > 1e-5) == changes, names[j]
    with pytest.raises(InputError, match="match no joint"):
        _model(tiny_train, config=VirtualBonesConfig(**{**TINY.__dict__, "exclude_joints": ("Tail",)}))


def test_a_run_from_before_the_joint_names_reads_every_joint(tiny_train):
    """Runs trained before the sizes held the body's joint names read every joint: the default exclusion must not
    change what such a run (a shipped pretrained garment, say) predicts."""
    sizes = VirtualBones.data_sizes(tiny_train)
    assert sizes["joint_names"][0] == "Hips" and len(sizes["joint_names"]) == sizes["num_joints"]
    old = {k: v for k, v in sizes.items() if k != "joint_names"}
    assert VirtualBones(old, TINY).joint_read.min() == 1.0
    assert VirtualBones(sizes, TINY).joint_read.min() == 0.0  # the default leaves the arms, hands and head out
    assert "joint_read" not in VirtualBones(sizes, TINY).state_dict()  # checkpoints stay as they were


def test_the_default_exclusion_on_smpl_leaves_out_its_hands_neck_and_head():
    from loosefit.body.smpl_body import smpl_joint_names
    from loosefit.models.virtualbones import EXCLUDED_JOINTS, joints_read

    names = smpl_joint_names(24)
    read = joints_read(names, EXCLUDED_JOINTS, len(names))[:, 0]
    left_out = sorted(n for n, r in zip(names[1:], read.tolist()) if r == 0)
    assert left_out == ["head", "left_hand", "neck", "right_hand"]


def test_an_excluded_joint_the_garment_reaches_is_read():
    """A sleeve follows its arm: a joint within GARMENT_REACH_M of the rest garment is read although excluded."""
    from loosefit.models.virtualbones import EXCLUDED_JOINTS, joints_read

    names = ["Hips", "LeftUpLeg", "LeftArm", "LeftForeArm", "LeftHand", "Neck"]
    assert joints_read(names, EXCLUDED_JOINTS, 6)[:, 0].tolist() == [1, 0, 0, 0, 0]
    assert joints_read(names, EXCLUDED_JOINTS, 6, ("LeftArm", "LeftForeArm", "Hips"))[:, 0].tolist() == [1, 1, 1, 0, 0]


def test_the_garments_reach_comes_from_the_rest_pose(tiny_train):
    from loosefit.models.virtualbones import GARMENT_REACH_M

    sizes = VirtualBones.data_sizes(tiny_train)
    body = training_body(tiny_train)
    joints, verts = body.rest_joints(), tiny_train.garment.verts
    brute = [n for n, j in zip(body.joint_names, joints)
             if min(float(np.linalg.norm(v - j)) for v in verts) < GARMENT_REACH_M]
    assert sizes["joints_reached"] == brute and "Hips" in brute and "LeftHand" not in brute


def test_pose_noise_is_one_offset_per_window_and_joint_on_the_read_joints_in_training_only(tiny_train):
    config = VirtualBonesConfig(**{**TINY.__dict__, "exclude_joints": ("Arm", "Hand"), "pose_noise": 0.3})
    model = _model(tiny_train, config=config)
    batch = _batch(WindowDataset(tiny_train, window=16, stride=16, burn_in=4))
    clean = model._inputs(batch["root"], batch["joints"])
    torch.manual_seed(0)
    noisy = model._inputs(batch["root"], batch["joints"], 0.3)
    offset = noisy - clean
    R = model.root_features
    assert offset[..., :R].abs().max() == 0  # the root is not a pose
    joints = offset[..., R:].unflatten(-1, (-1, 6))  # (N, T, J-1, 6)
    assert (joints - joints[:, :1]).abs().max() < 1e-6  # the same offset in every frame of a window
    read = model.joint_read[:, 0].bool()
    assert joints[:, :, ~read].abs().max() == 0 and (~read).any()  # an unread joint stays unread
    drawn = joints[:, 0, read]
    assert drawn.std().item() == pytest.approx(0.3, rel=0.15)  # the std asked, in normalised units
    assert (drawn[0] - drawn[1]).abs().min() > 0  # each window its own
    # the low stage's loss draws it (torch's generator), the high stage's does not
    losses = {}
    for stage in ("low", "high"):
        for seed in (0, 0, 1):
            torch.manual_seed(seed)
            losses.setdefault(stage, []).append(model.training_loss(batch, stage)[0].item())
    assert losses["low"][0] == losses["low"][1] != losses["low"][2]
    assert losses["high"][0] == losses["high"][1] == losses["high"][2]
    with pytest.raises(InputError, match="pose_noise"):
        VirtualBonesConfig(**{**TINY.__dict__, "pose_noise": -0.1})
