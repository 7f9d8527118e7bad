"""Motions: the Motion type, procedural generators, BVH and AMASS import with retargeting."""

from loosefit.motion.motion import DEFAULT_FPS, Motion

__all__ = ["Motion", "DEFAULT_FPS"]
