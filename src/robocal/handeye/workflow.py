"""The ``handeye`` workflow's steps (:mod:`robocal.workflow`): two pose lists -> X = T_gripper_cam.

``robocal handeye calibrate GRIPPER TARGET`` (AX = XB, one closed form then the
refinement) and ``robocal handeye robot-world GRIPPER TARGET`` (AX = ZB) over
the library :mod:`robocal.handeye`; ``simulate`` writes the
two lists with their truth (:func:`.simulate.simulate_eye_in_hand`). The
declaration is ``HANDEYE`` in :mod:`.cli`. Errors a solver raises without a
file are named with both lists by the core (``gripper.csv + target.csv``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal.io import CalibrationResult, hash_inputs
from robocal.progress import progress as _progress

__all__ = ["SOLVER_FIELDS", "solver_record", "PosePair", "load_pose_pair", "calibrate", "to_result", "robot_world",
           "robot_world_result", "summary", "simulate_files", "run_robot_world"]

# the report and the image commands live in their own modules (.report, .commands); their names stay
# importable from here, where the declaration and older code found them
def __getattr__(name):
    if name == "build_report":
        from robocal.handeye.report import build_report
        return build_report
    if name in ("run_images", "run_simulate_images"):
        from robocal.handeye import commands
        return getattr(commands, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

_LABELS = ("rx", "ry", "rz", "tx", "ty", "tz")


@dataclass
class PosePair:
    """Two pose lists paired pose by pose: ``T_base_gripper`` and ``T_cam_target`` (N, 4, 4), metres."""

    T_base_gripper: np.ndarray
    T_cam_target: np.ndarray
    gripper_path: Path
    target_path: Path
    t: np.ndarray | None = None
    forms: tuple[str, str] = ("", "")
    #: two timed streams as paired by :func:`load_pose_pair` (:class:`~robocal.handeye.clock.StreamPairing`:
    #: the robot stream, the clock offset, the samples dropped and cropped); None for lists paired pose by pose
    stream: object = None

    @property
    def names(self) -> tuple[str, str]:
        return self.gripper_path.name, self.target_path.name

    @property
    def files(self) -> list[Path]:
        return [self.gripper_path, self.target_path]


#: The fields of :meth:`robocal.estimation.LSQResult.to_dict` the report's solver section shows (the full
#: record holds every residual and the covariance).
SOLVER_FIELDS = ("method", "loss", "message", "status", "iterations", "nfev", "cost_history", "cost", "rms",
                 "rank", "free_labels", "condition_number", "outlier_sigma")


def solver_record(lsq) -> dict:
    """The solver's record for :func:`robocal.report.solver_section`: :data:`SOLVER_FIELDS` of ``lsq.to_dict()``."""
    if lsq is None:
        return {}
    d = lsq.to_dict()
    return {k: d[k] for k in SOLVER_FIELDS if k in d}


def _stages(desc: str, n: int, enabled: bool = True):
    """A stage bar on a terminal (10^4 poses: ~8 s to read, ~15 s to solve): ``tick()`` starts the next stage."""
    it = iter(_progress(range(n), desc=desc, total=n, enabled=enabled))
    return lambda: next(it, None)


