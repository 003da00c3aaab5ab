"""Plausibility of a projector calibration input: a unit slip or swapped columns, named (robocal.plausibility).
"""

from __future__ import annotations

import math

import numpy as np

from robocal.errors import RobocalError
from robocal.geometry import rigid_fit
from robocal.rigs.projector.closed_form import closed_form
from robocal.rigs.projector.consistency import _spots, _tilt_span, spread_ratio
from robocal.rigs.projector.model import ProjectorModel
from robocal.rigs.projector.nonlinear import nonlinear

__all__ = ["H_PLAUSIBLE", "SLIP_SAMPLE"]


#: Plausible ceiling heights H (m) of a projector room; a slip check that moves H outside is no explanation.
H_PLAUSIBLE = (0.5, 50.0)
#: The slip checks fit at most this many points (evenly spaced): a unit slip shows in any of them.
SLIP_SAMPLE = 2000


def _slip_checks(pw, th, p0_given, model: ProjectorModel, sigma, joint_noise, *, accept: bool,
                 source: str | None):
    """Judge the input's physical scales; name the likely slip (robocal.plausibility).

    Figure of merit: the median floor residual (mm, in the world points' unit
    as read) of a fit that allows for the nominal model's own error: yaw, t,
    ``h`` and the tilt offset free (seed eqs. 1, 6); a rigid fit when the
    ``{0}`` points are given directly. It counts as no fit (inf) when ``H``
    leaves :data:`H_PLAUSIBLE`, when the spots' and world points' spreads
    differ by more than 2x, when the fitted ``h`` leaves ``(0, 1.5 H]`` or
    the tilt offset +-10 deg, or when it exceeds 5 % of the world points' own
    spread (a slip that shrinks them shrinks their residual too). Plausible: a figure of at most 10x the stated
    noise at the largest tilt (5 % of the points' spread without stated noise).

    A unit slip on one side (world points, H, the joint angles), swapped world
    columns (a mirror image, which no rotation fits) or swapped angle columns
    leave it far above that; each slip is undone on its own and the fit redone.
    When the scales agree and no slip explains a poor fit, this returns None:
    the consistency check and the outlier test report it. With ``{0}`` points
    given directly their z is tied to ``H`` (checked before), so a scale slip
    is named on the world points. At most :data:`SLIP_SAMPLE` points are used.
    """
    from robocal.plausibility import Slip, check_slips, try_slips

    n = pw.shape[0]
    idx = np.arange(n) if n <= SLIP_SAMPLE else np.linspace(0, n - 1, SLIP_SAMPLE).round().astype(int)
    pw_s = pw[idx]
    th_s = None if th is None else th[idx]
    p0_s = None if p0_given is None else p0_given[idx]

    def merit(w, m=model, t=th_s, p0=None):
        if not H_PLAUSIBLE[0] <= m.H <= H_PLAUSIBLE[1]:
            return math.inf
        p = (_spots(m, t) if t is not None else p0_s) if p0 is None else p0
        if not 0.5 < spread_ratio(w, p) < 2.0:
            return math.inf
        if t is None:
            fit = rigid_fit(p, w)
            r = (p @ fit.R.T + fit.t - w)[:, :2]
        else:
            est = nonlinear(w, theta=t, model=m, estimate=("h", "tilt_offset"), x0=closed_form(w, p))
            h, o2 = est.extra["h"], est.extra["offsets"][1]
            if not (0.0 < h <= 1.5 * m.H and abs(o2) <= math.radians(10.0)):
                return math.inf
            r = est.residuals
        med = float(np.median(np.linalg.norm(r, axis=1)))
        # a slip that shrinks the world points shrinks their residual too: a fit is one only against its own spread
        sp = float(np.sqrt(np.mean(np.sum((w[:, :2] - w[:, :2].mean(0)) ** 2, axis=1))))
        return 1e3 * med if med <= 0.05 * sp else math.inf

    p0 = _spots(model, th_s) if th_s is not None else p0_s
    spread = float(np.sqrt(np.mean(np.sum((pw_s[:, :2] - pw_s[:, :2].mean(0)) ** 2, axis=1))))
    ratio = spread_ratio(pw_s, p0)
    if sigma:
        jt = 0.0 if joint_noise is None else float(joint_noise[1])
        tmax = _tilt_span(model, th_s, p0)[1]
        limit = 10e3 * math.hypot(sigma, model.h * jt / math.cos(min(tmax, 1.5)) ** 2)
    else:
        limit = 0.05e3 * spread
    try:
        base = merit(pw_s)
    except RobocalError:
        base = math.inf
    if not math.isfinite(base):  # no fit as given: the message quotes the rigid fit's residual (always finite)
        fit = rigid_fit(p0, pw_s)
        r = (p0 @ fit.R.T + fit.t - pw_s)[:, :2]
        base = max(1e3 * float(np.median(np.linalg.norm(r, axis=1))), 1.01 * limit)
    if base <= limit:
        return None
    slips = []
    for f, unit_big, unit_small in ((1e3, "mm", "m"), (1e2, "cm", "m"), (1e1, "mm", "cm")):
        slips.append(Slip(f"world_{unit_big}_as_{unit_small}",
                          f"`points.world` looks like {unit_big} declared as {unit_small} ({f:g}x too large)",
                          f"with /{f:g}", lambda f=f: merit(pw_s / f)))
        slips.append(Slip(f"world_{unit_small}_as_{unit_big}",
                          f"`points.world` looks like {unit_small} declared as {unit_big} ({f:g}x too small)",
                          f"with x{f:g}", lambda f=f: merit(pw_s * f)))
        if th is not None:
            slips.append(Slip(f"H_{unit_big}_as_{unit_small}",
                              f"`projector.H` (and d1) look like {unit_big} declared as {unit_small} ({f:g}x too large)",
                              f"with /{f:g}", lambda f=f: merit(pw_s, m=model.with_(H=model.H / f, d1=model.d1 / f,
                                                                                      d2=model.d2 / f))))
            slips.append(Slip(f"H_{unit_small}_as_{unit_big}",
                              f"`projector.H` (and d1) look like {unit_small} declared as {unit_big} ({f:g}x too small)",
                              f"with x{f:g}", lambda f=f: merit(pw_s, m=model.with_(H=model.H * f, d1=model.d1 * f,
                                                                                      d2=model.d2 * f))))
    slips.append(Slip("world_xy_swapped", "`points.world` x and y look swapped (a mirror image: no rotation fits)",
                      "with x and y swapped back", lambda: merit(pw_s[:, [1, 0, 2]])))
    if th is not None:
        d = math.degrees(1.0)
        slips.append(Slip("angles_rad_as_deg", "`points.joint_angles` look like rad declared as deg",
                          "read as rad", lambda: merit(pw_s, t=th_s * d)))
        slips.append(Slip("angles_deg_as_rad", "`points.joint_angles` look like deg declared as rad",
                          "read as deg", lambda: merit(pw_s, t=th_s / d)))
        slips.append(Slip("angles_swapped", "`points.joint_angles` columns look swapped (tilt, pan instead of pan, tilt)",
                          "with the columns swapped back", lambda: merit(pw_s, t=th_s[:, ::-1])))
    h_ok = H_PLAUSIBLE[0] <= model.H <= H_PLAUSIBLE[1]
    trial = None
    if 0.5 < ratio < 2.0 and h_ok:
        trial = try_slips(slips, base, threshold=limit)
        if trial.best is None:
            # the scales agree: a poor fit is the consistency check's and outlier test's to report
            return None
    reason = (f"projector.H = {model.H:.4g} m is outside the plausible {H_PLAUSIBLE[0]:g}-{H_PLAUSIBLE[1]:g} m"
              if not h_ok else
              f"the floor points do not fit the projector's spots: distances in {{0}} are {ratio:.3g} times those "
              f"in {{W}}, median residual {base:.3g} mm (plausible: <= {limit:.3g} mm)")
    # (a trial already made is judged as it is: each of its figures was a refit)
    return check_slips(what="median residual", residual=base, unit="mm", plausible=False, reason=reason,
                       slips=slips, accept=accept, source=source, threshold=limit, trial=trial)


