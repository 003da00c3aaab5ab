"""Plausibility of a flow run: the slips that exit 0 with garbage, named in one line.

Two checks, both a few vectorised passes over the run (no fusion, no solve):

* **Height against the optics** (every run): one pixel sees ``h / f`` of
  floor. A downward flow sensor on an array whose sensors sit ``R`` from the
  robot's centre resolves texture much finer than the array: when one pixel
  covers more floor than the array's largest ``R`` (h = 100 m at f = 167 px:
  0.6 m per pixel against R = 0.35 m), the height is not in metres.
* **Flow against the reference motion** (runs with a ``reference``): over
  windows of the drive each sensor's chained displacement ``M`` must be the
  sensor point's motion under the reference, up to the sensor's own rotation
  ``phi`` and scale (the calibration's window model,
  :mod:`robocal.rigs.flow.calibrate`, with the sensor position ``r`` of
  run.yaml). That model is linear in ``(scale cos phi, scale sin phi)``: its
  free least-squares fit per sensor must leave a small relative misfit
  (:data:`MAX_FREE_MISFIT`) with a scale near one (:data:`SCALE_RANGE`: height
  errors of 10-15 % are common, a factor 3 is not). A height in mm gives scale
  0.001 with a perfect fit; swapped reference columns mirror the path, which
  no rigid array follows (misfit ~70 %); a heading in degrees ~95 %.

When a check fails, the likely slips are undone one at a time and the check
re-run; the figure in the message is the misfit of the array *as given in
run.yaml* (so it says how far the data are from what the user told), and a
slip explains the data only when its undoing also passes the free fit.
Measured on the examples (``examples/flow/calibration``, ``loop``): correct
runs 2-6 % free misfit and scale 0.92-1.01 (nominal-array misfit 4-14 %);
swapped columns 69-73 % (scale 0.66-1.06); height in mm scale 0.001.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from robocal.errors import RobocalError
from robocal.plausibility import Slip, check_slips
from robocal.rigs.flow.calibrate import MIN_WINDOW_FRAMES, interpolate_poses, window_observations
from robocal.rigs.flow.model import SensorArray, median, rot2
from robocal.rigs.flow.odometry import SensorSteps

__all__ = ["reference_misfit", "check_height", "check_reference", "MAX_FREE_MISFIT", "SCALE_RANGE"]

#: Largest relative misfit (RMS residual / RMS reference motion, per sensor) of the free window fit
#: of a plausible run: the examples give 2-6 %; a mirrored path 69-73 %, a heading in deg 93-99 %.
MAX_FREE_MISFIT = 0.3
#: PX4FLOW's binned pixel (6 um MT9V034 pixels, 4x4 binning), m: a focal length in mm over it is in px
BINNED_PIXEL = 24e-6
#: Plausible range of a sensor's fitted scale (height or focal-length error of the metric flow).
SCALE_RANGE = (1 / 3, 3.0)


def _windows(steps: SensorSteps) -> float:
    """Window length: 0.1 s, shorter on short runs so that at least 8 windows fit."""
    dt = median(steps.dt)
    span = float(steps.t[-1] - steps.t[0])
    return max(MIN_WINDOW_FRAMES * dt, min(0.1, span / 8))


def reference_misfit(steps: SensorSteps, t_ref, poses_ref, array: SensorArray):
    """Per sensor: relative misfit of the array as given, of the free fit, and the free fit's scale.

    Returns ``None`` when the run is too short for windows (the check is then skipped).

    Returns
    -------
    nominal, free, scale : ndarray, shape (n,)
        ``RMS|s R(phi) M - (dP + (R(dth) - I) r)| / RMS|dP + ...|`` with the array as given
        (``nominal``) and with ``(s cos phi, s sin phi)`` fitted (``free``), and the fitted ``s``.
    """
    poses = interpolate_poses(t_ref, poses_ref, steps.t)
    try:
        M, dP, dth = window_observations(steps, poses, _windows(steps))
    except RobocalError:
        return None
    n = array.n
    nominal, free, scale = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    c, s = np.cos(dth) - 1.0, np.sin(dth)
    for i in range(n):
        ok = np.all(np.isfinite(M[i]), axis=1)
        if ok.sum() < 4:
            continue
        Mi, dPi, ci, si = M[i][ok], dP[ok], c[ok], s[ok]
        r = array.R[i] * np.array([np.cos(array.psi[i]), np.sin(array.psi[i])])
        rhs = dPi + np.einsum("jab,b->ja", rot2(dth[ok]), r) - r
        lhs = array.scale[i] * Mi @ rot2(array.phi[i]).T
        den = np.sqrt(np.mean(np.sum(rhs**2, axis=1)))
        if not den > 0:
            continue
        nominal[i] = np.sqrt(np.mean(np.sum((lhs - rhs) ** 2, axis=1))) / den
        # (s cos phi, s sin phi) free, r at the array's: a free r is ill-posed on a drive with little
        # turning (its columns are (R(dth) - I), near zero) and then spoils the scale
        rows = np.stack([np.stack([Mi[:, 0], -Mi[:, 1]], 1), np.stack([Mi[:, 1], Mi[:, 0]], 1)], 1)
        A, b = rows.reshape(-1, 2), rhs.reshape(-1)
        sol, *_ = np.linalg.lstsq(A, b, rcond=None)
        free[i] = np.sqrt(np.mean((A @ sol - b) ** 2)) / max(np.sqrt(np.mean(b**2)), 1e-300)
        scale[i] = np.hypot(sol[0], sol[1])
    return nominal, free, scale


def _free_plausible(free, scale) -> bool:
    ok = np.isfinite(free)
    return bool(ok.any() and np.all(free[ok] <= MAX_FREE_MISFIT)
                and np.all((scale[ok] >= SCALE_RANGE[0]) & (scale[ok] <= SCALE_RANGE[1])))


def check_reference(steps: SensorSteps, t_ref, poses_ref, array: SensorArray, *, height_from: str = "the flow log",
                    reference_name: str = "the reference", rescaled_gyro: Callable[[float], SensorSteps] | None = None,
                    refocused: Callable[[float], SensorSteps] | None = None, focal_px: float | None = None,
                    accept: bool = False, source: str | None = None):
    """Judge the run's flow against its reference trajectory; name the slip when implausible.

    Parameters
    ----------
    steps : SensorSteps
        The run's displacements (m, sensor frames).
    t_ref, poses_ref : array_like
        Reference times (s) and ``(X, Y, theta)`` (m, m, rad) as read.
    array : SensorArray
        The array as given in run.yaml (the message's figure).
    height_from, reference_name : str
        File names for the messages.
    rescaled_gyro : callable, optional
        ``f(k) -> SensorSteps`` rebuilt with every gyro rate multiplied by ``k`` (flow logs only):
        tries gyro rates in deg/s declared rad/s.
    refocused, focal_px : callable, float, optional
        ``f(focal) -> SensorSteps`` rebuilt with another focal length (px), and the one of run.yaml:
        tries the lens focal length in mm given as ``focal_px`` (PX4FLOW's binned pixel,
        :data:`BINNED_PIXEL`) and the unbinned focal length (x4 binning).
    accept : bool
        ``--accept-implausible``: return an ``implausible_input`` warning instead of raising.

    Returns
    -------
    Diagnostic or None
    """
    t_ref = np.asarray(t_ref, float)
    p_ref = np.asarray(poses_ref, float)
    got = reference_misfit(steps, t_ref, p_ref, array)
    if got is None:
        return None
    nominal, free, scale = got
    if _free_plausible(free, scale):
        return None

    def trial(st=steps, p=p_ref):
        res = reference_misfit(st, t_ref, p, array)
        if res is None or not _free_plausible(res[1], res[2]):
            return np.nan                   # the undone slip must make the data fit a rigid array
        return 100 * float(np.nanmax(res[0]))

    def scaled(k):
        return replace(steps, disp=steps.disp * k)

    ref = reference_name
    slips = [
        Slip("height_mm_as_m", f"`height` in {height_from} looks like mm, not m", "with /1000",
             lambda: trial(st=scaled(1e-3))),
        Slip("height_m_as_mm", f"`height` in {height_from} looks like m, not mm", "with x1000",
             lambda: trial(st=scaled(1e3))),
        Slip("columns_xy_swapped", f"the x and y columns of {ref} look swapped", "with them swapped back",
             lambda: trial(p=p_ref[:, [1, 0, 2]])),
        Slip("reference_mm_as_m", f"x, y of {ref} look like mm, not m", "with /1000",
             lambda: trial(p=p_ref * [1e-3, 1e-3, 1.0])),
        Slip("reference_m_as_mm", f"x, y of {ref} look like m, not mm", "with x1000",
             lambda: trial(p=p_ref * [1e3, 1e3, 1.0])),
        Slip("theta_deg_as_rad", f"theta of {ref} looks like deg, not rad", "with deg -> rad",
             lambda: trial(p=p_ref * [1.0, 1.0, np.pi / 180])),
    ]
    if rescaled_gyro is not None:
        slips.append(Slip("gyro_deg_as_rad", f"the gyro rates in {height_from} look like deg/s, not rad/s",
                          "with deg/s -> rad/s", lambda: trial(st=rescaled_gyro(np.pi / 180))))
    if refocused is not None and focal_px is not None:
        f = float(focal_px)
        slips += [
            Slip("focal_mm_as_px", f"`camera: focal_px` ({f:g}) looks like the lens focal length in mm, not px",
                 f"with PX4FLOW's {BINNED_PIXEL * 1e6:g} um binned pixel (f = {f * 1e-3 / BINNED_PIXEL:.4g} px)",
                 lambda: trial(st=refocused(f * 1e-3 / BINNED_PIXEL))),
            Slip("focal_unbinned", f"`camera: focal_px` ({f:g}) looks like the unbinned focal length",
                 f"with the 4x4 binning (f = {f / 4:.4g} px)", lambda: trial(st=refocused(f / 4))),
        ]
    worst = int(np.nanargmax(np.where(np.isfinite(free), np.maximum(free, np.abs(np.log(scale))), -1)))
    reason = (f"the flow does not follow {ref}: sensor {array.names[worst]}'s best rigid fit leaves "
              f"{100 * free[worst]:.3g} % of the motion unexplained with scale {scale[worst]:.3g} "
              f"(plausible: <= {100 * MAX_FREE_MISFIT:g} %, scale {SCALE_RANGE[0]:.2g}..{SCALE_RANGE[1]:g})")
    return check_slips(what="misfit to the reference motion with the array of run.yaml",
                       residual=100 * float(np.nanmax(nominal)), unit="%", plausible=False, reason=reason,
                       slips=slips, accept=accept, source=source)


def check_height(heights, focal_px: float, array: SensorArray, *,
                 height_from: str = "the flow log", accept: bool = False, source: str | None = None):
    """Judge the logged heights against the optics and the array: one pixel must see less floor than max R.

    ``heights`` (m) as read, any shape; ``focal_px`` in px. Returns a Diagnostic or None.
    """
    h = np.asarray(heights, float)
    h = h[np.isfinite(h)]
    if h.size == 0:
        return None
    pix = float(np.median(h)) / float(focal_px)           # floor seen by one pixel, m
    limit = float(np.max(array.R))
    if pix <= limit:
        return None
    return check_slips(
        what="floor seen by one pixel", residual=1e3 * pix, unit="mm", plausible=False,
        reason=(f"the median height {np.median(h):.4g} m makes one pixel (f = {focal_px:.4g} px) see "
                f"{1e3 * pix:.4g} mm of floor, more than the array's largest R = {1e3 * limit:.4g} mm"),
        slips=[Slip("height_mm_as_m", f"`height` in {height_from} looks like mm, not m", "with /1000",
                    lambda: 1e3 * pix / 1e3 if pix / 1e3 <= limit else np.nan)],
        threshold=1e3 * limit, accept=accept, source=source)
