"""World-to-projector extrinsic calibration (seed 000, §2.2) and two better solvers.

Data: floor points measured in the world ``^W P_i`` (z = 0) and the same spots
in the projector frame ``^0 P_i = f(theta_i)`` from the joint angles (seed
eq. 6). Unknown: ``R_0_W, t_0_W`` with ``^0P = R ^WP + t`` (seed eq. 1).

Three solvers:

(a) :func:`seed_method` -- the seed's algorithm as published: unit difference
    vectors (eq. 12), a closed-form initial rotation from composed Gibbs
    vectors (eqs. 15-23) and the iterative refinement of eqs. (24)-(29) with
    the Moore-Penrose pseudo-inverse, keeping the cost per iteration (Fig. 4).
(b) :func:`closed_form` -- the maximum-likelihood rigid fit (Umeyama/Kabsch,
    :func:`robocal.geometry.rigid_fit`) for any N >= 3.
(c) :func:`nonlinear` -- least squares on the floor-plane spot error with
    :mod:`robocal.estimation`: yaw and floor translation, optionally
    ``h = H - d1`` and the tilt zero offset; covariance included.

Noise model: the world measurements ``^W P`` (tape, total station) carry
isotropic floor noise ``sigma`` per coordinate; the joint encoders carry
``joint_noise`` (pan, tilt), mapped to the floor per point by the spot model's
joint Jacobian (:func:`floor_covariance`, issue 19).
Because ``{W}``'s floor (z_W = 0) and the model's floor (z_0 = -H) are both
planes, a rigid transform between them is a rotation about ``z`` plus a
translation: only the yaw, ``t_x``, ``t_y`` are determined by floor points
(``t_z = -H`` by definition of ``{0}``; a roll/pitch of the base would
violate the model's level-floor assumption, seed §2.1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import InconsistentDataError, InputError, ShapeError
from robocal.rigs.projector.closed_form import (ExtrinsicEstimate, closed_form, floor_covariance,  # noqa: F401
                                                floor_pose_jacobian, floor_prediction_columns, rotation_error,
                                                seed_initial_rotation, seed_method, yaw_of)
from robocal.rigs.projector.consistency import (CAL_BYTES_PER_POINT, ConsistencyReport, _spots,  # noqa: F401
                                                _tilt_span, beyond_tilt_limit, check_correspondences,
                                                distance_consistency, spread_ratio)
from robocal.rigs.projector.model import ProjectorModel, UnreachablePointError
from robocal.rigs.projector.nonlinear import deleted_residual_outliers, nonlinear  # noqa: F401
from robocal.rigs.projector.slips import _slip_checks
from robocal.validation import check_array

__all__ = [
    "ExtrinsicEstimate",
    "ConsistencyReport",
    "CalibrationRun",
    "check_correspondences",
    "distance_consistency",
    "seed_initial_rotation",
    "seed_method",
    "closed_form",
    "nonlinear",
    "calibrate",
    "yaw_of",
    "floor_pose_jacobian",
    "floor_prediction_columns",
    "rotation_error",
    "beyond_tilt_limit",
    "floor_covariance",
    "deleted_residual_outliers",
    "spread_ratio",
    "TILT_OFFSET_LIMIT",
]

METHODS = ("seed", "closed_form", "nonlinear")


# --------------------------------------------------------------- the driver
@dataclass
class CalibrationRun:
    """Everything one calibration produced: the consistency check and each method's estimate."""

    points_W: np.ndarray
    points_0: np.ndarray
    theta: np.ndarray | None
    model: ProjectorModel
    consistency: ConsistencyReport
    estimates: dict
    sigma: float | None
    primary: str
    consistency_prefit: ConsistencyReport | None = None
    input_warnings: list = field(default_factory=list)
    joint_noise: tuple | None = None  # encoder noise std (pan, tilt), rad

    @property
    def best(self) -> ExtrinsicEstimate:
        return self.estimates[self.primary]

    @property
    def warnings(self) -> list:
        return list(self.input_warnings) + list(self.consistency.warnings) + [w for w in self.best.warnings]

    def calibrated_model(self, method: str | None = None) -> ProjectorModel:
        """The projector model with the estimated extrinsics (and h / offsets when estimated)."""
        est = self.estimates[method or self.primary]
        m = self.model.with_(R_0_W=est.R_0_W, t_0_W=est.t_0_W)
        if "h" in est.extra:
            m = m.with_(d1=m.H - est.extra["h"], offsets=tuple(est.extra["offsets"]))
        return m


