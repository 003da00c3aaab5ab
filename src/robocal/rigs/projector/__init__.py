"""Rig ``projector``: ceiling pan-tilt laser projector (seed 000).

D-H model, inverse kinematics and Jacobians (:mod:`.model`); world-to-projector
extrinsic calibration by the seed's method, the optimal closed form and
nonlinear least squares (:mod:`.calibrate`); the seed's Table 2 evaluation
(:mod:`.evaluate`); spot paths over one or several projectors (:mod:`.path`);
simulation (:mod:`.simulate`) and the command line (:mod:`.cli`).
"""

from robocal.rigs.projector.model import *  # noqa: F401,F403
from robocal.rigs.projector import model as _model

__all__ = [*_model.__all__]
