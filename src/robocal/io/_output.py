"""A command's output folder and files: claim ``--out``, write ``result.json`` + ``report.html``.

Library-level (no argparse), so that a rig's command functions (``Command.run``)
use them without importing the CLI; :mod:`robocal.cli._common` re-exports them.
"""

from __future__ import annotations

import datetime as _dt
import sys
from pathlib import Path

from robocal.io._result import CalibrationResult, write_result
from robocal.io._runs import claim_folder

__all__ = ["prepare_out_dir", "write_run"]


def prepare_out_dir(out: Path | None, label: str, *, force: bool | None = None) -> Path:
    """Create ``out`` (or a fresh time-stamped folder named after ``label``) as this run's output folder.

    ``label`` names the command (``"flow-simulate"``). Inside a command run
    (:class:`robocal.io.CommandRun`, which ``robocal``'s ``main`` opens) the
    folder is checked and marked: an earlier run of the same command is
    removed first, another command's run or unknown files are refused unless
    ``force`` (default: the run's ``--force``), and ``INCOMPLETE`` stays until
    the command finishes (see ``docs/results.md``, "Output folders"). From
    the Python API without a run it only makes the folder.
    """
    if out is None:
        stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
        out = Path(f"robocal-out-{label}-{stamp}")
        n = 1
        while out.exists():
            n += 1
            out = Path(f"robocal-out-{label}-{stamp}-{n}")
    return claim_folder(Path(out), label, force=force)


def write_run(out_dir: Path, result: CalibrationResult | None, report=None, *, quiet: bool = False):
    """Write ``out_dir/result.json`` and ``out_dir/report.html`` (a :class:`robocal.report.Report`), atomically."""
    paths = []
    if result is not None:
        paths.append(write_result(Path(out_dir) / "result.json", result))
    if report is not None:
        paths.append(report.write(Path(out_dir) / "report.html"))
    if not quiet:
        for p in paths:
            print(f"wrote {p}")
        if result is not None:
            for w in result.warnings:
                print(f"warning: {w}", file=sys.stderr)
    return paths
