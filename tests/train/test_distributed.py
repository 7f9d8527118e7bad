"""DistributedDataParallel training with gloo on CPU: two spawned processes train the same weights as
one process with the same seed and global batch (to float tolerance), only rank 0 writes, an
interrupted two-process run resumes exactly, and bad settings get clear errors."""

from __future__ import annotations

import csv
import os

import pytest
import torch
from torch import nn
from torch.utils.data import TensorDataset

from loosefit.errors import InputError, LoosefitError
from loosefit.train import StageConfig, TrainConfig, load_checkpoint, seed_everything, train
from loosefit.train.distributed import ShardedSampler, launch, local_batch_size, resolve_device

SAMPLES, GLOBAL_BATCH = 24, 8  # 3 optimiser steps per epoch


class TwoStageMLP(nn.Module):
    """A deterministic regression MLP trained in two stages ("body", then "head" alone); ``stop_at``
    raises at that training_loss call (1-based) to interrupt a run."""

    def __init__(self, stop_at: int | None = None):
        super().__init__()
        self.body = nn.Sequential(nn.Linear(3, 16), nn.Tanh())
        self.head = nn.Linear(16, 2)
        self.stop_at, self.calls = stop_at, 0

    def stages(self):
        return ["body", "head"]

    def stage_parameters(self, stage):
        return self.parameters() if stage == "body" else self.head.parameters()

    def training_loss(self, batch, stage):
        self.calls += 1
        if self.calls == self.stop_at:
            raise LoosefitError(f"stopped at call {self.calls}")
        x, y = batch
        loss = ((self.head(self.body(x)) - y) ** 2).mean()
        return loss, {"l2": loss.item()}

    def validation_metrics(self, batch, stage):
        x, y = batch
        return {"rmse_mm": 1000 * ((self.head(self.body(x)) - y) ** 2).mean().sqrt().item()}


def _data(n: int, seed: int) -> TensorDataset:
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(n, 3, generator=g)
    return TensorDataset(x, torch.stack([x[:, 0] * x[:, 1], torch.sin(2 * x[:, 2])], 1))


def _config(**kw) -> TrainConfig:
    base = dict(seed=3, batch_size=GLOBAL_BATCH, lr=1e-2, optimizer="adam", schedule="cosine", progress=False,
                tensorboard=False, stages={"body": StageConfig(epochs=3), "head": StageConfig(epochs=2, lr=5e-3)})
    return TrainConfig(**{**base, **kw})


def job(out: str, resume: bool = False, stop_at: int | None = None, **config) -> dict:
    """One training run (in this process or in each spawned one): the final weights and history."""
    seed_everything(3)
    model = TwoStageMLP(stop_at)
    result = train(model, _data(SAMPLES, 0), _data(8, 1), _config(**config), out, resume=resume)
    return {"weights": {k: v.detach().clone() for k, v in model.state_dict().items()},
            "history": result.history, "steps": result.global_step}


def _max_diff(a: dict, b: dict) -> float:
    assert a.keys() == b.keys()
    return max(float((a[k] - b[k]).abs().max()) for k in a)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("ddp")
    one = job(str(root / "one"))
    two = launch(job, 2, str(root / "two"))
    return root, one, two


def test_two_gloo_processes_match_one_process(runs):
    root, one, two = runs
    assert one["steps"] == two["steps"] == 5 * SAMPLES // GLOBAL_BATCH
    diff = _max_diff(one["weights"], two["weights"])
    print(f"max |w_2proc - w_1proc| after {two['steps']} steps: {diff:.3e}")
    assert diff < 1e-5
    # the weights moved far more than the tolerance: the comparison is not vacuous
    seed_everything(3)
    initial = TwoStageMLP().state_dict()
    assert _max_diff(initial, one["weights"]) > 1e-2
    # the logged training loss averages every rank's samples, like one process's
    for r1, r2 in zip(one["history"], two["history"]):
        assert r2["train_loss"] == pytest.approx(r1["train_loss"], rel=1e-5)
        assert r2["val_rmse_mm"] == pytest.approx(r1["val_rmse_mm"], rel=1e-5)


def test_rank_zero_writes_the_run(runs):
    root, _, two = runs
    saved = load_checkpoint(root / "two" / "checkpoints" / "last.pt")
    assert _max_diff(saved["model"], two["weights"]) == 0.0
    with open(root / "two" / "metrics.csv", newline="") as f:
        assert len(list(csv.DictReader(f))) == 5  # one row per epoch, not one per process
    assert (root / "two" / "run.json").is_file()


def test_interrupted_two_process_run_resumes_exactly(runs, tmp_path):
    _, _, two = runs
    out = str(tmp_path / "resumed")
    with pytest.raises(LoosefitError, match="stopped at call 8"):  # in epoch 3 of stage 1
        launch(job, 2, out, stop_at=8, checkpoint_every=2)
    assert load_checkpoint(tmp_path / "resumed" / "checkpoints" / "last.pt")["epoch"] == 2
    resumed = launch(job, 2, out, resume=True, checkpoint_every=2)
    assert _max_diff(resumed["weights"], two["weights"]) == 0.0


def test_sharded_sampler_splits_one_process_batches():
    """Rank r's k-th batch of b samples is the r-th interleaved share of one process's k-th batch of N*b."""
    data = list(range(10))
    order = torch.randperm(10, generator=torch.Generator().manual_seed(5)).tolist()
    shares = []
    for r in range(2):
        os.environ.update(RANK=str(r), WORLD_SIZE="2")
        try:
            shares.append(list(ShardedSampler(data, torch.Generator().manual_seed(5))))
        finally:
            del os.environ["RANK"], os.environ["WORLD_SIZE"]
    assert shares[0] == order[0::2] and shares[1] == order[1::2]


def test_bad_settings_are_clear(tmp_path):
    os.environ.update(RANK="0", WORLD_SIZE="2")
    try:
        with pytest.raises(InputError, match="multiple of the 2 processes"):
            local_batch_size(7)
        assert local_batch_size(8) == 4
    finally:
        del os.environ["RANK"], os.environ["WORLD_SIZE"]
    with pytest.raises(InputError, match="--nproc must be >= 1"):
        launch(job, 0, str(tmp_path / "none"))
    if not torch.cuda.is_available():
        with pytest.raises(InputError, match="CUDA is not available"):
            resolve_device("cuda")
