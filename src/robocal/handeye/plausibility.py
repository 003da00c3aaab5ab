"""Plausibility of two pose lists (issue 18): the slip behind an implausible pair, named in one line.

From the closed-form closure ``T_base_gripper[i] X T_cam_target[i] = Y``
(:func:`closure_residuals`): a rotation residual that an inverted list or
scalar-first quaternions explain, translations in the wrong unit. See
:func:`judge_poses`.
"""

from __future__ import annotations

import math

import numpy as np

from robocal.errors import DegenerateGeometryError
from robocal.geometry import invert_transform, project_to_rotation, rotvec_from_matrix, transform_from
from robocal.handeye._lie import log_so3
from robocal.handeye.axxb import _check_method, _solve_checked
from robocal.handeye.motions import _check_poses, _motions, _pose_residual, pair_indices, relative_motions

__all__ = ["TRANS_ROT_RATIO_MAX", "TRANS_FLOOR", "ROT_TRY", "REACH_FACTOR", "ROT_IMPLAUSIBLE", "SWAP_CANDIDATES",
           "closure_residuals", "judge_poses"]

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
#: rotation residual (rad) that no slip explains but is refused anyway (5.7 deg: a camera on a robot
#: gives well below 1 deg; one outlier pose of 4 deg among 20 gives ~1 deg RMS)
ROT_IMPLAUSIBLE = 0.1
#: how many of the worst poses (by each of two figures) are tried pairwise for a swap (<= 45 closed forms)
SWAP_CANDIDATES = 5


def closure_residuals(T_base_gripper, T_cam_target, method: str = "tsai", *, pairs: str = "consecutive"):
    """Closed-form X and the RMS closure residuals ``(rot_rms rad, trans_rms m, X)`` of two pose lists.

    ``Y`` is the mean of ``T_base_gripper[i] X T_cam_target[i]`` (the fixed target); the residuals are
    each pose's deviation from it (rotation vector, translation).
    """
    Tg, Tc = np.asarray(T_base_gripper, float), np.asarray(T_cam_target, float)
    A, B = relative_motions(Tg, Tc, pairs=pairs)
    return _closure_residuals(Tg, Tc, A, B, _check_method(method), pairs)


def _closure_residuals(Tg, Tc, A, B, m: str, pairs: str):
    """:func:`closure_residuals` on validated poses and their motions (``m`` a checked method name): the
    plausibility check calls it once per slip tried, on transforms of poses already validated."""
    try:
        X, _ = _solve_checked(A, B, m)
    except DegenerateGeometryError:
        if pairs != "consecutive":
            raise
        # consecutive motions about one axis can still span several with more pairs
        X, _ = _solve_checked(*_motions(Tg, Tc, *pair_indices(Tg, "auto")), m)
    Yall = Tg @ X @ Tc
    Ry, ty = project_to_rotation(np.mean(Yall[:, :3, :3], axis=0)), Yall[:, :3, 3].mean(axis=0)
    # _pose_residual's figures with the NumPy log map: products of validated poses need none of SciPy
    # Rotation's validation (~0.15 ms a call, once per slip tried)
    r_rot = log_so3(Yall[:, :3, :3] @ Ry.T)
    return float(np.sqrt(np.mean(r_rot ** 2))), float(np.sqrt(np.mean((Yall[:, :3, 3] - ty) ** 2))), X


def _translations_plausible(Tg, Tc, rot_rms, trans_rms, X, floor: float = TRANS_FLOOR) -> tuple[bool, str]:
    # the sums np.mean / np.linalg.norm take, without their wrappers (issue 16: every calibration asks)
    tx = math.sqrt(float(X[:3, 3] @ X[:3, 3]))
    tc2 = np.einsum("ij,ij->i", Tc[:, :3, 3], Tc[:, :3, 3])
    lever = math.sqrt(float(tc2.sum()) / len(tc2)) + tx
    reach = max(math.sqrt(float(np.einsum("ij,ij->i", Tg[:, :3, 3], Tg[:, :3, 3]).max())), 0.2)
    if tx > max(2.0, REACH_FACTOR * reach):
        return False, (f"the camera comes out {tx:.3g} m from the gripper, more than {REACH_FACTOR:g} x the "
                       f"gripper's largest distance from the base ({reach:.3g} m)")
    if trans_rms > floor and trans_rms > TRANS_ROT_RATIO_MAX * rot_rms * lever:
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


