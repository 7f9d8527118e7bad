"""Shipped garments: a run reduced to what animation reads animates exactly as the run; names resolve or are refused
with the list of what is shipped; every shipped garment loads, stays under the size limit and animates a motion."""

import json

import numpy as np
import pytest
import torch

from loosefit import pretrained
from loosefit.animate import Animator
from loosefit.data.store import DatasetStore
from loosefit.errors import InputError
from loosefit.training import train_model


@pytest.fixture(scope="module")
def lbs_run(tiny_store, tmp_path_factory):
    run = tmp_path_factory.mktemp("pretrained") / "lbs"
    train_model("body-lbs", tiny_store, "skirt+average", run)
    return run


def test_a_shipped_run_animates_as_the_run_itself(lbs_run, tiny_store, tmp_path, monkeypatch):
    monkeypatch.setattr(pretrained, "ROOT", tmp_path)
    out = pretrained.ship(lbs_run, tmp_path / "skirt-body-lbs", {"trained_on": "tiny"})
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()) == sorted(pretrained.FILES)
    state = torch.load(out / "checkpoints" / "best.pt", weights_only=True)
    assert state["optimizer"] is None and state["scheduler"] is None
    info = json.loads((out / "pretrained.json").read_text())
    assert info["trained_on"] == "tiny" and info["checkpoint_bytes"] == (out / "checkpoints" / "best.pt").stat().st_size
    assert pretrained.available() == ["skirt/body-lbs"]
    assert pretrained.resolve_run("pretrained:skirt/body-lbs") == out
    store = DatasetStore.open(tiny_store)
    motion = store.motion(store.sequence(store.sequence_names(split="test")[0]).motion)
    original = torch.load(lbs_run / "checkpoints" / "last.pt", weights_only=True)["model"]
    for key, value in original.items():  # large float tensors halved, the rest as trained
        big = value.is_floating_point() and value.numel() > pretrained.HALF_ABOVE
        assert state["model"][key].dtype == (torch.float16 if big else value.dtype)
        torch.testing.assert_close(state["model"][key].to(value.dtype), value, rtol=1e-3, atol=1e-4)
    shipped = Animator("pretrained:skirt/body-lbs").animate(motion)
    # float16 weights move a vertex by well under a millimetre (0.75 mm at most on a held-out clip of the shipped
    # VirtualBones skirt)
    np.testing.assert_allclose(shipped, Animator(lbs_run, checkpoint="last").animate(motion), rtol=0, atol=1e-3)


def test_names_that_are_not_shipped_are_refused_with_the_list(tmp_path, monkeypatch):
    monkeypatch.setattr(pretrained, "ROOT", tmp_path)
    (tmp_path / "skirt-virtualbones").mkdir()
    (tmp_path / "skirt-virtualbones" / "model.json").write_text("{}")
    assert pretrained.resolve_run("pretrained:skirt") == tmp_path / "skirt-virtualbones"  # VirtualBones by default
    assert pretrained.resolve_run("runs/vb") == pretrained.Path("runs/vb")  # a folder stays a folder
    for name in ("pretrained:coat", "pretrained:", "pretrained:skirt/jointnet", "pretrained:skirt/a/b"):
        with pytest.raises(InputError, match="shipped: pretrained:skirt/virtualbones"):
            pretrained.resolve_run(name)


def test_shipping_refuses_what_is_not_a_finished_run(tmp_path):
    with pytest.raises(InputError, match="checkpoint not found"):
        pretrained.ship(tmp_path, tmp_path / "out", {})
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name", pretrained.available() or [pytest.param("none", marks=pytest.mark.skip("none shipped"))])
def test_every_shipped_garment_animates_a_motion_under_the_size_limit(name, body):
    from loosefit.motion.procedural import generate

    folder = pretrained.resolve_run(pretrained.PREFIX + name)
    assert (folder / "checkpoints" / "best.pt").stat().st_size <= pretrained.MAX_BYTES
    info = json.loads((folder / "pretrained.json").read_text())
    assert {"trained_on", "test"} <= set(info)
    animator = Animator(pretrained.PREFIX + name)
    motion = generate("walk", 1.0, 0, body)
    verts = animator.animate(motion)
    assert verts.shape == (motion.num_frames, len(np.unique(animator.faces)), 3) and np.isfinite(verts).all()
    # worn on the body: the garment's centre stays within 0.5 m of the root, horizontally, every frame
    offset = verts.mean(1)[:, :2] - motion.translation[:, :2]
    assert np.linalg.norm(offset, axis=-1).max() < 0.5