def load_pose_pair(gripper_poses=None, target_poses=None, *, bag=None, clock_offset="none",
                   **bag_options) -> PosePair:
    """``T_base_gripper`` and ``T_cam_target`` from two pose-list files (CSV/YAML, scalar-last quaternions).

    The one place where two streams are paired. When both lists have timestamps that differ (or
    ``clock_offset`` is not ``"none"``), they are two streams (:func:`robocal.handeye.clock.pair_streams`):
    samples whose stamp does not advance are dropped and counted, the robot stream is resampled (SLERP +
    linear) at the sensor's times plus the clock offset (``"none"``: 0; seconds; ``"auto"``: from the
    rotation rates, then refined with X by :func:`calibrate`), and the streams are cropped to their
    overlap (counted). Without timestamps in both the counts must match (pose i with pose i) and the
    stamps of a list that has them must increase. Errors name the file(s). A recording (``bag`` and the
    ``--base/--gripper/--images/...`` options): :func:`robocal.handeye.bag_input.load_bag_pair`.
    """
    from robocal.errors import FileFormatError, InputError, RobocalError, ShapeError
    from robocal.handeye.clock import pair_streams, parse_clock_offset
    from robocal.io import load_poses

    images = bag_options.get("images")
    if bag is None and target_poses is None and images is not None and (
            gripper_poses is not None or Path(images).is_dir()):
        # a folder of images, one per robot pose (the same path as 'calibrate-images')
        from robocal.handeye.commands import load_image_pair

        return load_image_pair(gripper_poses, images, bag_options.get("camera"),
                               bag_options.get("target"))
    if bag is not None or target_poses is None or any(v is not None for v in bag_options.values()):
        from robocal.handeye.bag_input import load_bag_pair

        return load_bag_pair(bag, gripper_poses, target_poses, clock_offset=clock_offset, **bag_options)

    gripper_poses, target_poses = Path(gripper_poses), Path(target_poses)
    tick = _stages("handeye: read poses", 1)
    tick()
    mode = parse_clock_offset(clock_offset)
    # a recorded stream's stamps repeat and step back: read them as they are, drop and count below
    g = load_poses(gripper_poses, strict_times=False)
    c = load_poses(target_poses, strict_times=False)
    Tg, tg, Tc, tc = g.T, g.t, c.T, c.t
    timed = tg is not None and tc is not None
    if timed and not (mode == "none" and len(tg) == len(tc) and np.all(np.abs(tg - tc) <= 1e-9)
                      and np.all(np.diff(tc) > 0)):
        try:
            s = pair_streams(tg, Tg, tc, Tc, mode, names=(gripper_poses.name, target_poses.name))
        except RobocalError as exc:
            raise exc.with_source(f"{gripper_poses} paired by time with {target_poses}") from None
        tick()
        return PosePair(s.T_base_gripper, s.T_cam_target, gripper_poses, target_poses, s.t, (g.form, c.form), s)
    if mode != "none":
        raise InputError(f"--clock-offset {clock_offset} pairs two streams by time: both lists need timestamps ("
                         + ", ".join(str(p) for p, pl in ((gripper_poses, g), (target_poses, c)) if pl.t is None)
                         + " has none)")
    for pl, path in ((g, gripper_poses), (c, target_poses)):
        # paired pose by pose (or by equal stamps): no sample can be dropped, so a stamp slip stays an error
        if pl.t is not None and np.any(~(np.diff(pl.t) > 0)):
            k = int(np.flatnonzero(~(np.diff(pl.t) > 0))[0]) + 1
            raise FileFormatError(f"pose {k}: timestamps must increase strictly, t = {pl.t[k]:.6f} s follows "
                                  f"{pl.t[k - 1]:.6f} s (the lists pair pose by pose, so no pose can be dropped)",
                                  source=str(path))
    if len(Tg) != len(Tc):
        raise ShapeError(f"{gripper_poses} has {len(Tg)} poses but {target_poses} has {len(Tc)}: "
                         "without timestamps in both lists the counts must match (pose i with pose i)")
    tick()
    return PosePair(Tg, Tc, gripper_poses, target_poses, tc if tc is not None else tg, (g.form, c.form))


# ----------------------------------------------------------------------------- AX = XB
def _gripper(pair: PosePair, setup: str) -> np.ndarray:
    """The robot poses as the closure takes them: ``T_base_gripper`` (eye-in-hand), their inverses
    (eye-to-hand)."""
    from robocal.geometry import invert_transform

    return pair.T_base_gripper if setup == "eye-in-hand" else invert_transform(pair.T_base_gripper)


class Calibration(tuple):
    """What :func:`calibrate` returns: ``(HandEyeResult, comparison)`` as a pair (``res, comparison =
    calibrate(...)``), with ``extra``: the refined clock, the jackknife and the pairs X was estimated on
    (:func:`_clock_and_jackknife`), which :func:`to_result` writes."""

    def __new__(cls, res, comparison, extra=None):
        obj = super().__new__(cls, (res, comparison))
        obj.extra = dict(extra or {})
        return obj


