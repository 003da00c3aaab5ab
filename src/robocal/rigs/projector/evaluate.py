"""The seed's Table 2 protocol on a simulated rig, and a floor error map.

For each desired world point the *calibrated* model commands joint angles
(seed eqs. 1 and 8); the *true* projector lands the spot there; the error is
``landed - desired`` on the floor (m).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from robocal.errors import InputError, RobocalError
from robocal.rigs.projector.closed_form import floor_prediction_columns
from robocal.rigs.projector.model import NearSingularityWarning, ProjectorModel
from robocal.rigs.projector.published import TABLE2_DESIRED, TABLE2_MEASURED_A, TABLE2_MEASURED_B
from robocal.validation import check_array

__all__ = ["Evaluation", "evaluate_points", "table2_grid", "error_map", "published_table2_errors",
           "floor_prediction_jacobian", "spot_error_covariance", "predicted_error_map", "estimate_covariance",
           "evaluation_extent"]


@dataclass
class Evaluation:
    """Commanded angles and spot errors for a set of desired floor points.

    Attributes
    ----------
    desired : ndarray, shape (M, 2)
        Desired world floor points (m).
    theta : ndarray, shape (M, 2)
        Joint angles the calibrated model commands (rad; NaN where it refused).
    landed : ndarray, shape (M, 2)
        Where the true projector puts the spot (m; NaN where not reached).
    error : ndarray, shape (M, 2)
        ``landed - desired`` (m).
    reached : ndarray of bool, shape (M,)
    """

    desired: np.ndarray
    theta: np.ndarray
    landed: np.ndarray
    error: np.ndarray
    reached: np.ndarray

    @property
    def norm(self) -> np.ndarray:
        return np.linalg.norm(self.error, axis=1)

    @property
    def rms(self) -> float:
        n = self.norm[self.reached]
        return float(np.sqrt(np.mean(n**2))) if n.size else float("nan")

    @property
    def max(self) -> float:
        n = self.norm[self.reached]
        return float(n.max()) if n.size else float("nan")

    def rows(self) -> list[dict]:
        """Table 2 layout: desired, landed (cm) and error (mm)."""
        out = []
        for i in range(len(self.desired)):
            out.append({
                "#": i + 1,
                "desired x [cm]": 100 * self.desired[i, 0], "desired y [cm]": 100 * self.desired[i, 1],
                "theta1 [deg]": np.degrees(self.theta[i, 0]), "theta2 [deg]": np.degrees(self.theta[i, 1]),
                "landed x [cm]": 100 * self.landed[i, 0], "landed y [cm]": 100 * self.landed[i, 1],
                "error [mm]": 1000 * self.norm[i] if self.reached[i] else None,
            })
        return out

    def to_dict(self) -> dict:
        return dict(desired=self.desired, theta=self.theta, landed=self.landed, error=self.error,
                    reached=self.reached.tolist(), rms=self.rms, max=self.max)


def table2_grid(center=(0.0, 0.0), spacing: float = 2.0) -> np.ndarray:
    """The seed's Table 2 grid: 3 x 3 points ``spacing`` (m) apart around ``center``, shape (9, 2)."""
    c = check_array(center, "center", shape=(2,))
    g = np.array([-1.0, 0.0, 1.0]) * spacing
    xx, yy = np.meshgrid(g, g, indexing="ij")
    return np.column_stack([xx.ravel(), yy.ravel()]) + c


