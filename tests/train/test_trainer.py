"""The trainer on a real two-stage GRU: determinism, exact resume (also across a stage boundary and
with sparse checkpoints), stage isolation, weighted validation averages, logs and failure modes."""

from __future__ import annotations

import csv
import json
import math

import pytest
import torch

from loosefit.errors import InputError
from loosefit.train import StageConfig, TrainConfig, TrainingError, load_checkpoint, train
from loosefit.train.trainer import StaleRunError
from tests.train.conftest import SineGRU, SineSequences, make_model, quick_config

STEPS_PER_EPOCH = 5  # 20 samples, batches of 4


def _params(model):
    return {k: v.detach().clone() for k, v in model.state_dict().items()}


def _assert_same_weights(a, b):
    sa, sb = a.state_dict(), b.state_dict()
    assert sa.keys() == sb.keys()
    for key in sa:
        assert torch.equal(sa[key], sb[key]), key


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _without_seconds(rows):
    return [{k: v for k, v in r.items() if k != "seconds"} for r in rows]


def test_same_seed_same_weights_other_seed_differs(data, tmp_path):
    train_set, val_set = data
    a, b, c = make_model(), make_model(), make_model()
    train(a, train_set, val_set, quick_config(), tmp_path / "a")
    train(b, train_set, val_set, quick_config(), tmp_path / "b")
    train(c, train_set, val_set, quick_config(seed=1), tmp_path / "c")
    _assert_same_weights(a, b)
    assert not torch.equal(a.head.weight, c.head.weight)  # the seed drives shuffling and noise


def test_worker_processes_and_progress_bars_change_nothing(data, tmp_path):
    train_set, val_set = data
    a, b = make_model(), make_model()
    config = quick_config(epochs=1)
    train(a, train_set, val_set, config, tmp_path / "a")
    train(b, train_set, val_set, quick_config(epochs=1, num_workers=2, progress=True), tmp_path / "b")
    _assert_same_weights(a, b)


@pytest.mark.parametrize(
    "crash_at_call, checkpoint_every, saved_position",
    [
        (8, 1, (0, 1)),  # Ctrl-C inside epoch 2 of stage "encoder"
        (16, 1, (0, 3)),  # first step of stage "head": resume across the stage boundary
        (6, 2, (0, 1)),  # epoch 1 was not due for a checkpoint: the interrupt writes it
    ],
)
def test_resume_gives_identical_weights(data, tmp_path, crash_at_call, checkpoint_every, saved_position):
    train_set, val_set = data
    config = quick_config(checkpoint_every=checkpoint_every)
    reference = make_model()
    expected = train(reference, train_set, val_set, config, tmp_path / "ref")

    crashed = make_model()
    crashed.crash_at_call = crash_at_call
    with pytest.raises(KeyboardInterrupt):
        train(crashed, train_set, val_set, config, tmp_path / "run")
    saved = load_checkpoint(tmp_path / "run" / "checkpoints" / "last.pt")
    assert (saved["stage_index"], saved["epoch"]) == saved_position and not saved["complete"]
    assert saved["global_step"] == (saved_position[0] * 3 + saved_position[1]) * STEPS_PER_EPOCH

    resumed = make_model(seed=123)  # other initial weights: all must come from the checkpoint
    result = train(resumed, train_set, val_set, config, tmp_path / "run", resume=True)
    _assert_same_weights(reference, resumed)
    assert result.global_step == expected.global_step == 6 * STEPS_PER_EPOCH
    assert result.best_metric == expected.best_metric
    assert _without_seconds(_rows(tmp_path / "run" / "metrics.csv")) == _without_seconds(
        _rows(tmp_path / "ref" / "metrics.csv")
    )


def test_stage_optimises_only_its_parameters(data, tmp_path):
    train_set, val_set = data
    model = make_model()
    before = _params(model)
    config = quick_config(stages={"encoder": StageConfig(epochs=2), "head": StageConfig(epochs=0)})
    train(model, train_set, val_set, config, tmp_path / "enc")
    after = _params(model)
    for key in before:
        assert torch.equal(before[key], after[key]) == key.startswith("head."), key

    model = make_model()
    before = _params(model)
    config = quick_config(stages={"encoder": StageConfig(epochs=0), "head": StageConfig(epochs=2)})
    train(model, train_set, val_set, config, tmp_path / "head")
    after = _params(model)
    for key in before:
        assert torch.equal(before[key], after[key]) == key.startswith("gru."), key


