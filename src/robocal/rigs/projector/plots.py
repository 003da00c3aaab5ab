"""Plots of the projector rig (pure: take ``ax``, return it) and the report sections."""

from __future__ import annotations

import math

import numpy as np

from robocal.report import Section, new_figure

__all__ = ["plot_cost_curves", "iterative_methods", "plot_residuals", "plot_error_map", "plot_path",
           "calibration_sections",
           "evaluation_sections", "error_map_section"]


def iterative_methods(estimates: dict) -> list[str]:
    """Methods with a cost history of more than one value (the closed form has none to plot)."""
    return [name for name, est in estimates.items() if np.asarray(est.cost_history).size > 1]


def plot_cost_curves(estimates: dict, ax=None):
    """Cost per iteration of each iterative solver (the seed's Fig. 4), log scale.

    ``ax``: one axis per method of :func:`iterative_methods` (a sequence), or a
    single axis. The seed's ``eps^T eps`` (eq. 27, ~1e-5) and the LS cost
    ``0.5 sum r^2 / sigma^2`` (~1e2) differ by orders of magnitude, so on one
    axis the seed's curve is a flat line: give one axis each.
    """
    names = iterative_methods(estimates)
    if ax is None:
        _, ax = new_figure(1, max(1, len(names)), size=(5.0 * max(1, len(names)), 4.0))
    axes = list(np.atleast_1d(ax))
    if len(axes) == 1:
        axes = axes * len(names)
    elif len(axes) < len(names):
        raise ValueError(f"plot_cost_curves: {len(names)} methods to plot, {len(axes)} axes given")
    for a, name in zip(axes, names):
        h = np.asarray(estimates[name].cost_history, dtype=float)
        a.semilogy(np.arange(h.size), np.maximum(h, 1e-300), marker="o", ms=3,
                   label=f"{name} ({'eps^T eps, eq. 27' if name == 'seed' else '0.5 sum r^2/sigma^2'})")
        a.set_xlabel("iteration")
        a.set_ylabel("eps^T eps (eq. 27)" if name == "seed" else "LS cost")
        a.set_title(f"{name}: cost per iteration" + (" (seed Fig. 4)" if name == "seed" else ""))
        a.legend(fontsize=8)
    return ax


#: Residual plots draw at most this many points, and label every point only up to MAX_LABELLED.
MAX_DRAWN = 2000
MAX_LABELLED = 30