def calibrate(pair: PosePair, *, method: str = "tsai", no_refine: bool = False, accept_implausible: bool = False,
              pairs: str = "auto", setup: str = "eye-in-hand", pose_sigmas=None, pose_covariances=None,
              progress: bool = True, **_):
    """``X = T_gripper_cam`` (:func:`~robocal.handeye.calibrate_hand_eye`) and the
    other closed forms on the same motions, for the report's comparison.

    Returns a :class:`Calibration` ``(HandEyeResult, comparison)``; ``comparison`` lists per closed-form method the
    rotation (rad) and translation (m) difference of its X from the estimate and its closure RMS
    (on the estimate's own pose pairs, ``pairs``: :func:`~robocal.handeye.pair_indices`).
    """
    from robocal.errors import RobocalError
    from robocal.handeye import AXXB_METHODS, calibrate_hand_eye, closure_residuals, transform_error

    tick = _stages("handeye: solve", 1, enabled=progress)
    tick()
    if pose_sigmas is None:  # a recording's image views carry their own stds (bag_input.BagPosePair)
        pose_sigmas = getattr(pair, "pose_sigmas", None)
    if pose_covariances is None:  # ... and covariances, as calibrate-images passes them
        pose_covariances = getattr(pair, "pose_covariances", None)
    res = calibrate_hand_eye(pair.T_base_gripper, pair.T_cam_target, method, refine=not no_refine, pairs=pairs,
                             times=pair.t, setup=setup, pose_sigmas=pose_sigmas,
                             accept_implausible=accept_implausible, names=pair.names)
    res.warnings = list(getattr(pair, "warnings", ())) + list(res.warnings)
    whitening = None
    if pose_covariances is not None and not no_refine:
        res, whitening = _with_pose_covariances(res, pair, pose_covariances, setup)
    res, pair, extra = _clock_and_jackknife(res, pair, setup=setup, refined=not no_refine, pose_sigmas=pose_sigmas,
                                            whitening=whitening)
    comparison = []
    Tg = _gripper(pair, setup)
    for m in AXXB_METHODS:
        try:
            rot_rms, trans_rms, Xm = closure_residuals(Tg, pair.T_cam_target, m, pairs=pairs)
        except RobocalError as exc:             # one closed form may fail where another does not
            comparison.append({"method": m, "error": str(exc)})
            continue
        rot, trans = transform_error(Xm, res.X)
        comparison.append({"method": m, "pairs": pairs, "n_motions": res.n_motions, "rotation_diff_rad": rot,
                           "translation_diff_m": trans,
                           "rotation_rms_rad": rot_rms, "translation_rms_m": trans_rms})
    tick()
    return Calibration(res, comparison, extra)


def _with_pose_covariances(res, pair: PosePair, pose_covariances, setup: str):
    """``res`` refined again on closures whitened by each view's covariance
    (:func:`robocal.handeye.weighted.refine_with_pose_covariances`); returns it and the whitening."""
    from robocal.handeye import HandEyeResult
    from robocal.handeye.motions import _rms
    from robocal.handeye.weighted import refine_with_pose_covariances

    w = refine_with_pose_covariances(_gripper(pair, setup), pair.T_cam_target, pose_covariances, res.X, res.Y,
                                     times=pair.t)
    rot, trans = _rms(w.residuals)
    return HandEyeResult(
        X=w.X, method=f"{res.method}+cov", Y=w.Y, cov=w.cov, std=w.std, rot_rms=rot,
        trans_rms=trans, n_motions=res.n_motions, setup=res.setup, lsq=w.lsq,
        warnings=[x for x in res.warnings if x.code != "outliers"] + list(w.warnings)), w.whitening


def _clock_and_jackknife(res, pair: PosePair, *, setup: str, refined: bool, pose_sigmas=None, whitening=None):
    """After :func:`~robocal.handeye.calibrate_hand_eye`: the streams' warnings; with ``--clock-offset auto``
    X, Y and the offset refined together (:func:`robocal.handeye.clock.refine_with_clock`) and the pairs
    re-paired at it; the jackknife std of X (:func:`robocal.handeye.jackknife.jackknife_hand_eye`).

    Returns ``(res, pair, extra)``: the result (X's covariance then the joint one's, which counts the
    offset's uncertainty), the pairs X was estimated on, ``{"clock": ClockRefinement | None,
    "jackknife": Jackknife | None, "pair": pair}``.
    """
    from dataclasses import replace

    from robocal.handeye import HandEyeResult
    from robocal.handeye.jackknife import jackknife_hand_eye

    stream, clock, jk = pair.stream, None, None
    if stream is not None:
        res.warnings = list(stream.warnings) + list(res.warnings)
        if stream.mode == "auto" and refined:
            from robocal.handeye.clock import refine_with_clock
            from robocal.handeye.motions import _LABELS

            clock = refine_with_clock(stream, res.X, res.Y, setup=setup)
            res = HandEyeResult(
                X=clock.X, method=f"{res.method}+clock", Y=clock.Y, cov=clock.cov[:6, :6],
                std={k: clock.lsq.std.get(f"X.{k}") for k in _LABELS}, rot_rms=clock.rot_rms,
                trans_rms=clock.trans_rms, n_motions=res.n_motions, setup=res.setup, lsq=clock.lsq,
                # the outliers of the pairing at the coarse offset give way to those at the refined one
                warnings=[w for w in res.warnings if w.code != "outliers"] + list(clock.warnings))
            s = clock.pairing
            pair = replace(pair, T_base_gripper=s.T_base_gripper, T_cam_target=s.T_cam_target, t=s.t, stream=s)
            pose_sigmas = None
    if refined and res.cov is not None:
        try:
            jk = jackknife_hand_eye(_gripper(pair, setup), pair.T_cam_target, res.X, res.Y, pose_sigmas=pose_sigmas,
                                    whitening=whitening)
        except np.linalg.LinAlgError:           # a replicate without a determined X: no jackknife, the rest stands
            jk = None
    return res, pair, {"clock": clock, "jackknife": jk, "pair": pair}


