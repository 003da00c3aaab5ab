"""Small helpers shared by the rigs' command-line wiring.

CLI code stays thin: parse arguments, call a library function that returns a
result object, write files with these helpers, print a short summary.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from robocal.io import prepare_out_dir, write_run  # noqa: F401 - re-exported: the CLI's helpers, library-level
from robocal.workflow import seed_value

__all__ = [
    "add_out_argument",
    "add_seed_argument",
    "prepare_out_dir",
    "write_run",
    "examples_epilog",
    "RawHelp",
    "OneLineErrorParser",
    "LazySubParsers",
    "add_command",
]


class OneLineErrorParser(argparse.ArgumentParser):
    """Argument parser whose usage errors are one stderr line and exit status 2.

    argparse's default prints the whole usage block first; the CLI contract
    (one line naming the problem, status 2) holds for usage mistakes too.
    Sub-parsers inherit the class, so every rig's commands behave the same.
    """

    def error(self, message: str):  # noqa: D102 - argparse hook
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


class RawHelp(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Keeps example blocks as written and shows defaults that say something.

    No "(default: None)" or "(default: False)" for options and flags whose
    absence is their meaning, and none appended to a help text that already
    states its default.
    """

    def _get_help_string(self, action):  # noqa: D102 - argparse hook
        text = action.help or ""
        if action.default is None or action.default is False or action.default == argparse.SUPPRESS \
                or "default" in text:
            return text
        return super()._get_help_string(action)


class _Pending:
    """A sub-command's parser not made yet: the keyword arguments of its ``add_parser`` and its builder."""

    __slots__ = ("make", "kwargs", "build")

    def __init__(self, make, kwargs, build):
        self.make, self.kwargs, self.build = make, kwargs, build


class _Parsers(dict):
    """name -> parser of a :class:`LazySubParsers`; a pending parser is made and built when looked up.

    Every way argparse and a caller read a parser (``[name]``, ``get``, ``values``, ``items``) gives the
    built one; the keys (the choices, ``in``) need no parser at all.
    """

    def _ready(self, name):
        p = dict.__getitem__(self, name)
        if isinstance(p, _Pending):
            pending, p = p, p.make(**p.kwargs)
            for k, v in dict.items(self):  # the name and its aliases share one parser
                if v is pending:
                    dict.__setitem__(self, k, p)
            pending.build(p)
        return p

    def __getitem__(self, name):
        return self._ready(name)

    def get(self, name, default=None):
        return self._ready(name) if name in self else default

    def values(self):
        return [self._ready(k) for k in self]

    def items(self):
        return [(k, self._ready(k)) for k in self]


class LazySubParsers(argparse._SubParsersAction):
    """Sub-commands whose parsers are made when argparse (or ``--help``) first looks one up.

    ``add_parser(name, build=fn, **kwargs)`` records the name and its help line at once (the parent's
    ``--help`` lists it as before) and calls ``fn(parser)`` to add the arguments only when that command is
    parsed: ``robocal flow odometry`` builds one of the flow rig's 13 parsers and none of the core's other
    commands (~10 ms of a command's start-up with argparse's per-argument formatter and gettext calls,
    issue 16). Without ``build`` it is argparse's ``add_parser``. Use as
    ``parser.add_subparsers(..., action=LazySubParsers)``.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._name_parser_map = self.choices = _Parsers()

    def add_parser(self, name, *, build=None, **kwargs):  # noqa: D102 - argparse hook
        if build is None:
            return super().add_parser(name, **kwargs)
        make = self._parser_class
        self._parser_class = lambda **kw: _Pending(make, kw, build)
        try:
            super().add_parser(name, **kwargs)  # argparse's checks, prog and help line; the parser is pending
        finally:
            self._parser_class = make
        return None


def add_command(sub, name: str, build, **kwargs) -> None:
    """``sub.add_parser(name, **kwargs)`` with its arguments added by ``build(parser)``: when the command is
    first looked up under a :class:`LazySubParsers`, at once under argparse's own sub-parsers action."""
    if isinstance(sub, LazySubParsers):
        sub.add_parser(name, build=build, **kwargs)
    else:
        build(sub.add_parser(name, **kwargs))


def examples_epilog(*lines: str) -> str:
    """An ``Examples:`` block for a parser's epilog."""
    return "examples:\n" + "\n".join(f"  {ln}" for ln in lines)


FORCE_HELP = ("replace the files of another command's run in the --out folder (files robocal did not write "
              "and this command's inputs are never removed)")


def add_out_argument(parser: argparse.ArgumentParser, *, help: str | None = None) -> None:
    """``--out DIR`` and ``--force`` (see ``docs/results.md``, "Output folders")."""
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help=help or "output directory (default: a fresh robocal-out-<command>-<time> folder)",
    )
    parser.add_argument("--force", action="store_true", help=FORCE_HELP)


def add_seed_argument(parser: argparse.ArgumentParser, default: int = 0) -> None:
    parser.add_argument("--seed", type=seed_value, default=default, help="seed of the random generator (>= 0)")

