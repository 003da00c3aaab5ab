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

