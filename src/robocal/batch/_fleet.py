"""The fleet report: each parameter across the robots of a batch, and the robots that stand out.

For every scalar parameter the robots' estimates give a robust centre and
spread: the median and ``sigma_r = 1.4826 MAD`` (the median absolute
deviation scaled so that it estimates the standard deviation of Gaussian
values; Huber & Ronchetti, *Robust Statistics*, 2nd ed., 2009, sec. 5.1 --
one robot with a broken joint moves neither) -- for the plot and the table.

Whether a robot **stands out** is a test with a stated false-alarm rate. The
MAD of ten robots is itself uncertain by ~35 %, so "more than 4 robust
sigmas" named a good robot in about one fleet report of ten (21 parameters,
10 robots). Instead each robot is compared with the others by a prediction
interval (Hahn & Meeker, *Statistical Intervals*, 1991, sec. 4.2): with
the ``m`` other robots' mean and std ``s``, ``t = (x - mean) / (s sqrt(1 +
1/m))`` follows Student's t with ``m - 1`` degrees of freedom for a
Gaussian fleet -- exactly, for any ``m``. A robot is named when its
two-sided p-value is below ``FALSE_ALARM`` divided by the number of
robot-parameters judged (Bonferroni): a report on a fleet of good robots
names anyone with probability at most ``FALSE_ALARM``, whatever the fleet's
size. A robot named leaves the other robots' reference set of that
parameter and the test is repeated until no one more is named (a forward
search, Hadi & Simonoff, JASA 88, 1993: a broken robot does not widen the
band the others are judged by); so does a weak recording (below) from the
start. Screening the reference set by the MAD
instead (Iglewicz & Hoaglin's modified z > 3.5) cuts good robots' tails
when the MAD of ten is low by chance, and named a good robot in ~9 % of
such reports. ``s`` is never taken below the median reported std of one
calibration (the spread of a few identical robots is noise; this only makes
the test stricter). The price of a small fleet is a higher bar: 10 robots, 21
parameters: ~9 spreads; 200 robots: ~5. The robot's own reported std then tells the cause:

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
from scipy import stats

__all__ = ["fleet_summary", "build_fleet_report", "write_fleet", "FALSE_ALARM", "NOISE", "WEAK", "MIN_FLEET"]

#: the probability that the report on a fleet of good (Gaussian-scattered) robots names anyone
FALSE_ALARM = 0.01
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
        elif isinstance(v, (list, tuple)) and 1 < len(v) <= 6 and all(e is None or _scalar(e) is not None for e in v):
            # an element that is None (a direction the data cannot determine) is left out, not the vector
            tags = "xyz" if len(v) == 3 else [str(j) for j in range(len(v))]
            out.update({f"{k}.{t}": _scalar(e) for t, e in zip(tags, v) if e is not None})
    return out


def _prediction_t(x, own, floor: float, named=()) -> list:
    """``(index, t, m, spread, p)`` of each robot against the others (module docstring); none when too few.

    ``x``: the robots' values; ``own``: their reported stds (nan: none);
    ``floor``: the smallest spread believed (the median reported std);
    ``named``: indices already named, left out of every reference set. A
    robot whose own std is above the typical one gets the excess in its
    spread (``s^2 + own^2 - floor^2``): a weak recording strays by its own
    noise, which is not the robot's fault.
    """
    ref = np.ones(x.size, bool)
    ref[list(named)] = False
    c = x - x[ref].mean()  # centred first: the leave-one-out sums below then lose no digits
    m = ref.sum() - ref  # the others in robot i's reference set
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = (c[ref].sum() - ref * c) / m
        var = (np.sum(c[ref] ** 2) - ref * c ** 2 - m * mean ** 2) / (m - 1)
        spread = np.maximum(np.sqrt(np.maximum(var, 0.0)), floor)
        excess = np.where(np.isfinite(own) & (own > floor), np.nan_to_num(own) ** 2 - floor ** 2, 0.0)
        spread = np.sqrt(spread ** 2 + excess)
        t = (c - mean) / (spread * np.sqrt(1.0 + 1.0 / m))
    # a std of 2 values has 1 degree of freedom: no bar a good robot could not trip
    ok = (m >= 3) & (spread > 0)
    p = np.full(x.size, np.nan)
    p[ok] = 2.0 * stats.t.sf(np.abs(t[ok]), m[ok] - 1)
    return [(int(i), float(t[i]), int(m[i]), float(spread[i]), float(p[i])) for i in np.flatnonzero(ok)]


def _t_limit(p_limit: float, n: int) -> float | None:
    """The |t| a robot must pass in a fleet of ``n`` (reference set of ``n - 1``): the plot's band."""
    return float(stats.t.isf(p_limit / 2.0, n - 2)) if n >= 4 else None


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
        ``standouts``: ``id``, ``parameter``, ``deviation`` (from the median),
        ``robust_sigmas``, ``t`` and ``p_value`` (the test against the other
        robots), ``own_stds``, ``cause`` (``mechanical`` or ``noise``), ``text``;
        ``weak``: ``id``, ``std_ratio``, ``text``; ``failed``.
    """
    ids = list(results)
    est = {i: _flat(r.estimate) for i, r in results.items()}
    std = {i: _flat(r.std) for i, r in results.items()}
    names = []
    for i in ids:
        names += [k for k in est[i] if k not in names]
    params, standouts, judged, vals = {}, [], [], {}
    ratios = {i: [] for i in ids}
    for name in names:
        base = name if any(name in r.units for r in results.values()) else name.rpartition(".")[0]
        unit = next((r.units.get(base) for r in results.values() if r.units.get(base)), "")
        shown, k = _DISPLAY.get(unit, (unit, 1.0)) if isinstance(unit, str) else ("", 1.0)
        vals[name] = {i: est[i].get(name) for i in ids}
        stds = {i: std[i].get(name) for i in ids}
        have = [i for i in ids if vals[name][i] is not None]
        x = np.array([vals[name][i] for i in have]) * k
        med = float(np.median(x)) if x.size else None
        sig = float(1.4826 * np.median(np.abs(x - med))) if x.size else None
        s_all = np.array([stds[i] * k for i in have if stds[i] is not None and stds[i] > 0])
        med_std = float(np.median(s_all)) if s_all.size else None
        params[name] = {"unit": shown, "median": med, "robust_sigma": sig, "median_std": med_std, "n": len(have),
                        "value": {i: None if vals[name][i] is None else vals[name][i] * k for i in ids},
                        "std": {i: None if stds[i] is None else stds[i] * k for i in ids}}
        if med_std:
            for i in have:
                if stds[i] is not None and stds[i] > 0:
                    ratios[i].append(stds[i] * k / med_std)
        # the plot's and the table's unit: never narrower than one calibration's noise
        scale = max(sig or 0.0, med_std or 0.0)
        params[name]["judged_by"] = scale
        if len(have) < MIN_FLEET or not scale:
            continue
        own = np.array([np.nan if stds[i] is None else stds[i] * k for i in have])
        judged.append((name, have, x, own, med_std or 0.0, shown, k, med))
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
    # a weak recording is judged, but judges no one: its noisy values would widen the others' reference
    # sets (one at 5x the noise hid a 3 deg slip in a fleet of 8 projectors)
    weak_ids = {w["id"] for w in weak}
    named = {name: {j for j, i in enumerate(have) if i in weak_ids} for name, have, *_ in judged}
    while True:  # the forward search (module docstring): at most one round more than robots named
        tests = [(name, j, have[j], t, m, spread, shown, k, med, p)
                 for name, have, x, own, floor, shown, k, med in judged
                 for j, t, m, spread, p in _prediction_t(x, own, floor, named.get(name, ()))]
        # Bonferroni over every robot-parameter judged: the whole report's false-alarm rate is FALSE_ALARM
        p_limit = FALSE_ALARM / max(len(tests), 1)
        grown = False
        for name, j, *_, p_value in tests:
            if p_value < p_limit and j not in named[name]:
                named[name].add(j)
                grown = True
        if not grown:
            break
    for name, _, i, t, m, spread, shown, k, med, p_value in tests:
        if p_value >= p_limit:
            continue
        dev = vals[name][i] * k - med
        own = None if std[i].get(name) is None or std[i][name] <= 0 else abs(dev) / (std[i][name] * k)
        cause = "mechanical" if own is not None and own > NOISE else "noise"
        std_text = "no std reported" if own is None else f"std {std[i][name] * k:.2g} {shown}"
        why = ("a mechanical cause, not noise" if cause == "mechanical" else
               "within its own uncertainty: recalibrate with a better recording before blaming the robot")
        standouts.append({
            "id": i, "parameter": name, "deviation": dev, "robust_sigmas": abs(dev) / params[name]["judged_by"],
            "t": abs(t), "p_value": p_value, "own_stds": own, "cause": cause,
            "text": f"{i}: {name} {vals[name][i] * k:+.3g} {shown}, {dev:+.2g} {shown} from the fleet median, "
                    f"{abs(dev) / spread:.0f} x the fleet's spread ({spread:.2g} {shown}; p = {p_value:.1g}); "
                    f"{std_text}: {why}"})
    standouts.sort(key=lambda s: -s["robust_sigmas"])
    return {"schema": "robocal.fleet/1", "rig": rig, "n_robots": len(ids), "ids": ids,
            "thresholds": {"false_alarm": FALSE_ALARM, "p_value": p_limit, "judged": len(tests),
                           "standout_t": _t_limit(p_limit, len(ids)),
                           "noise_own_stds": NOISE, "weak_std_ratio": WEAK, "min_fleet": MIN_FLEET},
            "parameters": params, "standouts": standouts, "weak": weak,
            "failed": [{"id": r["id"], "error": r["error"]} for r in failed]}


def plot_fleet(summary: dict, ax=None):
    """Each robot's deviation from the fleet median in robust sigmas, one column per parameter; returns the axes.

    Standouts are drawn red and labelled with their id; the grey band is
    the t a robot must pass (``thresholds.standout_t``, in the reference
    set's spread: roughly so in robust sigmas). One axis for all parameters: in robust sigmas the
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
    band = summary["thresholds"].get("standout_t") or 4.0
    ax.axhspan(-band, band, color="0.92", zorder=0)
    # linear inside the band, logarithmic beyond: a 100-sigma robot does not flatten everyone else
    ax.set_yscale("symlog", linthresh=band)
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set_xticks(range(len(names)))
    ax.set_xticklabels(names, rotation=70 if len(names) > 6 else 0, fontsize=7 if len(names) > 6 else 9)
    ax.set_ylabel("(estimate - median) / max(robust sigma, median std)")
    ax.set_title(f"{summary['n_robots']} robots: each parameter across the fleet (grey band: \u00b1{band:.2g})")
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
        sec.status(True, f"no robot stands out from the others in any parameter (two-sided p below "
                         f"{FALSE_ALARM:g} / {summary['thresholds']['judged']} robot-parameters: a fleet of good "
                         f"robots is named with probability {FALSE_ALARM:g}), and no recording's uncertainty is "
                         f"above {WEAK:g}x the fleet's")
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
