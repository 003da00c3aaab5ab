"""Finding the rigs: the ``robocal.rigs`` entry-point group.

A rig package exposes ``RIG = Workflow(...)`` (:mod:`robocal.workflow`, the
contract) in its ``cli`` module and lists it in ``pyproject.toml`` under
``[project.entry-points."robocal.rigs"]``; the core discovers rigs through
that group and never imports one by name.

Command convention, the same for every rig::

    robocal <rig> simulate ... --out DIR      # writes simulated input files
    robocal <rig> calibrate INPUT --out DIR   # writes DIR/result.json + DIR/report.html
"""

from __future__ import annotations

import sys
from collections.abc import Iterable

from robocal._metadata import entry_points  # importlib.metadata's answer, cached: ~70 ms less start-up
from robocal.workflow import DemoContext, DemoOutcome, Workflow, resolve

__all__ = ["Workflow", "DemoContext", "DemoOutcome", "discover_rigs", "registered_rig_names", "demo_of"]


def demo_of(rig: Workflow):
    """The rig's demo callable (imported now for a workflow's ``"module:attr"``), or None."""
    return resolve(rig.demo)


def registered_rig_names() -> list[str]:
    """Names in the ``robocal.rigs`` entry-point group, sorted; imports no rig."""
    return sorted({ep.name for ep in entry_points(group="robocal.rigs")})


def discover_rigs(names: Iterable[str] | None = None) -> list[Workflow]:
    """Load the rigs registered in the ``robocal.rigs`` entry-point group.

    Parameters
    ----------
    names : iterable of str, optional
        Load only these rigs (unknown names are ignored). ``robocal <rig> ...``
        loads just the invoked rig: importing all five costs ~0.9 s, mostly
        the flow rig's numba kernel, which a projector command never uses.

    A registered rig whose package is absent from this build (the module is
    not found) is skipped silently. A rig that fails to import for any other
    reason is skipped with one warning line on stderr naming it and the
    error: one broken plugin must not take every other command down with it
    (the test suite asserts that all five rigs load, so a bug still fails CI).
    """
    wanted = None if names is None else set(names)
    rigs = []
    for ep in sorted(entry_points(group="robocal.rigs"), key=lambda e: e.name):
        if wanted is not None and ep.name not in wanted:
            continue
        module = ep.value.split(":")[0]
        try:
            rig = ep.load()
        except ModuleNotFoundError as exc:
            if exc.name and module.startswith(exc.name):
                continue
            _warn_broken(ep, exc)
            continue
        except Exception as exc:  # noqa: BLE001 - any plugin failure is reported, not fatal
            _warn_broken(ep, exc)
            continue
        if not isinstance(rig, Workflow):
            raise TypeError(f"entry point {ep.name} -> {ep.value} is not a robocal.workflow.Workflow")
        rigs.append(rig)
    return rigs


def _warn_broken(ep, exc: Exception) -> None:
    msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    print(f"robocal: warning: rig '{ep.name}' could not be loaded ({type(exc).__name__}: {msg}); "
          "its commands are unavailable", file=sys.stderr)
