"""Plausibility of two pose lists (issue 18): the slip behind an implausible pair, named in one line.

From the closed-form closure ``T_base_gripper[i] X T_cam_target[i] = Y``
(:func:`closure_residuals`): a rotation residual that an inverted list or
scalar-first quaternions explain, translations in the wrong unit. See
:func:`judge_poses`.
"""

from __future__ import annotations

import numpy as np

from robocal.errors import DegenerateGeometryError
from robocal.geometry import invert_transform, project_to_rotation, transform_from
from robocal.handeye.axxb import solve_ax_xb
from robocal.handeye.motions import _pose_residual, relative_motions

__all__ = ["TRANS_ROT_RATIO_MAX", "TRANS_FLOOR", "ROT_TRY", "REACH_FACTOR", "closure_residuals", "judge_poses"]

# Plausibility of the pose lists (:func:`judge_poses`). The closure T_base_gripper X T_cam_target = Y
# turns a rotation error d into a translation error of about d times the lever (the target's distance
# from the camera plus the camera's from the gripper), so with consistent data the translation RMS is
# about the rotation RMS times the lever (the shipped example: ratio 1.1). A unit slip on one list's
# translations breaks that (target in mm: ratio 28, gripper in mm: 2.8e4); a translation-only noise
# source can too, hence the absolute floor below which no translation residual is judged.
#: translation residual / (rotation residual x lever) above which the translations are implausible
TRANS_ROT_RATIO_MAX = 10.0
#: translation residual (m) below which the translations are never judged implausible
TRANS_FLOOR = 0.01
#: rotation residual (rad) above which pose inversions / quaternion orders are tried (0.17 deg:
#: the example has 0.72 mrad; an inverted list 11 mrad, scalar-first quaternions 10.5 mrad)
ROT_TRY = 3e-3
#: a camera farther from the gripper than this many times the robot's reach is implausible
REACH_FACTOR = 10.0


def closure_residuals(T_base_gripper, T_cam_target, method: str = "tsai", *, pairs: str = "consecutive"):
    """Closed-form X and the RMS closure residuals ``(rot_rms rad, trans_rms m, X)`` of two pose lists.

    ``Y`` is the mean of ``T_base_gripper[i] X T_cam_target[i]`` (the fixed target); the residuals are
    each pose's deviation from it (rotation vector, translation).
    """
    Tg, Tc = np.asarray(T_base_gripper, float), np.asarray(T_cam_target, float)
    A, B = relative_motions(Tg, Tc, pairs=pairs)
    try:
        X, _ = solve_ax_xb(A, B, method)
    except DegenerateGeometryError:
        if pairs != "consecutive":
            raise
        # consecutive motions about one axis can still span several with more pairs
        X, _ = solve_ax_xb(*relative_motions(Tg, Tc, pairs="auto"), method)
    Yall = Tg @ X @ Tc
    Y = transform_from(project_to_rotation(np.mean(Yall[:, :3, :3], axis=0)), Yall[:, :3, 3].mean(axis=0))
    r = _pose_residual(Yall, Y[None])
    return float(np.sqrt(np.mean(r[:, :3] ** 2))), float(np.sqrt(np.mean(r[:, 3:] ** 2))), X


def _translations_plausible(Tg, Tc, rot_rms, trans_rms, X) -> tuple[bool, str]:
    lever = float(np.sqrt(np.mean(np.sum(Tc[:, :3, 3] ** 2, axis=1)))) + float(np.linalg.norm(X[:3, 3]))
    reach = max(float(np.max(np.linalg.norm(Tg[:, :3, 3], axis=1))), 0.2)
    tx = float(np.linalg.norm(X[:3, 3]))
    if tx > max(2.0, REACH_FACTOR * reach):
        return False, (f"the camera comes out {tx:.3g} m from the gripper, more than {REACH_FACTOR:g} x the "
                       f"gripper's largest distance from the base ({reach:.3g} m)")
    if trans_rms > TRANS_FLOOR and trans_rms > TRANS_ROT_RATIO_MAX * rot_rms * lever:
        return False, (f"the translation residual {1e3 * trans_rms:.3g} mm is {trans_rms / max(rot_rms * lever, 1e-300):.3g} x "
                       f"what the rotation residual {1e3 * rot_rms:.3g} mrad gives over the {lever:.3g} m lever "
                       f"(consistent poses: about 1, plausible <= {TRANS_ROT_RATIO_MAX:g})")
    return True, ""


