"""The ``robocal`` program (its launcher and ``python -m robocal``): :func:`robocal.cli.main.main` with the
garbage collector kept off the objects that live until the process ends (issue 16, a command's fixed cost).

Importing the CLI (NumPy, PyYAML, the core) builds ~100k objects that stay alive
until exit; the collector would walk them some sixty times meanwhile, and
Python's shutdown once more in a full collection (measured on ``robocal flow
odometry``: ~20 ms of start-up, ~25 ms of shutdown after a 30 s log). So the
collector is paused while the CLI is imported, and what exists then is frozen
(:func:`gc.freeze`: left out of every later collection); the same again when the
command has returned, before the interpreter exits. The command itself runs
with the collector on, as any program. Frozen objects are still freed at exit
by the modules' teardown; only unreachable reference cycles among them are not
finalized, which nothing of robocal's relies on (the command's files are
written and closed before it returns; atexit handlers run as usual).

Not in :mod:`robocal.cli.main` because this module must run before that one is
imported; ``robocal/__init__.py`` imports nothing heavy, so importing this
module costs nothing before the pause.
"""

from __future__ import annotations

import gc
import sys

__all__ = ["run"]


def run() -> None:
    """Run the CLI on ``sys.argv`` and exit with its status."""
    gc.disable()
    try:
        from robocal.cli.main import main
    finally:
        gc.freeze()
        gc.enable()
    code = main()
    gc.freeze()
    sys.exit(code)
