"""``robocal humanoid --help`` stays fast: the cli module and the package import no heavy library.

The package exports its names lazily (``robocal._lazy.lazy_exports``); these tests check that every name in
``__all__`` is still the object its submodule defines, whatever is imported first. ``calibrate`` is both an
exported function and a submodule: the package attribute must stay the function, as it was when the package
imported its submodules eagerly (``from .calibrate import calibrate``).
"""

import importlib
import json
import pkgutil
import subprocess
import sys
import types

import robocal.rigs.humanoid as pkg

PKG = "robocal.rigs.humanoid"
#: modules a parser build must not import (scipy.optimize ~0.25 s via robocal.estimation, cv2, scipy.spatial)
HEAVY = ("numba", "matplotlib", "cv2", "scipy.optimize", "scipy.spatial", "skimage")
#: where each exported name came from when the package imported its submodules eagerly
SOURCES = {
    "calibrate": ("HumanoidCalibration", "calibrate", "resolve_parameters"),
    "dataset": ("load_dataset", "write_dataset"),
    "model": ("HumanoidModel", "default_model"),
    "plan": ("PosePlan", "plan_poses"),
    "simulate": ("HumanoidDataset", "Truth", "draw_truth", "sample_poses", "simulate_dataset"),
}
ALL = [
    "HumanoidModel", "default_model", "HumanoidDataset", "Truth", "draw_truth", "sample_poses",
    "simulate_dataset", "load_dataset", "write_dataset", "HumanoidCalibration", "calibrate",
    "resolve_parameters", "PosePlan", "plan_poses",
]
#: exported names that are also submodule names
COLLISIONS = {"calibrate"}


def _run(code: str):
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_cli_import_and_help_import_no_heavy_module():
    code = f"""
import argparse, json, sys
import {PKG}.cli as cli
after_import = [m for m in {HEAVY!r} if m in sys.modules]
p = argparse.ArgumentParser(prog="robocal humanoid")
cli.RIG.add_commands(p)
p.format_help()
n_sub = 0
for a in p._actions:
    if isinstance(getattr(a, "choices", None), dict):
        for sp in a.choices.values():
            sp.format_help()
            n_sub += 1
after_help = [m for m in {HEAVY!r} if m in sys.modules]
rig_modules = sorted(m for m in sys.modules if m.startswith("{PKG}."))
print(json.dumps([after_import, after_help, rig_modules, n_sub]))
"""
    after_import, after_help, rig_modules, n_sub = _run(code)
    assert after_import == []
    assert after_help == []
    assert rig_modules == [f"{PKG}.cli"]
    assert n_sub == 4  # simulate, calibrate, plan, report


def test_main_help_and_usage_error_import_no_heavy_module():
    for argv in (["humanoid", "--help"], ["humanoid", "calibrate", "--help"], ["humanoid", "plan", "--help"],
                 ["humanoid", "calibrate"], ["humanoid", "simulate", "--views", "many"],
                 ["humanoid", "frobnicate"], ["humanoid", "report"]):
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


def test_console_script_help_and_usage_error():
    """``python -m robocal humanoid --help`` exits 0, a usage error exits 2 with the usage on stderr."""
    ok = subprocess.run([sys.executable, "-m", "robocal", "humanoid", "--help"], capture_output=True, text=True,
                        timeout=300)
    assert ok.returncode == 0, ok.stderr
    assert "simulate" in ok.stdout and "calibrate" in ok.stdout
    bad = subprocess.run([sys.executable, "-m", "robocal", "humanoid", "calibrate"], capture_output=True,
                         text=True, timeout=300)
    assert bad.returncode == 2
    assert "input" in bad.stderr


def test_all_unchanged_and_names_come_from_their_submodule():
    assert pkg.__all__ == ALL
    assert sorted(n for names in SOURCES.values() for n in names) == sorted(ALL)
    assert pkg._EXPORTS == {n: module for module, names in SOURCES.items() for n in names}
    for module, names in SOURCES.items():
        sub = importlib.import_module(f"{PKG}.{module}")
        for name in names:
            assert getattr(pkg, name) is getattr(sub, name), name
    assert isinstance(pkg.calibrate, types.FunctionType)
    assert set(ALL) <= set(dir(pkg))
    ns = {}
    exec(f"from {PKG} import *", ns)
    assert sorted(k for k in ns if not k.startswith("__")) == sorted(ALL)
    assert all(ns[n] is getattr(pkg, n) for n in ALL)


def test_collisions_are_exactly_the_exported_submodule_names():
    """Every exported name that is also a submodule name is declared, so the submodule never replaces it."""
    submodules = {m.name for m in pkgutil.iter_modules(pkg.__path__)}
    assert set(SOURCES) | {"cli", "detect", "report", "montecarlo"} <= submodules
    assert set(pkg.__all__) & submodules == COLLISIONS
    assert set(pkg._COLLISIONS) == COLLISIONS


def test_exported_names_with_every_submodule_imported_first():
    """Fresh interpreter: import every submodule, then ``from package import name`` for each name."""
    code = f"""
import importlib, json, pkgutil, sys, types
import {PKG} as pkg
subs = sorted(m.name for m in pkgutil.iter_modules(pkg.__path__))
for s in subs:
    importlib.import_module("{PKG}." + s)
bad = []
for module, names in {SOURCES!r}.items():
    sub = sys.modules["{PKG}." + module]
    for name in names:
        ns = {{}}
        exec("from {PKG} import " + name, ns)
        if ns[name] is not getattr(sub, name) or isinstance(ns[name], types.ModuleType):
            bad.append(name)
        if getattr(pkg, name) is not getattr(sub, name):
            bad.append("pkg." + name)
import {PKG}.calibrate as m  # getattr(package, "calibrate") first (Python 3.7+): the function, as eagerly
if m is not sys.modules["{PKG}.calibrate"].calibrate:
    bad.append("import as")
print(json.dumps([subs, bad]))
"""
    subs, bad = _run(code)
    assert set(SOURCES) <= set(subs)
    assert bad == []


def test_exported_names_before_any_submodule():
    """Fresh interpreter: the names first (lazy path), then the submodules; same objects."""
    code = f"""
import importlib, json, sys, types
from {PKG} import *
import {PKG} as pkg
loaded = sorted(m for m in sys.modules if m.startswith("{PKG}."))
got = {{n: globals()[n] for n in pkg.__all__}}
bad = []
for module, names in {SOURCES!r}.items():
    sub = importlib.import_module("{PKG}." + module)
    bad += [n for n in names if got[n] is not getattr(sub, n)]
    bad += ["pkg." + n for n in names if getattr(pkg, n) is not getattr(sub, n)]
from {PKG} import calibrate as again
if not isinstance(again, types.FunctionType) or again is not got["calibrate"]:
    bad.append("calibrate after the submodule")
print(json.dumps([loaded, bad]))
"""
    loaded, bad = _run(code)
    assert {f"{PKG}.{m}" for m in SOURCES} <= set(loaded)
    assert bad == []


def test_submodules_are_attributes_and_unknown_names_raise():
    assert pkg.detect is importlib.import_module(f"{PKG}.detect")
    assert sys.modules[f"{PKG}.calibrate"].calibrate is pkg.calibrate
    try:
        pkg.no_such_name
    except AttributeError as exc:
        assert "no_such_name" in str(exc)
    else:
        raise AssertionError("no AttributeError")
    assert not hasattr(pkg, "_private_missing")
