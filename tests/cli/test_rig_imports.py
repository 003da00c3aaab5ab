"""Every rig's command line stays fast: help and usage errors import no heavy library.

``robocal --help`` imports every rig's ``cli`` module and hence its package.
The rig packages export their names lazily (:func:`robocal._lazy.lazy_exports`)
and the cli modules import the rig's library inside the command functions, so
help texts take ~0.2 s instead of ~0.9 s. These tests run in fresh interpreters
(``sys.modules`` of this process is full) and check that the lazy exports are
the very objects their submodules define, whatever is imported first.
"""

import importlib
import json
import pkgutil
import subprocess
import sys

import pytest

RIGS = ("projector", "humanoid", "mirror", "flow", "lineprofiler")
#: numba ~0.3 s, scipy.spatial ~0.4 s (via robocal.geometry), OpenCV, matplotlib, scikit-image
HEAVY = ("numba", "matplotlib", "cv2", "scipy.optimize", "scipy.spatial", "skimage")


def _run(code: str):
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _main(argv) -> tuple[int, list[str]]:
    code = f"""
import contextlib, io, json, sys
from robocal.cli.main import main
with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
    try:
        rc = main({list(argv)!r})
    except SystemExit as exc:
        rc = exc.code
print(json.dumps([rc, [m for m in {HEAVY!r} if m in sys.modules]]))
"""
    return tuple(_run(code))


def test_top_level_help_imports_no_heavy_module():
    assert _main(["--help"]) == (0, [])


@pytest.mark.parametrize("rig", RIGS)
def test_rig_help_and_usage_errors_import_no_heavy_module(rig):
    assert _main([rig, "--help"]) == (0, [])
    assert _main([rig, "calibrate", "--help"]) == (0, [])
    assert _main([rig, "calibrate"]) == (2, [])  # the input file is missing: argparse's error


@pytest.mark.parametrize("rig", RIGS)
def test_every_subcommand_help_builds_without_the_rig_library(rig):
    pkg = f"robocal.rigs.{rig}"
    code = f"""
import argparse, json, sys
import {pkg}.cli as cli
p = argparse.ArgumentParser(prog="robocal {rig}")
if hasattr(cli.RIG, "add_commands"):
    cli.RIG.add_commands(p)
else:  # a declared Workflow: the core builds its commands
    from robocal.cli._workflow import add_workflow_commands
    add_workflow_commands(p, cli.RIG)
p.format_help()
for a in p._actions:
    if isinstance(getattr(a, "choices", None), dict):
        for sp in a.choices.values():
            sp.format_help()
print(json.dumps([[m for m in {HEAVY!r} if m in sys.modules],
                  sorted(m for m in sys.modules if m.startswith("{pkg}."))]))
"""
    heavy, rig_modules = _run(code)
    assert heavy == []
    assert rig_modules == [f"{pkg}.cli"]


def _exports(rig):
    pkg = importlib.import_module(f"robocal.rigs.{rig}")
    return pkg, getattr(pkg, "_EXPORTS", {}), getattr(pkg, "_COLLISIONS", ())


@pytest.mark.parametrize("rig", RIGS)
def test_exports_are_all_and_collisions_are_declared(rig):
    pkg, exports, collisions = _exports(rig)
    assert sorted(pkg.__all__) == sorted(exports)
    submodules = {m.name for m in pkgutil.iter_modules(pkg.__path__)}
    assert set(exports.values()) <= submodules
    # an exported name that is also a submodule would become the module once that is imported
    assert set(collisions) == set(pkg.__all__) & submodules
    with pytest.raises(AttributeError, match="no_such_name"):
        pkg.no_such_name  # noqa: B018


@pytest.mark.parametrize("rig", [r for r in RIGS if _exports(r)[1]])
@pytest.mark.parametrize("order", ["submodules first", "names first"])
def test_exported_names_are_their_submodules_objects_in_either_order(rig, order):
    pkg = f"robocal.rigs.{rig}"
    code = f"""
import importlib, json, pkgutil, types
import {pkg} as pkg
exports = dict(pkg._EXPORTS)
subs = sorted(m.name for m in pkgutil.iter_modules(pkg.__path__) if m.name != "cli")
if {order == "submodules first"!r}:
    for s in subs:
        importlib.import_module("{pkg}." + s)
ns = {{}}
exec("from {pkg} import *", ns)
bad = [n for n, mod in exports.items()
       if isinstance(ns[n], types.ModuleType) or ns[n] is not getattr(importlib.import_module("{pkg}." + mod), n)]
# and after everything is imported, attribute access agrees with the star import
for s in subs:
    importlib.import_module("{pkg}." + s)
bad += [n for n in exports if getattr(pkg, n) is not ns[n]]
print(json.dumps(bad))
"""
    assert _run(code) == []