def _quat_scalar_first(T):
    """The rotations a file meant when its qx, qy, qz, qw columns held w, x, y, z."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(T[:, :3, :3]).as_quat()        # what was read, scalar-last (x', y', z', w')
    out = np.array(T, float, copy=True)
    out[:, :3, :3] = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    return out


def judge_poses(T_base_gripper, T_cam_target, *, names=("T_base_gripper", "T_cam_target"),
                method: str = "tsai", accept: bool = False, source: str | None = None) -> list:
    """Judge two pose lists before calibration; name the slip when they are implausible.

    Two cheap figures of the closed-form closure (:func:`closure_residuals`, consecutive pairs):

    * **rotation residual**: above :data:`ROT_TRY` the lists are tried inverted (``T_a_b`` given as
      ``T_b_a``) and with scalar-first quaternions; one that lowers the residual 5 x is named.
    * **translations**: the translation residual against the rotation residual times the lever
      (:data:`TRANS_ROT_RATIO_MAX`, above :data:`TRANS_FLOOR`), and ``|t_gripper_cam|`` against the
      robot's reach (:data:`REACH_FACTOR`); when implausible, each list's translations are tried
      /1000 and x1000 (mm <-> m).

    Parameters
    ----------
    T_base_gripper, T_cam_target : array_like, shape (N, 4, 4)
        As read (metres).
    names : (str, str)
        The two lists' files, for the message.
    accept : bool
        ``--accept-implausible``: a warning instead of :class:`~robocal.errors.ImplausibleInputError`.

    Returns
    -------
    list of Diagnostic
        Empty when plausible; one ``implausible_input`` warning when accepted.
    """
    from robocal.plausibility import Slip, check_slips

    Tg, Tc = np.asarray(T_base_gripper, float), np.asarray(T_cam_target, float)
    rot, trans, X = closure_residuals(Tg, Tc, method)
    out = []
    gname, tname = names

    def rot_of(a, b):
        return 1e3 * closure_residuals(a, b, method)[0]

    if rot > ROT_TRY:
        rslips = [
            Slip("target_poses_inverted", f"the poses of {tname} look inverted (T_target_cam given as T_cam_target)",
                 "with them inverted", lambda: rot_of(Tg, invert_transform(Tc))),
            Slip("gripper_poses_inverted", f"the poses of {gname} look inverted (T_gripper_base given as "
                 "T_base_gripper)", "with them inverted", lambda: rot_of(invert_transform(Tg), Tc)),
            Slip("target_quaternion_scalar_first", f"the quaternions of {tname} look scalar-first (w, x, y, z), "
                 "not scalar-last", "with (w, x, y, z) read", lambda: rot_of(Tg, _quat_scalar_first(Tc))),
            Slip("gripper_quaternion_scalar_first", f"the quaternions of {gname} look scalar-first (w, x, y, z), "
                 "not scalar-last", "with (w, x, y, z) read", lambda: rot_of(_quat_scalar_first(Tg), Tc)),
        ]
        # on a poorly excited set (small rotations about few axes) several may explain the data about
        # equally: the best is named, the others within 10 % listed, rather than a guess
        from dataclasses import replace as _replace

        from robocal.plausibility import try_slips

        trial = try_slips(rslips, 1e3 * rot, unit="mrad")
        if trial.best is not None:
            also = [n for n, v in trial.tried if v is not None and n != trial.best.name
                    and v <= 1.1 * trial.best_value]
            describe = trial.best.describe if not also else \
                f"{trial.best.describe} (or, as well explained by these motions: {', '.join(also)})"
            named = _replace(trial, best=_replace(trial.best, describe=describe))
            d = check_slips(what="rotation residual", residual=1e3 * rot, unit="mrad", plausible=False,
                            reason="", trial=named, accept=accept, source=source)
            out.append(d)
            return out
    ok, reason = _translations_plausible(Tg, Tc, rot, trans, X)
    if ok:
        return out

    def trans_of(a, b):
        # scaling both lists alike keeps them consistent, so the undone slip must also give physical
        # sizes: a gripper within 2 cm..20 m of the base, a target 5 mm..100 m from the camera
        reach = float(np.max(np.linalg.norm(a[:, :3, 3], axis=1)))
        dist = float(np.median(np.linalg.norm(b[:, :3, 3], axis=1)))
        if not (0.02 <= reach <= 20.0 and 0.005 <= dist <= 100.0):
            return np.nan
        r, t, x = closure_residuals(a, b, method)
        return 1e3 * t if _translations_plausible(a, b, r, t, x)[0] else np.nan

    def scaled(T, k):
        T = np.array(T, float, copy=True)
        T[:, :3, 3] *= k
        return T

    tslips = [
        Slip("target_mm_as_m", f"x, y, z of {tname} look like mm, not m", "with /1000",
             lambda: trans_of(Tg, scaled(Tc, 1e-3))),
        Slip("gripper_mm_as_m", f"x, y, z of {gname} look like mm, not m", "with /1000",
             lambda: trans_of(scaled(Tg, 1e-3), Tc)),
        Slip("both_mm_as_m", f"x, y, z of {gname} and {tname} look like mm, not m", "with /1000",
             lambda: trans_of(scaled(Tg, 1e-3), scaled(Tc, 1e-3))),
        Slip("target_m_as_mm", f"x, y, z of {tname} look like m, not mm", "with x1000",
             lambda: trans_of(Tg, scaled(Tc, 1e3))),
        Slip("gripper_m_as_mm", f"x, y, z of {gname} look like m, not mm", "with x1000",
             lambda: trans_of(scaled(Tg, 1e3), Tc)),
    ]
    d = check_slips(what="translation residual", residual=1e3 * trans, unit="mm", plausible=False, reason=reason,
                    slips=tslips, accept=accept, source=source)
    out.append(d)
    return out