def _closure(Tg, Tc, X, Y) -> dict:
    """Per-pose closure residuals of ``T_base_gripper[i] X T_cam_target[i] = Y``: rotation angle (rad) and
    translation distance (m)."""
    from robocal.handeye.motions import _pose_residual

    r = _pose_residual(Tg @ X @ Tc, Y[None])
    return {"rotation_rad": np.linalg.norm(r[:, :3], axis=1).tolist(),
            "translation_m": np.linalg.norm(r[:, 3:], axis=1).tolist()}


def _forms(pair: PosePair) -> dict:
    """What the pose reader found in each file (:attr:`robocal.io.PoseList.form`)."""
    return {str(pair.gripper_path.name): pair.forms[0], str(pair.target_path.name): pair.forms[1]}


def _std_of(lsq, prefix: str):
    """(rotation std (3,), translation std (3,)) of block ``prefix`` from the solver, or (None, None)."""
    if lsq is None:
        return None, None
    s = [lsq.std.get(f"{prefix}.{k}") for k in _LABELS]
    return s[:3], s[3:]


def to_result(calibration, pair: PosePair) -> CalibrationResult:
    """The result of :func:`calibrate`: X and the target pose (with std after refinement), named by the set-up:
    ``T_gripper_cam`` + ``T_base_target`` (eye-in-hand) or ``T_base_cam`` + ``T_gripper_target`` (eye-to-hand)."""
    from robocal.handeye import SETUPS

    res, comparison = calibration
    extra = getattr(calibration, "extra", None) or {}
    pair = extra.get("pair") or pair                # re-paired at a refined clock offset
    result = CalibrationResult(
        rig="handeye", method=res.method, estimate={}, std={}, units={}, residual_rms=res.trans_rms,
        residual_unit="m", warnings=res.warnings, inputs=hash_inputs(pair.files))
    frames = SETUPS[res.setup]
    for key, T in (("X", res.X), ("Y", res.Y)):
        name, parent, child = frames[key]
        sr, st = _std_of(res.lsq, key)
        result.add_pose(name, T, std_rotation=sr, std_translation=st, parent=parent, child=child)
    xn, yn = res.names
    closure = ("T_base_gripper[i] X T_cam_target[i] = Y" if res.setup == "eye-in-hand"
               else "T_base_gripper[i]^-1 X T_cam_target[i] = Y")
    result.diagnostics = {
        "rotation_rms_rad": res.rot_rms, "n_motions": res.n_motions, "n_poses": len(pair.T_base_gripper),
        "pairs": next((c["pairs"] for c in comparison if "pairs" in c), None), "setup": res.setup,
        "pose_files": _forms(pair),
        "convention": f"{res.setup}: A X = X B, X = {xn}, Y = {yn} = "
                      + ("T_base_gripper[i] X T_cam_target[i]" if res.setup == "eye-in-hand"
                         else "T_gripper_base[i] X T_cam_target[i]")
                      + "; std as rotation vector of R_perturbed R^T (rad) and translation (m); quaternions "
                        "scalar-last",
        "closure": closure,
        "closure_residuals": _closure(_gripper(pair, res.setup), pair.T_cam_target, res.X, res.Y),
        "solver_comparison": comparison,
        "solver": solver_record(res.lsq),
    }
    _streams_into(result, pair, extra.get("clock"), extra.get("jackknife"), xn)
    result.diagnostics.update(getattr(pair, "diagnostics", None) or {})  # a recording's: frames, stamps, views
    return result


