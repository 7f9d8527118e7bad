"""The garment's pins kept where it is animated: the fade along the mesh, the skinning in every frame against the
simulator's own pins, and what animate, the one-frame graph and old runs do with them."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from loosefit.errors import InputError
from loosefit.models.body_lbs import training_body
from loosefit.models.motion_features import motion_features
from loosefit.models.pins import Pins, pin_blend, pin_sizes
from loosefit.motion.heading import FRAMES, motion_frames, to_world
from loosefit.motion.procedural import generate
from loosefit.sim.attach import garment_weights, skin_garment


def strip(n: int = 30, spacing: float = 0.01):
    """A 2 x n strip of triangles along x, ``spacing`` metres apart: vertices ``(2 n, 3)``, faces."""
    x = np.arange(n) * spacing
    verts = np.concatenate([np.stack([x, np.zeros(n), np.zeros(n)], 1), np.stack([x, np.full(n, spacing), np.zeros(n)], 1)])
    faces = [[i, i + 1, n + i] for i in range(n - 1)] + [[i + 1, n + i + 1, n + i] for i in range(n - 1)]
    return verts, np.asarray(faces)


def test_the_blend_falls_linearly_along_the_mesh_from_the_pins():
    verts, faces = strip()
    pinned = verts[:, 0] == 0  # the strip's end, both rows
    a = pin_blend(verts, faces, pinned, 0.1)
    # along the rows the shortest path is the row itself: x metres from the pinned end
    np.testing.assert_allclose(a, np.clip(1 - verts[:, 0] / 0.1, 0, 1), atol=1e-6)
    np.testing.assert_array_equal(pin_blend(verts, faces, pinned, 0.0), pinned.astype(np.float32))
    np.testing.assert_array_equal(pin_blend(verts, faces, np.zeros(len(verts), bool), 0.1), 0)
    for bad in (-0.1, float("nan")):
        with pytest.raises(InputError, match="pin_radius"):
            pin_blend(verts, faces, pinned, bad)
    with pytest.raises(InputError, match="pinned must be"):
        pin_blend(verts, faces, pinned[:-1], 0.1)


@pytest.mark.parametrize("frame", FRAMES)
def test_skinned_in_the_models_frame_is_the_simulators_pin_target(tiny_train, frame):
    """From the motion features alone, in each frame a model predicts in: put back in the world, the rest garment
    skinned as the simulator skins its pinned vertices (:func:`skin_garment` with :func:`garment_weights`)."""
    body = training_body(tiny_train)
    garment = tiny_train.garment
    pins = Pins(pin_sizes(garment, body, 0.1)["vertices"], body.parents, frame)
    pins.fill(garment.verts, garment.faces, garment.pinned, body, 0.1)
    index = pins.index.numpy()
    a = np.zeros(len(garment.verts), np.float32)
    a[index] = pins.blend.numpy()
    np.testing.assert_array_equal(a, pin_blend(garment.verts, garment.faces, garment.pinned, 0.1))
    motion = generate("mix", 0.5, 3, body)
    f = motion_features(motion)
    root, joints = torch.from_numpy(f["root"]), torch.from_numpy(f["joints"])
    with torch.no_grad():
        skinned = pins.skinned(root, joints).numpy()  # the moved vertices only
    world = to_world(skinned, *motion_frames(motion, frame))
    expected = skin_garment(garment.verts, garment_weights(garment.verts, body), body, motion)
    assert np.abs(world - expected[:, index]).max() < 2e-5
    # the pins take the skinned garment, vertices beyond the radius keep theirs, the others are in between
    canonical = to_canonical_of(expected, motion, frame)
    net = torch.from_numpy(canonical) + torch.randn(canonical.shape) * 0.05
    with torch.no_grad():
        kept = pins(net, root, joints).numpy()
    assert garment.pinned.any() and (a == 0).any() and ((a > 0) & (a < 1)).any() and len(index) < len(a)
    np.testing.assert_allclose(kept[:, garment.pinned], canonical[:, garment.pinned], atol=2e-5)
    np.testing.assert_array_equal(kept[:, a == 0], net.numpy()[:, a == 0])
    np.testing.assert_allclose(kept, net.numpy() + a[:, None] * (canonical - net.numpy()), atol=2e-5)
    with pytest.raises(InputError, match="sized for"):
        Pins(len(index) + 1, body.parents, frame).fill(garment.verts, garment.faces, garment.pinned, body, 0.1)


def to_canonical_of(world: np.ndarray, motion, frame: str) -> np.ndarray:
    from loosefit.motion.heading import to_canonical

    return to_canonical(world, *motion_frames(motion, frame)).astype(np.float32)


@pytest.fixture(scope="module")
def tiny_runs(tiny_store, tmp_path_factory):
    from loosefit.training import train_model

    root = tmp_path_factory.mktemp("pins")
    quiet = ["train.progress=false", "train.tensorboard=false", "data.window=20", "data.stride=10", "data.burn_in=4"]
    train_model("virtualbones", tiny_store, "skirt+average", root / "virtualbones", overrides=[
        "model.lf_hidden=16", "model.hf_hidden=16", "model.global_channels=4", "model.edge_channels=[8]",
        "train.stages.low.epochs=1", "train.stages.high.epochs=1", *quiet])
    train_model("jointnet", tiny_store, "skirt+average", root / "jointnet", overrides=[
        "model.gru_hidden=16", "model.features=16", "model.bone_mlp=[32]", "model.psd_mlp=[16]", "model.psd_shapes=4",
        "train.stages.stage1.epochs=1", "train.stages.stage2.epochs=1", *quiet])
    train_model("virtualbones", tiny_store, "skirt+average", root / "no-pins", overrides=[
        "model.pin_radius=null", "model.lf_hidden=16", "model.hf_hidden=16", "model.global_channels=4",
        "model.edge_channels=[8]", "train.stages.low.epochs=1", "train.stages.high.epochs=1", "train.progress=false",
        "train.tensorboard=false", "data.window=20", "data.stride=10", "data.burn_in=4"])
    return root


def test_a_run_trained_without_pins_is_given_them_with_its_own_weights(tiny_runs, tiny_store):
    """:func:`with_pins` (what ships a run trained without pins with them): the same network, the pins added."""
    from loosefit.animate import Animator
    from loosefit.data import DatasetStore
    from loosefit.models.pins import with_pins

    model = Animator(tiny_runs / "no-pins").model
    assert model.pins is None and "pins" not in model.sizes()
    store = DatasetStore.open(tiny_store)
    seq = store.sequence(store.sequence_names(split="test")[0])
    motion = store.motion(seq.motion).slice(0, 10)
    garment, body = store.garment(seq.garment), training_body_of(store, seq)
    pinned = with_pins(model, garment, body, 0.05)
    assert pinned.sizes()["pins"]["radius"] == 0.05 == pinned.config.pin_radius and not pinned.training
    f = motion_features(motion, model.history)
    root, joints = torch.from_numpy(f["root"])[None], torch.from_numpy(f["joints"])[None]
    with torch.no_grad():
        raw = model(root, joints)["verts"]
        kept = pinned.pinned(pinned(root, joints)["verts"], root, joints)
    a = np.zeros(len(garment.verts))
    a[pinned.pins.index.numpy()] = pinned.pins.blend.numpy()
    np.testing.assert_array_equal(kept[0, :, a == 0].numpy(), raw[0, :, a == 0].numpy())
    expected = skin_garment(garment.verts, garment_weights(garment.verts, body), body, motion)
    world = to_world(kept[0].numpy(), *motion_frames(motion, model.frame))
    np.testing.assert_allclose(world[:, garment.pinned], expected[:, garment.pinned], atol=2e-5)
    with pytest.raises(InputError, match="vertices"):
        with_pins(model, dataclasses.replace(garment, verts=garment.verts[:-1], faces=garment.faces[:1],
                                             pinned=garment.pinned[:-1]), body, 0.05)


@pytest.mark.parametrize("method", ["virtualbones", "jointnet"])
def test_a_trained_run_animates_its_pins_where_the_simulator_holds_them(tiny_runs, tiny_store, method):
    """A run trained with the default pins: ``animate`` puts the pinned vertices on the body's skinning, the stream
    agrees; without pins (an old run's sizes) the model is the method's alone."""
    from loosefit.animate import Animator
    from loosefit.data import DatasetStore

    animator = Animator(tiny_runs / method)
    model = animator.model
    assert model.pins is not None and model.sizes()["pins"]["radius"] == model.config.pin_radius
    store = DatasetStore.open(tiny_store)
    seq = store.sequence(store.sequence_names(split="test")[0])
    motion = store.motion(seq.motion).slice(0, 12)
    garment = store.garment(seq.garment)
    body = training_body_of(store, seq)
    expected = skin_garment(garment.verts, garment_weights(garment.verts, body), body, motion)
    world = animator.animate(motion)
    np.testing.assert_allclose(world[:, garment.pinned], expected[:, garment.pinned], atol=2e-5)
    stream = animator.stream()
    streamed = np.stack([stream.step(motion.rotations[t], motion.translation[t]) for t in range(motion.num_frames)])
    np.testing.assert_allclose(streamed, world, atol=2e-5)
    raw = to_world(_forward(model, motion), *motion_frames(motion, model.frame))
    moved = np.linalg.norm(world - raw, axis=-1).max(0)
    still = np.ones(len(garment.verts), bool)
    still[model.pins.index.numpy()] = False
    assert (moved[still] < 1e-6).all() and moved[garment.pinned].max() > 1e-4
    sizes = {k: v for k, v in model.sizes().items() if k != "pins"}
    assert type(model)(sizes, model.config).pins is None
    with pytest.raises(InputError, match="pins need"):
        type(model)({**sizes, "pins": {"radius": 0.1}}, model.config)


def training_body_of(store, seq):
    from loosefit.body import AnnyBody, AnnyShape

    return AnnyBody(AnnyShape.from_array(store.body(seq.body)), rig=store.motion(seq.motion).rig)


def _forward(model, motion) -> np.ndarray:
    f = motion_features(motion, model.history)
    with torch.no_grad():
        return model(torch.from_numpy(f["root"])[None], torch.from_numpy(f["joints"])[None])["verts"][0].numpy()