def test_validation_metrics_are_batch_size_weighted(data, tmp_path):
    train_set, val_set = data  # 7 validation samples in batches of 3: sizes 3, 3, 1
    model = make_model()
    result = train(model, train_set, val_set, quick_config(batch_size=3), tmp_path / "run")
    model.eval()
    with torch.no_grad():
        err = model(val_set.x) - val_set.y
    # per-sample errors have equal sizes, so the weighted average of batch means is the overall mean
    assert result.val_metrics["mae"] == pytest.approx(err.abs().mean().item(), rel=1e-6)
    # the model's per-batch rmse (not additive) is averaged with weights 3, 3, 1
    batches = [(1000 * err[i : i + 3].pow(2).mean().sqrt().item(), len(err[i : i + 3])) for i in range(0, 7, 3)]
    weighted = sum(v * n for v, n in batches) / 7
    assert result.val_metrics["rmse_mm"] == pytest.approx(weighted, rel=1e-6)
    assert result.val_metrics["rmse_mm"] != pytest.approx(sum(v for v, _ in batches) / 3, rel=1e-6)


def test_metrics_csv_and_run_summary(data, tmp_path):
    train_set, val_set = data
    model = make_model()
    config = quick_config(lr=0.02, min_lr=0.001, validate_every=2, stages={"head": StageConfig(epochs=2, lr=0.01)})
    result = train(model, train_set, val_set, config, tmp_path / "run")
    rows = _rows(tmp_path / "run" / "metrics.csv")
    assert list(rows[0])[:5] == ["stage", "epoch", "step", "lr", "seconds"]
    assert {"train_loss", "train_l1", "val_rmse_mm", "val_mae"} <= set(rows[0])
    assert [(r["stage"], int(r["epoch"]), int(r["step"])) for r in rows] == [
        ("encoder", 1, 5), ("encoder", 2, 10), ("encoder", 3, 15), ("head", 1, 20), ("head", 2, 25)
    ]
    # cosine from lr to min_lr over each stage's epochs, value at the start of each epoch
    for row in rows:
        lr0, epochs = (0.02, 3) if row["stage"] == "encoder" else (0.01, 2)
        e = int(row["epoch"]) - 1
        assert float(row["lr"]) == pytest.approx(0.001 + (lr0 - 0.001) * (1 + math.cos(math.pi * e / epochs)) / 2)
    # validation every 2nd epoch and at each stage's end
    assert [r["val_mae"] != "" for r in rows] == [False, True, True, False, True]
    # the epoch's training loss is the batch-size-weighted mean of its steps' losses
    for i, row in enumerate(rows):
        steps = model.step_log[i * STEPS_PER_EPOCH : (i + 1) * STEPS_PER_EPOCH]
        assert {s for s, _, _ in steps} == {row["stage"]}
        mean = sum(n * loss for _, n, loss in steps) / sum(n for _, n, _ in steps)
        assert float(row["train_loss"]) == pytest.approx(mean, rel=1e-6)
    summary = json.loads((tmp_path / "run" / "run.json").read_text())
    assert summary["parameter_count"] == sum(p.numel() for p in model.parameters()) == result.parameter_count
    assert summary["global_step"] == 25 and summary["epochs"] == {"encoder": 3, "head": 2}
    assert summary["val_metrics"]["mae"] == pytest.approx(float(rows[-1]["val_mae"]))
    assert summary["best_metric"] == min(float(r["val_rmse_mm"]) for r in rows[3:] if r["val_rmse_mm"])
    assert (tmp_path / "run" / "config.yaml").is_file()
    best = load_checkpoint(tmp_path / "run" / "checkpoints" / "best.pt")
    assert best["best_metric"] == summary["best_metric"] and best["stages"][best["stage_index"]] == "head"


def test_threads_applied_and_restored(data, tmp_path):
    train_set, _ = data
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        model = make_model()
        result = train(model, train_set, None, quick_config(threads=1, tensorboard=True), tmp_path / "run")
        assert model.threads_seen == {1}
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
    assert result.monitor == "loss" and result.val_metrics == {}
    assert result.best_metric == min(r["train_loss"] for r in result.history if r["stage"] == "head")
    # the training loss selects no checkpoint: without validation there is no best.pt
    assert result.best_checkpoint is None and not (tmp_path / "run" / "checkpoints" / "best.pt").exists()
    assert list((tmp_path / "run" / "tensorboard").glob("events.out.tfevents.*"))


