"""Rigid-body geometry: SO(3)/SE(3), reflections, registration and geometric fits.

Conventions: ``T_a_b`` maps frame-b points into frame a; quaternions are
scalar-last ``(x, y, z, w)``; angles in radians, lengths in metres.
"""

from robocal.geometry._so3 import *  # noqa: F401,F403
from robocal.geometry._se3 import *  # noqa: F401,F403
from robocal.geometry._reflection import *  # noqa: F401,F403
from robocal.geometry._registration import *  # noqa: F401,F403
from robocal.geometry._fits import *  # noqa: F401,F403
from robocal.geometry._pose_cov import *  # noqa: F401,F403
from robocal.geometry import _so3, _se3, _reflection, _registration, _fits, _pose_cov

__all__ = [*_so3.__all__, *_se3.__all__, *_reflection.__all__, *_registration.__all__, *_fits.__all__,
           *_pose_cov.__all__]
