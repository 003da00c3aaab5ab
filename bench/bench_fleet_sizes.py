"""How often a simulated fleet's report names exactly its planted robots, by rig and fleet size.

    python bench/bench_fleet_sizes.py RIG N FIRST_SEED SEEDS [option=value ...]
    python bench/bench_fleet_sizes.py handeye 8 100 20
    python bench/bench_fleet_sizes.py mirror 10 0 10 placements=4 sigma_px=0.1
    python bench/bench_fleet_sizes.py camera 10 0 10 views=6 width=480 height=360

For each seed ``FIRST_SEED, FIRST_SEED + 1, ...``: ``robocal RIG simulate
--fleet N --seed SEED`` with the ``simulate`` options given (their Python
names, ``sigma_px=0.1`` for ``--sigma 0.1``) through
:func:`robocal.batch.simulate_fleet`, then ``robocal batch`` serially without
per-robot reports (:func:`robocal.batch.run_batch`), in a temporary folder.
A fleet is **named** when the report's mechanical standouts are exactly the
planted faults, its weak recordings exactly the planted weak one, and no
one else stands out (a weak recording may, as noise). One line a fleet:
the planted robots, what the report named, the largest ``t`` of each
robot named, the bar (``thresholds.standout_t``) and the wall times; then
the count. The docs' table of the smallest fleets (docs/batch.md,
"Simulated fleets") comes from these runs.
"""

from __future__ import annotations

import ast
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def fleet_named(rig: str, n: int, seed: int, options: dict) -> tuple[bool, str]:
    """Simulate and calibrate one fleet; ``(named exactly, one line)``."""
    from robocal.batch import load_manifest, run_batch, simulate_fleet
    from robocal.cli._rig import discover_rigs

    (wf,) = discover_rigs([rig])
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        (d / "sim").mkdir()
        (d / "cal").mkdir()
        fleet = simulate_fleet(wf, d / "sim", n, np.random.default_rng(seed), **options)
        t1 = time.perf_counter()
        outcome = run_batch(wf, load_manifest(fleet.manifest, rig=rig), d / "cal", reports=False)
        report = json.loads((d / "cal" / "fleet.json").read_text())
    t2 = time.perf_counter()
    faults, weak = set(fleet.of_kind("fault")), set(fleet.of_kind("weak"))
    mechanical = {s["id"] for s in report["standouts"] if s["cause"] == "mechanical"}
    named = {s["id"] for s in report["standouts"]}
    weak_named = {w["id"]: round(w["std_ratio"], 1) for w in report["weak"]}
    ok = (mechanical == faults and set(weak_named) == weak and named <= faults | weak and not outcome.failed)
    top = {}
    for s in report["standouts"]:
        top[s["id"]] = max(top.get(s["id"], 0.0), round(s["t"], 1))
    bar = report["thresholds"]["standout_t"]
    line = (f"seed {seed}: {'named' if ok else 'MISSED'}; planted faults {sorted(faults)} weak {sorted(weak)}; "
            f"report: standouts {top} (bar {bar:.1f}) weak {weak_named}; "
            f"simulate {t1 - t0:.1f} s, calibrate {t2 - t1:.1f} s"
            + (f"; failed {[r['error'] for r in outcome.failed]}" if outcome.failed else ""))
    return ok, line


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) < 4:
        print(__doc__)
        return 2
    rig, n, first, count = argv[0], int(argv[1]), int(argv[2]), int(argv[3])
    options = {}
    for kv in argv[4:]:
        key, _, value = kv.partition("=")
        options[key] = ast.literal_eval(value)
    named = 0
    for seed in range(first, first + count):
        ok, line = fleet_named(rig, n, seed, options)
        named += ok
        print(line, flush=True)
    print(f"{rig}, {n} robots, {options}: {named} of {count} fleets named exactly")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
