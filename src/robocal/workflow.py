"""The rig contract: every rig is a :class:`Workflow` the core drives.

A rig declares, in its ``cli`` module, what it can do as library functions
(none of them parses arguments or writes the result file)::

    WORKFLOW = Workflow(
        name="mirror", help="...", description="...",
        simulate="robocal.rigs.mirror.workflow:simulate_files",
        load_input="robocal.rigs.mirror.workflow:load_input",
        calibrate="robocal.rigs.mirror.workflow:calibrate_input",
        to_result="robocal.rigs.mirror.workflow:to_result",
        build_report="robocal.rigs.mirror.report:build_report",
        demo="robocal.rigs.mirror.workflow:demo",
        simulate_options=(Option("--placements", type=int, default=1, help="..."), ...),
        calibrate_options=(Option("--no-refine", action="store_true", help="..."),),
        commands=(Command("plan", ...),),          # the rig's extra commands
    )

and lists it in ``pyproject.toml`` under the entry-point group
``robocal.rigs``. The core (:mod:`robocal.cli._workflow`) then builds
``robocal <rig> simulate``, ``robocal <rig> calibrate``, ``robocal <rig>
report`` and the rig-independent ``robocal report RESULT.json`` once for every
rig: the output folder, the error's source file, atomic writing, the summary
line and the exit status are the core's, the same for all rigs.

The steps, with the keywords the core passes (a rig's function may take
``**_`` for the ones it does not use):

``simulate(out_dir, rng, *, progress, **simulate_options) -> list[Path]``
    Write a simulated input (with its ground truth) into ``out_dir``; return
    the files written. ``rng`` is the run's ``np.random.Generator``.
``load_input(*paths, **input_options) -> input``
    Read and validate the input file(s) named on the command line (one
    ``INPUT`` unless ``input_arguments`` declares others).
``calibrate(input, *, out_dir, progress, accept_implausible, **calibrate_options) -> calibration``
    The estimate with its uncertainty and diagnostics.
``to_result(calibration, input) -> CalibrationResult``
    The result file's content (schema in ``docs/results.md``).
``build_report(result, *, base_dir) -> Report``
    The report, from the result alone (``base_dir``: the result's folder, for
    files it names), so that ``robocal report`` rebuilds the same page.
``write_outputs(result, out_dir) -> list[Path]``, optional
    Files of the rig's own beside ``result.json`` (the camera rig's camera in
    OpenCV, ROS and JSON form), written from the result alone, atomically.
``summary(result) -> str``, optional
    The lines printed after ``calibrate`` (default: the residual RMS).
``demo(ctx: DemoContext) -> DemoOutcome``
    ``robocal demo``'s part for this rig.
``fleet(out_dir, rng, *, kind, progress, **simulate_options) -> dict``, optional
    One robot of a simulated fleet (``robocal <rig> simulate --fleet N``,
    :func:`robocal.batch.simulate_fleet`): ``simulate``'s files with the true
    parameters scattered as across real robots of the rig; ``kind`` None (a
    healthy robot), ``"fault"`` (one parameter well outside the fleet's
    spread) or ``"weak"`` (a weak recording: fewer views, more noise).
    Returns what was planted (``{}`` for a healthy robot; else ``parameter``,
    as the result names it, and ``text``).

A step is a callable or a ``"module:attribute"`` string resolved on first use,
so that declaring a workflow imports none of the rig's numerical code (``robocal
<rig> --help`` stays at ~0.2 s).
"""

from __future__ import annotations

import argparse
import importlib
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Workflow", "Option", "Command", "DemoContext", "DemoOutcome", "STEPS", "resolve", "seed_value",
           "ACCEPT_IMPLAUSIBLE_HELP", "accept_implausible_option", "number_at_least"]

#: The steps a workflow may declare, in the order the core runs them.
STEPS = ("simulate", "load_input", "calibrate", "to_result", "build_report", "write_outputs", "summary", "demo",
         "fleet")


def resolve(step: Callable | str | None) -> Callable | None:
    """The callable a step names: itself, or ``module:attr`` imported now."""
    if step is None or callable(step):
        return step
    module, _, attr = str(step).partition(":")
    if not attr:
        raise ValueError(f"a workflow step must be a callable or 'module:attribute', got {step!r}")
    obj = importlib.import_module(module)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