def test_corrupt_checkpoint_stops_resume(data, tmp_path):
    train_set, val_set = data
    run = tmp_path / "run"
    train(make_model(), train_set, val_set, quick_config(epochs=1), run)
    last = run / "checkpoints" / "last.pt"
    with pytest.raises(InputError, match="already holds a training run"):
        train(make_model(), train_set, val_set, quick_config(epochs=1), run)
    data_bytes = last.read_bytes()
    last.write_bytes(data_bytes[: len(data_bytes) // 2])
    with pytest.raises(InputError, match="corrupt or truncated") as info:
        train(make_model(), train_set, val_set, quick_config(epochs=1), run, resume=True)
    assert str(last) in str(info.value)
    torch.save({"weights": torch.zeros(3)}, last)
    with pytest.raises(InputError, match="not a loosefit checkpoint"):
        load_checkpoint(last)


def test_resume_checks_config_and_model(data, tmp_path):
    train_set, val_set = data
    run = tmp_path / "run"
    model = make_model()
    model.crash_at_call = 8
    with pytest.raises(KeyboardInterrupt):
        train(model, train_set, val_set, quick_config(), run)
    # StaleRunError: the demo trains such a run again from the start
    with pytest.raises(StaleRunError, match=r"differs from the checkpoint's in \['lr'\]"):
        train(make_model(), train_set, val_set, quick_config(lr=0.5), run, resume=True)
    with pytest.raises(StaleRunError, match="does not fit this model"):
        train(SineGRU(hidden=5), train_set, val_set, quick_config(), run, resume=True)
    # settings that leave the numbers alone may change
    train(make_model(), train_set, val_set, quick_config(progress=True, log_every=2), run, resume=True)


def test_resume_of_finished_run_and_of_empty_folder(data, tmp_path):
    train_set, val_set = data
    model = make_model()
    first = train(model, train_set, val_set, quick_config(), tmp_path / "run", resume=True)  # nothing to resume
    again_model = make_model(seed=5)
    again = train(again_model, train_set, val_set, quick_config(), tmp_path / "run", resume=True)
    _assert_same_weights(model, again_model)
    assert again.global_step == first.global_step and again.val_metrics == first.val_metrics
    assert again.best_metric == first.best_metric
    assert load_checkpoint(tmp_path / "run" / "checkpoints" / "last.pt")["complete"]


def test_bad_inputs(data, tmp_path):
    train_set, val_set = data
    with pytest.raises(InputError, match="not stages of this model"):
        train(make_model(), train_set, val_set, quick_config(stages={"decoder": StageConfig(epochs=1)}), tmp_path / "a")
    with pytest.raises(InputError, match="monitor metric 'psnr'"):
        train(make_model(), train_set, val_set, quick_config(monitor="psnr"), tmp_path / "b")
    with pytest.raises(InputError, match="training set is empty"):
        train(make_model(), SineSequences(0), None, quick_config(), tmp_path / "c")


def test_nan_loss_keeps_last_checkpoint(data, tmp_path):
    train_set, val_set = data
    model = make_model()
    original = model.training_loss

    def exploding(batch, stage):
        loss, terms = original(batch, stage)
        return (loss * float("nan") if model.calls == 12 else loss), terms

    model.training_loss = exploding
    with pytest.raises(TrainingError, match="epoch 3 step 12"):
        train(model, train_set, val_set, quick_config(checkpoint_every=2), tmp_path / "run")
    saved = load_checkpoint(tmp_path / "run" / "checkpoints" / "last.pt")
    assert (saved["stage_index"], saved["epoch"], saved["global_step"]) == (0, 2, 10)


@pytest.mark.parametrize("optimizer, first_step, state_key", [("adam", 1.0, "exp_avg_sq"), ("rmsprop", 1.0, "exp_avg_sq"),
                                                              ("rmsprop-torch", 10.0, "square_avg")])
def test_optimizer_first_step_matches_closed_form(data, tmp_path, optimizer, first_step, state_key):
    # One step on the head: Adam moves every weight by lr (m/sqrt(v) = sign g), and so does RMSProp with its
    # squared-gradient average corrected for its zero start (g / sqrt(0.01 g^2 / 0.01)); torch's RMSprop
    # (smoothing 0.99, uncorrected) by lr * g / sqrt(0.01 g^2) = 10 lr.
    train_set, _ = data
    model = make_model()
    before = model.head.weight.detach().clone()
    config = quick_config(optimizer=optimizer, lr=1e-4, batch_size=20, schedule="none",
                          stages={"encoder": StageConfig(epochs=0), "head": StageConfig(epochs=1)})
    train(model, train_set, None, config, tmp_path / optimizer)
    step = (model.head.weight.detach() - before).abs()
    assert torch.allclose(step, torch.full_like(step, first_step * 1e-4), rtol=1e-3)
    state = load_checkpoint(tmp_path / optimizer / "checkpoints" / "last.pt")["optimizer"]["state"]
    assert state_key in state[0]


def test_corrected_rmsprop_steps_follow_the_closed_form(data, tmp_path):
    """Three steps of ``"rmsprop"`` on the head against RMSProp written out: ``v_t = 0.99 v + 0.01 g^2``,
    ``w -= lr g / (sqrt(v_t / (1 - 0.99^t)) + 1e-8)``, with the gradients the run itself took."""
    train_set, _ = data
    model = make_model()
    grads, weights = [], [model.head.weight.detach().clone()]
    model.head.weight.register_hook(lambda g: grads.append(g.detach().clone()))
    config = quick_config(optimizer="rmsprop", lr=1e-3, batch_size=20, schedule="none", epochs=0,
                          stages={"head": StageConfig(epochs=3)})
    train(model, train_set, None, config, tmp_path / "run")
    assert len(grads) == 3
    w, v = weights[0].double(), torch.zeros_like(weights[0], dtype=torch.float64)
    for t, g in enumerate(grads, 1):
        v = 0.99 * v + 0.01 * g.double() ** 2
        w = w - 1e-3 * g.double() / ((v / (1 - 0.99**t)).sqrt() + 1e-8)
    torch.testing.assert_close(model.head.weight.detach().double(), w, rtol=1e-5, atol=1e-8)


class Drift(torch.nn.Module):
    """One weight ``w`` (from 0) trained towards 2 (loss ``(w - 2)^2``) and validated against 1 (``rmse_mm =
    1000 |w - 1|``): the validation error falls until ``w`` passes 1, then rises while training goes on."""

    def __init__(self):
        super().__init__()
        self.w = torch.nn.Parameter(torch.zeros(()))

    def training_loss(self, batch, stage):
        loss = ((self.w - 2) ** 2) * batch["x"].mean()
        return loss, {}

    def validation_metrics(self, batch, stage):
        return {"rmse_mm": 1000 * abs(self.w.item() - 1.0)}


def test_best_checkpoint_is_the_validation_minimum(tmp_path):
    """A run whose validation error rises after an early minimum keeps that minimum's epoch in best.pt;
    last.pt holds the end of training."""
    samples = [{"x": torch.ones(1)} for _ in range(4)]
    config = TrainConfig(epochs=12, batch_size=4, lr=0.15, schedule="none", progress=False, tensorboard=False)
    model = Drift()
    result = train(model, samples, samples[:1], config, tmp_path / "run")
    rows = _rows(tmp_path / "run" / "metrics.csv")
    val = [float(r["val_rmse_mm"]) for r in rows]
    # Adam by hand (one step an epoch, gradient 2 (w - 2)): the validation errors the run must have recorded
    w, m, v, expected = 0.0, 0.0, 0.0, []
    for t in range(1, 13):
        g = 2 * (w - 2)
        m, v = 0.9 * m + 0.1 * g, 0.999 * v + 0.001 * g * g
        w -= 0.15 * (m / (1 - 0.9**t)) / (math.sqrt(v / (1 - 0.999**t)) + 1e-8)
        expected.append(1000 * abs(w - 1.0))
    assert val == pytest.approx(expected, rel=1e-4, abs=1e-3)
    best_epoch = 1 + expected.index(min(expected))  # an early minimum (epoch 7), then a rise to 675 mm
    best = load_checkpoint(tmp_path / "run" / "checkpoints" / "best.pt")
    last = load_checkpoint(tmp_path / "run" / "checkpoints" / "last.pt")
    assert best["epoch"] == best_epoch and last["epoch"] == 12
    assert 1000 * abs(float(best["model"]["w"]) - 1.0) == pytest.approx(min(val), rel=1e-6)
    assert float(last["model"]["w"]) == pytest.approx(model.w.item(), rel=1e-6)
    assert result.best_metric == pytest.approx(min(val), rel=1e-6)
    assert result.best_checkpoint == tmp_path / "run" / "checkpoints" / "best.pt"