def _swap_slips(Tg, Tc, X, lever, closure_of, names, times, k: int = SWAP_CANDIDATES) -> list:
    """Slips "poses a and b swapped (mispaired)" for the ``k`` poses with the largest closure residual.

    A swap spoils exactly two poses; any other pose keeps its closure. Up to 10 poses every pair is tried;
    beyond, the ``k`` worst by closure residual and the ``k`` worst by the angle mismatch of their
    consecutive motions, when the worst stands out (> 5 x the median). Each candidate pair costs one closed
    form on consecutive pairs.
    """
    from robocal.handeye.motions import pose_label
    from robocal.plausibility import Slip

    Yall = Tg @ X @ Tc
    Y = transform_from(project_to_rotation(np.mean(Yall[:, :3, :3], axis=0)), np.median(Yall[:, :3, 3], axis=0))
    r = _pose_residual(Yall, Y[None])
    per = np.hypot(np.linalg.norm(r[:, :3], axis=1), np.linalg.norm(r[:, 3:], axis=1) / lever)
    # the closed-form X is itself spoilt by the swap; the angle mismatch of the consecutive motions
    # (|angle A - angle B|, the motion check's figure) does not depend on X: a swapped pose spoils both
    # of its motions
    A, B = relative_motions(Tg, Tc, pairs="consecutive")
    mis = np.abs(np.linalg.norm(rotvec_from_matrix(A[:, :3, :3]), axis=1)
                 - np.linalg.norm(rotvec_from_matrix(B[:, :3, :3]), axis=1))
    per_m = np.r_[mis, 0.0] + np.r_[0.0, mis]
    n = len(per)
    if n <= 10:
        worst = np.arange(n)                     # 45 closed forms at most
    elif per.max() > 5 * np.median(per) or per_m.max() > 5 * np.median(per_m):
        worst = np.unique(np.r_[np.argsort(per)[::-1][:k], np.argsort(per_m)[::-1][:k]])
    else:
        return []
    out = []
    gname, tname = names
    for ia in range(len(worst)):
        for ib in range(ia + 1, len(worst)):
            a, b = sorted((int(worst[ia]), int(worst[ib])))

            def swapped(a=a, b=b):
                T = Tc.copy()
                T[[a, b]] = T[[b, a]]
                return closure_of(Tg, T)
            out.append(Slip("poses_swapped",
                            f"{pose_label(a, times)} and {pose_label(b, times)} look swapped: pose {a} of {gname} "
                            f"pairs with pose {b} of {tname} and the other way round",
                            "with the two swapped", swapped))
    return out


def judge_poses(T_base_gripper, T_cam_target, *, names=("T_base_gripper", "T_cam_target"),
                method: str = "tsai", accept: bool = False, source: str | None = None, times=None) -> list:
    """Judge two pose lists before calibration; name the slip when they are implausible.

    Two cheap figures of the closed-form closure (:func:`closure_residuals`, consecutive pairs):

    * **rotation residual**: above :data:`ROT_TRY` the lists are tried inverted (``T_a_b`` given as
      ``T_b_a``), with scalar-first quaternions, and with two poses swapped (the
      :data:`SWAP_CANDIDATES` worst poses pairwise, when the worst stands out); one that lowers the
      closure residual (rotation and translation over the lever, in mrad) 5 x is named. Above
      :data:`ROT_IMPLAUSIBLE` with no slip explaining it the lists are refused all the same.
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
    times : array_like, shape (N,), optional
        The poses' times (s), to name swapped poses.
    accept : bool
        ``--accept-implausible``: a warning instead of :class:`~robocal.errors.ImplausibleInputError`.

    Returns
    -------
    list of Diagnostic
        Empty when plausible; one ``implausible_input`` warning when accepted.
    """
    Tg, Tc = _check_poses(T_base_gripper, names[0]), _check_poses(T_cam_target, names[1])
    return _judge_checked(Tg, Tc, names=names, method=_check_method(method), accept=accept, source=source,
                          times=times)