def _streams_into(result, pair: PosePair, clock, jk, xn: str) -> None:
    """The streams' counts and clock offset (``diagnostics.streams``; ``estimate.clock_offset`` with its std
    when estimated) and the jackknife std of X (``diagnostics.jackknife``) into ``result``."""
    s = pair.stream
    if s is not None:
        result.diagnostics["streams"] = s.to_dict()
        if s.mode == "auto":
            result.estimate["clock_offset"] = float(s.clock_offset)
            result.std["clock_offset"] = None if clock is None else clock.clock_offset_std
            result.units["clock_offset"] = "s"
            result.diagnostics["streams"]["clock_offset_meaning"] = (
                "added to the camera's stamps to put them on the robot's clock: T_base_gripper(t + "
                "clock_offset) pairs with T_cam_target(t)")
    if jk is not None:
        first = [result.std.get(f"{xn}.rotvec") or [None] * 3, result.std.get(f"{xn}.translation") or [None] * 3]
        result.diagnostics["jackknife"] = {
            "pose": xn, **jk.to_dict(), "first_order_std": [*first[0], *first[1]],
            "about": "std of X (rx, ry, rz [rad], tx, ty, tz [m]) from the spread of X re-estimated with each "
                     "pose (delete-one, up to 100 poses) or each of 50 contiguous groups (delete-a-group) left "
                     "out, beside the first-order std; the two should agree when the noise model holds"}


# ----------------------------------------------------------------------------- AX = ZB
#: robot-world per set-up: (X, Z, their inverses) as (name, parent, child). eye-in-hand: ``A X = Z B`` with
#: ``A = T_cam_target``, ``B = T_gripper_base``; eye-to-hand: ``B = T_base_gripper`` (the robot poses as given).
RW_SETUPS = {
    "eye-in-hand": {"X": ("T_target_base", "target", "robot base"), "Z": ("T_cam_gripper", "camera", "gripper"),
                    "Xinv": ("T_base_target", "robot base", "target"), "Zinv": ("T_gripper_cam", "gripper", "camera"),
                    "B": "T_gripper_base (inverse of the robot's T_base_gripper)"},
    "eye-to-hand": {"X": ("T_target_gripper", "target", "gripper"), "Z": ("T_cam_base", "camera", "robot base"),
                    "Xinv": ("T_gripper_target", "gripper", "target"), "Zinv": ("T_base_cam", "robot base", "camera"),
                    "B": "T_base_gripper (the robot's poses as given)"},
}


def robot_world(pair: PosePair, *, no_refine: bool = False, accept_implausible: bool = False,
                setup: str = "eye-in-hand", pairs: str = "auto"):
    """``A X = Z B`` (:func:`~robocal.handeye.calibrate_robot_world`), ``A = T_cam_target``.

    eye-in-hand: ``B = T_gripper_base``, X = T_target_base, Z = T_cam_gripper; eye-to-hand (fixed camera, target
    on the gripper): ``B = T_base_gripper``, X = T_target_gripper, Z = T_cam_base (:data:`RW_SETUPS`).
    ``pairs``: the motions of the excitation check (:func:`~robocal.handeye.pair_indices`).
    """
    from robocal.errors import InputError
    from robocal.geometry import invert_transform
    from robocal.handeye import calibrate_robot_world

    if setup not in RW_SETUPS:
        raise InputError(f"setup must be one of {', '.join(RW_SETUPS)}, got {setup!r}")
    tick = _stages("handeye robot-world: solve", 1)
    tick()
    B = invert_transform(pair.T_base_gripper) if setup == "eye-in-hand" else pair.T_base_gripper
    res = calibrate_robot_world(pair.T_cam_target, B, refine=not no_refine, pairs=pairs,
                                times=pair.t, accept_implausible=accept_implausible, names=pair.names)
    tick()
    return res


