"""Kinematics: D-H serial chains, kinematic trees of named joints, URDF I/O.

* :class:`DHChain` / :class:`DHLink` -- serial chains from Denavit-Hartenberg
  tables in the standard or modified (Craig) convention (seed 000, Table 1 and
  eq. 5), with forward kinematics, the geometric Jacobian and the exact
  Jacobian w.r.t. the table's calibration parameters.
* :class:`KinematicTree` / :class:`Joint` / :class:`Mimic` -- trees of named
  links (a humanoid: torso -> legs, torso -> head -> camera), with mimic
  (tied) joints, joint zero offsets and their Jacobians (seed 001).
* :func:`tree_from_urdf` / :func:`urdf_from_tree` -- URDF loading and writing.

Conventions (``docs/conventions.md``): ``T_a_b`` maps frame-b points into
frame a; metres and radians; Jacobian columns are twists ``[d t; w]`` in the
reference frame with ``dR @ R^T = [w]_x``. Every function is vectorised over
leading axes of the joint values.
"""

from robocal.kinematics._dh import *  # noqa: F401,F403
from robocal.kinematics._joint import *  # noqa: F401,F403
from robocal.kinematics._tree import *  # noqa: F401,F403
from robocal.kinematics._urdf import *  # noqa: F401,F403
from robocal.kinematics import _dh, _joint, _tree, _urdf

__all__ = [*_dh.__all__, *_joint.__all__, *_tree.__all__, *_urdf.__all__]
