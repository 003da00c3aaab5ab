"""Plots of the projector rig (pure: take ``ax``, return it); the report's sections are in :mod:`.report`."""

from __future__ import annotations

import numpy as np

from robocal.report import new_figure, plot_cost

__all__ = ["plot_cost_curves", "iterative_methods", "plot_residuals", "residual_sample", "plot_error_map",
           "plot_path", "COLUMN_WIDTH"]

#: Widest figure (inches at the reports' 100 dpi): a report column of ~1000 px shows it unscaled.
COLUMN_WIDTH = 9.6


def iterative_methods(estimates: dict) -> list[str]:
    """Methods with a cost history of more than one value (the closed form has none to plot).

    ``estimates``: ``{name: ExtrinsicEstimate}`` or ``{name: cost history}``.
    """
    return [name for name, est in estimates.items() if np.asarray(_history(est)).size > 1]


def _history(est):
    return getattr(est, "cost_history", est)


def plot_cost_curves(estimates: dict, ax=None):
    """Cost per iteration of each iterative solver (the seed's Fig. 4), log scale, one axis each.

    ``estimates``: ``{name: ExtrinsicEstimate}`` or ``{name: cost history}``;
    ``ax``: one axis per method of :func:`iterative_methods` (a sequence), or a
    single axis. The seed's ``eps^T eps`` (eq. 27, ~1e-5) and the LS cost
    ``0.5 sum r^2 / sigma^2`` (~1e2) differ by orders of magnitude, so on one
    axis the seed's curve is a flat line: give one axis each. Each curve is
    drawn by the core's :func:`robocal.report.plot_cost`.
    """
    names = iterative_methods(estimates)
    if ax is None:
        k = max(1, len(names))
        _, ax = new_figure(1, k, size=(min(COLUMN_WIDTH, 4.8 * k), 3.6))
    axes = list(np.atleast_1d(ax))
    if len(axes) == 1:
        axes = axes * len(names)
    elif len(axes) < len(names):
        raise ValueError(f"plot_cost_curves: {len(names)} methods to plot, {len(axes)} axes given")
    for a, name in zip(axes, names):
        seed = name == "seed"
        plot_cost(np.asarray(_history(estimates[name]), dtype=float), a,
                  label=f"{name} ({'eps^T eps, eq. 27' if seed else '0.5 sum (r/sigma)^2'})",
                  ylabel="eps^T eps (eq. 27)" if seed else "LS cost 0.5 sum (r/sigma)^2")
        a.set_xlabel("iteration")
        a.set_title(f"{name}: cost per iteration" + (" (seed Fig. 4)" if seed else ""), fontsize=10)
    return ax


#: Residual plots draw at most this many points, and label every point only up to MAX_LABELLED.
MAX_DRAWN = 2000
MAX_LABELLED = 30


def residual_sample(residuals) -> np.ndarray:
    """Indices of the points a residual plot draws: all up to :data:`MAX_DRAWN`, else a sample.

    A figure of 10^4 labelled arrows took minutes to lay out: many points are
    drawn as a sample that keeps every point with one of the largest residuals
    (a tenth of the sample) plus evenly spaced ones. The result file keeps
    this sample, so that its size does not grow with N.
    """
    n = np.linalg.norm(np.asarray(residuals, dtype=float), axis=1)
    if len(n) <= MAX_DRAWN:
        return np.arange(len(n))
    worst = np.argsort(-n)
    return np.union1d(worst[:MAX_DRAWN // 10], np.linspace(0, len(n) - 1, MAX_DRAWN - MAX_DRAWN // 10).astype(int))


def plot_residuals(points_W: np.ndarray, residuals: np.ndarray, ax=None, *, scale: float | None = None,
                   index=None, n_total: int | None = None):
    """Floor residuals (m) as arrows at the measured points (exaggerated by ``scale``).

    ``index``: the points' numbers in the data set when ``points_W`` and
    ``residuals`` are a sample of it (:func:`residual_sample`) of ``n_total``
    points; the point labels use them.
    """
    if ax is None:
        _, ax = new_figure()
    points_W = np.asarray(points_W, dtype=float)
    r = np.asarray(residuals, dtype=float)
    n = np.linalg.norm(r, axis=1)
    index = np.arange(len(n)) if index is None else np.asarray(index, dtype=int)
    n_total = len(n) if n_total is None else int(n_total)
    if scale is None:
        span = float(np.ptp(points_W[:, :2], axis=0).max()) or 1.0
        scale = 0.1 * span / max(float(n.max()), 1e-12)
    worst = np.argsort(-n)
    shown = residual_sample(r)
    labelled = shown if n_total <= MAX_LABELLED else worst[:10]
    ax.scatter(points_W[shown, 0], points_W[shown, 1], c="k", s=12 if len(shown) <= 200 else 2)
    ax.quiver(points_W[shown, 0], points_W[shown, 1], r[shown, 0] * scale, r[shown, 1] * scale, angles="xy",
              scale_units="xy", scale=1, color="tab:red")
    for i in labelled:
        ax.annotate(f"{index[i]}: {1000 * n[i]:.1f} mm", points_W[i, :2], fontsize=7, xytext=(3, 3),
                    textcoords="offset points")
    if len(shown) < n_total:
        ax.text(0.01, 0.01, f"{len(shown)} of {n_total} points drawn (the largest residuals among them)",
                transform=ax.transAxes, fontsize=7)
    ax.set_aspect("equal")
    ax.margins(0.18)  # room for the point labels at the edge
    ax.set_xlabel("x_W [m]")
    ax.set_ylabel("y_W [m]")
    ax.set_title(f"floor residuals (arrows x{scale:.3g})", fontsize=10)
    return ax


def plot_error_map(xs, ys, err, ax=None, *, points=None, nadir=None, title="floor error: landed - desired",
                   label="spot error [mm]", points_label="grid"):
    """Heat map of a spot error magnitude (m, shown in mm) over the floor, with points overlaid.

    The colorbar sits below the map (its label is then as wide as the map, not
    an extra column), so that two maps side by side fit a report column.
    """
    if ax is None:
        _, ax = new_figure()
    im = ax.pcolormesh(xs, ys, 1000 * np.asarray(err), shading="auto", cmap="viridis")
    ax.figure.colorbar(im, ax=ax, label=label, location="bottom", shrink=0.85, aspect=30)
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
    ax.set_title(title, fontsize=10)
    return ax


def plot_path(plan, ax=None, *, walls=None, projectors=None):
    """World path coloured by serving projector, walls, nadirs, hand-overs and infeasible samples."""
    from matplotlib.ticker import MaxNLocator

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
    # equal scales by widening the data limits, not by shrinking the box: a nearly straight path
    # (path_timed.yaml) otherwise leaves a strip a few pixels high with overlapping ticks
    ax.set_aspect("equal", adjustable="datalim")
    ax.xaxis.set_major_locator(MaxNLocator(nbins=8))
    ax.yaxis.set_major_locator(MaxNLocator(nbins=8))
    ax.set_xlabel("x_W [m]")
    ax.set_ylabel("y_W [m]")
    ax.legend(fontsize=7, loc="best")
    ax.set_title("spot path (stars: hand-over points)", fontsize=10)
    return ax
