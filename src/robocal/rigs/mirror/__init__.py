"""Rig ``mirror``: camera-to-robot-body ("foot-eye") calibration from a plane mirror (seed 002).

One image of a plane mirror carrying four markers (a known rectangle) in which
the camera sees the reflection of feature points on the robot body gives the
camera pose in the robot frame. See ``docs/rigs/mirror.md``.
"""

from robocal.rigs.mirror.model import *  # noqa: F401,F403
from robocal.rigs.mirror import model as _model

__all__ = [*_model.__all__]