def robot_world_result(res, pair: PosePair, *, setup: str = "eye-in-hand", pairs: str | None = None
                       ) -> CalibrationResult:
    """The result of :func:`robot_world`: X, Z and their inverses (eye-in-hand ``T_base_target``,
    ``T_gripper_cam``; eye-to-hand ``T_gripper_target``, ``T_base_cam``), each with its std after refinement
    (the inverses' by first-order propagation, :meth:`~robocal.geometry.PoseWithCovariance.inverse`)."""
    from robocal.geometry import PoseWithCovariance, invert_transform

    names = RW_SETUPS[setup]
    result = CalibrationResult(
        rig="handeye", method=f"robot-world {res.method}", estimate={}, std={}, units={},
        residual_rms=res.trans_rms, residual_unit="m", warnings=res.warnings, inputs=hash_inputs(pair.files))
    xr, xt = _std_of(res.lsq, "X")
    zr, zt = _std_of(res.lsq, "Z")
    for key, T, sr, st in (("X", res.X, xr, xt), ("Z", res.Z, zr, zt)):
        name, parent, child = names[key]
        result.add_pose(name, T, std_rotation=sr, std_translation=st, parent=parent, child=child)
    for key, T, sl in (("Xinv", res.X, slice(0, 6)), ("Zinv", res.Z, slice(6, 12))):
        name, parent, child = names[key]
        sr = st = None
        if res.cov is not None and res.std and all(v is not None for v in res.std.values()):
            inv = PoseWithCovariance(T, np.asarray(res.cov)[sl, sl]).inverse()
            sr, st = inv.std_rotation.tolist(), inv.std_translation.tolist()
        result.add_pose(name, invert_transform(T), std_rotation=sr, std_translation=st, parent=parent,
                        child=child)
    B = names["B"]
    result.diagnostics = {
        "rotation_rms_rad": res.rot_rms, "n_poses": len(pair.T_cam_target), "pose_files": _forms(pair),
        "setup": setup, "pairs": pairs,
        "convention": f"{setup}: A X = Z B, A = T_cam_target, B = {B}, X = {names['X'][0]}, "
                      f"Z = {names['Z'][0]}; std as rotation vector of R_perturbed R^T (rad) and "
                      "translation (m), of the inverses by first-order propagation; quaternions scalar-last",
        "closure": f"T_cam_target[i] {names['X'][0]} = {names['Z'][0]} {B.split(' ')[0]}[i]",
        "closure_residuals": _rw_closure(res, pair, setup),
        "solver": solver_record(res.lsq),
    }
    _streams_into(result, pair, None, None, names["Zinv"][0])      # the offset: the correlation's, no std
    return result


def _rw_closure(res, pair: PosePair, setup: str) -> dict:
    """Per-pose residuals of ``A[i] X = Z B[i]``: rotation angle (rad), translation distance (m)."""
    from robocal.geometry import invert_transform
    from robocal.handeye.motions import _pose_residual

    B = invert_transform(pair.T_base_gripper) if setup == "eye-in-hand" else pair.T_base_gripper
    r = _pose_residual(pair.T_cam_target @ res.X, res.Z @ B)
    return {"rotation_rad": np.linalg.norm(r[:, :3], axis=1).tolist(),
            "translation_m": np.linalg.norm(r[:, 3:], axis=1).tolist()}


def run_robot_world(args) -> int:
    """``robocal handeye robot-world GRIPPER TARGET --out DIR``: ``DIR/result.json`` and ``DIR/report.html``."""
    from robocal.errors import RobocalError
    from robocal.handeye.report import build_report
    from robocal.io import prepare_out_dir, write_run

    pair = load_pose_pair(args.gripper_poses, args.target_poses, clock_offset=getattr(args, "clock_offset", "none"))
    try:
        res = robot_world(pair, no_refine=args.no_refine, accept_implausible=args.accept_implausible,
                          setup=args.setup, pairs=args.pairs)
        result = robot_world_result(res, pair, setup=args.setup, pairs=args.pairs)
        report = build_report(result)
    except RobocalError as exc:
        raise exc if exc.source is not None else exc.with_source(f"{pair.gripper_path} + {pair.target_path}") \
            from None
    out = prepare_out_dir(args.out, "handeye-robot-world")
    write_run(out, result, report)
    print(summary(result))
    zname = RW_SETUPS[args.setup]["Zinv"][0]
    sr = result.std.get(f"{zname}.rotvec")
    if sr is not None and all(v is not None for v in sr):
        print(f"{zname} rotation std [mrad] (rotation vector of R_perturbed R^T): "
              + ", ".join(f"{1e3 * v:.3f}" for v in sr))
    return 0


