"""End-to-end workflows behind the CLI and the demo (each returns objects; no printing)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robocal.errors import InputError
from robocal.geometry import quaternion_from_matrix
from robocal.io import CalibrationResult, hash_inputs
from robocal.report import Report, Section
from robocal.rigs.projector.calibrate import CalibrationRun, calibrate, yaw_of
from robocal.rigs.projector.evaluate import Evaluation, error_map, evaluate_points, table2_grid
from robocal.rigs.projector.files import CalibrationInput, load_calibration_input, projector_to_yaml
from robocal.rigs.projector.model import ProjectorModel
from robocal.rigs.projector.plots import calibration_sections, evaluation_sections, plot_path
from robocal.report import new_figure

__all__ = ["run_calibration", "truth_errors", "calibration_result", "calibration_report", "run_evaluation", "scenario_document",
           "path_report", "EvaluationRun"]


def run_calibration(inp: CalibrationInput, *, accept_implausible: bool = False) -> CalibrationRun:
    """Calibrate from a loaded input file."""
    kw = {} if inp.tilt_offset_limit is None else {"tilt_offset_limit": inp.tilt_offset_limit}
    return calibrate(inp.points_W, theta=inp.theta, points_0=inp.points_0, model=inp.model, methods=inp.methods,
                     estimate=inp.estimate, sigma=inp.sigma, strict=inp.strict, seed_alpha=inp.seed_alpha,
                     seed_order=inp.seed_order, joint_noise=inp.joint_noise, accept_implausible=accept_implausible,
                     source=inp.source, **kw)


def truth_errors(est, truth: ProjectorModel) -> dict:
    """Estimate minus truth for every estimated parameter (SI: rad, m): yaw, t (3,), and h, offsets when estimated."""
    dt = np.asarray(est.t_0_W - truth.t_0_W, dtype=float)
    out = {"yaw": float(est.yaw - yaw_of(truth.R_0_W)), "t_x": float(dt[0]), "t_y": float(dt[1]), "t_0_W": dt}
    if "h" in est.extra:
        out["h"] = float(est.extra["h"] - truth.h)
        out["pan_offset"] = float(est.extra["offsets"][0] - truth.offsets[0])
        out["tilt_offset"] = float(est.extra["offsets"][1] - truth.offsets[1])
    return out


def calibration_result(run: CalibrationRun, *, inputs=(), truth: ProjectorModel | None = None) -> CalibrationResult:
    """The shared result record (schema robocal.result/2), SI units."""
    best = run.best
    R = best.R_0_W
    est = {"R_0_W": R, "t_0_W": best.t_0_W, "yaw": best.yaw, "q_0_W": quaternion_from_matrix(R), "H": run.model.H}
    std = {"R_0_W": None, "t_0_W": [best.std.get("t_x"), best.std.get("t_y"), 0.0], "yaw": best.std.get("yaw"),
           "q_0_W": None, "H": None}
    units = {"R_0_W": "1", "t_0_W": "m", "yaw": "rad", "q_0_W": "1", "H": "m"}
    if "h" in best.extra:
        est["h"] = best.extra["h"]
        est["offsets"] = best.extra["offsets"]
        std["h"] = best.std.get("h")
        std["offsets"] = [best.std.get("pan_offset"), best.std.get("tilt_offset")]
        units.update(h="m", offsets="rad")
    per_method = {}
    for name, e in run.estimates.items():
        d = {"R_0_W": e.R_0_W, "t_0_W": e.t_0_W, "yaw": e.yaw, "std": e.std, "rms": e.rms,
             "iterations": e.iterations, "cost_history": e.cost_history,
             "warnings": [w.to_dict() for w in e.warnings]}
        if name == "seed":
            d["R_init"] = e.extra["R_init"]
            d["alpha"] = e.extra["alpha"]
            d["order"] = e.extra["order"]
            d["converged"] = e.extra["converged"]
        if name == "nonlinear" and "lsq" in e.extra:
            lsq = e.extra["lsq"]
            d.update(rank=lsq.rank, condition_number=lsq.condition_number, correlations=lsq.correlations[:5],
                     status=lsq.message)
        per_method[name] = d
    diag = {"methods": per_method, "consistency": run.consistency.rows(),
            "consistency_threshold": run.consistency.threshold, "suspect_points": run.consistency.suspects,
            "n_points": int(len(run.points_W)), "sigma": run.sigma, "joint_noise": run.joint_noise,
            "n_pairs_checked": run.consistency.n_pairs,
            "std_basis": ("absolute: the input's noise sigma taken as known" if run.sigma else
                          "residual-scaled: no noise given, sigma estimated from the residuals"),
            "frames": "p_0 = R_0_W p_W + t_0_W (seed eq. 1); quaternion scalar-last"}
    if truth is not None:
        err = truth_errors(best, truth)
        diag["truth"] = {"yaw": float(yaw_of(truth.R_0_W)), "t_0_W": truth.t_0_W, "h": truth.h,
                         "offsets": list(truth.offsets),
                         "yaw_error": best.yaw - float(yaw_of(truth.R_0_W)),
                         "t_error": best.t_0_W - truth.t_0_W,
                         "errors": err,
                         "errors_over_std": {k: (None if not isinstance(v, float) or not best.std.get(k) else
                                                 v / best.std[k]) for k, v in err.items()},
                         "errors_by_method": {name: truth_errors(e, truth) for name, e in run.estimates.items()}}
    return CalibrationResult(rig="projector", method=run.primary, estimate=est, std=std, units=units,
                             residual_rms=best.rms, residual_unit="m", warnings=run.warnings,
                             inputs=hash_inputs(inputs), diagnostics=diag)


def calibration_report(run: CalibrationRun, *, title: str, truth: ProjectorModel | None = None,
                       evaluation: "EvaluationRun | None" = None) -> Report:
    rep = Report(title, subtitle="ceiling pan-tilt laser projector (seed 000): ^0P = R_0_W ^WP + t_0_W")
    for s in calibration_sections(run, truth=truth):
        rep.sections.append(s)
    if evaluation is not None:
        for s in evaluation.sections():
            rep.sections.append(s)
    return rep


@dataclass
class EvaluationRun:
    evaluation: Evaluation
    emap: tuple
    nadir: np.ndarray

    def sections(self) -> list[Section]:
        return evaluation_sections(self.evaluation, self.emap, nadir=self.nadir)


def run_evaluation(truth: ProjectorModel, calibrated: ProjectorModel, *, center=(0.0, 0.0), spacing: float = 2.0,
                   map_n: int = 41) -> EvaluationRun:
    """Table 2 protocol on ``table2_grid(center, spacing)`` plus an error map over the reachable floor."""
    grid = table2_grid(center, spacing)
    ev = evaluate_points(truth, calibrated, grid)
    nadir = truth.nadir_world
    r = truth.floor_radius * 0.6
    xr = (min(grid[:, 0].min(), nadir[0] - r) - 0.5, max(grid[:, 0].max(), nadir[0] + r) + 0.5)
    yr = (min(grid[:, 1].min(), nadir[1] - r) - 0.5, max(grid[:, 1].max(), nadir[1] + r) + 0.5)
    return EvaluationRun(ev, error_map(truth, calibrated, xr, yr, map_n), nadir)


def scenario_document(sc, *, estimate=("h", "tilt_offset"), comment: str = "") -> dict:
    """A calibration input mapping (mm / deg) for a simulated scenario, with its truth."""
    if sc.theta is None:
        raise InputError("scenario has no joint angles")
    return {
        "units": {"length": "mm", "angle": "deg"},
        "projector": projector_to_yaml(sc.nominal),
        "points": {"world": np.round(sc.points_W[:, :2] * 1e3, 3).tolist(),
                   "joint_angles": np.round(np.degrees(sc.theta), 9).tolist()},
        "noise": {"value": round(sc.sigma * 1e3, 6), "unit": "mm"},
        **({"joint_noise": {"value": [float(np.degrees(sc.theta_sigma))] * 2, "unit": "deg"}}
           if sc.theta_sigma else {}),
        "methods": ["seed", "closed_form", "nonlinear"],
        "estimate": list(estimate),
        "truth": projector_to_yaml(sc.truth, extrinsics=True),
    }


def path_report(plan, projectors, walls, *, title="projector spot path", preaim: list | None = None) -> Report:
    rep = Report(title, subtitle="world path -> timed joint commands (seed eqs. 1, 2, 8, 9)")
    s = rep.section("Assignment and hand-overs")
    s.status(plan.ok, "every sample is served" if plan.ok else f"{len(plan.infeasible)} infeasible stretch(es)")
    s.table([dict(projector=g["projector"], start=g["start"], stop=g["stop"], **{"t0 [s]": g["t0"], "t1 [s]": g["t1"]})
             for g in plan.segments] or [{"projector": "none"}])
    if plan.handovers:
        s.table([{"t [s]": h["t"], "x [m]": h["point"][0], "y [m]": h["point"][1], "from": h["from"], "to": h["to"]}
                 for h in plan.handovers], caption="hand-over points")
    if preaim is None:
        _, preaim = plan.projector_commands()
    if preaim:
        s.table([{"projector": a["projector"], "slew from [s]": a["t_start"], "ready at [s]": a["t_ready"],
                  "takes over at [s]": a["t_handover"], "ready in time": a["ok"]} for a in preaim],
                caption="pre-aiming: an idle head slews (laser off) to the pose where it takes over next")
    for bad in plan.infeasible:
        s.text(f"infeasible t = {bad['t0']:.2f} .. {bad['t1']:.2f} s: "
               + "; ".join(f"{k}: {v}" for k, v in bad["reasons"].items()), cls="fail")
    fig, ax = new_figure(size=(6.4, 5.2))
    plot_path(plan, ax, walls=walls, projectors=projectors)
    s.figure(fig, "path coloured by serving projector")
    s2 = rep.section("Joint commands")
    cmd = plan.commands()
    fig, ax = new_figure(2, 1, size=(7.5, 5.5), sharex=True)
    ax[0].plot(cmd["t"], np.degrees(cmd["theta"]))
    ax[0].set_ylabel("theta [deg]")
    ax[0].legend(["pan theta1", "tilt theta2"], fontsize=8)
    ax[1].plot(cmd["t"], np.degrees(cmd["theta_dot"]))
    ax[1].set_ylabel("rate [deg/s]")
    ax[1].set_xlabel("t [s]")
    s2.figure(fig, "commands of the serving projector (pan unwrapped)")
    for tr in plan.trajectories:
        if len(tr.branches) > 1 or any(b["branch"] for b in tr.branches):
            s2.table([{"t0 [s]": b["t0"], "t1 [s]": b["t1"], "IK branch": b["ik"], "why": b["why"]}
                      for b in tr.branches[:50]],
                     caption=f"{tr.name}: IK branch per stretch between nadir crossings")
        if tr.segments:  # the nadir_pass record's text is already in the reason
            s2.table([dict(projector=tr.name, **{k: v for k, v in g.items() if k != "nadir_pass"})
                      for g in tr.segments[:20]], caption=f"{tr.name}: samples it cannot serve on its own")
    return rep


def _deg(x) -> str:
    return f"{math.degrees(x):.4f} deg"
