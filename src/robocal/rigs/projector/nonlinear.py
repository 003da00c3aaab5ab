"""Nonlinear least squares on the floor spot error (seed 000 eqs. 1, 6) and its outlier test.

:func:`nonlinear` fits yaw and the floor translation, optionally ``h = H -
d1`` and the joint zero offsets, with :mod:`robocal.estimation` (covariance
included); :func:`deleted_residual_outliers` names the points inconsistent
with the fit of the others (studentized deleted residuals, backward
elimination) at the core's multiplicity-corrected threshold.
"""

from __future__ import annotations

import math
import sys

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import ConvergenceError, InputError, ShapeError
from robocal.estimation import Problem, outlier_sigma, outlier_threshold, solve
from robocal.geometry import matrix_from_angle
from robocal.rigs.projector.closed_form import (ExtrinsicEstimate, _rms, _whitener, closed_form, floor_covariance,
                                                floor_prediction_columns)
from robocal.rigs.projector.consistency import LARGE_N, _spots, check_correspondences
from robocal.rigs.projector.model import ProjectorModel
from robocal.validation import check_array

__all__ = ["nonlinear", "deleted_residual_outliers", "EXTRA_PARAMS"]


# ---------------------------------------------------------- (c) nonlinear LS
EXTRA_PARAMS = ("h", "pan_offset", "tilt_offset")


