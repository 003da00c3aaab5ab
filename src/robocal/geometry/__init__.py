"""Rigid-body geometry: SO(3)/SE(3), reflections, registration and geometric fits.

Conventions: ``T_a_b`` maps frame-b points into frame a; quaternions are
scalar-last ``(x, y, z, w)``; angles in radians, lengths in metres.

The names are imported from their submodule on first access (PEP 562,
:func:`robocal._lazy.lazy_exports`): a caller that needs ``wrap_angle`` or
``rigid_fit`` (the flow rig's odometry) does not build the geometric fits'
and the pose covariance's dataclasses (~1 ms each; issue 16, a command's fixed
cost). ``from robocal.geometry import X``, ``import *``, ``dir()`` and
``__all__`` are as with the eager package; a test checks the table below
against each submodule's ``__all__``.
"""

from robocal._lazy import lazy_exports

#: exported name -> submodule defining it, in the order of the eager package's star imports
_EXPORTS = {
    **dict.fromkeys(("skew", "unskew", "matrix_from_angle", "rotx", "roty", "rotz", "matrix_from_rotvec",
                     "rotvec_from_matrix", "matrix_from_quaternion", "quaternion_from_matrix", "matrix_from_euler",
                     "euler_from_matrix", "matrix_from_gibbs", "gibbs_from_matrix", "compose_gibbs", "rotation_angle",
                     "rotation_distance", "project_to_rotation", "small_rotation_update", "so3_left_jacobian",
                     "wrap_angle"), "_so3"),
    **dict.fromkeys(("transform_from", "transform_from_translation", "rotation_from_transform",
                     "translation_from_transform", "rotation_of", "translation_of", "invert_transform", "compose",
                     "apply_transform", "apply_rotation", "transform_from_pq", "pq_from_transform",
                     "transform_from_rotvec", "rotvec_translation_from_transform", "translation_transform"), "_se3"),
    **dict.fromkeys(("householder_from_normal", "reflection_from_plane", "householder_matrix", "reflection_transform",
                     "reflect_points", "reflect_frame"), "_reflection"),
    **dict.fromkeys(("RigidFit", "wahba_rotation", "rigid_fit", "rigid_fit_rotation_crb", "rigid_fit_covariance"),
                    "_registration"),
    **dict.fromkeys(("LineFit", "PlaneFit", "Circle2DFit", "Circle3DFit", "SphereFit", "fit_line", "fit_plane",
                     "fit_circle_2d", "fit_circle_3d", "fit_sphere"), "_fits"),
    **dict.fromkeys(("PoseWithCovariance", "PoseError", "POSE_PARAMS"), "_pose_cov"),
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
