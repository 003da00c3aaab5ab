"""``robocal batch RIG MANIFEST --out DIR``: the arguments; the work is :mod:`robocal.batch`."""

from __future__ import annotations

import sys
from pathlib import Path

from robocal.cli._common import RawHelp, add_command, add_out_argument, examples_epilog
from robocal.workflow import ACCEPT_IMPLAUSIBLE_HELP, number_at_least

__all__ = ["add_batch_command", "run_batch_command"]


def add_batch_command(sub, rig_names) -> None:
    """Add ``robocal batch``; ``rig_names()`` lists the installed rigs (for the help text only)."""
    def build(p):
        p.add_argument("rig", metavar="RIG", help=f"the rig that calibrates each data set ({', '.join(rig_names())})")
        p.add_argument("manifest", type=Path, metavar="MANIFEST", help="the data sets: .yaml/.yml/.json or .csv")
        p.add_argument("--workers", type=number_at_least(int, 1), default=None, metavar="N",
                       help="worker processes of the embedded Dask cluster (default: one per core); "
                            "1 runs serially without starting Dask")
        p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="use a running Dask cluster (tcp://host:8786) instead of an embedded one; its workers "
                            "must see the inputs and DIR at the same paths")
        p.add_argument("--resume", action="store_true",
                       help="keep DIR's earlier batch and skip the data sets it already finished")
        p.add_argument("--no-fleet", action="store_true", help="skip fleet.html / fleet.json")
        p.add_argument("--no-reports", action="store_true",
                       help="skip each data set's report.html (its figures are most of a quick calibration's time; "
                            "'robocal report DIR/<id>/result.json' builds one later)")
        p.add_argument("--accept-implausible", action="store_true", help=ACCEPT_IMPLAUSIBLE_HELP)
        add_out_argument(p)
        p.set_defaults(func=run_batch_command)

    add_command(
        sub, "batch", build, formatter_class=RawHelp,
        help="calibrate a fleet: every data set of a manifest as its own task, plus a fleet report",
        description="Calibrates each data set of MANIFEST (YAML or CSV: an id and the calibrate inputs per data\n"
                    "set; docs/batch.md) with RIG's calibrate step, as its own task on a Dask cluster: DIR/<id>/\n"
                    "result.json + report.html, each written whole or not at all. A data set that fails is one\n"
                    "row with its one-line error (DIR/batch.csv, batch.json); the batch goes on. Then\n"
                    "DIR/fleet.html + fleet.json: each parameter across the fleet, the robots that stand out.\n"
                    "Exit status 0 when every data set was calibrated, 1 when some failed.",
        epilog=examples_epilog("robocal batch humanoid fleet.yaml --out fleet-cal",
                               "robocal batch humanoid fleet.csv --out fleet-cal --resume     # after a kill",
                               "robocal batch mirror fleet.yaml --out cal --scheduler tcp://10.0.0.5:8786",
                               "robocal batch projector fleet.yaml --out cal --workers 1      # serial, no Dask"))


def run_batch_command(args) -> int:
    from robocal.batch import load_manifest, open_executor, run_batch
    from robocal.batch._run import claim_batch_folder
    from robocal.cli._rig import discover_rigs, registered_rig_names
    from robocal.errors import InputError

    rigs = {w.name: w for w in discover_rigs([args.rig])}
    wf = rigs.get(args.rig)
    if wf is None or wf.calibrate is None:
        have = ", ".join(registered_rig_names())
        raise InputError(f"RIG: {args.rig!r} is not an installed rig with a calibrate command (have: {have})")
    entries = load_manifest(args.manifest, rig=wf.name)
    out = claim_batch_folder(args.out, resume=args.resume)
    with open_executor(args.workers, args.scheduler) as ex:
        outcome = run_batch(wf, entries, out, executor=ex, resume=args.resume, progress=True,
                            accept_implausible=args.accept_implausible, fleet=not args.no_fleet,
                            reports=not args.no_reports,
                            echo=lambda line: print(f"robocal: {line}", file=sys.stderr))
    for path in outcome.files:
        print(f"wrote {path}")
    print(outcome.summary())
    return 1 if outcome.failed else 0
