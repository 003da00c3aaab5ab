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
The flow kernel's bias, which a drive repeats and no resampling sees, is the
separate ``systematic`` term, derived from the run's flow phases
(:mod:`robocal.rigs.flow.kernel_bias`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import InputError, NotEnoughDataError
from robocal.rigs.flow.kernel_bias import displacement_bias
from robocal.rigs.flow.model import SensorArray, median, rot2
from robocal.rigs.flow.odometry import SensorSteps

__all__ = ["ArrayCalibration", "calibrate_array", "interpolate_poses", "window_observations", "KERNEL_SYSTEMATIC"]

#: Shortest window, frame intervals: one-frame windows difference the reference every frame
#: and make the white-noise sigma meaningless (it shrank 4x at window 0 before this check).
MIN_WINDOW_FRAMES = 4

#: Jackknife segments: contiguous blocks of windows deleted one at a time.
JACKKNIFE_SEGMENTS = 10

#: Fallback systematic uncertainty per parameter kind from the flow kernel's pixel locking, used
#: only when the steps carry no raw flow of this kernel (hand-built steps, a log that states
#: another kernel's flow error): the RMS
#: error over sensors and seeds of rendered calibration drives (gravel, 400 Hz, equiangular
#: kernel, seeds 100-103, 6 s; docs/rigs/flow.md), rounded up. Otherwise the systematic is
#: derived from the run (:mod:`robocal.rigs.flow.kernel_bias`): it follows each sensor's
#: motion, e.g. 9-10 mm for s270.R of the simulated rig and 1-2 mm for s60.R and s120.R.
KERNEL_SYSTEMATIC = {"R": 0.007, "psi": np.radians(0.6), "phi": np.radians(0.2), "scale": 0.009}


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
    dt = median(steps.dt)
    if not np.isfinite(window) or window < MIN_WINDOW_FRAMES * dt * (1 - 1e-9):
        raise InputError(f"window must be at least {MIN_WINDOW_FRAMES} frame intervals ({MIN_WINDOW_FRAMES * dt:.4g} s "
                         f"at this log's {1 / dt:.4g} Hz), got {window} s")
    m = int(round(window / dt))
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


def array_estimate(array: SensorArray) -> dict:
    """``{"<sensor>.R": m, ".psi": rad, ".phi": rad, ".scale": 1}`` of an array, sensor by sensor."""
    return {f"{nm}.{p}": float(getattr(array, p)[i]) for i, nm in enumerate(array.names)
            for p in ("R", "psi", "phi", "scale")}


@dataclass
class ArrayCalibration:
    """Result of :func:`calibrate_array`.

    Attributes
    ----------
    array : SensorArray
        The calibrated placement.
        Parameters the drive does not determine keep their nominal values
        (listed in ``undetermined``).
    std : dict
        Statistical standard deviation, ``{"<sensor>.R": m, ".psi": rad,
        ".phi": rad, ".scale": 1}``: the segment jackknife (``std_jackknife``,
        honest for time-correlated flow errors), or the white-noise model
        (``std_model``) on drives too short for it. None where the drive does
        not determine a parameter.
    std_model, std_jackknife : dict
        The two ingredients of ``std`` (same keys; None where undetermined or
        not computed).
    systematic : dict
        Systematic uncertainty of the flow kernel (pixel locking of the
        sub-pixel fit, which no resampling of one drive can see), same units.
        Derived from the run: ``|estimate - estimate_debiased|``, the change
        when the kernel's bias, evaluated at each frame's flow phase, is
        removed (:mod:`robocal.rigs.flow.kernel_bias`). The bias table is
        measured on the run's own frames (``systematic_source == "run"``) or,
        for a flow log of this kernel, on gravel-photograph frames
        (``"model"``); else (steps without raw flow, a log of another kernel)
        the constant :data:`KERNEL_SYSTEMATIC` (``"constant"``). Combine as
        ``hypot(std, systematic)``.
    systematic_source : str
        ``"run"``, ``"model"`` or ``"constant"``.
    array_debiased : SensorArray or None
        The estimate with the modelled kernel bias removed (None with the
        constant; ``array`` itself when the steps were debiased, ``FlowConfig.debias``):
        closer to the physical mounting (s270.R within 2 mm instead of 10-11 mm
        short on rendered drives), but the odometry of a later run reads the
        same biased kernel, so ``array`` (effective parameters) is the one to use.
    bias_table : ndarray or None
        The kernel's bias per sub-pixel phase cell, px (``kernel_bias.measure_bias_table``).
    undetermined : list of str
        Parameters the drive does not determine (kept at nominal).
    window_times : dict
        Per sensor, the start times (s) of the windows it entered with, in
        the order of its residuals.
    residual_rms : float
        RMS of the window residuals, m.
    n_windows : ndarray of int, shape (n,)
        Windows used per sensor.
    lsq : LSQResult
    warnings : list of Diagnostic
    window : float or None
        The window length, s.
    array_file : str or None
        The file the calibrated array was written to (relative to the result's
        folder), when it was (``robocal flow calibrate``).
    """

    array: SensorArray
    std: dict
    residual_rms: float
    n_windows: np.ndarray
    lsq: object
    warnings: list = field(default_factory=list)
    std_model: dict = field(default_factory=dict)
    std_jackknife: dict = field(default_factory=dict)
    systematic: dict = field(default_factory=dict)
    undetermined: list = field(default_factory=list)
    window_times: dict = field(default_factory=dict)
    systematic_source: str = "constant"
    array_debiased: SensorArray | None = None
    bias_table: np.ndarray | None = None
    window: float | None = None
    array_file: str | None = None

    def total_std(self) -> dict:
        """``hypot(std, systematic)`` per parameter (None where undetermined)."""
        return {k: (None if v is None else float(np.hypot(v, self.systematic.get(k, 0.0)))) for k, v in self.std.items()}

    def estimate_dict(self) -> dict:
        return array_estimate(self.array)

    def units(self) -> dict:
        return {k: {"R": "m", "psi": "rad", "phi": "rad", "scale": "1"}[k.split(".")[-1]] for k in self.estimate_dict()}


def _near(ref, angles) -> np.ndarray:
    """``angles`` (rad) wrapped to within half a turn of ``ref`` (270 deg stays 270, not -90)."""
    from robocal.geometry import wrap_angle

    ref = np.asarray(ref, dtype=float)
    return ref + wrap_angle(np.asarray(angles, dtype=float) - ref)


def _problem(M, dP, dth, names, x0s, keep):
    """The windowed model of the module doc over the windows ``keep[i]`` of each sensor."""
    from robocal.estimation import Problem  # imported when calibrating: odometry does without scipy.optimize

    prob = Problem()
    for i, nm in enumerate(names):
        Mi, dPi, dthi = M[i][keep[i]], dP[keep[i]], dth[keep[i]]
        prob.add_block(nm, x0s[i], labels=[f"{nm}.R", f"{nm}.psi", f"{nm}.phi", f"{nm}.scale"], unit=["m", "rad", "rad", "1"])

        def fun(p, nm=nm, Mi=Mi, dPi=dPi, dthi=dthi):
            R, psi, phi, sc = p[nm]
            r = np.array([R * np.cos(psi), R * np.sin(psi)])
            lhs = sc * np.einsum("ab,jb->ja", rot2(phi), Mi)
            rhs = dPi + np.einsum("jab,b->ja", rot2(dthi), r) - r
            return lhs - rhs

        prob.add_residuals(fun, name=nm, blocks=[nm], residual_dim=2)
    return prob


def _solve(prob, loss):
    from robocal.estimation import solve

    return solve(prob, method="lm" if loss == "linear" else "trf", loss=loss)


def calibrate_array(steps: SensorSteps, t_ref, poses_ref, nominal: SensorArray, *, window: float = 0.1,
                    loss: str = "linear", jackknife: bool = True) -> ArrayCalibration:
    """Estimate every sensor's ``(R, psi, phi, scale)`` from a drive with a reference trajectory.

    Parameters
    ----------
    steps : SensorSteps
        The drive's per-sensor displacements (computed with scale 1: raw eq. 5).
    t_ref, poses_ref : array_like, shapes (M,), (M, 3)
        Reference trajectory (motion capture, a total station, a simulator):
        times (s) and ``(X, Y, theta)`` (m, m, rad).
    nominal : SensorArray
        Names and starting values; parameters the drive does not determine
        keep these values.
    window : float
        Window length, s (at least :data:`MIN_WINDOW_FRAMES` frame intervals).
    loss : str
        Robust loss for :func:`robocal.estimation.solve` (``"soft_l1"``,
        ``"huber"``, ...); outlying windows are named either way.
    jackknife : bool
        Compute the statistical std by a delete-one-segment jackknife over
        :data:`JACKKNIFE_SEGMENTS` contiguous stretches of the drive (fewer, down
        to 4, for drives of fewer windows; none below that: ``std_model`` only). The flow
        errors are correlated in time (the kernel's bias follows the slowly
        changing sub-pixel phase), so the white-noise std from the residual
        scatter understates the error and grows with ``window``; the
        jackknife sees the correlation and does not depend on ``window``.
    """
    from robocal.geometry import wrap_angle

    if steps.disp.shape[0] != nominal.n:
        raise InputError(f"the log has {steps.disp.shape[0]} sensors but the array describes {nominal.n}")
    poses = interpolate_poses(t_ref, poses_ref, steps.t)
    M, dP, dth = window_observations(steps, poses, window)
    J = dP.shape[0]
    t_win = steps.t[np.arange(J) * int(round(window / float(np.median(steps.dt))))]
    starts = []
    keep = np.all(np.isfinite(M), axis=2)                          # (n, J)
    n_win = keep.sum(axis=1)
    for i, nm in enumerate(nominal.names):
        ok = keep[i]
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
        if not np.all(np.isfinite(x0)) or x0[3] <= 0 or x0[0] < 1e-6:
            x0 = np.array([nominal.R[i], nominal.psi[i], nominal.phi[i], nominal.scale[i]])
        starts.append(x0)
    res = _solve(_problem(M, dP, dth, nominal.names, starts, keep), loss)
    est = {nm: np.array(res.params[nm], float) for nm in nominal.names}
    labels = [f"{nm}.{p}" for nm in nominal.names for p in ("R", "psi", "phi", "scale")]
    undetermined = [lab for lab in labels if res.std.get(lab) is None]
    # an undetermined parameter has no value from the data (the solver leaves it anywhere on
    # the null space, e.g. R = 0 on a straight drive): it keeps its nominal value
    nom = {"R": nominal.R, "psi": nominal.psi, "phi": nominal.phi, "scale": nominal.scale}
    for lab in undetermined:
        nm, p = lab.split(".")
        est[nm][("R", "psi", "phi", "scale").index(p)] = nom[p][nominal.names.index(nm)]
    std_model = {lab: (None if lab in undetermined else float(res.std[lab])) for lab in labels}
    std_jk = {lab: None for lab in labels}
    G = min(JACKKNIFE_SEGMENTS, J // 2)
    if jackknife and G >= 4:
        seg = np.minimum(np.arange(J) * G // J, G - 1)
        x_full = [est[nm] for nm in nominal.names]
        reps = []
        for g in range(G):
            kg = keep & (seg != g)[None, :]
            if np.any(kg.sum(axis=1) < 3):
                continue
            rg = _solve(_problem(M, dP, dth, nominal.names, x_full, kg), loss)
            reps.append(np.concatenate([rg.params[nm] for nm in nominal.names]))
        if len(reps) >= 4:
            G = len(reps)
            reps = np.array(reps)
            d = reps - np.concatenate(x_full)[None, :]
            ang = np.array([lab.split(".")[1] in ("psi", "phi") for lab in labels])
            d[:, ang] = wrap_angle(d[:, ang])
            d = d - d.mean(axis=0)
            sd = np.sqrt((G - 1) / G * np.sum(d**2, axis=0))
            std_jk = {lab: (None if lab in undetermined else float(sd[j])) for j, lab in enumerate(labels)}
    # the jackknife when the drive allows it: the white-noise std follows the window length
    # (residuals correlated in time), the jackknife does not
    std = {lab: (std_jk[lab] if std_jk[lab] is not None else std_model[lab]) for lab in labels}
    systematic = {lab: (None if lab in undetermined else float(KERNEL_SYSTEMATIC[lab.split(".")[1]])) for lab in labels}
    source, est_deb, table = "constant", None, None
    if steps.kernel is not None:
        # the kernel's pull towards whole pixels depends on each frame's sub-pixel phase, which a
        # drive repeats: measure it (on the run's own frames; gravel frames for a flow log), remove
        # it and re-solve; the change is this run's kernel systematic (s270 of the simulated rig:
        # 9-10 mm in R, s60 and s120 1-2 mm, where a constant gave 7 mm to all)
        table, source = steps.kernel.bias_table()
        # steps already debiased (FlowConfig.debias): put the bias back instead; the systematic
        # is then the size of the removed bias (conservative: the removal is not trusted further)
        sign = 1.0 if steps.kernel.debiased else -1.0
        deb = replace(steps, disp=steps.disp + sign * displacement_bias(steps.kernel, table))
        M_d, _, _ = window_observations(deb, poses, window)
        rd = _solve(_problem(M_d, dP, dth, nominal.names, [est[nm] for nm in nominal.names], keep), loss)
        est_deb = {nm: np.array(rd.params[nm], float) for nm in nominal.names}
        for j, lab in enumerate(labels):
            nm, k = divmod(j, 4)
            if lab in undetermined:
                est_deb[nominal.names[nm]][k] = est[nominal.names[nm]][k]
                continue
            d = est[nominal.names[nm]][k] - est_deb[nominal.names[nm]][k]
            systematic[lab] = float(abs(wrap_angle(d) if k in (1, 2) else d))
    arr = nominal.copy(
        R=np.array([est[nm][0] for nm in nominal.names]),
        psi=_near(nominal.psi, [est[nm][1] for nm in nominal.names]),
        phi=_near(nominal.phi, [est[nm][2] for nm in nominal.names]),
        scale=np.array([est[nm][3] for nm in nominal.names]),
    )
    arr_deb = None
    if est_deb is not None and steps.kernel.debiased:
        arr_deb = arr
    elif est_deb is not None:
        arr_deb = arr.copy(
            R=np.array([est_deb[nm][0] for nm in nominal.names]),
            psi=_near(arr.psi, [est_deb[nm][1] for nm in nominal.names]),
            phi=_near(arr.phi, [est_deb[nm][2] for nm in nominal.names]),
            scale=np.array([est_deb[nm][3] for nm in nominal.names]),
        )
    warnings = list(res.warnings)
    if undetermined:
        warnings.append(Diagnostic("rank_deficient", f"the drive does not determine {', '.join(undetermined)}: they keep "
                                   "their nominal values (R and psi need turns, phi and scale need translation)",
                                   params=tuple(undetermined)))
    return ArrayCalibration(array=arr, std=std, residual_rms=float(res.rms), n_windows=n_win, lsq=res,
                            warnings=warnings, std_model=std_model, std_jackknife=std_jk, systematic=systematic,
                            undetermined=undetermined, systematic_source=source, array_debiased=arr_deb,
                            bias_table=table, window=float(window), window_times={nm: t_win[keep[i]] for i, nm in enumerate(nominal.names)})
