"""The seed's Table 2 protocol on a simulated rig, and a floor error map.

For each desired world point the *calibrated* model commands joint angles
(seed eqs. 1 and 8); the *true* projector lands the spot there; the error is
``landed - desired`` on the floor (m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.errors import InputError, RobocalError
from robocal.rigs.projector.model import ProjectorModel
from robocal.rigs.projector.published import TABLE2_DESIRED, TABLE2_MEASURED_A, TABLE2_MEASURED_B
from robocal.validation import check_array

__all__ = ["Evaluation", "evaluate_points", "table2_grid", "error_map", "published_table2_errors"]


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


def published_table2_errors() -> dict:
    """Errors of the seed's Table 2 (measured - desired, m) for projectors A and B, with RMS and max."""
    out = {}
    for name, meas in (("A", TABLE2_MEASURED_A), ("B", TABLE2_MEASURED_B)):
        e = meas - TABLE2_DESIRED
        n = np.linalg.norm(e, axis=1)
        out[name] = dict(error=e, norm=n, rms=float(np.sqrt(np.mean(n**2))), max=float(n.max()),
                         mean=e.mean(axis=0))
    return out
