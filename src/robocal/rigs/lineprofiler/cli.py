"""Command line of the ``lineprofiler`` rig and of ``robocal handeye``."""

from __future__ import annotations

from robocal.cli import Rig


def _add_lineprofiler(parser) -> None:
    parser.add_subparsers(dest="subcommand", metavar="COMMAND")


def _add_handeye(parser) -> None:
    parser.add_subparsers(dest="subcommand", metavar="COMMAND")


RIG = Rig(name="lineprofiler", help="hand-eye calibration of an arm-mounted line laser (seed 004)",
          description="Line-laser profiler hand-eye calibration (FPDP, MCT, geometric refinement).",
          add_commands=_add_lineprofiler)
HANDEYE = Rig(name="handeye", help="AX = XB / AX = ZB hand-eye solvers (Tsai, Park, Horaud, Andreff, Daniilidis, Shah)",
              description="Classic hand-eye calibration from pose lists.", add_commands=_add_handeye)