def nonlinear(points_W, *, theta=None, points_0=None, model: ProjectorModel | None = None, estimate=(),
              sigma: float | None = None, x0: ExtrinsicEstimate | None = None, absolute_sigma: bool = False,
              loss: str = "linear", joint_noise=None, hold=()) -> ExtrinsicEstimate:
    """Nonlinear least squares on the floor spot error (robocal.estimation).

    Residual per point: ``^WP_i - [R_0_W^T (f(theta_i) - t_0_W)]_xy`` (m), with
    ``f`` the spot model (seed eq. 6). Parameter blocks: ``R`` (rotation vector,
    only ``rz`` free: see the module docstring), ``t`` (``t_z = -H`` fixed),
    and, with joint angles, ``h = H - d1``, ``pan_offset``, ``tilt_offset`` when
    named in ``estimate``.

    The pan zero offset is **not identifiable** from floor points: turning the
    pan by ``o1`` rotates every spot about the nadir, which a change of yaw and
    ``t`` reproduces exactly. Asking for it yields a ``rank_deficient`` warning
    and ``std = None``.

    Noise model (issue 19): each point's residual has the covariance
    :func:`floor_covariance` (world noise ``sigma`` plus the encoder noise
    ``joint_noise`` mapped to the floor); the residuals are whitened with it,
    so weights, covariance and the outlier test all use it. The covariance
    depends on ``h`` and the offsets: it is taken at the start, and the fit is
    repeated once with it taken at the first solution.

    Outliers (with a stated ``sigma``): each point's studentized deleted
    residual ``t_i^2 = e_i^T (I - H_ii)^-1 e_i`` (whitened residual ``e_i``,
    2x2 hat-matrix block ``H_ii``; chi-square with 2 dof) is compared with the
    chi-square quantile of ``0.01 / N`` (Bonferroni: <= 1 % false alarms per
    data set); the worst point is named first, dropped, and the test repeated
    on the rest (backward elimination, linearised), so one gross point does not
    drag its neighbours over the threshold.

    Parameters
    ----------
    points_W : array_like, shape (N, 2) or (N, 3)
    theta : array_like, shape (N, 2), optional
        Joint angles (rad) for each spot; requires ``model``.
    points_0 : array_like, shape (N, 3), optional
        Spots in ``{0}`` when joint angles are not available (then ``estimate``
        must be empty).
    model : ProjectorModel
        Provides ``H, d1`` and offsets (initial values).
    estimate : sequence of {'h', 'pan_offset', 'tilt_offset'}
    sigma : float, optional
        World measurement noise (m); with ``absolute_sigma`` taken as known.
    x0 : ExtrinsicEstimate, optional
        Start (default: the closed form).
    joint_noise : (float, float), optional
        Encoder noise (pan, tilt) std (rad); needs ``sigma`` and joint angles.
    hold : sequence of str
        Parameters of ``estimate`` held at the model's value (physical bounds, see :func:`calibrate`).
    """
    estimate = tuple(estimate)
    unknown = [e for e in estimate if e not in EXTRA_PARAMS]
    if unknown:
        raise InputError(f"estimate: unknown parameter(s) {unknown} (known: {', '.join(EXTRA_PARAMS)})")
    if theta is None:
        if points_0 is None:
            raise InputError("nonlinear: give joint angles theta (with model) or points_0")
        if estimate:
            raise InputError(f"nonlinear: estimating {list(estimate)} needs joint angles, only points_0 were given")
        pw, p0 = check_correspondences(points_W, points_0, unit_check=False)
        th = None
        H = float(-np.mean(p0[:, 2]))
        model = ProjectorModel(H=H) if model is None else model
    else:
        if model is None:
            raise InputError("nonlinear: joint angles need a ProjectorModel (H, d1)")
        th = check_array(theta, "theta", shape=("N", 2))
        if th.ndim != 2:
            raise ShapeError(f"theta must have shape (N, 2), got {tuple(th.shape)}")
        p0 = _spots(model, th)
        pw, p0 = check_correspondences(points_W, p0, unit_check=False)
    jn = None
    if joint_noise is not None and np.any(np.asarray(joint_noise, dtype=float) > 0):
        if not sigma:
            raise InputError("joint_noise needs the world noise (noise:) too: the two make each point's covariance")
        jn = np.asarray(joint_noise, dtype=float)
    H = model.H
    free = tuple(e for e in estimate if e not in hold)
    start = x0 or closed_form(pw, p0, sigma=sigma)
    n = pw.shape[0]
    target = pw[:, :2]
    # {0} points given directly come from encoder readings too: their angles by IK (seed eq. 8)
    th_cov = th if th is not None else (model.ik(p0, check_reach=False, on_nadir="ignore") if jn is not None
                                        else None)

    def build(x_start, params_start, Winv):
        prob = Problem()
        prob.add_block("R", [0.0, 0.0, x_start[0]], fixed=[True, True, False], labels=["rx", "ry", "yaw"],
                       unit="rad")
        prob.add_block("t", [x_start[1], x_start[2], -H], fixed=[False, False, True],
                       labels=["t_x", "t_y", "t_z"], unit="m")
        if th is not None:
            prob.add_block("h", [params_start[0]], fixed=["h" not in free], labels=["h"], unit="m")
            prob.add_block("offsets", list(params_start[1:]), fixed=["pan_offset" not in free,
                                                                      "tilt_offset" not in free],
                           labels=["pan_offset", "tilt_offset"], unit="rad")

        def raw(q):
            c, s = math.cos(q["R"][2]), math.sin(q["R"][2])
            if th is None:
                sp = p0[:, :2]
            else:
                a1 = th[:, 0] + q["offsets"][0]
                a2 = th[:, 1] + q["offsets"][1]
                rho = q["h"][0] * np.tan(a2)
                sp = np.column_stack([rho * np.sin(a1), rho * np.cos(a1)])
            d = sp - q["t"][:2]
            # R_0_W = Rz(yaw) => ^WP_xy = Rz(-yaw) (f - t)_xy
            pred = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
            return target - pred

        def residuals(q):
            r = raw(q)
            return r if Winv is None else np.einsum("nij,nj->ni", Winv, r)

        def jacobian(q):  # residual = target - pred
            if th is None:
                cols = floor_prediction_columns(q["R"][2], q["t"], spots_xy=p0[:, :2])
            else:
                cols = floor_prediction_columns(q["R"][2], q["t"], theta=th, h=q["h"][0], offsets=q["offsets"])
            if Winv is not None:
                cols = {k: np.einsum("nij,nj->ni", Winv, v) for k, v in cols.items()}
            out = {"R": np.zeros((2 * n, 3)), "t": np.zeros((2 * n, 3))}
            out["R"][:, 2] = -cols["yaw"].reshape(-1)
            out["t"][:, 0], out["t"][:, 1] = -cols["t_x"].reshape(-1), -cols["t_y"].reshape(-1)
            if th is not None:
                out["h"] = -cols["h"].reshape(-1, 1)
                out["offsets"] = -np.stack([cols["pan_offset"], cols["tilt_offset"]], axis=-1).reshape(-1, 2)
            return out

        # whitened residuals have unit covariance: sigma 1 (in units of each point's own covariance)
        prob.add_residuals(residuals, name="floor", jacobian=jacobian, residual_dim=2,
                           sigma=1.0 if Winv is not None else (sigma if sigma else None))
        return prob, raw

    x_start = [start.yaw, start.t_0_W[0], start.t_0_W[1]]
    p_start = [model.h, *model.offsets]
    Winv = None
    passes = 1
    if jn is not None:
        Winv = _whitener(floor_covariance(model, th_cov, start.yaw, sigma=sigma, joint_noise=jn))
        passes = 2
    res = raw = None
    for k in range(passes):
        prob, raw = build(x_start, p_start, Winv)
        # trf, not lm: MINPACK keeps iterating on an exact (zero-residual) fit until max_nfev
        res = solve(prob, method="trf", loss=loss, absolute_sigma=absolute_sigma and bool(sigma),
                    progress=n > LARGE_N and sys.stderr.isatty())
        if not np.all(np.isfinite(res.x)):
            raise ConvergenceError("nonlinear: the solver returned a non-finite estimate")
        x_start = [float(res.params["R"][2]), float(res.params["t"][0]), float(res.params["t"][1])]
        if th is not None:
            p_start = [float(res.params["h"][0]), *map(float, res.params["offsets"])]
        if k + 1 < passes:  # the covariance at the first solution's h and offsets
            m_k = model.with_(d1=H - p_start[0], offsets=tuple(p_start[1:])) if th is not None else model
            Winv = _whitener(floor_covariance(m_k, th_cov, x_start[0], sigma=sigma, joint_noise=jn))
    yaw = float(res.params["R"][2])
    R = matrix_from_angle("z", yaw)
    t = np.array(res.params["t"], dtype=float)
    resid = raw(res.params)
    std = {"yaw": res.std.get("yaw"), "t_x": res.std.get("t_x"), "t_y": res.std.get("t_y")}
    extra = {}
    if th is not None:
        extra["h"] = float(res.params["h"][0])
        extra["offsets"] = [float(v) for v in res.params["offsets"]]
        for lab in estimate:
            std[lab] = res.std.get(lab) if lab in free else None
    warns = list(res.warnings)
    if sigma and absolute_sigma and loss == "linear":
        # the solver's per-observation test sees residuals pulled towards a gross point by the fit itself
        warns = [w for w in warns if w.code != "outliers"]
        order, scores, thr = deleted_residual_outliers(res.weighted_residuals.reshape(n, 2),
                                                       res.jac.toarray() if hasattr(res.jac, "toarray") else res.jac)
        extra["outlier_scores"] = scores
        if order:
            shown = ", ".join(f"{i} ({math.sqrt(scores[i]):.1f} sigma)" for i in order[:10])
            warns.append(Diagnostic(
                "outliers",
                f"{len(order)} of {n} point(s) inconsistent with the fit of the others: [{shown}"
                f"{', ...' if len(order) > 10 else ''}] (studentized deleted residual beyond "
                f"{math.sqrt(thr):.2f} sigma, the core's Bonferroni bound of 1 %/N; worst first)",
                indices=tuple(order)))
    extra["whitened"] = Winv is not None
    return ExtrinsicEstimate("nonlinear", R, t, std, resid, _rms(resid), np.asarray(res.cost_history),
                             res.iterations, warns, dict(extra, lsq=res), res.cov, list(res.free_labels))


