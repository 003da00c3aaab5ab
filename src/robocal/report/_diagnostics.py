"""The report's estimation sections, written once for every rig.

A rig's ``build_report`` calls these with what its result file holds (the
solver record ``LSQResult.to_dict()`` under ``diagnostics``, residuals), so
the solver table, the cost plot and the residual histogram look and read the
same in every report, and a rebuilt report equals the first.
"""

from __future__ import annotations

import math

import numpy as np

from robocal.report._html import Section, new_figure

__all__ = ["plot_cost", "plot_residual_histogram", "solver_section", "truth_section"]


def plot_cost(history, ax=None, *, label: str | None = None, ylabel: str = "cost 0.5 sum (r/sigma)^2"):
    """Cost at the start and after each accepted step, log scale. Returns the axes.

    ``history`` may be a sequence of such arrays keyed by a label (a dict):
    several passes or methods drawn one after the other on the same axes.
    """
    if ax is None:
        _, ax = new_figure(size=(6.0, 3.2))
    curves = history if isinstance(history, dict) else {label: history}
    k0 = 0
    for name, h in curves.items():
        h = np.asarray(h, dtype=float).reshape(-1)
        if h.size == 0:
            continue
        x = k0 + np.arange(h.size)
        # a cost of exactly 0 (noise-free data) has no logarithm: floor it for drawing
        ax.semilogy(x, np.maximum(h, 1e-300), "o-", ms=3, label=name)
        k0 = int(x[-1])
    ax.set_xlabel("accepted step")
    ax.set_ylabel(ylabel)
    if any(k is not None for k in curves):
        ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    return ax


def plot_residual_histogram(residuals, ax=None, *, sigma: float | None = None, unit: str = "", bins: int = 40,
                            label: str | None = None):
    """Histogram of residual components with the Gaussian of ``sigma`` over it. Returns the axes.

    ``residuals``: any shape (flattened), in ``unit``; non-finite values are
    left out. ``sigma``: the noise level the estimate assumed (or the residual
    std), drawn as a density for comparing the tails.
    """
    if ax is None:
        _, ax = new_figure(size=(6.0, 3.2))
    r = np.asarray(residuals, dtype=float).reshape(-1)
    r = r[np.isfinite(r)]
    if r.size == 0:
        ax.text(0.5, 0.5, "no residuals", ha="center", va="center", transform=ax.transAxes)
        return ax
    ax.hist(r, bins=bins, density=True, color="tab:gray", alpha=0.8, label=label or f"{r.size} residuals")
    if sigma is not None and math.isfinite(sigma) and sigma > 0:
        x = np.linspace(r.min(), r.max(), 200)
        ax.plot(x, np.exp(-0.5 * (x / sigma) ** 2) / (sigma * math.sqrt(2 * math.pi)), "C0-",
                label=f"N(0, {sigma:.3g}{(' ' + unit) if unit else ''})")
    ax.set_xlabel(f"residual [{unit}]" if unit else "residual")
    ax.set_ylabel("density")
    ax.legend(fontsize=8)
    return ax


def solver_section(section: Section, record: dict, *, caption: str = "", passes: dict | None = None) -> Section:
    """The solver's record as a table (status, steps, cost, rank, condition) and its cost plot.

    ``record``: :meth:`robocal.estimation.LSQResult.to_dict` (as stored in a
    result's ``diagnostics``); missing fields are shown as dashes.
    ``passes``: ``{label: cost history}`` of several solver passes (a start
    pass, then the final one), drawn one after the other; default: the
    record's own ``cost_history``.
    """
    if not record:
        return section.text("No iterative solver ran (closed-form estimate).")
    curves = {k: _floats(v) for k, v in passes.items()} if passes else None
    hist = _floats(record.get("cost_history") or ([] if not curves else next(iter(curves.values()))))
    row = {
        "method": record.get("method"),
        "loss": record.get("loss"),
        "status": record.get("message") or record.get("status"),
        "accepted steps": record.get("iterations"),
        "residual evaluations": record.get("nfev"),
        "initial cost": hist[0] if hist.size else None,
        "final cost": record.get("cost"),
        "residual RMS": record.get("rms"),
        "rank": record.get("rank"),
        "parameters": len(record.get("free_labels") or []) or None,
        "condition number": _number(record.get("condition_number")),
        "outlier threshold [sigma]": record.get("outlier_sigma"),
    }
    section.table([{"quantity": k, "value": v} for k, v in row.items()], ["quantity", "value"], digits=5,
                  caption=caption or None)
    if curves:
        ax = plot_cost(curves)
        section.figure(ax.figure, caption="cost per accepted step of each solver pass (log scale)")
    elif hist.size > 1:
        ax = plot_cost(hist)
        section.figure(ax.figure, caption="cost per accepted step of the least-squares solver (log scale)")
    return section


def _floats(values) -> np.ndarray:
    return np.asarray([np.nan if v is None else float(v) for v in values], dtype=float)


def truth_section(section: Section, check: dict) -> Section:
    """A simulated run's truth check (:class:`robocal.estimation.TruthCheck` ``.to_dict()``): verdict and z table."""
    ok = bool(check.get("passed"))
    section.status(ok, f"NEES {check['nees']:.2f} over {check['dof']} parameters, limit {check['threshold']:.1f} "
                       f"(p = {check.get('alpha', 1e-3):g}): the errors are "
                       f"{'consistent' if ok else 'NOT consistent'} with the reported uncertainty")
    z = check.get("z") or {}
    if z:
        section.table([{"parameter": k, "error / std": v} for k, v in z.items()], ["parameter", "error / std"],
                      digits=3)
    return section


def _number(v):
    if isinstance(v, str):  # LSQResult.to_dict writes an infinite value as "inf"
        try:
            return float(v)
        except ValueError:
            return v
    return v
