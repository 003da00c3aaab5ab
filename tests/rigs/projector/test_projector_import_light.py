"""``robocal projector --help`` stays fast: the cli module and the package import no heavy library.

The package exports its names lazily (PEP 562 ``__getattr__``); these tests check that every name in
``__all__`` is still the object its submodule defines, whatever is imported first.
"""

import importlib
import json
import pkgutil
import subprocess
import sys

import robocal.rigs.projector as pkg

PKG = "robocal.rigs.projector"
#: modules a parser build must not import (scipy.spatial: ~0.4 s through robocal.geometry)
HEAVY = ("numba", "matplotlib", "cv2", "scipy.optimize", "scipy.spatial")


def _run(code: str):
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_cli_import_and_help_import_no_heavy_module():
    code = f"""
import argparse, json, sys
import {PKG}.cli as cli
after_import = [m for m in {HEAVY!r} if m in sys.modules]
p = argparse.ArgumentParser(prog="robocal projector")
cli.RIG.add_commands(p)
p.format_help()
for a in p._actions:
    for sp in getattr(a, "choices", None) or {{}}:
        if isinstance(a.choices, dict):
            a.choices[sp].format_help()
after_help = [m for m in {HEAVY!r} if m in sys.modules]
rig_modules = sorted(m for m in sys.modules if m.startswith("{PKG}."))
print(json.dumps([after_import, after_help, rig_modules]))
"""
    after_import, after_help, rig_modules = _run(code)
    assert after_import == []
    assert after_help == []
    assert rig_modules == [f"{PKG}.cli"]


def test_main_help_and_usage_error_import_no_heavy_module():
    for argv in (["projector", "--help"], ["projector", "path", "--help"], ["projector", "calibrate"],
                 ["projector", "simulate", "--points", "2", "--out", "/nonexistent/never-written"]):
        code = f"""
import contextlib, io, json, sys
from robocal.cli.main import main
with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
    try:
        rc = main({argv!r})
    except SystemExit as exc:
        rc = exc.code
print(json.dumps([rc, [m for m in {HEAVY!r} if m in sys.modules]]))
"""
        rc, heavy = _run(code)
        assert rc == (0 if "--help" in argv else 2), argv
        assert heavy == [], argv


def test_all_unchanged_and_names_come_from_their_submodule():
    model = importlib.import_module(f"{PKG}.model")
    assert pkg.__all__ == model.__all__
    for name in pkg.__all__:
        assert getattr(pkg, name) is getattr(model, name), name
    assert set(pkg.__all__) <= set(dir(pkg))
    ns = {}
    exec(f"from {PKG} import *", ns)
    assert all(ns[name] is getattr(model, name) for name in pkg.__all__)


def test_no_exported_name_is_a_submodule_name():
    """A submodule named like an exported name would replace it as a package attribute once imported."""
    submodules = {m.name for m in pkgutil.iter_modules(pkg.__path__)}
    assert "model" in submodules and "cli" in submodules
    assert not set(pkg.__all__) & submodules


def test_exported_names_with_every_submodule_imported_first():
    """Fresh interpreter: import every submodule, then ``from package import name`` for each name."""
    code = f"""
import importlib, json, pkgutil, types
import {PKG} as pkg
subs = sorted(m.name for m in pkgutil.iter_modules(pkg.__path__))
for s in subs:
    importlib.import_module("{PKG}." + s)
model = importlib.import_module("{PKG}.model")
bad = []
for name in pkg.__all__:
    ns = {{}}
    exec("from {PKG} import " + name, ns)
    if ns[name] is not getattr(model, name) or isinstance(ns[name], types.ModuleType):
        bad.append(name)
print(json.dumps([subs, bad]))
"""
    subs, bad = _run(code)
    assert "model" in subs and "path" in subs
    assert bad == []


def test_exported_names_before_any_submodule():
    """Fresh interpreter: the names first (lazy path), then the submodule; same objects."""
    code = f"""
import json, sys
from {PKG} import *
import {PKG} as pkg
got = {{n: globals()[n] for n in pkg.__all__}}
from {PKG} import model
print(json.dumps([n for n, v in got.items() if v is not getattr(model, n)]))
"""
    assert _run(code) == []


def test_submodules_are_attributes_and_unknown_names_raise():
    assert pkg.path is importlib.import_module(f"{PKG}.path")
    try:
        pkg.no_such_name
    except AttributeError as exc:
        assert "no_such_name" in str(exc)
    else:
        raise AssertionError("no AttributeError")
    assert not hasattr(pkg, "_private_missing")


def test_cli_nadir_snap_constants_equal_the_path_planner_ones():
    """cli repeats them so that building the parser does not import path (and scipy)."""
    from robocal.rigs.projector import cli, path

    assert cli.NADIR_SNAP == path.NADIR_SNAP
    assert cli.MAX_NADIR_SNAP == path.MAX_NADIR_SNAP
