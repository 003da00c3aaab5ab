"""Hand-eye calibration, a core capability: AX = XB (eye-in-hand) and AX = ZB (robot-world).

Frames and names (see ``docs/conventions.md``: ``T_a_b`` maps b into a):

* eye-in-hand, absolute poses: ``T_base_gripper[i]`` from the robot and
  ``T_cam_target[i]`` from the sensor; unknown ``X = T_gripper_cam`` and the
  fixed target ``Y = T_base_target = T_base_gripper[i] X T_cam_target[i]``.
  These are OpenCV's ``R/t_gripper2base``, ``R/t_target2cam`` and
  ``R/t_cam2gripper`` (``cv2.calibrateHandEye``).
* relative motions: for a pair (i, j), ``A = T_base_gripper[j]^-1 T_base_gripper[i]``
  (gripper motion) and ``B = T_cam_target[j] T_cam_target[i]^-1`` (sensor
  motion) satisfy ``A X = X B``.
* robot-world: ``A[i] X = Z B[i]`` with ``A = T_cam_world``,
  ``B = T_gripper_base``, ``X = T_world_base`` and ``Z = T_cam_gripper``
  (``cv2.calibrateRobotWorldHandEye``'s ``world2cam``, ``base2gripper``,
  ``base2world``, ``gripper2cam``).

Closed-form rotation solvers: Tsai-Lenz (modified Rodrigues vectors),
Park-Martin (log map / orthogonal Procrustes), Horaud-Dornaika (unit
quaternions, eigenvector), Andreff (Kronecker null space), Daniilidis (dual
quaternions, rotation and translation together); Shah (Kronecker) for AX = ZB.
Every solver can be followed by a nonlinear refinement on all poses
(:mod:`robocal.estimation`), which gives the covariance.

Modules: :mod:`.motions` (pose pairs, relative motions, the excitation check),
:mod:`.axxb` (closed-form AX = XB), :mod:`.refine` (AX = XB refined, with
covariance; :func:`invert_with_covariance`), :mod:`.axzb` (robot-world AX =
ZB), :mod:`.plausibility` (:func:`judge_poses`: the slip behind implausible
pose lists), :mod:`.simulate` (simulated pose lists with their truth).
Everything below is importable from this package (lazily: ``robocal handeye
--help`` imports none of it). The functions take pose arrays only (no file, no
rig): the command's steps are in :mod:`.workflow`, its declaration ``HANDEYE``
in :mod:`.cli`. A pose with its covariance (inverse, error to a truth, result
fields) is :class:`robocal.geometry.PoseWithCovariance`. Docs:
``docs/handeye.md``.

Degenerate motion sets are refused, never answered with an identity: if every
relative rotation is below ``min_rotation``, or all rotation axes are parallel
(planar motion of a mobile robot, seed 002; a single revolute joint), a
:class:`~robocal.errors.DegenerateGeometryError` names the undetermined part
(rotation about the common axis from rotations alone, translation along it).

References
----------
R. Tsai, R. Lenz, IEEE T-RA 5(3), 1989. F. Park, B. Martin, IEEE T-RA 10(5),
1994. R. Horaud, F. Dornaika, IJRR 14(3), 1995. N. Andreff, R. Horaud,
B. Espiau, 3DIM 1999. K. Daniilidis, IJRR 18(3), 1999. M. Shah, J. Mech. Rob.
5(3), 2013.
"""

from robocal._lazy import lazy_exports

_EXPORTS = {
    "AXXB_METHODS": "axxb", "solve_ax_xb": "axxb",
    "RobotWorldResult": "axzb", "calibrate_robot_world": "axzb",
    "MAX_ALL_PAIRS": "motions", "MAX_LONG_PAIRS": "motions", "LONG_PAIR_ANGLES": "motions",
    "PAIR_MODES": "motions", "pair_indices": "motions", "pose_label": "motions",
    "MIN_AXIS_SPREAD": "motions", "MIN_ROTATION": "motions",
    "WEAK_AXIS_SPREAD": "motions", "MotionCheck": "motions", "check_motions": "motions",
    "relative_motions": "motions", "transform_error": "motions",
    "REACH_FACTOR": "plausibility", "ROT_TRY": "plausibility", "TRANS_FLOOR": "plausibility",
    "TRANS_ROT_RATIO_MAX": "plausibility", "closure_residuals": "plausibility", "judge_poses": "plausibility",
    "HandEyeResult": "refine", "calibrate_hand_eye": "refine", "invert_with_covariance": "refine",
    "HandEyeSimulation": "simulate", "simulate_eye_in_hand": "simulate", "simulate_eye_to_hand": "simulate",
    "SETUPS": "refine", "ViewPoses": "images", "view_poses": "images",
}

__all__ = list(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