def plot_residuals(points_W: np.ndarray, residuals: np.ndarray, ax=None, *, scale: float | None = None):
    """Floor residuals (m) as arrows at the measured points (exaggerated by ``scale``)."""
    if ax is None:
        _, ax = new_figure()
    r = np.asarray(residuals)
    n = np.linalg.norm(r, axis=1)
    if scale is None:
        span = float(np.ptp(points_W[:, :2], axis=0).max()) or 1.0
        scale = 0.1 * span / max(float(n.max()), 1e-12)
    # A figure of 10^4 labelled arrows took minutes to lay out: many points are drawn as a sample (every
    # point with one of the largest residuals kept) and only the largest residuals are labelled.
    worst = np.argsort(-n)
    shown = np.arange(len(n)) if len(n) <= MAX_DRAWN else np.union1d(
        worst[:MAX_DRAWN // 10], np.linspace(0, len(n) - 1, MAX_DRAWN - MAX_DRAWN // 10).astype(int))
    labelled = shown if len(n) <= MAX_LABELLED else worst[:10]
    ax.scatter(points_W[shown, 0], points_W[shown, 1], c="k", s=12 if len(shown) <= 200 else 2)
    ax.quiver(points_W[shown, 0], points_W[shown, 1], r[shown, 0] * scale, r[shown, 1] * scale, angles="xy",
              scale_units="xy", scale=1, color="tab:red")
    for i in labelled:
        ax.annotate(f"{i}: {1000 * n[i]:.1f} mm", points_W[i, :2], fontsize=7, xytext=(3, 3),
                    textcoords="offset points")
    if len(shown) < len(n):
        ax.text(0.01, 0.01, f"{len(shown)} of {len(n)} points drawn (the largest residuals among them)",
                transform=ax.transAxes, fontsize=7)
    ax.set_aspect("equal")
    ax.margins(0.18)  # room for the point labels at the edge
    ax.set_xlabel("x_W [m]")
    ax.set_ylabel("y_W [m]")
    ax.set_title(f"floor residuals (arrows x{scale:.3g})")
    return ax


def plot_error_map(xs, ys, err, ax=None, *, points=None, nadir=None, title="floor error: landed - desired",
                   label="spot error [mm]", points_label="grid"):
    """Heat map of a spot error magnitude (m, shown in mm) over the floor, with points overlaid."""
    if ax is None:
        _, ax = new_figure()
    im = ax.pcolormesh(xs, ys, 1000 * np.asarray(err), shading="auto", cmap="viridis")
    ax.figure.colorbar(im, ax=ax, label=label)
    if points is not None:
        pts = points if len(points) <= MAX_DRAWN else points[np.linspace(0, len(points) - 1, MAX_DRAWN).astype(int)]
        ax.scatter(pts[:, 0], pts[:, 1], c="w", edgecolors="k", s=25 if len(pts) <= 200 else 3, label=points_label)
    if nadir is not None:
        ax.plot(*nadir, "r+", ms=10, label="nadir")
    if points is not None or nadir is not None:
        ax.legend(fontsize=7, loc="upper right")
    ax.set_aspect("equal")
    ax.set_xlabel("x_W [m]")
    ax.set_ylabel("y_W [m]")
    ax.set_title(title)
    return ax


def plot_path(plan, ax=None, *, walls=None, projectors=None):
    """World path coloured by serving projector, walls, nadirs, hand-overs and infeasible samples."""
    if ax is None:
        _, ax = new_figure(size=(6.4, 5.0))
    colors = ["tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown"]
    pts = plan.points
    for k, name in enumerate(plan.names):
        m = plan.assignment == k
        ax.scatter(pts[m, 0], pts[m, 1], s=4, color=colors[k % len(colors)], label=f"served by {name}")
    bad = plan.assignment < 0
    if np.any(bad):
        ax.scatter(pts[bad, 0], pts[bad, 1], s=10, color="red", marker="x", label="infeasible")
    for h in plan.handovers:
        ax.plot(*h["point"], "k*", ms=10)
    if walls is not None:
        for w in np.asarray(walls):
            ax.plot(w[[0, 2]], w[[1, 3]], "k-", lw=3)
    if projectors is not None:
        for p in projectors:
            ax.plot(*p.nadir_world, "k^", ms=8)
            ax.annotate(p.name, p.nadir_world, xytext=(4, 4), textcoords="offset points")
    ax.set_aspect("equal")
    ax.set_xlabel("x_W [m]")
    ax.set_ylabel("y_W [m]")
    ax.legend(fontsize=7, loc="best")
    ax.set_title("spot path (stars: hand-over points)")
    return ax


def calibration_sections(run, *, truth=None) -> list[Section]:
    """Report sections for a :class:`~robocal.rigs.projector.calibrate.CalibrationRun`."""
    secs = []
    s = Section("Consistency of pairwise distances")
    c = run.consistency
    s.status(c.consistent, "distances in {W} and {0} agree within " + c.threshold if c.consistent
             else (f"inconsistent: uniform scale error {100 * c.scale:+.2f} % (model, not points)"
                   + (f"; suspect point(s) {c.suspects}" if c.suspects else "")) if c.scale is not None
             else f"inconsistent: suspect point(s) {c.suspects}")
    s.table([dict(pair=f"{r['i']}-{r['j']}", **{"d_W [mm]": 1000 * r["d_W"], "d_0 [mm]": 1000 * r["d_0"],
                                                 "diff [mm]": 1000 * r["diff"], "diff [%]": 100 * r["rel"],
                                                 "ok": r["ok"]}) for r in c.rows()[:60]], digits=5)
    s.diagnostics(c.warnings)
    secs.append(s)
    s = Section("Extrinsics by method")
    rows = []
    for name, e in run.estimates.items():
        row = {"method": name, "yaw [deg]": math.degrees(e.yaw),
               "std yaw [deg]": None if e.std.get("yaw") is None else math.degrees(e.std["yaw"]),
               "t_x [m]": e.t_0_W[0], "t_y [m]": e.t_0_W[1], "t_z [m]": e.t_0_W[2], "rms [mm]": 1000 * e.rms,
               "iterations": e.iterations}
        if truth is not None:
            row["yaw error [mrad]"] = 1000 * (e.yaw - math.atan2(truth.R_0_W[1, 0], truth.R_0_W[0, 0]))
            row["t error [mm]"] = 1000 * float(np.linalg.norm(e.t_0_W[:2] - truth.t_0_W[:2]))
        rows.append(row)
    s.table(rows, digits=6)
    if "seed" in run.estimates:
        Ri = run.estimates["seed"].extra["R_init"]
        s.text(f"seed method: eq. (23) initial yaw {math.degrees(math.atan2(Ri[1, 0], Ri[0, 0])):.4f} deg, "
               f"refined {math.degrees(run.estimates['seed'].yaw):.4f} deg after "
               f"{run.estimates['seed'].iterations} iterations of eq. (29).")
    best = run.best
    basis = (f"the stated noise sigma = {1000 * run.sigma:.3g} mm taken as known (absolute sigma)" if run.sigma
             else "scaled by the residuals (no noise stated in the input)")
    s.text(f"Primary estimate: {run.primary}. Standard deviations are sampling error under the model "
           f"(noise on the world measurements), not model error; they use {basis}.")
    est = {"yaw [rad]": best.yaw, "t_x [m]": best.t_0_W[0], "t_y [m]": best.t_0_W[1]}
    std = {"yaw [rad]": best.std.get("yaw"), "t_x [m]": best.std.get("t_x"), "t_y [m]": best.std.get("t_y")}
    for k in ("h", "tilt_offset", "pan_offset"):
        if k in best.std:
            val = best.extra["h"] if k == "h" else best.extra["offsets"][0 if k == "pan_offset" else 1]
            est[k] = val
            std[k] = best.std[k]
    s.parameters(est, std)
    if truth is not None:
        from robocal.rigs.projector.workflow import truth_errors

        err = truth_errors(best, truth)
        trows = []
        for k, unit, f in (("yaw", "mrad", 1e3), ("t_x", "mm", 1e3), ("t_y", "mm", 1e3), ("h", "mm", 1e3),
                           ("tilt_offset", "mrad", 1e3), ("pan_offset", "mrad", 1e3)):
            v = err.get(k)
            if v is None or (k in ("h", "tilt_offset", "pan_offset") and k not in best.std):
                continue
            sd = best.std.get(k)
            trows.append({"parameter": k, f"error [{unit}]": f * v, "error": f"{f * v:.4g} {unit}",
                          "std": None if sd is None else f"{f * sd:.4g} {unit}",
                          "error / std": None if not sd else v / sd})
        s.table([{k: v for k, v in r.items() if "[" not in k} for r in trows], digits=4,
                caption="primary estimate minus the truth (a held or unidentifiable parameter has no std)")
    s.diagnostics(run.warnings)
    secs.append(s)
    s = Section("Cost curves and residuals")
    names = iterative_methods(run.estimates)
    fig, ax = new_figure(1, len(names) + 1, size=(5.0 * (len(names) + 1), 4.2))
    ax = np.atleast_1d(ax)
    if names:
        plot_cost_curves(run.estimates, ax[:-1])
    plot_residuals(run.points_W, best.residuals, ax[-1])
    s.figure(fig, ("cost per iteration, one panel per method (" + ", ".join(names) + "; seed Fig. 4 for the seed's "
                   "method); " if names else "") + "right: floor residuals of the primary estimate")
    secs.append(s)
    secs.append(error_map_section(run, truth=truth))
    return secs


def error_map_section(run, *, truth=None, n: int = 41) -> Section:
    """"Predicted spot error" heat map of the primary estimate (and the true error map when ``truth`` is known).

    Propagates the estimate's covariance through the spot model (seed eqs. 1,
    6, 8; :func:`robocal.rigs.projector.evaluate.predicted_error_map`): the RMS
    length of the error vector, 1 sigma, of a spot commanded by the calibrated
    model, over its reachable floor.
    """
    from robocal.rigs.projector.evaluate import error_map, estimate_covariance, predicted_error_map

    s = Section("Error map: predicted spot error over the floor")
    model, cov, labels, note = estimate_covariance(run)
    nadir = model.nadir_world
    r = model.floor_radius
    pts = run.points_W[:, :2]
    xr = (min(nadir[0] - r, pts[:, 0].min()) - 0.2, max(nadir[0] + r, pts[:, 0].max()) + 0.2)
    yr = (min(nadir[1] - r, pts[:, 1].min()) - 0.2, max(nadir[1] + r, pts[:, 1].max()) + 0.2)
    if cov is None:
        s.status(False, f"no predicted error map: {note}")
        return s
    xs, ys, err = predicted_error_map(model, cov, labels, xr, yr, n)
    fin = err[np.isfinite(err)]
    if fin.size == 0:
        s.status(False, "no predicted error map: no grid cell on the reachable floor")
        return s
    s.text(f"1-sigma spot error (RMS length of the error vector) of a spot commanded by the {run.primary} "
           f"estimate, from its covariance over {', '.join(labels)} propagated to first order through the spot "
           f"model (seed eqs. 1, 6, 8): {1000 * fin.min():.2f} to {1000 * fin.max():.2f} mm over the reachable "
           f"floor (radius {r:.2f} m at tilt {math.degrees(model.tilt_limit):g} deg). 95 % of spots lie within "
           f"1.7 (round error ellipse) to 2.0 (flat ellipse) times this. Sampling error only: a model error "
           f"(wrong H) is not included."
           + (f" Note: {note}." if note else ""))
    ncol = 2 if truth is not None else 1
    fig, ax = new_figure(1, ncol, size=(6.4 * ncol, 5.0))
    axes = np.atleast_1d(ax)
    plot_error_map(xs, ys, err, axes[0], points=pts, nadir=nadir, title="predicted spot error (1 sigma)",
                   label="predicted 1-sigma spot error [mm]", points_label="calibration points")
    if truth is not None:
        txs, tys, terr = error_map(truth, model, xr, yr, n)
        plot_error_map(txs, tys, terr, axes[1], points=pts, nadir=truth.nadir_world,
                       title="true spot error (simulated truth)", points_label="calibration points")
    s.figure(fig, "predicted spot error over the floor" + ("; right: the actual error against the simulated truth"
                                                             if truth is not None else ""))
    return s


def evaluation_sections(ev, emap=None, *, nadir=None, title="Evaluation (seed Table 2 protocol)") -> list[Section]:
    s = Section(title)
    s.text(f"{int(ev.reached.sum())} of {len(ev.reached)} desired points reached; spot error RMS "
           f"{1000 * ev.rms:.2f} mm, max {1000 * ev.max:.2f} mm.")
    s.table(ev.rows(), digits=5)
    if emap is not None:
        fig, ax = new_figure(size=(6.4, 5.0))
        plot_error_map(*emap, ax, points=ev.desired, nadir=nadir)
        s.figure(fig, "spot error over the reachable floor (simulated true rig driven by the calibrated model)")
    return [s]
