"""Model-agnostic training: typed config, stages, logs, checkpoints and exact resume."""

from loosefit.train.protocol import TrainableModel
from loosefit.train.run import RunDir, load_checkpoint, load_weights, save_checkpoint
from loosefit.train.seeding import seed_everything
from loosefit.train.settings import StageConfig, TrainConfig, TrainResult
from loosefit.train.trainer import TrainingError, train

__all__ = [
    "TrainableModel",
    "RunDir",
    "load_checkpoint",
    "load_weights",
    "save_checkpoint",
    "seed_everything",
    "StageConfig",
    "TrainConfig",
    "TrainingError",
    "TrainResult",
    "train",
]