#: Default bound on the estimated tilt zero offset (rad); ``tilt_offset_limit`` in the input changes it.
TILT_OFFSET_LIMIT = math.radians(5.0)


def _bound_violations(est: ExtrinsicEstimate, model: ProjectorModel, free, tilt_offset_limit: float) -> dict:
    """Estimated parameters outside their physical bounds: ``{name: text}``.

    ``h = H - d1 <= H`` (d1 >= 0: the tilt axis is not above the ceiling
    reference of ``{0}``), ``h > 0``, ``|tilt_offset| <= tilt_offset_limit``.
    """
    out = {}
    if "h" in free:
        h = est.extra["h"]
        if h > model.H:
            out["h"] = f"h = {h:.4g} m above H = {model.H:.4g} m (d1 = {model.H - h:+.4g} m < 0)"
        elif h <= 0:
            out["h"] = f"h = {h:.4g} m <= 0 (the tilt axis below the floor)"
    if "tilt_offset" in free:
        o = est.extra["offsets"][1]
        if abs(o) > tilt_offset_limit:
            out["tilt_offset"] = (f"tilt offset {math.degrees(o):+.3g} deg beyond +-{math.degrees(tilt_offset_limit):g} "
                                  f"deg (tilt_offset_limit)")
    return out


def calibrate(points_W, *, theta=None, points_0=None, model: ProjectorModel | None = None,
              methods=METHODS, estimate=(), sigma: float | None = None, strict: bool = False,
              seed_alpha: float = 0.5, seed_order=None, joint_noise=None,
              tilt_offset_limit: float = TILT_OFFSET_LIMIT, accept_implausible: bool = False,
              source: str | None = None) -> CalibrationRun:
    """Run the consistency check and the chosen solvers on one data set.

    Parameters
    ----------
    points_W : array_like, shape (N, 2) or (N, 3)
        Measured world floor points (m).
    theta : array_like, shape (N, 2), optional
        Joint angles (rad) that put the spot on each point (then ``model`` is needed).
    points_0 : array_like, shape (N, 3), optional
        The spots in ``{0}``, when given directly (as in the seed's §3).
    model : ProjectorModel, optional
    methods : sequence of {'seed', 'closed_form', 'nonlinear'}
    estimate : extra parameters for the nonlinear solver, see :func:`nonlinear`
    sigma : float, optional
        World measurement noise (m). When given, every standard deviation uses
        it as known (absolute sigma); without it the covariances are scaled by
        the residual variance (needs N > number of parameters / 2).
    joint_noise : (float, float), optional
        Encoder noise std (pan, tilt) in rad; needs ``sigma``. Each point's floor
        covariance is then :func:`floor_covariance`, used by the consistency
        check, the closed form's std and the nonlinear fit's weights, std and
        outlier test.
    tilt_offset_limit : float
        Physical bound (rad) on an estimated tilt zero offset.
    seed_alpha, seed_order
        Step factor and point order of :func:`seed_method`.
    strict : bool
        Raise :class:`~robocal.errors.InconsistentDataError` when the distance
        check fails or an estimate leaves its physical bounds, and
        :class:`~robocal.rigs.projector.model.UnreachablePointError` for spots
        beyond the tilt limit, instead of warning (``inconsistent_data``,
        ``parameter_held``, ``near_singularity``).
    accept_implausible : bool
        Go on when the input's scales are implausible (a likely unit slip or
        swapped columns, :func:`robocal.plausibility.check_slips`) with an
        ``implausible_input`` warning, instead of raising
        :class:`~robocal.errors.ImplausibleInputError`.
    source : str, optional
        Input file, named in errors.

    Physical bounds: an estimated ``h`` above ``H`` (d1 < 0) or at/below 0, or
    a tilt offset beyond ``tilt_offset_limit``, is not returned: the parameter is
    held at its nominal value, the fit redone, and a ``parameter_held`` warning
    says why, with the tilt span of the points (``h`` and the tilt offset are
    told apart only by points at different tilts).

    Returns
    -------
    CalibrationRun
        ``primary`` is the nonlinear estimate when run, else the closed form, else the seed's.
    """
    methods = tuple(methods)
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise InputError(f"methods must be a non-empty subset of {', '.join(METHODS)}, got {list(methods)}")
    if theta is not None:
        if model is None:
            raise InputError("calibrate: joint angles need a projector model (H, d1)")
        th = check_array(theta, "theta", shape=("N", 2))
        if th.ndim != 2:
            raise ShapeError(f"theta must have shape (N, 2), got {tuple(th.shape)}")
        p0 = _spots(model, th)
    elif points_0 is not None:
        th = None
        p0 = check_array(points_0, "points_0")
        if p0.ndim != 2 or p0.shape[-1] != 3:
            raise ShapeError(f"points_0 must have shape (N, 3), got {tuple(p0.shape)}")
        H = float(-np.mean(p0[:, 2]))
        if model is None:
            if not H > 0:
                raise InputError(f"points_0: the floor must be below the projector (z_0 = -H < 0), got mean z {-H:g} m")
            model = ProjectorModel(H=H)
        if np.abs(p0[:, 2] + model.H).max() > 1e-6 * max(1.0, model.H):
            raise InputError(f"points_0: every z must equal -H = {-model.H:g} m (the floor in {{0}}), got "
                             f"{p0[:, 2].tolist()[:10]}")
    else:
        raise InputError("calibrate: give joint angles (theta) or projector-frame points (points_0)")
    jn = None
    if joint_noise is not None:
        jn = check_array(joint_noise, "joint_noise", shape=(2,))
        if np.any(jn < 0):
            raise InputError(f"joint_noise must be >= 0 (rad), got {jn.tolist()}")
        if not np.any(jn > 0):
            jn = None
        elif not sigma:
            raise InputError("joint_noise needs noise (the world measurement sigma) too: together they make each "
                             "point's floor covariance")
    if not 0 < tilt_offset_limit < math.pi / 2:
        raise InputError(f"tilt_offset_limit must be in (0, 90) deg, got {math.degrees(tilt_offset_limit):g} deg")
    from robocal.resources import require_memory

    require_memory(CAL_BYTES_PER_POINT * len(p0), f"calibrating {len(p0)} points", source=source)
    pw, p0 = check_correspondences(points_W, p0, unit_check=False)
    if np.abs(pw[:, 2]).max() > 1e-9:
        raise InputError("points_W: world points must lie on the floor (z_W = 0)")
    input_warnings = []
    slip = _slip_checks(pw, th, p0 if th is None else None, model, sigma, jn, accept=accept_implausible,
                        source=source)
    if slip is not None:
        input_warnings.append(slip)
    reach = beyond_tilt_limit(model, p0, "joint_angles" if th is not None else "points_0")
    if reach is not None:
        if strict:
            raise UnreachablePointError(reach.message)
        input_warnings.append(reach)
    estimate = tuple(estimate)
    if estimate and "nonlinear" not in methods:
        raise InputError(f"estimate: {list(estimate)} is estimated only by the 'nonlinear' method, which is not among "
                         f"methods {list(methods)}: add it or drop estimate")
    hint = ("H - d1 or the tilt offset is probably wrong (estimate: [h, tilt_offset] with the nonlinear method)"
            if th is not None else "H or the units of the {0} points are probably wrong")
    th_cov = None
    if jn is not None:
        th_cov = th if th is not None else model.ik(p0, check_reach=False, on_nadir="ignore")

    def cov0(m):  # joint-noise covariance of the spots in {0} (no world part: the check adds it per pair)
        return None if jn is None else floor_covariance(m, th_cov, 0.0, joint_noise=jn)

    cons = distance_consistency(pw, p0, sigma=sigma, scale_hint=hint, cov_0=cov0(model))
    refine_model = th is not None and any(e in ("h", "tilt_offset") for e in estimate) and "nonlinear" in methods
    # With h or the tilt offset unknown, the nominal f(theta) carries a model error that the
    # distances show too; the check is then repeated with the refined model before judging.
    if strict and not cons.consistent and not refine_model:
        raise InconsistentDataError(cons.warnings[0].message)
    ests = {}
    if "seed" in methods:
        ests["seed"] = seed_method(pw, p0, alpha=seed_alpha, order=seed_order)
    if "closed_form" in methods or "nonlinear" in methods:
        cf = closed_form(pw, p0, sigma=sigma)
        if jn is not None:  # the sandwich covariance under the per-point noise
            cf = closed_form(pw, p0, sigma=sigma, cov=floor_covariance(model, th_cov, cf.yaw, sigma=sigma,
                                                                       joint_noise=jn))
        ests["closed_form"] = cf
    held = {}
    if "nonlinear" in methods:
        # A stated noise is the measurement sigma: with few points (N = 3, h and the tilt offset free
        # leaves 1 dof) the residual-scaled covariance is far too small, so the stated sigma is used as is.
        kw = dict(theta=th, points_0=None if th is not None else p0, model=model, estimate=estimate, sigma=sigma,
                  x0=ests["closed_form"], absolute_sigma=sigma is not None, joint_noise=jn)
        nl = free_fit = nonlinear(pw, **kw)
        for _ in range(2):  # hold what leaves its bounds, refit, check what is still free
            out = _bound_violations(nl, model, [e for e in estimate if e not in held], tilt_offset_limit)
            if not out:
                break
            held.update(out)
            nl = nonlinear(pw, hold=tuple(held), **kw)
        if held:
            lo, hi = _tilt_span(model, th, p0)
            corr = _h_tilt_correlation(free_fit)  # the fit before anything was held
            why = (f"the points span {math.degrees(lo):.1f}-{math.degrees(hi):.1f} deg of tilt "
                   f"({math.degrees(hi - lo):.1f} deg" + (f", correlation of h and the tilt offset {corr:+.3f}"
                                                          if corr is not None else "")
                   + "): h and the tilt offset cannot be told apart; add points nearer and farther from the nadir")
            msg = (f"{'; '.join(held.values())}: {why}; held at nominal "
                   + ", ".join(f"h = {model.h:.4g} m" if k == "h" else f"tilt offset {math.degrees(model.offsets[1]):g} deg"
                               for k in held)
                   + " and the rest refitted (their std take the held value as exact)")
            if strict:
                raise InconsistentDataError(msg, source=source)
            nl.warnings.insert(0, Diagnostic("parameter_held", msg, params=tuple(held)))
            nl.extra["held"] = dict(held)
        ests["nonlinear"] = nl
    if "closed_form" not in methods:
        ests.pop("closed_form", None)
    prefit = cons
    if refine_model and not cons.consistent:
        nl = ests["nonlinear"]
        refined = model.with_(d1=model.H - nl.extra["h"], offsets=tuple(nl.extra["offsets"]))
        cons = distance_consistency(pw, _spots(refined, th), sigma=sigma, scale_hint=hint, cov_0=cov0(refined))
        if strict and not cons.consistent:
            raise InconsistentDataError(cons.warnings[0].message)
    primary = "nonlinear" if "nonlinear" in ests else ("closed_form" if "closed_form" in ests else "seed")
    run = CalibrationRun(pw, p0, th, model, cons, ests, sigma, primary)
    run.consistency_prefit = prefit
    run.input_warnings = input_warnings
    run.joint_noise = None if jn is None else (float(jn[0]), float(jn[1]))
    return run


def _h_tilt_correlation(est: ExtrinsicEstimate) -> float | None:
    lsq = est.extra.get("lsq")
    if lsq is None or lsq.corr is None or "h" not in lsq.free_labels or "tilt_offset" not in lsq.free_labels:
        return None
    i, j = lsq.free_labels.index("h"), lsq.free_labels.index("tilt_offset")
    c = float(np.asarray(lsq.corr)[i, j])
    return c if math.isfinite(c) else None


