"""A tiny real model for the trainer tests: a GRU that predicts the next value of sine sequences,
trained in two stages ("encoder": the GRU, "head": the output layer)."""

from __future__ import annotations

import math

import pytest
import torch
from torch import nn
from torch.utils.data import Dataset

from loosefit.train import TrainConfig, seed_everything


class SineSequences(Dataset):
    """``n`` sine sequences of ``length`` steps with random frequency and phase; item ``i`` is
    ``{"x": (length, 1), "y": (length, 1)}`` with ``y`` the next value of ``x``."""

    def __init__(self, n: int, length: int = 12, seed: int = 0):
        g = torch.Generator().manual_seed(seed)
        freq = 0.3 + 0.5 * torch.rand(n, generator=g)
        phase = 2 * math.pi * torch.rand(n, generator=g)
        t = torch.arange(length + 1, dtype=torch.float32)
        s = torch.sin(freq[:, None] * t + phase[:, None])
        self.x, self.y = s[:, :-1, None], s[:, 1:, None]

    def __len__(self) -> int:
        return len(self.x)

    def __getitem__(self, i):
        return {"x": self.x[i], "y": self.y[i]}


class SineGRU(nn.Module):
    """GRU + linear head. Training adds input noise and dropout, so it draws from torch's global
    generator (resume must restore it). ``crash_at_call`` raises KeyboardInterrupt in the
    training_loss call of that number (1-based), to simulate Ctrl-C."""

    def __init__(self, hidden: int = 8):
        super().__init__()
        self.gru = nn.GRU(1, hidden, batch_first=True)
        self.drop = nn.Dropout(0.1)
        self.head = nn.Linear(hidden, 1)
        self.crash_at_call: int | None = None
        self.calls = 0
        self.threads_seen: set[int] = set()
        self.step_log: list[tuple[str, int, float]] = []  # (stage, batch size, loss) of every step

    def stages(self):
        return ["encoder", "head"]

    def stage_parameters(self, stage):
        return self.gru.parameters() if stage == "encoder" else self.head.parameters()

    def forward(self, x):
        return self.head(self.drop(self.gru(x)[0]))

    def training_loss(self, batch, stage):
        self.calls += 1
        if self.crash_at_call is not None and self.calls == self.crash_at_call:
            raise KeyboardInterrupt
        self.threads_seen.add(torch.get_num_threads())
        x = batch["x"] + 0.01 * torch.randn_like(batch["x"])
        err = self(x) - batch["y"]
        l2 = (err**2).mean()
        l1 = err.abs().mean()
        self.step_log.append((stage, len(x), l2.item()))
        return l2, {"l1": l1.item()}

    def validation_metrics(self, batch, stage):
        err = self(batch["x"]) - batch["y"]
        return {"rmse_mm": 1000 * err.pow(2).mean().sqrt().item(), "mae": err.abs().mean().item()}


def make_model(seed: int = 0) -> SineGRU:
    seed_everything(seed)
    return SineGRU()


def quick_config(**changes) -> TrainConfig:
    """3 epochs per stage, batches of 4 (20 training samples: 5 steps per epoch), no bars, no TensorBoard."""
    base = dict(epochs=3, batch_size=4, lr=1e-2, progress=False, tensorboard=False)
    base.update(changes)
    return TrainConfig(**base)


@pytest.fixture
def data():
    return SineSequences(20, seed=1), SineSequences(7, seed=2)