# ----------------------------------------------------------------------------- report, summary
def summary(result) -> str:
    """``read g.csv: <form>; c.csv: <form>`` (what the pose reader found) and ``T_gripper_cam translation [mm]
    (method): x +/- s, ...``: the lines the commands print (the core prints the warnings, with the poses they
    name, on stderr)."""
    name = "T_base_cam" if (result.diagnostics or {}).get("setup") == "eye-to-hand" else "T_gripper_cam"
    t = result.estimate[f"{name}.translation"]
    st = result.std.get(f"{name}.translation") or [None] * 3
    head = f"{name} translation [mm]" + ("" if result.method.startswith("robot-world") else
                                         f" ({result.method})")
    forms = (result.diagnostics or {}).get("pose_files") or {}
    read = ("read " + "; ".join(f"{k}: {v}" for k, v in forms.items()) + "\n") if any(forms.values()) else ""
    streams = _streams_line(result)
    line = f"{head}: " + ", ".join(f"{1e3 * v:.3f}" + ("" if s is None else f" +/- {1e3 * s:.3f}")
                                   for v, s in zip(t, st))
    jk = (result.diagnostics or {}).get("jackknife")
    if jk:
        line += (f"\n{name} translation std [mm], {jk['kind']} jackknife ({jk['replicates']} replicates): "
                 + ", ".join(f"{1e3 * v:.3f}" for v in jk["std"][3:]))
    return read + streams + line


def _streams_line(result) -> str:
    """``streams: ...`` (samples dropped and cropped, the clock offset) for two timed streams, else ''."""
    s = (result.diagnostics or {}).get("streams")
    if not s:
        return ""
    d, c = s["dropped_stamps"], s["cropped"]
    sd = (result.std or {}).get("clock_offset") if s["mode"] == "auto" else None
    off = f"clock offset {1e3 * s['clock_offset_s']:.3f}" + ("" if sd is None else f" +/- {1e3 * sd:.3f}") + " ms"
    if s["mode"] == "auto":
        off += f" (auto: rotation-rate correlation {s['correlation']:.2f}" + (", refined with X)" if sd else ")")
    elif s["mode"] == "given":
        off += " (given)"
    return (f"streams: {s['n_pairs']} pairs; stamps not advancing dropped: robot {d.get('robot', 0)}, camera "
            f"{d.get('camera', 0)}; outside the overlap: camera {c.get('camera', 0)} cropped, robot "
            f"{c.get('robot', 0)} unused; {off}\n")


# ----------------------------------------------------------------------------- simulate
def simulate_files(out_dir: Path, rng: np.random.Generator, *, poses: int = 16, noise_free: bool = False,
                   setup: str = "eye-in-hand", progress: bool = True, **_) -> list[Path]:
    """``robocal handeye simulate``: ``gripper_poses.csv``, ``target_poses.csv`` and their truth ``truth.yaml``.

    :func:`.simulate.simulate_eye_in_hand`: ``poses`` views of a fixed target by a camera on the gripper;
    1 mrad / 0.2 mm sensor noise unless ``noise_free``; ``setup="eye-to-hand"``: a fixed camera viewing a
    target on the gripper (:func:`.simulate.simulate_eye_to_hand`), truth ``T_base_cam``, ``T_gripper_target``.
    """
    from robocal.handeye import SETUPS
    from robocal.handeye.simulate import simulate_eye_in_hand, simulate_eye_to_hand
    from robocal.io import atomic_write_text, write_poses

    sim = (simulate_eye_in_hand if setup == "eye-in-hand" else simulate_eye_to_hand)(rng, poses, noise=not noise_free)
    xn, yn = SETUPS[setup]["X"][0], SETUPS[setup]["Y"][0]
    out = Path(out_dir)
    t = np.arange(poses) * 0.1
    paths = [write_poses(out / "gripper_poses.csv", sim.T_base_gripper, t),
             write_poses(out / "target_poses.csv", sim.T_cam_target, t)]

    def pose(T):
        return "{rotation: %s, translation: %s}" % (np.round(T[:3, :3], 12).tolist(), np.round(T[:3, 3], 12).tolist())
    paths.append(atomic_write_text(out / "truth.yaml", (
        "# ground truth of the simulated pose lists (m); not an input of 'robocal handeye calibrate'\n"
        f"setup: {setup}\n{xn}: {pose(sim.X)}\n{yn}: {pose(sim.Y)}\n"
        f"noise: {{rotation_rad: {sim.sigma_rotation}, translation_m: {sim.sigma_translation}}}\n")))
    return [Path(p) for p in paths]


# ----------------------------------------------------------------------------- images in
