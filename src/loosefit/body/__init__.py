"""Body models behind one interface: Anny (default) and SMPL / SMPL-X through smplx."""

from loosefit.body.anny_body import AnnyBody, AnnyShape
from loosefit.body.base import BodyModel, PosedBody

__all__ = ["BodyModel", "PosedBody", "AnnyBody", "AnnyShape", "default_body"]


def default_body(shape: AnnyShape | str | None = None) -> AnnyBody:
    """The default body: Anny, full resolution, rig ``cmu_mb``; ``shape`` as AnnyShape or ``"gender=0.8,..."``."""
    if isinstance(shape, str):
        shape = AnnyShape.parse(shape)
    return AnnyBody(shape)
