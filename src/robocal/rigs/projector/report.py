"""The projector's report, built from its result file alone (``robocal report`` rebuilds the same page).

:func:`build_report` reads what :func:`robocal.rigs.projector.workflow.calibration_result`
put into the result: the pose ``T_0_W`` and the parameters with their std and
units, and under ``diagnostics`` each method's cost history, the consistency
check, a sample of the floor residuals, the primary estimate's covariance for
the predicted error map, the nominal (and, when simulated, the true) projector
and the truth check. Every figure fits a report column of ~1000 px.
"""

from __future__ import annotations

import json
import math

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import FileFormatError
from robocal.io import CalibrationResult
from robocal.report import Report, Section, new_figure, plot_residual_histogram, solver_section, truth_section
from robocal.rigs.projector.model import ProjectorModel
from robocal.rigs.projector.plots import (COLUMN_WIDTH, iterative_methods, plot_cost_curves, plot_error_map,
                                          plot_residuals)

__all__ = ["build_report", "report_sections", "evaluation_sections", "model_from_dict", "calibrated_model",
           "SUBTITLE"]

SUBTITLE = "ceiling pan-tilt laser projector (seed 000): ^0P = R_0_W ^WP + t_0_W, the pose T_0_W"


def model_from_dict(d: dict) -> ProjectorModel:
    """A :class:`ProjectorModel` from :meth:`ProjectorModel.to_dict` (SI: m, rad)."""
    kw = dict(d)
    for k in ("offsets", "rate_limits", "pan_range"):
        if kw.get(k) is not None:
            kw[k] = tuple(float(v) for v in kw[k])
    for k in ("R_0_W", "t_0_W"):
        if kw.get(k) is not None:
            kw[k] = np.asarray(kw[k], dtype=float)
    return ProjectorModel(**kw)


def calibrated_model(result: CalibrationResult) -> ProjectorModel:
    """The nominal projector of ``result`` with its estimated pose (and ``h``, offsets when estimated)."""
    m = model_from_dict(result.diagnostics["model"])
    T = result.pose("T_0_W").T
    m = m.with_(R_0_W=T[:3, :3], t_0_W=T[:3, 3])
    e = result.estimate
    if "h" in e:
        m = m.with_(d1=m.H - float(e["h"]), offsets=tuple(float(v) for v in e["offsets"]))
    return m


def _normalised(result: CalibrationResult) -> CalibrationResult:
    """The result as its file reads back (lists, None for NaN): the page is the same before and after writing."""
    return CalibrationResult.from_dict(json.loads(json.dumps(result.to_dict())))