def seed_value(text: str) -> int:
    """argparse ``type=`` of a ``--seed``: a whole number >= 0 (NumPy's ``SeedSequence`` takes no negative entropy)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {value}")
    return value


def number_at_least(kind: type, minimum: float, *, strict: bool = False, why: str = "", unit: str = ""):
    """argparse ``type=``: a finite ``kind`` (``int`` or ``float``) ``>= minimum`` (``> minimum`` when ``strict``).

    A bad value is argparse's one-line usage error naming the option, the
    bound and, when given, ``why`` it holds: ``--runs: must be >= 2 (the spread
    of repeated calibrations needs 2 or more), got 1``.
    """
    what = "a whole number" if kind is int else "a number"

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}{' of ' + unit if unit else ''}, got {text!r}") from None
        if not math.isfinite(value) or value < minimum or (strict and value == minimum):
            because = f" ({why})" if why else ""
            raise argparse.ArgumentTypeError(f"must be {'>' if strict else '>='} {minimum:g}{(' ' + unit) if unit else ''}"
                                             f"{because}, got {text}")
        return value

    parse.__name__ = kind.__name__  # argparse names the type in "invalid int value" fallbacks
    return parse


class Option:
    """A command-line option or positional argument, declared: ``argparse.add_argument``'s arguments.

    ``Option("--placements", type=int, default=1, help="...")`` reaches the
    step as the keyword ``placements``. ``to`` names the step that receives
    it: ``"calibrate"`` (default for calibrate options), ``"load_input"``, or
    ``None`` for an option only the command itself reads (e.g. ``--seed``).
    """

    def __init__(self, *flags: str, to: str | None = "", **kwargs):
        if not flags:
            raise ValueError("an Option needs at least one flag or a positional name")
        self.flags = tuple(flags)
        self.to = to
        self.kwargs = dict(kwargs)

    @property
    def dest(self) -> str:
        if "dest" in self.kwargs:
            return self.kwargs["dest"]
        longs = [f for f in self.flags if f.startswith("--")]
        name = (longs or self.flags)[0].lstrip("-")
        return name.replace("-", "_")

    def add_to(self, parser) -> None:
        parser.add_argument(*self.flags, **self.kwargs)

    def __repr__(self) -> str:
        return f"Option({', '.join(map(repr, self.flags))}, to={self.to!r})"


#: The help of ``--accept-implausible``, the same on every command that has it (see :mod:`robocal.plausibility`).
ACCEPT_IMPLAUSIBLE_HELP = ("when the answer is physically implausible (a likely unit slip, a transposed board, an "
                           "inverted pose list, ...), write it with an implausible_input warning instead of stopping "
                           "with exit status 2")


def accept_implausible_option() -> Option:
    """``--accept-implausible`` for a rig's own command (``calibrate`` gets it from the core)."""
    return Option("--accept-implausible", action="store_true", to=None, help=ACCEPT_IMPLAUSIBLE_HELP)


@dataclass(frozen=True)
class Command:
    """An extra command of a rig (besides ``simulate``, ``calibrate``, ``report``).

    Attributes
    ----------
    name, help, description : str
        ``robocal <rig> <name>``, its line in the rig's help, its own help text.
    run : callable or "module:attr"
        ``run(args) -> int``: the command's work (a library-level function in
        the rig, taking the parsed arguments; it claims ``args.out`` with
        :func:`robocal.io.prepare_out_dir` and writes with
        :func:`robocal.io.write_run` when it has ``out``).
    options : tuple of Option
        Its arguments.
    examples : tuple of str
        Example command lines for ``--help``.
    out : bool
        Whether it writes files (adds ``--out DIR`` and ``--force``).
    """

    name: str
    help: str
    run: Callable | str
    options: tuple = ()
    description: str = ""
    examples: tuple = ()
    out: bool = True


@dataclass
class DemoContext:
    """What ``robocal demo`` hands a rig.

    Attributes
    ----------
    out_dir : Path
        Folder the rig may write its own files into (``<demo out>/<rig>``).
    rng : numpy.random.Generator
        The only source of randomness the demo may use.
    progress : bool
        Whether progress bars may be shown.
    """

    out_dir: Path
    rng: np.random.Generator
    progress: bool = True