def evaluate_points(truth: ProjectorModel, calibrated: ProjectorModel, desired_W, *,
                    rng: np.random.Generator | None = None, measure_sigma: float = 0.0) -> Evaluation:
    """Run the Table 2 protocol: desired -> commanded angles -> landed spot -> error.

    Parameters
    ----------
    truth : ProjectorModel
        The real rig (extrinsics, ``H - d1``, offsets).
    calibrated : ProjectorModel
        The model the calibration produced (what commands the projector).
    desired_W : array_like, shape (M, 2)
        Desired world floor points (m).
    rng, measure_sigma
        Optional noise (m) of measuring the landed spot, as the seed's tape did.
    """
    d = check_array(desired_W, "desired_W", shape=("M", 2))
    if d.ndim != 2:
        raise InputError(f"desired_W must have shape (M, 2), got {tuple(d.shape)}")
    ok = calibrated.reachable(calibrated.to_projector(d))
    theta = np.full(d.shape, np.nan)
    landed = np.full(d.shape, np.nan)
    if np.any(ok):
        theta[ok] = calibrated.ik_world(d[ok], on_nadir="ignore")
        with warnings.catch_warnings():  # the true head may sit just past its tilt limit at the disc's rim
            warnings.simplefilter("ignore", NearSingularityWarning)
            try:
                landed[ok] = truth.spot_world(theta[ok])[:, :2]
            except RobocalError:  # a wildly wrong calibration can aim above the horizon
                for i in np.flatnonzero(ok):
                    try:
                        landed[i] = truth.spot_world(theta[i])[:2]
                    except RobocalError:
                        ok[i] = False
    if measure_sigma and rng is not None:
        landed[ok] += rng.normal(0.0, measure_sigma, (int(ok.sum()), 2))
    return Evaluation(d, theta, landed, landed - d, ok)


def error_map(truth: ProjectorModel, calibrated: ProjectorModel, x_range, y_range, n: int = 41):
    """Spot error magnitude (m) over a floor grid; NaN outside the reachable floor.

    Returns ``(xs (n,), ys (n,), err (n, n))`` with ``err[j, i]`` at ``(xs[i], ys[j])``.
    """
    xs = np.linspace(*x_range, n)
    ys = np.linspace(*y_range, n)
    X, Y = np.meshgrid(xs, ys)
    ev = evaluate_points(truth, calibrated, np.column_stack([X.ravel(), Y.ravel()]))
    err = np.where(ev.reached, ev.norm, np.nan).reshape(n, n)
    return xs, ys, err


def evaluation_extent(truth: ProjectorModel, desired) -> tuple:
    """``(x_range, y_range)`` (m) of the evaluation's error map: the grid and 60 % of the reachable floor, + 0.5 m."""
    grid = np.asarray(desired, dtype=float)
    nadir = truth.nadir_world
    r = truth.floor_radius * 0.6
    xr = (min(grid[:, 0].min(), nadir[0] - r) - 0.5, max(grid[:, 0].max(), nadir[0] + r) + 0.5)
    yr = (min(grid[:, 1].min(), nadir[1] - r) - 0.5, max(grid[:, 1].max(), nadir[1] + r) + 0.5)
    return xr, yr


def published_table2_errors() -> dict:
    """Errors of the seed's Table 2 (measured - desired, m) for projectors A and B, with RMS and max."""
    out = {}
    for name, meas in (("A", TABLE2_MEASURED_A), ("B", TABLE2_MEASURED_B)):
        e = meas - TABLE2_DESIRED
        n = np.linalg.norm(e, axis=1)
        out[name] = dict(error=e, norm=n, rms=float(np.sqrt(np.mean(n**2))), max=float(n.max()),
                         mean=e.mean(axis=0))
    return out


#: Parameters whose covariance :func:`spot_error_covariance` propagates (labels of the calibrate estimates).
MAP_PARAMS = ("yaw", "t_x", "t_y", "h", "pan_offset", "tilt_offset")


def floor_prediction_jacobian(model: ProjectorModel, theta, labels=MAP_PARAMS) -> np.ndarray:
    """``d pred / d p`` (M, 2, P): world floor spot ``pred = Rz(-yaw) (f(theta) - t)_xy`` (seed eqs. 1, 6).

    ``p`` are the parameters named in ``labels`` (yaw, pan/tilt offsets in rad;
    ``t_x, t_y, h`` in m), evaluated at ``model`` (its yaw, ``t_0_W``, ``h = H -
    d1`` and offsets). The same derivatives as the residual Jacobian of
    :func:`robocal.rigs.projector.calibrate.nonlinear`, with the opposite sign
    (both from :func:`robocal.rigs.projector.calibrate.floor_prediction_columns`).
    """
    th = np.atleast_2d(np.asarray(theta, dtype=float))
    yaw = float(np.arctan2(model.R_0_W[1, 0], model.R_0_W[0, 0]))
    cols = floor_prediction_columns(yaw, model.t_0_W, theta=th, h=model.h, offsets=model.offsets)
    unknown = [lab for lab in labels if lab not in cols]
    if unknown:
        raise InputError(f"labels: unknown parameter(s) {unknown} (known: {', '.join(MAP_PARAMS)})")
    return np.stack([cols[lab] for lab in labels], axis=-1)


