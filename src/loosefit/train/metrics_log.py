"""Training logs: ``metrics.csv`` (one row per epoch per stage) and TensorBoard scalars.

CSV columns: ``stage, epoch, step, lr, seconds``, then ``train_<term>`` (epoch averages of the loss
and its terms, weighted by batch size) and ``val_<metric>`` (validation averages; empty in epochs
without validation), in order of first appearance. The CSV is rewritten atomically after each epoch,
so that it always matches the rows kept (a resumed run drops rows newer than its checkpoint).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

from loosefit.paths import atomic_path

FIXED_COLUMNS = ("stage", "epoch", "step", "lr", "seconds")


class MetricsLog:
    """Epoch rows kept in memory and mirrored to a CSV file, plus an optional TensorBoard writer.

    Args:
        csv_path: the CSV file, rewritten on every :meth:`add_row`.
        rows: rows already logged (from a checkpoint when resuming); written out at once.
        tensorboard_dir: folder for event files, or ``None`` for no TensorBoard.
        purge_step: when resuming, TensorBoard drops events at or after this global step (written
            by the interrupted run after its checkpoint).
    """

    def __init__(
        self,
        csv_path: str | Path,
        rows: list[dict[str, Any]] | None = None,
        tensorboard_dir: str | Path | None = None,
        purge_step: int | None = None,
    ):
        self.csv_path = Path(csv_path)
        self.rows: list[dict[str, Any]] = [dict(r) for r in rows or []]
        self._writer = None
        if tensorboard_dir is not None:
            from torch.utils.tensorboard import SummaryWriter  # imports tensorboard: only when asked

            self._writer = SummaryWriter(log_dir=str(tensorboard_dir), purge_step=purge_step)
        self._write_csv()

    def columns(self) -> list[str]:
        """The CSV header: fixed columns, then every other key in order of first appearance."""
        columns = list(FIXED_COLUMNS)
        for row in self.rows:
            columns.extend(k for k in row if k not in columns)
        return columns

    def add_row(self, row: dict[str, Any]) -> None:
        """Append an epoch row (keys as in the module docstring) and rewrite the CSV."""
        self.rows.append(dict(row))
        self._write_csv()

    def _write_csv(self) -> None:
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=self.columns(), restval="", lineterminator="\n")
        writer.writeheader()
        writer.writerows(self.rows)
        with atomic_path(self.csv_path) as tmp:
            tmp.write_text(buffer.getvalue())

    def scalars(self, values: dict[str, float], step: int, prefix: str = "") -> None:
        """Send ``{name: value}`` to TensorBoard as ``<prefix><name>`` at ``step`` (no-op without it)."""
        if self._writer is not None:
            for name, value in values.items():
                self._writer.add_scalar(f"{prefix}{name}", value, step)

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None
