"""The flow rig's reports, built from a result file alone (``robocal report`` rebuilds the same page).

Three commands write results of rig ``flow``, told apart by ``result.method``:

* ``windowed-lsq`` (``calibrate``): the calibrated array with its statistical,
  kernel-systematic and total std, the per-window residuals over the drive,
  their histogram and the solver's record;
* ``multi-sensor-lsq`` (``odometry``): the trajectory (against the reference
  when the run has one, else the flow odometry with the wheel odometry when
  logged), the velocity with its 3-sigma band and the sensors' quality;
* ``ate-rpe`` (``evaluate``): the trajectories and their ATE / RPE.

What a figure needs is in ``result.diagnostics`` (the series thinned to at
most :data:`STORED_POINTS` points by :func:`plot_series`); the report reads
nothing else, so the page that ``calibrate`` writes and the one rebuilt from
its ``result.json`` are equal.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from robocal.errors import InputError
from robocal.io import CalibrationResult
from robocal.rigs.flow.evaluate import TrajectoryErrors, plot_trajectories

if TYPE_CHECKING:
    from robocal.report import Report

# robocal.report (and html, matplotlib's helpers) is imported by the functions that draw: the odometry
# command imports this module for plot_series and display, and with --no-report draws nothing (issue 16)

__all__ = ["build_report", "calibration_report", "odometry_report", "evaluation_report", "trajectory_section",
           "compare_text", "systematic_note", "velocity_figure", "quality_figure", "window_residual_figure",
           "plot_series", "thin", "STORED_POINTS", "display"]

#: most points a figure line gets: a 10^6-row log's velocity figure took minutes to draw in full
PLOT_POINTS = 5000
#: most points of a series stored in a result for its report (a 3200-interval drive: every 4th; the
#: figures are 6 inches wide, ~600 px: more points draw nothing new and make result.json megabytes)
STORED_POINTS = 1000


def _every(n: int, most: int = PLOT_POINTS) -> int:
    return max(1, -(-n // most))


def thin(a, most: int = STORED_POINTS) -> np.ndarray:
    """Every k-th row of ``a`` (and its last one) so that at most ``most + 1`` rows remain."""
    a = np.asarray(a, dtype=float)
    k = _every(len(a), most)
    if k == 1:
        return a
    return np.concatenate([a[::k], a[-1:]]) if (len(a) - 1) % k else a[::k]


def plot_series(od=None, steps=None, names=(), curves=None) -> dict:
    """The series a flow report draws, thinned (:data:`STORED_POINTS`), rounded to what a plot resolves.

    ``od``: an :class:`~robocal.rigs.flow.odometry.Odometry` (velocity with its std);
    ``steps``: its :class:`~robocal.rigs.flow.odometry.SensorSteps` (per-sensor quality);
    ``curves``: named ``(N, 3)`` trajectories ``(X, Y, theta)``, m, m, rad.
    """
    out = {}
    if curves:
        # 1 um / 1 urad: far below a pixel of the trajectory figure
        out["trajectories"] = {n: np.round(thin(c), 6).tolist() for n, c in curves.items()}
    if od is not None:
        k = _every(len(od.t) - 1, STORED_POINTS)
        tm = 0.5 * (od.t[1:] + od.t[:-1])
        out["velocity"] = {"t": np.round(tm[::k], 6).tolist(), "value": np.round(od.velocity[::k], 6).tolist(),
                           "std": np.round(od.velocity_std[::k], 6).tolist()}
    if steps is not None:
        k = _every(len(steps.t) - 1, STORED_POINTS)
        out["quality"] = {"t": np.round(steps.t[1:][::k], 6).tolist(),
                          "value": {nm: np.round(steps.quality[i][::k], 2).tolist() for i, nm in enumerate(names)}}
    return out


def _nan(v) -> np.ndarray:
    """A stored series as floats (``None``, JSON's NaN, back to NaN)."""
    return np.array(v, dtype=float) if v is not None else np.array([])


def display(unit):
    """Converter and unit for showing a parameter stored in SI units (m -> mm, rad -> deg)."""
    if unit == "rad":
        return np.degrees, "deg"
    if unit == "m":
        return (lambda x: x * 1e3), "mm"
    return (lambda x: x), ("" if unit == "1" else unit)


def systematic_note(source: str, removed: bool) -> str:
    """How the kernel systematic of a calibration was found (``source``: run / model / constant)."""
    how = {"run": "derived from this run: the change of each parameter when the kernel's bias, measured on the run's "
                  "own frames per sub-pixel phase, is removed",
           "model": "derived from this run's flow phases: the change of each parameter when the kernel's bias per "
                    "sub-pixel phase (measured on gravel-photograph frames: the log has no frames) is removed",
           }.get(source, "a constant measured on rendered drives (the input has neither frames nor "
                         "this kernel's raw flow)")
    if removed:
        how += "; --debias removed that bias from the estimate, and the systematic is the size of what was removed"
    return how


def velocity_figure(t, velocity, velocity_std):
    """vx, vy, omega over time with the 3-sigma band of the array geometry and per-frame quality."""
    from robocal.report import new_figure

    fig, axs = new_figure(3, 1, size=(6.4, 5.5), sharex=True)
    t, v, s = _nan(t), _nan(velocity).reshape(-1, 3), _nan(velocity_std).reshape(-1, 3)
    k = _every(len(t))                                       # drawn every k-th interval on long runs
    for a, lab in enumerate(("vx [m/s]", "vy [m/s]", "omega [rad/s]")):
        va, sa = v[::k, a], s[::k, a]
        axs[a].plot(t[::k], va, lw=0.6)
        axs[a].fill_between(t[::k], va - 3 * sa, va + 3 * sa, alpha=0.3, lw=0)
        axs[a].set_ylabel(lab)
    axs[-1].set_xlabel("t [s]")
    fig.suptitle("robot velocity from the array, +/-3 sigma band from the geometry")
    return fig


def quality_figure(t, quality: dict):
    """Per-sensor quality (0..255) over time; ``quality``: sensor name -> series at the times ``t``."""
    from robocal.report import new_figure

    fig, ax = new_figure(size=(6.4, 3.0))
    t = _nan(t)
    k = _every(len(t))
    for nm, q in quality.items():
        ax.plot(t[::k], _nan(q)[::k], lw=0.7, label=nm)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("quality (0..255)")
    ax.legend(fontsize=8)
    return fig


def window_residual_figure(windows: dict):
    """Per-window residual norm of each sensor over the drive; ``windows``: name -> {"t", "residual"}."""
    from robocal.report import new_figure

    fig, ax = new_figure(size=(6.4, 3.2))
    for nm, w in windows.items():
        r = _nan(w["residual"]).reshape(-1, 2)
        ax.plot(_nan(w["t"]), np.linalg.norm(r, axis=1) * 1e3, ".", ms=3, label=nm)
    ax.set_xlabel("window start t [s]")
    ax.set_ylabel("|residual| [mm]")
    ax.legend(fontsize=8)
    return fig


def compare_text(nom, cal) -> str:
    """One line: calibrated vs nominal array in ATE and the headline RPE (0.5 m), saying which got worse."""
    def word(a, b):
        return "better" if b < a else "WORSE" if b > a else "same"

    rn, rc = nom.headline_rpe(), cal.headline_rpe()
    tn, tc = rn["trans_per_m"], rc["trans_per_m"]
    on, oc = np.degrees(rn["rot_per_m"]), np.degrees(rc["rot_per_m"])
    ate = (f"calibrated vs nominal array: ATE {nom.ate_rmse * 1e3:.1f} -> {cal.ate_rmse * 1e3:.1f} mm "
           f"({word(nom.ate_rmse, cal.ate_rmse)})")
    if not (rn["n"] and rc["n"]):
        return ate + "; no RPE (the reference path is too short)"
    return (ate + f"; {nom.rpe_label()} {tn * 100:.2f} -> {tc * 100:.2f} % ({word(tn, tc)}), "
            f"{on:.2f} -> {oc:.2f} deg/m ({word(on, oc)})")


def trajectory_section(report: Report, title: str, curves: dict, errors: dict | None = None) -> None:
    """The trajectories in the world frame and, when there is a reference, their ATE / RPE table.

    ``curves``: named ``(N, 3)`` poses; ``errors``: named
    :class:`~robocal.rigs.flow.evaluate.TrajectoryErrors` (empty or None: a run
    without a reference, drawn without truth).
    """
    from robocal.report import new_figure

    errors = errors or {}
    sec = report.section(title)
    fig, ax = new_figure(size=(6.0, 5.0))
    k = _every(max(len(c) for c in curves.values()))
    plot_trajectories({n: np.concatenate([c[::k], c[-1:]]) for n, c in ((n, _nan(c)) for n, c in curves.items())},
                      ax=ax, title=("true / flow odometry / wheel odometry (cf. seed Fig. 4)" if errors else
                                    "flow odometry" + (" / wheel odometry" if len(curves) > 1 else "")
                                    + " (no reference: not evaluated)"))
    sec.figure(fig, "Trajectories in the world frame; dots mark the end." if errors else
               "Estimated trajectory in the world frame (the run names no reference, so no error is shown); "
               "dots mark the end.")
    if not errors:
        return
    rows = []
    first = next(iter(errors.values()))
    label = first.rpe_label()
    seg = f"{first.rpe_headline:g} m" if first.rpe_headline is not None else "0.5 m"
    for name, ev in errors.items():
        r1 = ev.headline_rpe()
        rows.append({"trajectory": name, "ATE [mm]": ev.ate_rmse * 1e3, "final error [mm]": ev.final_error * 1e3,
                     "final heading [deg]": np.degrees(ev.heading_error_final),
                     f"{label} [%]": r1["trans_per_m"] * 100, "RPE rot [deg/m]": np.degrees(r1["rot_per_m"])})
    sec.table(rows, digits=4, caption="ATE: RMS position error after least-squares rigid 2D alignment (Umeyama); "
              f"RPE: RMS over all segment starts of the relative pose error over {seg} of travelled path "
              "(translation error per metre of path, rotation error per metre; other lengths, mean and median in "
              "result.json).")
    for note in dict.fromkeys(ev.rpe_note for ev in errors.values() if ev.rpe_note):
        sec.text(f"Note: {note}.")
    cal, nom = errors.get("flow odometry (calibrated)"), errors.get("flow odometry")
    if cal is not None and nom is not None:
        sec.text(compare_text(nom, cal))


def _errors(evaluation: dict | None) -> dict:
    return {k: TrajectoryErrors.from_dict(v) for k, v in (evaluation or {}).items()}


def _subtitle(result: CalibrationResult) -> str | None:
    # the run.yaml: the first input the command hashed
    return next(iter(result.inputs), None)


def calibration_report(result: CalibrationResult) -> Report:
    """``robocal flow calibrate``'s page: parameters with their three stds, window residuals, solver."""
    from robocal.report import Report, plot_residual_histogram, solver_section

    d = result.diagnostics
    report = Report("robocal flow calibrate", subtitle=_subtitle(result))
    sec = report.section("Calibrated array")
    sec.parameters(result.estimate, result.std, result.units)
    und = set(d.get("undetermined_kept_nominal") or ())
    sysk, tot = d.get("std_systematic_kernel") or {}, d.get("std_total") or {}
    rows = []
    for k, v in result.estimate.items():
        conv, u = display(result.units[k])
        nd = k in und
        rows.append({"parameter": k, "value": conv(v), "unit": u,
                     "std (statistical)": None if nd else conv(result.std[k]),
                     "systematic (kernel)": None if nd else conv(sysk[k]),
                     "total": None if nd else conv(tot[k]),
                     "note": "not determined: kept nominal" if nd else ""})
    how = systematic_note(d.get("std_systematic_kernel_source", "constant"), bool(d.get("kernel_debiased")))
    sec.table(rows, digits=4, caption="statistical std: delete-one-segment jackknife over the drive (the flow errors "
              f"are correlated in time); systematic: the flow kernel's pixel-locking bias, {how} "
              "(docs/rigs/flow.md); total = both in quadrature. Use the total to judge the values.")
    window = d.get("window_s")
    per = f" per {window:g} s window" if window is not None else " per window"
    sec.text(f"Residual RMS {result.residual_rms * 1e3:.3f} mm{per}; the reference is taken as exact.")
    windows = d.get("window_residuals") or {}
    if windows:
        sec.figure(window_residual_figure(windows), "Per-window residual of each sensor over the drive: outlying "
                   "windows (turns, texture gaps) stand out; a slow trend is the time-correlated flow error the "
                   "jackknife accounts for.")
        r = np.concatenate([_nan(w["residual"]).reshape(-1) for w in windows.values()]) * 1e3
        ax = plot_residual_histogram(r, sigma=result.residual_rms * 1e3, unit="mm")
        sec.figure(ax.figure, "Window residual components of all sensors, with the Gaussian of their RMS: heavy "
                   "tails are the outlying windows named in the warnings.")
    sec.diagnostics(result.warnings)
    solver_section(report.section("Solver"), d.get("solver") or {},
                   caption="the windowed least squares in the physical parameters (robocal.estimation.solve)")
    return report


def odometry_report(result: CalibrationResult) -> Report:
    """``robocal flow odometry``'s page: trajectory (with or without a reference), velocity, sensor quality."""
    from robocal.report import Report

    d = result.diagnostics
    report = Report("robocal flow odometry", subtitle=_subtitle(result))
    plots = d.get("plots") or {}
    curves = plots.get("trajectories") or {}
    if curves:
        trajectory_section(report, "Trajectory", curves, _errors(d.get("evaluation")))
    sec = report.section("Velocity and sensor quality")
    if "velocity" in plots:
        v = plots["velocity"]
        sec.figure(velocity_figure(v["t"], v["value"], v["std"]),
                   "vx, vy, omega with 3-sigma bands from the array geometry and per-frame quality")
    if "quality" in plots:
        q = plots["quality"]
        sec.figure(quality_figure(q["t"], q["value"]),
                   "per-sensor quality; 0 = frame without flow (low texture / ambiguous)")
    if d.get("frames_without_flow"):
        sec.table(d["frames_without_flow"],
                  caption="frames without a valid flow per sensor, by reason (left out of the fusion)")
    sec.diagnostics(result.warnings)
    return report


def evaluation_report(result: CalibrationResult) -> Report:
    """``robocal flow evaluate``'s page: the trajectories and their ATE / RPE."""
    from robocal.report import Report

    d = result.diagnostics
    report = Report("robocal flow evaluate", subtitle=_subtitle(result))
    curves = (d.get("plots") or {}).get("trajectories") or {}
    evaluation = d.get("evaluation")
    if evaluation is None:   # results written before the evaluation moved under its own key
        evaluation = {k: v for k, v in d.items() if isinstance(v, dict) and "ate_rmse_m" in v}
    if curves:
        trajectory_section(report, "Trajectory errors", curves, _errors(evaluation))
    return report


_BUILDERS = {"windowed-lsq": calibration_report, "multi-sensor-lsq": odometry_report, "ate-rpe": evaluation_report}


def build_report(result: CalibrationResult, *, base_dir=None) -> Report:
    """The report of a flow result, by the command that wrote it (``result.method``).

    The result is normalised through its JSON form first (NaN -> None, arrays
    -> lists), so the report built right after a command and the one rebuilt
    from the written file draw the same numbers.
    """
    result = CalibrationResult.from_dict(result.to_dict())
    fn = _BUILDERS.get(result.method)
    if fn is None:
        raise InputError(f"method: a flow result of {', '.join(map(repr, _BUILDERS))} has a report, "
                         f"got {result.method!r}")
    return fn(result)
