"""The pure helpers of ``benchmarks/experiments/levers.py``: lever parsing, probe sharing and the equal-budget epochs."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "experiments" / "levers.py"


@pytest.fixture(scope="module")
def levers():
    spec = importlib.util.spec_from_file_location("levers_script", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    saved = list(sys.path)
    try:
        spec.loader.exec_module(module)
    finally:
        sys.path[:] = saved
    return module


def test_a_lever_is_a_name_and_its_overrides(levers):
    assert levers.parse_lever("baseline=") == ("baseline", [])
    assert levers.parse_lever("whole=data.carry_state=true data.window=150") == \
        ("whole", ["data.carry_state=true", "data.window=150"])
    for bad in ("nothing", "=train.lr=1", "x=train.lr"):
        with pytest.raises(ValueError):
            levers.parse_lever(bad)


def test_levers_differing_in_the_learning_rate_only_share_a_probe(levers):
    assert levers.cost_key(["train.lr=2e-3", "train.schedule=none"]) == levers.cost_key([])
    assert levers.cost_key(["train.lr=2e-3", "model.bone_weight=1"]) == ("model.bone_weight=1",)


def test_the_preset_epochs_are_scaled_to_the_budget(levers):
    epochs = levers.scaled_epochs({"low": 60, "high": 40}, {"low": 2.0, "high": 1.0}, budget_s=80.0)
    assert epochs == {"low": 30, "high": 20}  # 30 * 2 + 20 * 1 = 80 s
    assert levers.scaled_epochs({"low": 60, "high": 40}, {"low": 100.0, "high": 100.0}, 10.0) == {"low": 1, "high": 1}
    with pytest.raises(ValueError):
        levers.scaled_epochs({"low": 1}, {"low": 0.0}, 10.0)


def test_kind_table_pools_squares_over_frames(levers):
    """The per-kind table (shared with accuracy.py's errors_by_kind) pools mean squares weighted by frames, which
    equals the RMSE over every frame of the sequences together (brute force)."""
    import numpy as np

    rng = np.random.default_rng(0)
    frames = {"walk": [rng.normal(size=(n, 5)) for n in (3, 7)], "spin": [rng.normal(size=(4, 5))]}
    squares = {kind: {"train": [(float((e**2).mean()), len(e)) for e in errs]} for kind, errs in frames.items()}
    table = levers.kind_table(squares)
    for kind, errs in frames.items():
        brute = float(np.sqrt((np.concatenate(errs) ** 2).mean()))
        assert table[kind] == {"train_rmse_mm": pytest.approx(brute, rel=1e-12), "train_sequences": len(errs)}
    assert levers.pooled_rmse([]) is None