@dataclass
class DemoOutcome:
    """What a rig's demo returns.

    Attributes
    ----------
    summary : dict
        A few headline figures for the demo's summary table, already formatted
        with units (``{"rotation error": "0.011 deg"}``).
    passed : bool
        Whether the rig's own acceptance check held (e.g. estimate within
        3 sigma of the simulated truth).
    sections : list of Section
        Report sections (plots, tables) for the demo's HTML report.
    result : CalibrationResult, optional
        The rig's main result, also written to ``<out_dir>/result.json``.
    """

    summary: dict[str, str]
    passed: bool
    sections: list = field(default_factory=list)
    result: Any = None


@dataclass(frozen=True)
class Workflow:
    """A rig, declared: its steps (see the module docstring) and its command-line options.

    Attributes
    ----------
    name : str
        ``robocal <name> ...``; also the ``rig`` field of its result files.
    help, description : str
        One line for ``robocal --help``; the text of ``robocal <name> --help``.
    simulate, load_input, calibrate, to_result, build_report, write_outputs, summary, demo, fleet
        The steps (callables or ``"module:attr"``); ``None`` where the rig has
        no such step (its command is then not built).
    simulate_options, calibrate_options : tuple of Option
        The options of the two core-built commands.
    input_arguments : tuple of Option
        The positional inputs of ``calibrate`` (default: one ``input`` file),
        handed to ``load_input`` in order (an argument with ``nargs`` hands
        each of its values).
    simulate_help, calibrate_help, calibrate_description, simulate_description : str
        Help texts of the core-built commands.
    simulate_examples, calibrate_examples : tuple of str
        Their example command lines.
    commands : tuple of Command
        The rig's extra commands.
    simulated_inputs : tuple of str
        The files (relative to the ``simulate`` folder) that ``calibrate``
        takes, in the order of ``input_arguments``: what makes simulate ->
        calibrate a round trip (``tests/test_rig_contract.py`` runs it).
    quick_simulate : tuple of str
        ``simulate`` options for a small, fast simulated run (a few seconds
        end to end), used by the contract test and CI.
    """

    name: str
    help: str
    description: str = ""
    simulate: Callable | str | None = None
    load_input: Callable | str | None = None
    calibrate: Callable | str | None = None
    to_result: Callable | str | None = None
    build_report: Callable | str | None = None
    write_outputs: Callable | str | None = None
    summary: Callable | str | None = None
    demo: Callable | str | None = None
    fleet: Callable | str | None = None
    simulate_options: tuple = ()
    calibrate_options: tuple = ()
    input_arguments: tuple = ()
    simulate_help: str = "write a simulated input (with its ground truth)"
    simulate_description: str = ""
    simulate_examples: tuple = ()
    calibrate_help: str = "calibrate from an input file: result.json + report.html"
    calibrate_description: str = ""
    calibrate_examples: tuple = ()
    commands: tuple = ()
    simulated_inputs: tuple = ()
    quick_simulate: tuple = ()

    def __post_init__(self):
        if (self.calibrate is None) != (self.load_input is None) or (self.calibrate is None) != (self.to_result is None):
            raise ValueError(f"workflow {self.name!r}: calibrate, load_input and to_result come together")
        if self.fleet is not None and (self.calibrate is None or not self.simulated_inputs):
            raise ValueError(f"workflow {self.name!r}: a fleet step needs calibrate and simulated_inputs (its manifest)")
        names = [c.name for c in self.commands]
        taken = {"simulate": self.simulate, "calibrate": self.calibrate, "report": self.build_report}
        clash = [n for n in names if taken.get(n) is not None or names.count(n) > 1]
        if clash:
            raise ValueError(f"workflow {self.name!r}: command {clash[0]!r} is declared twice")

    def step(self, name: str) -> Callable | None:
        """The callable of step ``name`` (imported on first use), or None."""
        if name not in STEPS:
            raise ValueError(f"unknown step {name!r}; steps: {', '.join(STEPS)}")
        return resolve(getattr(self, name))

    @property
    def inputs(self) -> tuple:
        return self.input_arguments or (Option("input", type=Path, help="calibration input file (YAML/JSON)"),)