def deleted_residual_outliers(e, J, *, max_removed: int = 20):
    """Points whose studentized deleted residual exceeds the core's outlier bound, worst first.

    The bound is the solver's default (:func:`robocal.estimation.outlier_sigma`
    of the N points, a chi-square(2) quantile by
    :func:`robocal.estimation.outlier_threshold`): at most 1 % false alarms per
    data set whatever N (Bonferroni), never below 3 sigma.

    Parameters
    ----------
    e : ndarray, shape (N, 2)
        Whitened residuals (unit covariance under the model).
    J : ndarray, shape (2N, p)
        Jacobian of the whitened residuals w.r.t. the free parameters.

    Returns
    -------
    order : list of int
        The flagged points, the worst first. After each flagged point the fit
        is updated without it (one Gauss-Newton step: exact for the linearised
        model) and the rest re-tested, at most ``max_removed`` times; points
        still beyond the bound after that follow by score.
    scores : ndarray, shape (N,)
        ``t_i^2 = e_i^T (I - H_ii)^-1 e_i`` of the full fit (chi-square, 2 dof).
    threshold : float
        The chi-square(2) quantile of the two-sided Gaussian tail of
        ``outlier_sigma(N)``: ``-2 ln(0.01 / N)`` for N >= 4.
    """
    n = e.shape[0]
    thr = outlier_threshold(outlier_sigma(n), 2)
    Jb = np.asarray(J, dtype=float).reshape(n, 2, -1)
    active = np.ones(n, bool)
    e_cur = np.array(e, dtype=float)
    order: list[int] = []
    scores0 = None
    exhausted = True
    for _ in range(max_removed + 1):
        Ja = Jb[active].reshape(-1, Jb.shape[2])
        Ninv = np.linalg.pinv(Ja.T @ Ja)
        Hii = np.einsum("nai,ij,nbj->nab", Jb, Ninv, Jb)
        M = np.eye(2)[None] - Hii  # residual covariance of a point in the fit
        sc = np.where(active, np.einsum("na,nab,nb->n", e_cur, np.linalg.inv(np.where(active[:, None, None], M,
                                                                                        np.eye(2)[None])), e_cur),
                      -np.inf)
        if scores0 is None:
            scores0 = sc.copy()
        k = int(np.argmax(sc))
        if not sc[k] > thr or active.sum() - 1 <= Jb.shape[2] // 2 + 1:
            exhausted = False
            break
        order.append(k)
        active[k] = False
        # one Gauss-Newton step of the fit without the dropped points (the whitened model is nearly linear)
        Ja = Jb[active].reshape(-1, Jb.shape[2])
        dx = -np.linalg.lstsq(Ja, e_cur[active].reshape(-1), rcond=None)[0]
        e_cur = e_cur + (Jb @ dx)
    rest = ([int(i) for i in np.argsort(-scores0) if active[i] and scores0[i] > thr] if exhausted else [])
    return order + rest, scores0, thr


