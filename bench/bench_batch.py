"""Scaling of robocal's Dask engine: a Monte Carlo study and a simulated fleet, serial vs a LocalCluster.

    python bench/bench_batch.py [--trials 10000] [--fleet 200] [--workers N] [--views 4] [--seed 2026]
    python bench/bench_batch.py --trials 400 --fleet 12          # a few minutes

1. **Study**: :func:`robocal.rigs.humanoid.montecarlo.calibration_monte_carlo`
   (corner-level humanoid calibrations, 5 poses a foot), ``--trials`` trials,
   serial in this process and on an embedded ``LocalCluster`` of ``--workers``
   single-threaded worker processes (default: one per core), default batch
   size (4 tasks a worker). The two results are checked bit-identical.
2. **Per-task overhead**: 400 tasks of one trial each minus the same trials
   run serially, per task; hence the smallest batch with overhead < 5 % of
   its work: ``b = overhead / (0.05 x trial time)``.
3. **Fleet**: ``--fleet`` humanoids simulated by
   :func:`robocal.batch.simulate_fleet` on the cluster (``robocal humanoid
   simulate --fleet``: rendered images, own true offsets per robot, ~5 %
   with a planted slip, one weak recording) into a temporary folder, then
   calibrated by :func:`robocal.batch.run_batch` serially and on the
   cluster (per-robot reports included, as ``robocal batch`` writes them).
   The fleet report's named robots are compared with the planted ones.
   ``--no-reports``: the same without the per-robot ``report.html``. The
   workers' CPU seconds are printed beside their wall time (a worker busy
   less than its wall time waited: disk, the scheduler, other processes).

Printed: wall times, speed-up, speed-up per core (the issue's goal: >= 0.85
on 2 cores), overhead. BLAS runs on one thread everywhere (the workers'
default), so the serial run is the same work as one worker's. Wall time
measures the machine: on a shared machine the figures say little, and the
script prints the load average before and after to tell.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402


def _load() -> str:
    try:
        return "load average %.2f %.2f %.2f" % os.getloadavg()
    except OSError:
        return "load average unknown"


def _noop_trials(n: int):
    """n cheap trials (a 3-parameter linear fit): what the per-task overhead is measured against."""

    def simulate(rng):
        t = np.linspace(0.0, 1.0, 20)
        return np.column_stack([np.ones(20), t, t**2]) @ [1.0, 2.0, 3.0] + rng.normal(0, 0.01, 20), np.array([1.0, 2.0, 3.0])

    def estimate(y):
        t = np.linspace(0.0, 1.0, 20)
        return np.linalg.lstsq(np.column_stack([np.ones(20), t, t**2]), y, rcond=None)[0]

    return simulate, estimate


def study(args, client, cores):
    from robocal.estimation import monte_carlo
    from robocal.rigs.humanoid.model import default_model
    from robocal.rigs.humanoid.montecarlo import calibration_monte_carlo

    model = default_model()
    print(f"\n== study: {args.trials} humanoid calibration trials (5 poses a foot) ==")
    t0 = time.perf_counter()
    serial = calibration_monte_carlo(model, args.trials, np.random.default_rng(args.seed), n_per_foot=5)
    ts = time.perf_counter() - t0
    t0 = time.perf_counter()
    par = calibration_monte_carlo(model, args.trials, np.random.default_rng(args.seed), n_per_foot=5, executor=client)
    tp = time.perf_counter() - t0
    same = np.array_equal(serial.errors, par.errors) and np.array_equal(serial.predicted_std, par.predicted_std)
    trial = ts / args.trials
    print(f"serial {ts:8.1f} s ({1e3 * trial:.1f} ms a trial); {cores} workers {tp:8.1f} s; speed-up {ts / tp:.2f}x, "
          f"{ts / tp / cores:.2f} per core; bit-identical: {same}")

    # per-task overhead: one trial a task vs the same trials serially
    sim, est = _noop_trials(0)
    n = 400
    t0 = time.perf_counter()
    monte_carlo(sim, est, n, np.random.default_rng(1))
    t_cheap = time.perf_counter() - t0
    t0 = time.perf_counter()
    monte_carlo(sim, est, n, np.random.default_rng(1), executor=client, batch_size=1)
    t_tasks = time.perf_counter() - t0
    # the cluster runs `cores` tasks at once: overhead per task of wall time x cores is the cost a task adds
    overhead = max(0.0, (t_tasks * cores - t_cheap) / n)
    b = int(np.ceil(overhead / (0.05 * trial))) if trial > 0 else 1
    print(f"per-task overhead {1e3 * overhead:.1f} ms (400 one-trial tasks: {t_tasks:.2f} s on {cores} workers vs "
          f"{t_cheap:.2f} s serial); overhead < 5 % from {b} trial(s) of {1e3 * trial:.1f} ms a task")
    return {"trials": args.trials, "serial_s": ts, "parallel_s": tp, "trial_ms": 1e3 * trial,
            "overhead_ms": 1e3 * overhead, "batch_for_5pct": b, "identical": same}


def _workers_cpu(client) -> float:
    """The cluster's worker processes' CPU seconds so far (user + system; children included)."""
    def cpu():
        t = os.times()
        return t.user + t.system + t.children_user + t.children_system

    return float(sum(client.run(cpu).values()))


def fleet(args, client, cores):
    from robocal.batch import load_manifest, run_batch, simulate_fleet
    from robocal.cli._rig import discover_rigs

    wf = {w.name: w for w in discover_rigs(["humanoid"])}["humanoid"]
    print(f"\n== fleet: {args.fleet} simulated humanoids ({args.views} views a foot, rendered) ==")
    with tempfile.TemporaryDirectory(prefix="robocal-bench-fleet-") as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        sim = simulate_fleet(wf, tmp / "sim", args.fleet, np.random.default_rng(args.seed), executor=client,
                             views=args.views, offset_scale=args.offset_scale)
        print(f"simulated on {cores} workers in {time.perf_counter() - t0:.1f} s; {sim.summary()}")
        entries = load_manifest(sim.manifest, rig="humanoid")
        reports = not args.no_reports
        t0, c0 = time.perf_counter(), time.process_time()
        a = run_batch(wf, entries, tmp / "serial", fleet=False, reports=reports)
        ts, cs = time.perf_counter() - t0, time.process_time() - c0
        w0 = _workers_cpu(client)
        t0 = time.perf_counter()
        b = run_batch(wf, entries, tmp / "cluster", executor=client, fleet=False, reports=reports)
        tp = time.perf_counter() - t0
        cw = _workers_cpu(client) - w0
        t0 = time.perf_counter()
        from robocal.batch import write_fleet

        write_fleet(tmp / "cluster", [e.id for e in entries], rig="humanoid")
        tf = time.perf_counter() - t0
        import json

        report = json.loads((tmp / "cluster" / "fleet.json").read_text())
        named = sorted({s["id"] for s in report["standouts"]} | {w["id"] for w in report["weak"]})
    print(f"calibrated: serial {ts:.1f} s ({ts / args.fleet:.2f} s a robot), {cores} workers {tp:.1f} s; speed-up "
          f"{ts / tp:.2f}x, {ts / tp / cores:.2f} per core; failed {len(a.failed)} / {len(b.failed)}; "
          f"fleet report {tf:.1f} s; named {named or 'none'}, planted {sorted(sim.planted) or 'none'}")
    # CPU beside wall: a worker busy less than its wall time waited (disk, the scheduler, the neighbours)
    print(f"CPU: serial {cs:.1f} s ({100 * cs / ts:.0f} % of its wall time); workers {cw:.1f} s "
          f"({100 * cw / (cores * tp):.0f} % of {cores} x wall); per-robot reports {'on' if reports else 'off'}")
    return {"robots": args.fleet, "serial_s": ts, "parallel_s": tp, "serial_cpu_s": cs, "workers_cpu_s": cw,
            "reports": reports, "fleet_report_s": tf,
            "named_is_planted": named == sorted(sim.planted)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=10_000)
    ap.add_argument("--fleet", type=int, default=200)
    ap.add_argument("--views", type=int, default=4)
    ap.add_argument("--offset-scale", type=float, default=0.5, help="the fleet's scatter of offsets [deg]")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--no-reports", action="store_true", help="the fleet's run_batch without per-robot report.html")
    args = ap.parse_args()
    from robocal.batch import available_cores, open_executor

    cores = args.workers or available_cores()
    print(f"{cores} worker process(es); {_load()}")
    with open_executor(cores, echo=print) as client:
        if client is None:
            raise SystemExit("needs >= 2 workers (--workers 2)")
        s = study(args, client, cores) if args.trials else None
        f = fleet(args, client, cores) if args.fleet else None
    print(f"\n{_load()} (on a shared machine, wall-time figures measure the neighbours too)")
    print({"study": s, "fleet": f})


if __name__ == "__main__":
    main()
