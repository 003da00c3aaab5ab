"""``robocal demo``'s fleet: after the rigs, eight simulated projector heads through the batch engine.

The projector is the cheapest rig to calibrate (a fraction of a second a
data set; the humanoid renders and detects images: ~5 s a robot), so a
fleet of 8 adds ~3 s to the demo: :func:`robocal.batch.simulate_fleet`
(one robot with its tilt encoder's zero slipped), :func:`run_batch` with
``executor=None`` (``--workers 1``: Dask is not started) and no per-robot
reports, then the fleet report ``<demo out>/fleet/fleet.html``, linked
from the demo's page. The check: the report names exactly the planted robot.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

__all__ = ["fleet_demo", "fleet_demo_workflows", "DEMO_RIG", "DEMO_ROBOTS"]

#: the rig whose fleet the demo shows, and how many robots
DEMO_RIG, DEMO_ROBOTS = "projector", 8
#: its simulate options: 30 floor points make the tilt offset's std ~0.12 deg (8 points: ~0.35 deg, too
#: close to the planted 3 deg slip for a fleet of 8 to name it surely)
DEMO_OPTIONS = {"points": 30, "noise": 5.0, "theta_noise": 0.0}


def fleet_demo_workflows(chosen) -> list:
    """``[the fleet's pseudo-rig]`` when ``chosen`` (the demo's rigs) holds :data:`DEMO_RIG` with a fleet step."""
    from robocal.workflow import Workflow

    rig = next((w for w in chosen if w.name == DEMO_RIG and w.fleet is not None), None)
    if rig is None:
        return []
    return [Workflow(name="fleet", help=f"a simulated fleet of {DEMO_ROBOTS} {DEMO_RIG}s through robocal batch",
                     demo=lambda ctx, rig=rig: fleet_demo(ctx, rig))]


def fleet_demo(ctx, wf, *, n: int = DEMO_ROBOTS, options=None):
    """Simulate ``n`` robots of ``wf`` into ``ctx.out_dir/sim``, batch them into ``ctx.out_dir``; a DemoOutcome.

    ``ctx``: :class:`robocal.workflow.DemoContext` (its ``rng`` the fleet's
    only randomness). Returns the outcome whose summary names the robots the
    fleet report named and whether they are the planted ones.
    """
    from robocal.batch import load_manifest, run_batch, simulate_fleet
    from robocal.report import Section
    from robocal.workflow import DemoOutcome

    out = Path(ctx.out_dir)
    sim = out / "sim"
    sim.mkdir(parents=True, exist_ok=True)
    fleet = simulate_fleet(wf, sim, n, ctx.rng, progress=ctx.progress, **(options or DEMO_OPTIONS))
    outcome = run_batch(wf, load_manifest(fleet.manifest, rig=wf.name), out, progress=ctx.progress, reports=False)
    report = json.loads((out / "fleet.json").read_text(encoding="utf-8"))
    named = sorted({s["id"] for s in report["standouts"]} | {w["id"] for w in report["weak"]})
    planted = sorted(fleet.planted)
    first = {}
    for s in report["standouts"]:
        first.setdefault(s["id"], s)
    words = [f"{i} ({first[i]['parameter']} {first[i]['deviation']:+.2g} "
             f"{report['parameters'][first[i]['parameter']]['unit']} from the median)" if i in first else f"{i} (weak)"
             for i in named]
    summary = {"robots": f"{n} {wf.name}s, {len(outcome.failed)} failed",
               "named": ", ".join(words) or "none",
               "planted": "; ".join(f"{i}: {fleet.planted[i].get('text', fleet.planted[i]['kind'])}" for i in planted)}
    sec = Section("A fleet through robocal batch")
    sec.text(f"{n} simulated {wf.name}s (robocal {wf.name} simulate --fleet {n}), calibrated one by one by "
             f"robocal batch {wf.name} (--workers 1: no Dask); the fleet report names the robots that stand out.")
    sec.items.append(f'<p><a href="fleet/fleet.html">{html.escape("fleet/fleet.html")}</a>: the fleet report '
                     f"({len(report['standouts'])} standout(s), {len(report['weak'])} weak recording(s))</p>")
    for s in report["standouts"]:
        sec.text(s["text"], cls="fail" if s["cause"] == "mechanical" else "warn")
    sec.text(f"planted ({fleet.truth.name}): {summary['planted'] or 'nothing'}")
    return DemoOutcome(summary=summary, passed=bool(named == planted and not outcome.failed), sections=[sec])
