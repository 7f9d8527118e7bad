"""metrics.csv: union of columns in order, fixed columns first, rewritten from the kept rows."""

from __future__ import annotations

import csv

from loosefit.train.metrics_log import MetricsLog


def _read(path):
    with open(path, newline="") as f:
        return list(csv.reader(f))


def test_columns_grow_and_resume_drops_newer_rows(tmp_path):
    path = tmp_path / "metrics.csv"
    log = MetricsLog(path)
    assert _read(path) == [["stage", "epoch", "step", "lr", "seconds"]]
    log.add_row({"stage": "a", "epoch": 1, "step": 2, "lr": 0.1, "seconds": 1.0, "train_loss": 0.5})
    log.add_row({"stage": "b", "epoch": 1, "step": 4, "lr": 0.1, "seconds": 1.0, "train_loss": 0.25, "val_m": 3.0})
    assert _read(path) == [
        ["stage", "epoch", "step", "lr", "seconds", "train_loss", "val_m"],
        ["a", "1", "2", "0.1", "1.0", "0.5", ""],
        ["b", "1", "4", "0.1", "1.0", "0.25", "3.0"],
    ]
    MetricsLog(path, rows=log.rows[:1])  # a resumed run keeps only the rows of its checkpoint
    assert _read(path) == [
        ["stage", "epoch", "step", "lr", "seconds", "train_loss"],
        ["a", "1", "2", "0.1", "1.0", "0.5"],
    ]