def spot_error_covariance(model: ProjectorModel, cov, labels, points_W) -> np.ndarray:
    """Predicted covariance (M, 2, 2) (m^2) of the spot error at desired world floor points.

    First-order propagation (seed eqs. 1, 6, 8): the calibrated ``model``
    commands ``theta = IK(w)``; the real rig, whose parameters differ from the
    estimate by ``dp ~ N(0, cov)``, lands the spot at ``w + G dp`` with ``G =
    d pred / d p`` at ``theta`` (:func:`floor_prediction_jacobian`). Returns
    ``G cov G^T``. Points must be reachable by ``model``.
    """
    w = check_array(points_W, "points_W", shape=("M", 2))
    C = check_array(cov, "cov")
    labels = list(labels)
    if C.shape != (len(labels), len(labels)):
        raise InputError(f"cov must be ({len(labels)}, {len(labels)}) for labels {labels}, got {C.shape}")
    theta = model.ik_world(w, on_nadir="ignore")
    G = floor_prediction_jacobian(model, theta, labels)
    return np.einsum("mip,pq,mjq->mij", G, C, G)


def predicted_error_map(model: ProjectorModel, cov, labels, x_range, y_range, n: int = 41):
    """Predicted 1-sigma spot error (m) over a floor grid, NaN outside the reachable floor.

    The value is ``sqrt(trace(Sigma_e))``, the RMS length of the error vector
    (:func:`spot_error_covariance`). Returns ``(xs, ys, err)`` like :func:`error_map`.
    """
    xs = np.linspace(*x_range, n)
    ys = np.linspace(*y_range, n)
    X, Y = np.meshgrid(xs, ys)
    pts = np.column_stack([X.ravel(), Y.ravel()])
    ok = model.reachable(model.to_projector(pts))
    err = np.full(len(pts), np.nan)
    if np.any(ok):
        S = spot_error_covariance(model, cov, labels, pts[ok])
        err[ok] = np.sqrt(np.maximum(np.trace(S, axis1=1, axis2=2), 0.0))
    return xs, ys, err.reshape(n, n)


def estimate_covariance(run):
    """``(model, cov, labels, note)`` of a calibration run's primary estimate, for :func:`predicted_error_map`.

    ``model`` is the calibrated projector. ``cov`` is the estimate's parameter
    covariance; where it is not finite (rank deficiency: the pan offset is not
    identifiable) it is rebuilt as ``s^2 (G^T G)^+`` from the calibration points,
    the unobservable direction moving no spot. ``cov`` is None (with ``note``
    saying why) when the estimate has none (the seed's method).
    """
    est = run.best
    model = run.calibrated_model()
    labels = [lab for lab in (est.labels or []) if lab in MAP_PARAMS]
    if est.cov is None or not labels:
        return model, None, [], f"the {run.primary} estimate has no covariance"
    C = np.asarray(est.cov, dtype=float)
    if np.all(np.isfinite(C)):
        return model, C, labels, ""
    theta = run.theta if run.theta is not None else model.ik_world(run.points_W[:, :2], on_nadir="ignore",
                                                                   check_reach=False)
    G = floor_prediction_jacobian(model, theta, labels).reshape(-1, len(labels))
    dof = G.shape[0] - np.linalg.matrix_rank(G)
    s2 = run.sigma**2 if run.sigma else (float(np.sum(est.residuals**2)) / dof if dof > 0 else None)
    if s2 is None:
        return model, None, [], "no noise level: give 'noise' or more points"
    return model, s2 * np.linalg.pinv(G.T @ G), labels, "covariance rebuilt with a pseudo-inverse (rank-deficient fit)"