def test_int8_storage_keeps_each_weight_within_half_a_step_of_its_row():
    from loosefit.train.run import quantize_int8

    rng = np.random.default_rng(0)
    weights = {"basis": torch.from_numpy(rng.normal(0, 0.01, (6, 5, 40, 3)).astype(np.float32)),
               "matrix": torch.from_numpy(rng.normal(0, 1, (300, 200)).astype(np.float32)),
               "bias": torch.ones(300)}
    q, scales = quantize_int8(weights, ["basis", "matrix"])
    assert set(scales) == {"basis", "matrix"} and q["bias"] is weights["bias"]
    # a row: the trailing dimensions that first hold 64 elements (40 x 3 for the basis, 200 for the matrix)
    assert scales["basis"].shape == (6, 5, 1, 1) and scales["matrix"].shape == (300, 1)
    for name in scales:
        w, step = weights[name].double(), scales[name].double()
        assert q[name].dtype == torch.int8 and int(q[name].abs().max()) == 127
        row_max = w.abs().amax(dim=[d for d in range(w.dim()) if scales[name].shape[d] == 1], keepdim=True)
        torch.testing.assert_close(step, row_max / 127, rtol=1e-6, atol=0)  # brute-force: the row's largest over 127
        assert bool(((q[name].double() * step - w).abs() <= step / 2 + 1e-9).all())


def test_a_garment_too_large_in_float16_ships_its_largest_tensor_as_int8(lbs_run, tiny_store, tmp_path, monkeypatch):
    from loosefit.train.run import dequantize_int8, load_checkpoint

    monkeypatch.setattr(pretrained, "ROOT", tmp_path)
    half = pretrained.ship(lbs_run, tmp_path / "half", {})
    original = torch.load(lbs_run / "checkpoints" / "last.pt", weights_only=True)["model"]
    large = [k for k, v in original.items() if v.is_floating_point() and v.dim() >= 2 and v.numel() > pretrained.HALF_ABOVE]
    assert large, "the tiny body-LBS run needs a tensor above HALF_ABOVE for this test"
    largest = max(large, key=lambda k: original[k].numel())
    monkeypatch.setattr(pretrained, "MAX_BYTES", (half / "checkpoints" / "best.pt").stat().st_size - 1)
    out = pretrained.ship(lbs_run, tmp_path / "skirt-body-lbs", {})
    assert json.loads((out / "pretrained.json").read_text())["int8"] == [largest]
    stored = torch.load(out / "checkpoints" / "best.pt", weights_only=True)
    assert stored["model"][largest].dtype == torch.int8 and set(stored["int8_scales"]) == {largest}
    loaded = load_checkpoint(out / "checkpoints" / "best.pt")["model"]
    assert loaded[largest].dtype == torch.float32 and "int8_scales" not in loaded
    # the shipped garment animates exactly as the run with its weights replaced by the dequantized ones
    store = DatasetStore.open(tiny_store)
    motion = store.motion(store.sequence(store.sequence_names(split="test")[0]).motion)
    reference = Animator(lbs_run, checkpoint="last")
    reference.model.load_state_dict({**reference.model.state_dict(), largest: loaded[largest]})
    np.testing.assert_allclose(Animator("pretrained:skirt/body-lbs").animate(motion), reference.animate(motion),
                               rtol=0, atol=1e-5)
    with pytest.raises(InputError, match=f"int8 tensor '{largest}' does not match its scale"):
        dequantize_int8(stored["model"], {largest: torch.ones(3)}, out / "checkpoints" / "best.pt")
