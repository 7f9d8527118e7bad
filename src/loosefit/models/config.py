"""Config pieces shared by the per-garment models (each method's module holds its own full ``Config``)."""

from __future__ import annotations

from dataclasses import dataclass

from loosefit.errors import InputError
from loosefit.models.dataset import GarmentSequences, WindowDataset


@dataclass(frozen=True)
class WindowConfig:
    """How sequences are cut into training windows (truncated back-propagation through time).

    Attributes:
        window: frames per window.
        stride: frames between the starts of consecutive windows of a sequence.
        burn_in: frames at the start of a window (not starting at frame 0) that only warm up the
            recurrent state and carry no loss.
    """

    window: int = 64
    stride: int = 32
    burn_in: int = 16

    def __post_init__(self):
        if self.window < 1 or self.stride < 1 or self.burn_in < 0:
            raise InputError(f"window and stride must be >= 1 and burn_in >= 0, "
                             f"got {self.window}, {self.stride}, {self.burn_in}")
        if self.window <= self.burn_in:
            raise InputError(f"window ({self.window}) must be longer than burn_in ({self.burn_in})")

    def dataset(self, data: GarmentSequences) -> WindowDataset:
        """The windows of ``data`` with these settings."""
        return WindowDataset(data, self.window, self.stride, self.burn_in)
