"""Calibration of the sensor array from a drive with a reference trajectory.

The seed's "next step" (§4): estimate each sensor's ``R_i``, ``psi_i``,
``phi_i`` and ``scale_i``. The drive is cut into windows of ``window``
seconds. Over window ``[k0, k1)`` sensor ``i``'s displacements, chained in
the sensor frame of the window's start with the reference headings,

    M_i = sum_k R(theta_{k+1} - theta_k0) dS_ik

must equal the sensor point's displacement in the robot frame at ``k0``,
rotated into the sensor frame:

    scale_i R(phi_i) M_i = R(-theta_k0) (P_k1 - P_k0) + (R(theta_k1 - theta_k0) - I) r_i,
    r_i = R_i (cos psi_i, sin psi_i).

The model is linear in ``(scale cos phi, scale sin phi, r_x, r_y)``, which
gives the start; the final estimate and its covariance come from
:func:`robocal.estimation.solve` in the physical parameters. ``r_i`` needs
rotation in the drive and ``(scale, phi)`` translation: a drive of straight
lines, turns on the spot and arcs (``trajectory="calibration"`` in the
simulator) determines all four per sensor.

Windows rather than single frames: the reference's noise is differenced
once per window instead of once per frame (at 400 Hz a 0.5 mm reference
noise would swamp 1 mm steps).

The covariance is sampling error under the model, from the residual scatter;
the reference trajectory is treated as exact (errors-in-variables ignored).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.errors import InputError, NotEnoughDataError
from robocal.estimation import Problem, solve
from robocal.rigs.flow.model import SensorArray, rot2
from robocal.rigs.flow.odometry import SensorSteps

__all__ = ["ArrayCalibration", "calibrate_array", "interpolate_poses", "window_observations"]


def interpolate_poses(t_ref, poses_ref, t):
    """Reference poses ``(X, Y, theta)`` at times ``t`` (linear; heading unwrapped)."""
    t_ref = np.asarray(t_ref, float)
    p = np.asarray(poses_ref, float)
    if np.any(np.diff(t_ref) <= 0):
        k = int(np.flatnonzero(np.diff(t_ref) <= 0)[0])
        raise InputError(f"reference timestamps must increase strictly: t[{k + 1}] = {t_ref[k + 1]} follows {t_ref[k]}")
    t = np.asarray(t, float)
    if t[0] < t_ref[0] - 1e-9 or t[-1] > t_ref[-1] + 1e-9:
        raise InputError(f"the reference covers {t_ref[0]:.3f}..{t_ref[-1]:.3f} s but the log spans {t[0]:.3f}..{t[-1]:.3f} s")
    th = np.unwrap(p[:, 2])
    return np.stack([np.interp(t, t_ref, p[:, 0]), np.interp(t, t_ref, p[:, 1]), np.interp(t, t_ref, th)], 1)


def window_observations(steps: SensorSteps, poses, window: float):
    """Per sensor and window: chained measurement ``M`` and the reference motion.

    Returns
    -------
    M : ndarray (n, J, 2)
        Chained sensor displacement (NaN where a frame of the window is invalid).
    dP : ndarray (J, 2)
        ``R(-theta_k0) (P_k1 - P_k0)``.
    dth : ndarray (J,)
        ``theta_k1 - theta_k0``.
    """
    K = steps.disp.shape[1]
    m = max(1, int(round(window / np.median(steps.dt))))
    J = K // m
    if J < 4:
        raise NotEnoughDataError(f"the drive gives {J} windows of {window} s; calibration needs at least 4 (a longer drive)")
    th = poses[:, 2]
    ks = np.arange(J * m).reshape(J, m)
    k0 = ks[:, 0]
    # a frame's displacement is measured in the sensor frame at the end of its interval
    rel = th[ks + 1] - th[k0][:, None]                              # (J, m)
    d = steps.disp[:, ks, :]                                        # (n, J, m, 2)
    ok = steps.valid[:, ks] & np.all(np.isfinite(d), axis=3)
    M = np.einsum("jmab,njmb->nja", rot2(rel), np.where(ok[..., None], d, 0.0))
    M = np.where(ok.all(axis=2)[..., None], M, np.nan)
    P0 = poses[k0, :2]
    P1 = poses[k0 + m, :2]
    dP = np.einsum("jba,jb->ja", rot2(th[k0]), P1 - P0)            # R(-theta) (P1 - P0)
    return M, dP, th[k0 + m] - th[k0]


@dataclass
class ArrayCalibration:
    """Result of :func:`calibrate_array`.

    Attributes
    ----------
    array : SensorArray
        The calibrated placement.
    std : dict
        ``{"<sensor>.R": m, ".psi": rad, ".phi": rad, ".scale": 1}``; None
        where the drive does not determine a parameter.
    residual_rms : float
        RMS of the window residuals, m.
    n_windows : ndarray of int, shape (n,)
        Windows used per sensor.
    lsq : LSQResult
    warnings : list of Diagnostic
    """

    array: SensorArray
    std: dict
    residual_rms: float
    n_windows: np.ndarray
    lsq: object
    warnings: list = field(default_factory=list)

    def estimate_dict(self) -> dict:
        out = {}
        for i, nm in enumerate(self.array.names):
            out[f"{nm}.R"] = float(self.array.R[i])
            out[f"{nm}.psi"] = float(self.array.psi[i])
            out[f"{nm}.phi"] = float(self.array.phi[i])
            out[f"{nm}.scale"] = float(self.array.scale[i])
        return out

    def units(self) -> dict:
        return {k: {"R": "m", "psi": "rad", "phi": "rad", "scale": "1"}[k.split(".")[-1]] for k in self.estimate_dict()}


def calibrate_array(steps: SensorSteps, t_ref, poses_ref, nominal: SensorArray, *, window: float = 0.1,
                    loss: str = "linear") -> ArrayCalibration:
    """Estimate every sensor's ``(R, psi, phi, scale)`` from a drive with a reference trajectory.

    Parameters
    ----------
    steps : SensorSteps
        The drive's per-sensor displacements (computed with scale 1: raw eq. 5).
    t_ref, poses_ref : array_like, shapes (M,), (M, 3)
        Reference trajectory (motion capture, a total station, a simulator):
        times (s) and ``(X, Y, theta)`` (m, m, rad).
    nominal : SensorArray
        Names and starting values.
    window : float
        Window length, s.
    loss : str
        Robust loss for :func:`robocal.estimation.solve` (``"soft_l1"``,
        ``"huber"``, ...); outlying windows are named either way.
    """
    if steps.disp.shape[0] != nominal.n:
        raise InputError(f"the log has {steps.disp.shape[0]} sensors but the array describes {nominal.n}")
    poses = interpolate_poses(t_ref, poses_ref, steps.t)
    M, dP, dth = window_observations(steps, poses, window)
    prob = Problem()
    starts = []
    n_win = np.zeros(nominal.n, int)
    for i, nm in enumerate(nominal.names):
        ok = np.all(np.isfinite(M[i]), axis=1)
        n_win[i] = ok.sum()
        if ok.sum() < 3:
            raise NotEnoughDataError(f"sensor {nm}: only {ok.sum()} complete windows with a valid flow (need >= 3)")
        Mi, dPi, dthi = M[i][ok], dP[ok], dth[ok]
        # linear start: [[Mx, -My], [My, Mx]] (a, b) - (R(dth) - I) r = dP
        c, s = np.cos(dthi) - 1.0, np.sin(dthi)
        rows = np.zeros((ok.sum(), 2, 4))
        rows[:, 0, :] = np.stack([Mi[:, 0], -Mi[:, 1], -c, s], 1)
        rows[:, 1, :] = np.stack([Mi[:, 1], Mi[:, 0], -s, -c], 1)
        sol, *_ = np.linalg.lstsq(rows.reshape(-1, 4), dPi.reshape(-1), rcond=None)
        a, b, rx, ry = sol
        x0 = np.array([np.hypot(rx, ry), np.arctan2(ry, rx), np.arctan2(b, a), np.hypot(a, b)])
        if not np.all(np.isfinite(x0)) or x0[3] <= 0:
            x0 = np.array([nominal.R[i], nominal.psi[i], nominal.phi[i], nominal.scale[i]])
        starts.append(x0)
        prob.add_block(nm, x0, labels=[f"{nm}.R", f"{nm}.psi", f"{nm}.phi", f"{nm}.scale"], unit=["m", "rad", "rad", "1"])

        def fun(p, nm=nm, Mi=Mi, dPi=dPi, dthi=dthi):
            R, psi, phi, sc = p[nm]
            r = np.array([R * np.cos(psi), R * np.sin(psi)])
            lhs = sc * np.einsum("ab,jb->ja", rot2(phi), Mi)
            rhs = dPi + np.einsum("jab,b->ja", rot2(dthi), r) - r
            return lhs - rhs

        prob.add_residuals(fun, name=nm, blocks=[nm], residual_dim=2)
    res = solve(prob, method="lm" if loss == "linear" else "trf", loss=loss)
    est = res.params
    arr = nominal.copy(
        R=np.array([est[nm][0] for nm in nominal.names]),
        psi=np.array([np.angle(np.exp(1j * est[nm][1])) for nm in nominal.names]),
        phi=np.array([np.angle(np.exp(1j * est[nm][2])) for nm in nominal.names]),
        scale=np.array([est[nm][3] for nm in nominal.names]),
    )
    return ArrayCalibration(array=arr, std=dict(res.std), residual_rms=float(res.rms), n_windows=n_win, lsq=res,
                            warnings=list(res.warnings))