def build_report(result: CalibrationResult, *, base_dir=None) -> Report:
    """The report of a projector result (calibrate, evaluate or the demo), from the result alone.

    Raises :class:`~robocal.errors.FileFormatError` naming the field when the
    result lacks what the report is drawn from (a result written before the
    report was built from results, or an edited file).
    """
    result = _normalised(result)
    d = result.diagnostics
    rep = Report(d.get("title") or "projector calibration", subtitle=SUBTITLE)
    try:
        rep.sections.extend(report_sections(result))
    except (KeyError, TypeError, IndexError, ValueError) as exc:
        what = repr(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
        raise FileFormatError(f"not a projector result this version can draw a report from: {what} missing or "
                              f"invalid (under 'diagnostics' or 'estimate'); run 'robocal projector calibrate' "
                              f"again") from None
    return rep


def report_sections(result: CalibrationResult) -> list[Section]:
    """Consistency, estimates by method, cost curves and residuals, error maps (and the evaluation, if any)."""
    result = _normalised(result)
    secs = [_consistency_section(result), _estimates_section(result), _cost_section(result),
            _error_map_section(result)]
    if "truth_check" in result.diagnostics:
        secs.insert(2, _truth_section(result))
    if "evaluation" in result.diagnostics:
        secs.extend(_evaluation_from_result(result))
    return secs


def _consistency_section(result) -> Section:
    d = result.diagnostics
    s = Section("Consistency of pairwise distances")
    ok, scale, suspects = d.get("consistency_consistent", True), d.get("consistency_scale"), d.get("suspect_points")
    s.status(ok, "distances in {W} and {0} agree within " + d["consistency_threshold"] if ok
             else (f"inconsistent: uniform scale error {100 * scale:+.2f} % (model, not points)"
                   + (f"; suspect point(s) {suspects}" if suspects else "")) if scale is not None
             else f"inconsistent: suspect point(s) {suspects}")
    s.table([dict(pair=f"{r['i']}-{r['j']}", **{"d_W [mm]": 1000 * r["d_W"], "d_0 [mm]": 1000 * r["d_0"],
                                                 "diff [mm]": 1000 * r["diff"], "diff [%]": 100 * r["rel"],
                                                 "ok": r["ok"]}) for r in d["consistency"][:60]], digits=5)
    s.diagnostics([Diagnostic.from_dict(w) for w in d.get("consistency_warnings", [])])
    return s


def _estimates_section(result) -> Section:
    d = result.diagnostics
    s = Section("Extrinsics by method")
    by_method = (d.get("truth") or {}).get("errors_by_method", {})
    rows = []
    for name, m in d["methods"].items():
        t = m["T_0_W.translation"]
        sy = m["std"].get("yaw")
        row = {"method": name, "yaw [deg]": math.degrees(m["yaw"]),
               "std yaw [deg]": None if sy is None else math.degrees(sy),
               "t_x [m]": t[0], "t_y [m]": t[1], "t_z [m]": t[2], "rms [mm]": 1000 * m["rms"],
               "iterations": m["iterations"]}
        if name in by_method:
            e = by_method[name]
            row["yaw error [mrad]"] = 1000 * e["yaw"]
            row["t error [mm]"] = 1000 * math.hypot(e["t_x"], e["t_y"])
        rows.append(row)
    s.table(rows, digits=6)
    seed = d["methods"].get("seed")
    if seed is not None:
        Ri = seed["R_init"]
        s.text(f"seed method: eq. (23) initial yaw {math.degrees(math.atan2(Ri[1][0], Ri[0][0])):.4f} deg, "
               f"refined {math.degrees(seed['yaw']):.4f} deg after {seed['iterations']} iterations of eq. (29).")
    sigma = d.get("sigma")
    basis = (f"the stated noise sigma = {1000 * sigma:.3g} mm taken as known (absolute sigma)" if sigma
             else "scaled by the residuals (no noise stated in the input)")
    s.text(f"Primary estimate: {result.method}. Standard deviations are sampling error under the model "
           f"(noise on the world measurements), not model error; they use {basis}. The pose T_0_W maps world "
           f"points into the projector's base frame {{0}} (seed eq. 1); its rotation is the yaw about z (roll and "
           f"pitch are zero by the level-floor model, std 0), t_z = -H.")
    s.parameters(result.estimate, result.std, result.units)
    s.diagnostics(result.warnings)
    return s


def _truth_section(result) -> Section:
    d = result.diagnostics
    s = Section("Check against the simulated truth")
    truth_section(s, d["truth_check"])
    err = d["truth"]["errors"]
    rows = []
    for k, unit in (("yaw", "mrad"), ("t_x", "mm"), ("t_y", "mm"), ("h", "mm"), ("tilt_offset", "mrad"),
                    ("pan_offset", "mrad")):
        if k not in err or k not in d["truth_check"]["z"]:
            continue
        rows.append({"parameter": k, "error": 1e3 * err[k], "unit": unit, "error / std": d["truth_check"]["z"][k]})
    s.table(rows, ["parameter", "error", "unit", "error / std"], digits=4,
            caption="primary estimate minus the truth (a held or unidentifiable parameter has no std)")
    return s


def _cost_section(result) -> Section:
    d = result.diagnostics
    s = Section("Cost curves and residuals")
    hist = {name: m["cost_history"] for name, m in d["methods"].items()}
    names = iterative_methods(hist)
    if names:
        fig, ax = new_figure(1, len(names), size=(min(COLUMN_WIDTH, 4.8 * len(names)), 3.6))
        plot_cost_curves(hist, np.atleast_1d(ax))
        s.figure(fig, "cost per iteration, one panel per method (" + ", ".join(names)
                 + "; seed Fig. 4 for the seed's method)")
    if d.get("solver"):
        solver_section(s, d["solver"], caption="nonlinear least squares (robocal.estimation.solve)")
    r = d["residuals"]
    res = np.asarray(r["residual"], dtype=float).reshape(-1, 2)
    fig, ax = new_figure(1, 2, size=(COLUMN_WIDTH, 4.2))
    plot_residuals(np.asarray(r["world"], dtype=float).reshape(-1, 2), res, ax[0], index=r["index"],
                   n_total=r["n"])
    sigma = d.get("sigma")
    plot_residual_histogram(1000 * res, ax[1], sigma=None if not sigma else 1000 * sigma, unit="mm",
                            bins=min(40, max(5, res.size // 2)))
    ax[1].set_title("residual components x, y", fontsize=10)
    s.figure(fig, f"floor residuals of the {result.method} estimate: left at the points (exaggerated), right "
                  f"their x and y components" + (" against the stated noise" if sigma else ""))
    return s


def _error_map_section(result, n: int = 41) -> Section:
    """Predicted 1-sigma spot error of the primary estimate (seed eqs. 1, 6, 8) and, simulated, the true one."""
    from robocal.rigs.projector.evaluate import error_map, predicted_error_map

    d = result.diagnostics
    s = Section("Error map: predicted spot error over the floor")
    cov = d.get("covariance") or {}
    model = calibrated_model(result)
    nadir = model.nadir_world
    r = model.floor_radius
    x0, x1, y0, y1 = d["floor_extent"]
    xr = (min(nadir[0] - r, x0) - 0.2, max(nadir[0] + r, x1) + 0.2)
    yr = (min(nadir[1] - r, y0) - 0.2, max(nadir[1] + r, y1) + 0.2)
    if cov.get("matrix") is None:
        s.status(False, f"no predicted error map: {cov.get('note') or 'the estimate has no covariance'}")
        return s
    labels = cov["labels"]
    xs, ys, err = predicted_error_map(model, np.asarray(cov["matrix"], dtype=float), labels, xr, yr, n)
    fin = err[np.isfinite(err)]
    if fin.size == 0:
        s.status(False, "no predicted error map: no grid cell on the reachable floor")
        return s
    note = cov.get("note")
    s.text(f"1-sigma spot error (RMS length of the error vector) of a spot commanded by the {result.method} "
           f"estimate, from its covariance over {', '.join(labels)} propagated to first order through the spot "
           f"model (seed eqs. 1, 6, 8): {1000 * fin.min():.2f} to {1000 * fin.max():.2f} mm over the reachable "
           f"floor (radius {r:.2f} m at tilt {math.degrees(model.tilt_limit):g} deg). 95 % of spots lie within "
           f"1.7 (round error ellipse) to 2.0 (flat ellipse) times this. Sampling error only: a model error "
           f"(wrong H) is not included." + (f" Note: {note}." if note else ""))
    pts = np.asarray(d["residuals"]["world"], dtype=float).reshape(-1, 2)
    truth = (d.get("truth") or {}).get("model")
    ncol = 2 if truth is not None else 1
    fig, ax = new_figure(1, ncol, size=(COLUMN_WIDTH, 5.0) if ncol == 2 else (6.4, 5.6))
    axes = np.atleast_1d(ax)
    plot_error_map(xs, ys, err, axes[0], points=pts, nadir=nadir, title="predicted spot error (1 sigma)",
                   label="predicted 1-sigma spot error [mm]", points_label="calibration points")
    if truth is not None:
        true_model = model_from_dict(truth)
        txs, tys, terr = error_map(true_model, model, xr, yr, n)
        plot_error_map(txs, tys, terr, axes[1], points=pts, nadir=true_model.nadir_world,
                       title="true spot error (simulated truth)", points_label="calibration points")
    s.figure(fig, "predicted spot error over the floor" + ("; right: the actual error against the simulated truth"
                                                             if truth is not None else ""))
    return s


def _evaluation_from_result(result) -> list[Section]:
    """The Table 2 evaluation recorded in ``diagnostics['evaluation']``, its error map recomputed from the models."""
    from robocal.rigs.projector.evaluate import Evaluation, error_map, evaluation_extent

    e = result.diagnostics["evaluation"]
    ev = Evaluation(*(np.asarray(e[k], dtype=float) for k in ("desired", "theta", "landed", "error")),
                    np.asarray(e["reached"], dtype=bool))
    truth = model_from_dict(result.diagnostics["truth"]["model"])
    xr, yr = evaluation_extent(truth, ev.desired)
    emap = error_map(truth, calibrated_model(result), xr, yr, int(e.get("map_n", 41)))
    return evaluation_sections(ev, emap, nadir=truth.nadir_world)


def evaluation_sections(ev, emap=None, *, nadir=None, title="Evaluation (seed Table 2 protocol)") -> list[Section]:
    """The seed's Table 2 protocol: its table and the spot error over the reachable floor."""
    s = Section(title)
    s.text(f"{int(ev.reached.sum())} of {len(ev.reached)} desired points reached; spot error RMS "
           f"{1000 * ev.rms:.2f} mm, max {1000 * ev.max:.2f} mm.")
    s.table(ev.rows(), digits=5)
    if emap is not None:
        fig, ax = new_figure(size=(6.4, 5.6))
        plot_error_map(*emap, ax, points=ev.desired, nadir=nadir)
        s.figure(fig, "spot error over the reachable floor (simulated true rig driven by the calibrated model)")
    return [s]