def _judge_checked(Tg, Tc, *, names=("T_base_gripper", "T_cam_target"), method: str = "tsai", accept: bool = False,
                   source: str | None = None, times=None, closed_form=None) -> list:
    """:func:`judge_poses` on poses already validated (:func:`~.motions._check_poses`) and a checked method
    name: :func:`~robocal.handeye.calibrate_hand_eye` validates the lists once for both (issue 16).

    ``closed_form``: ``(rot_rms, trans_rms, X)`` of the caller's closed form on more pose pairs, its closure
    figures as :func:`closure_residuals` defines them. When they pass both tests outright (rotation residual
    below :data:`ROT_TRY`; translation residual within :data:`TRANS_ROT_RATIO_MAX` of the rotation's over the
    lever *without* the :data:`TRANS_FLOOR` allowance, X within reach) the lists are plausible without a
    closed form of their own (~20 % of a 15-pose calibration, issue 16): an X exists that makes them one
    consistent set-up, which is what the tests ask. The floor is not granted here because it is an
    allowance for noise, not evidence: a target list in m read as mm gives 5.6 mm on all pairs of the
    example (below the floor) but 13 mm on consecutive ones, and is named. Otherwise the lists are judged as
    :func:`judge_poses` does (its own closed form on consecutive pairs, the slips tried against it).
    """
    if closed_form is not None:
        rot0, trans0, X0 = closed_form
        if rot0 <= ROT_TRY and _translations_plausible(Tg, Tc, rot0, trans0, X0, floor=0.0)[0]:
            return []
    from robocal.plausibility import Slip, check_slips

    m = method

    def closure_residuals(a, b, _method=None):
        # the lists are validated once above; every slip tried is a rigid transform of them (inverted,
        # re-read quaternions, swapped, scaled), so the trials skip validation (issue 16: this check ran
        # the closed form ~10 times per calibration, a third of its time)
        return _closure_residuals(a, b, *_motions(a, b, *pair_indices(a, "consecutive")), m, "consecutive")

    rot, trans, X = closure_residuals(Tg, Tc)
    out = []
    gname, tname = names

    # the figure the rotation-type slips are ranked by: the rotation residual and the translation residual
    # over the lever (|t_cam_target| is the same for a pose and its inverse, so one lever for every trial).
    # The rotations alone often cannot tell an inverted target list from an inverted gripper list or
    # scalar-first quaternions (each turns the rotation residual back to the noise); the translations can.
    lever = max(float(np.sqrt(np.mean(np.sum(Tc[:, :3, 3] ** 2, axis=1)))), 0.05)

    def closure_of(a, b):
        r, t, _ = closure_residuals(a, b, method)
        return 1e3 * float(np.hypot(r, t / lever))

    base = 1e3 * float(np.hypot(rot, trans / lever))
    what = f"closure residual (rotation and translation over the {lever:.3g} m lever)"
    if rot > ROT_TRY:
        rslips = [
            Slip("target_poses_inverted", f"the poses of {tname} look inverted (T_target_cam given as T_cam_target)",
                 "with them inverted", lambda: closure_of(Tg, invert_transform(Tc))),
            Slip("gripper_poses_inverted", f"the poses of {gname} look inverted (T_gripper_base given as "
                 "T_base_gripper), or the set-up is the other one (--setup eye-in-hand / eye-to-hand)",
                 "with them inverted", lambda: closure_of(invert_transform(Tg), Tc)),
            Slip("target_quaternion_scalar_first", f"the quaternions of {tname} look scalar-first (w, x, y, z), "
                 "not scalar-last", "with (w, x, y, z) read", lambda: closure_of(Tg, _quat_scalar_first(Tc))),
            Slip("gripper_quaternion_scalar_first", f"the quaternions of {gname} look scalar-first (w, x, y, z), "
                 "not scalar-last", "with (w, x, y, z) read", lambda: closure_of(_quat_scalar_first(Tg), Tc)),
            *_swap_slips(Tg, Tc, X, lever, closure_of, names, times),
        ]
        # on a poorly excited set (small rotations about few axes) several may explain the data about
        # equally: the best is named, the others within 10 % listed, rather than a guess
        from dataclasses import replace as _replace

        from robocal.plausibility import try_slips

        trial = try_slips(rslips, base, unit="mrad")
        if trial.best is not None:
            also = list(dict.fromkeys(n for n, v in trial.tried if v is not None and n != trial.best.name
                                      and v <= 1.1 * trial.best_value))
            describe = trial.best.describe if not also else \
                f"{trial.best.describe} (or, as well explained by these motions: {', '.join(also)})"
            named = _replace(trial, best=_replace(trial.best, describe=describe))
            d = check_slips(what=what, residual=base, unit="mrad", plausible=False,
                            reason="", trial=named, accept=accept, source=source)
            out.append(d)
            return out
        if rot > ROT_IMPLAUSIBLE:
            # no slip explains it, but no rigid set-up turns the two lists into one fixed target either;
            # the message lists each kind of slip once (the swap was tried for many pose pairs)
            best: dict = {}
            for nm, v in trial.tried:
                best[nm] = v if best.get(nm) is None else (best[nm] if v is None else min(best[nm], v))
            trial = _replace(trial, tried=tuple(best.items()))
            out.append(check_slips(
                what=what, residual=base, unit="mrad", plausible=False, trial=trial, accept=accept, source=source,
                reason=(f"the rotation residual of {gname} and {tname} is {np.rad2deg(rot):.3g} deg RMS (a "
                        f"camera on a robot: well below 1 deg): the two lists do not describe one camera on one "
                        f"gripper viewing one fixed target")))
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
