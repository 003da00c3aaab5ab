"""The fleet report: each parameter across the robots of a batch, and the robots that stand out.

For every scalar parameter the robots' estimates give a robust centre and
spread: the median and ``sigma_r = 1.4826 MAD`` (the median absolute
deviation scaled so that it estimates the standard deviation of Gaussian
values; Huber & Ronchetti, *Robust Statistics*, 2nd ed., 2009, sec. 5.1 --
one robot with a broken joint moves neither). A robot **stands out** in a
parameter when its estimate is more than ``STANDOUT`` times
``max(sigma_r, median reported std)`` from the median: the fleet's spread is
never taken as narrower than the noise of one calibration (the MAD of a
few identical robots is itself noise). The robot's own reported std then tells the cause:

* the distance is above ``NOISE`` of its own std: the estimate is sure, the
  robot really differs -- a mechanical cause (a slipped gear, a bent link, a
  camera knocked in its mount), not noise;
* otherwise the recording was too weak to tell: recalibrate it before
  blaming the robot.

A data set is a **weak recording** when its reported std, as a ratio to the
fleet's median std of the same parameter, has a median over the parameters
above ``WEAK`` (too few views, poor pose spread, blur).

Estimates are read from ``DIR/<id>/result.json`` (:func:`robocal.io.load_result`);
scalar entries and short vectors (one entry per element) are compared
(rad shown in deg, m in mm).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

__all__ = ["fleet_summary", "build_fleet_report", "write_fleet", "STANDOUT", "NOISE", "WEAK", "MIN_FLEET"]

#: robust sigmas from the fleet median that make a robot stand out (about p = 6e-5 for Gaussian values:
#: one false alarm in ~16,000 robot-parameters)
STANDOUT = 4.0
#: the deviation, in the robot's own std, above which it is the robot and not the noise
NOISE = 3.0
#: a data set's std over the fleet's (median over parameters) that marks a weak recording
WEAK = 3.0
#: the fewest robots whose median and MAD are worth comparing with
MIN_FLEET = 5

_DISPLAY = {"rad": ("deg", 180.0 / math.pi), "m": ("mm", 1e3)}


def _scalar(v):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        return None
    return float(v)


def _flat(values: dict) -> dict:
    """Scalar entries as they are; short vectors (a translation, a rotation vector) one entry per element."""
    out = {}
    for k, v in (values or {}).items():
        if _scalar(v) is not None:
            out[k] = _scalar(v)
        elif isinstance(v, (list, tuple)) and 1 < len(v) <= 6 and all(_scalar(e) is not None for e in v):
            tags = "xyz" if len(v) == 3 else [str(j) for j in range(len(v))]
            out.update({f"{k}.{t}": _scalar(e) for t, e in zip(tags, v)})
    return out


def fleet_summary(results: dict, *, rig: str | None = None, failed=()) -> dict:
    """The fleet's statistics and the robots named in words, as a JSON-ready dict (``fleet.json``).

    Parameters
    ----------
    results : dict of id -> CalibrationResult
        The calibrations of the fleet (one per robot or per recording).
    rig : str, optional
    failed : list of dict
        Rows of the data sets that failed (``id``, ``error``), listed as they are.

    Returns
    -------
    dict
        ``parameters``: per parameter its ``unit`` (as shown), ``median``,
        ``robust_sigma``, ``median_std`` and per robot ``value`` / ``std``;
        ``standouts``: ``id``, ``parameter``, ``deviation``, ``robust_sigmas``,
        ``own_stds``, ``cause`` (``mechanical`` or ``noise``), ``text``;
        ``weak``: ``id``, ``std_ratio``, ``text``; ``failed``.
    """
    ids = list(results)
    est = {i: _flat(r.estimate) for i, r in results.items()}
    std = {i: _flat(r.std) for i, r in results.items()}
    names = []
    for i in ids:
        names += [k for k in est[i] if k not in names]
    params, standouts = {}, []
    ratios = {i: [] for i in ids}
    for name in names:
        base = name if any(name in r.units for r in results.values()) else name.rpartition(".")[0]
        unit = next((r.units.get(base) for r in results.values() if r.units.get(base)), "")
        shown, k = _DISPLAY.get(unit, (unit, 1.0)) if isinstance(unit, str) else ("", 1.0)
        vals = {i: est[i].get(name) for i in ids}
        stds = {i: std[i].get(name) for i in ids}
        have = [i for i in ids if vals[i] is not None]
        x = np.array([vals[i] for i in have]) * k
        med = float(np.median(x)) if x.size else None
        sig = float(1.4826 * np.median(np.abs(x - med))) if x.size else None
        s_all = np.array([stds[i] * k for i in have if stds[i] is not None and stds[i] > 0])
        med_std = float(np.median(s_all)) if s_all.size else None
        params[name] = {"unit": shown, "median": med, "robust_sigma": sig, "median_std": med_std, "n": len(have),
                        "value": {i: None if vals[i] is None else vals[i] * k for i in ids},
                        "std": {i: None if stds[i] is None else stds[i] * k for i in ids}}
        if med_std:
            for i in have:
                if stds[i] is not None and stds[i] > 0:
                    ratios[i].append(stds[i] * k / med_std)
        # the fleet's spread is never judged narrower than its members' own noise: with identical
        # robots the MAD of a small fleet is itself noise, and would name robots for it
        scale = max(sig or 0.0, med_std or 0.0)
        params[name]["judged_by"] = scale
        if len(have) < MIN_FLEET or not scale:
            continue
        for i in have:
            dev = vals[i] * k - med
            z = dev / scale
            if abs(z) < STANDOUT:
                continue
            own = None if stds[i] is None or stds[i] <= 0 else abs(dev) / (stds[i] * k)
            cause = "mechanical" if own is not None and own > NOISE else "noise"
            std_text = "no std reported" if own is None else f"std {stds[i] * k:.2g} {shown}"
            why = ("a mechanical cause, not noise" if cause == "mechanical" else
                   "within its own uncertainty: recalibrate with a better recording before blaming the robot")
            standouts.append({
                "id": i, "parameter": name, "deviation": dev, "robust_sigmas": abs(z), "own_stds": own,
                "cause": cause,
                "text": f"{i}: {name} {vals[i] * k:+.3g} {shown}, {dev:+.2g} {shown} from the fleet median, "
                        f"{abs(z):.0f} x the fleet's spread ({scale:.2g} {shown}); {std_text}: {why}"})
    standouts.sort(key=lambda s: -s["robust_sigmas"])
    weak = []
    if len(ids) >= MIN_FLEET:
        for i in ids:
            if ratios[i]:
                q = float(np.median(ratios[i]))
                if q > WEAK:
                    weak.append({"id": i, "std_ratio": q,
                                 "text": f"{i}: a weak recording: its reported std is {q:.1f}x the fleet's "
                                         f"(median over {len(ratios[i])} parameters); record it again "
                                         "(more views, wider poses)"})
    weak.sort(key=lambda w: -w["std_ratio"])
    return {"schema": "robocal.fleet/1", "rig": rig, "n_robots": len(ids), "ids": ids,
            "thresholds": {"standout_robust_sigmas": STANDOUT, "noise_own_stds": NOISE, "weak_std_ratio": WEAK,
                           "min_fleet": MIN_FLEET},
            "parameters": params, "standouts": standouts, "weak": weak,
            "failed": [{"id": r["id"], "error": r["error"]} for r in failed]}


def plot_fleet(summary: dict, ax=None):
    """Each robot's deviation from the fleet median in robust sigmas, one column per parameter; returns the axes.

    Standouts are drawn red and labelled with their id; the band is
    ``+-STANDOUT``. One axis for all parameters: in robust sigmas the
    distributions of angles and lengths are comparable.
    """
    if ax is None:
        from robocal.report import new_figure

        _, ax = new_figure(size=(max(6.4, 0.35 * len(summary["parameters"]) + 2), 4.2))
    names = [n for n, p in summary["parameters"].items() if p.get("judged_by")]
    marked = {(s["id"], s["parameter"]) for s in summary["standouts"]}
    for j, name in enumerate(names):
        p = summary["parameters"][name]
        ids = [i for i, v in p["value"].items() if v is not None]
        z = np.array([(p["value"][i] - p["median"]) / p["judged_by"] for i in ids])
        # a deterministic jitter (by position) so that robots at one value stay visible
        xj = j + 0.25 * (np.arange(z.size) % 7 - 3) / 3
        bad = np.array([(i, name) in marked for i in ids])
        ax.plot(xj[~bad], z[~bad], ".", color="C0", ms=4, alpha=0.6)
        ax.plot(xj[bad], z[bad], "o", color="C3", ms=5)
        for x_, z_, i in zip(xj[bad], z[bad], np.array(ids)[bad]):
            ax.annotate(i, (x_, z_), textcoords="offset points", xytext=(3, 3), fontsize=7, color="C3")
    ax.axhspan(-STANDOUT, STANDOUT, color="0.92", zorder=0)
    # linear inside the band, logarithmic beyond: a 100-sigma robot does not flatten everyone else
    ax.set_yscale("symlog", linthresh=STANDOUT)
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set_xticks(range(len(names)))
    ax.set_xticklabels(names, rotation=70 if len(names) > 6 else 0, fontsize=7 if len(names) > 6 else 9)
    ax.set_ylabel("(estimate - median) / max(robust sigma, median std)")
    ax.set_title(f"{summary['n_robots']} robots: each parameter across the fleet (grey band: \u00b1{STANDOUT:g})")
    return ax


def build_fleet_report(summary: dict):
    """``fleet.html``: what stands out in words, the distributions, the per-parameter table, the failures."""
    from robocal.report import Report, new_figure

    n = summary["n_robots"]
    rep = Report(f"robocal batch: fleet of {n} {summary.get('rig') or ''} calibration(s)".replace("  ", " "),
                 subtitle=f"{len(summary['failed'])} data set(s) failed" if summary["failed"] else None)
    sec = rep.section("What stands out")
    if n < MIN_FLEET:
        sec.text(f"{n} calibration(s): fewer than {MIN_FLEET}, too few for a median and MAD to judge a robot by; "
                 "the table below lists them as they are.", cls="warn")
    for s in summary["standouts"]:
        sec.text(s["text"], cls="fail" if s["cause"] == "mechanical" else "warn")
    for w in summary["weak"]:
        sec.text(w["text"], cls="warn")
    if n >= MIN_FLEET and not summary["standouts"] and not summary["weak"]:
        sec.status(True, f"no robot is more than {STANDOUT:g} robust sigma from the fleet in any parameter, "
                         f"and no recording's uncertainty is above {WEAK:g}x the fleet's")
    if any(p.get("judged_by") for p in summary["parameters"].values()):
        fig, ax = new_figure(size=(max(6.4, 0.35 * len(summary["parameters"]) + 2), 4.2))
        plot_fleet(summary, ax)
        rep.section("Distributions").figure(
            fig, "Each dot a robot; red: a robot that stands out (named above). The fleet's spread is its "
                 "robust sigma (1.4826 MAD: one broken robot does not widen the band it is judged by), never "
                 "less than the median reported std of one calibration.")
    rows = []
    for name, p in summary["parameters"].items():
        vals = [v for v in p["value"].values() if v is not None]
        rows.append({"parameter": name, "unit": p["unit"], "robots": p["n"], "median": p["median"],
                     "robust sigma": p["robust_sigma"], "min": min(vals) if vals else None,
                     "max": max(vals) if vals else None, "median own std": p["median_std"]})
    rep.section("Parameters across the fleet").table(rows, digits=4)
    if summary["failed"]:
        rep.section("Failed data sets").table(summary["failed"], ["id", "error"])
    return rep


def write_fleet(out_dir, ids, *, rig: str | None = None, failed=()) -> list[Path]:
    """Read ``out_dir/<id>/result.json`` of ``ids``, write ``fleet.json`` and ``fleet.html``; return their paths."""
    from robocal.io import atomic_write_text, load_result

    out_dir = Path(out_dir)
    results = {i: load_result(out_dir / i / "result.json") for i in ids if (out_dir / i / "result.json").is_file()}
    summary = fleet_summary(results, rig=rig, failed=failed)
    paths = [atomic_write_text(out_dir / "fleet.json", json.dumps(summary, indent=2) + "\n")]
    paths.append(build_fleet_report(summary).write(out_dir / "fleet.html"))
    return paths
