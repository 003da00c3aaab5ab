"""``robocal flow --help`` stays fast: the cli module and the package import no heavy library.

The package exports its names lazily (PEP 562 ``__getattr__``); these tests check that every name in
``__all__`` is still the object its submodule defines, whatever is imported first.
"""

import importlib
import json
import pkgutil
import subprocess
import sys

import robocal.rigs.flow as pkg

PKG = "robocal.rigs.flow"
#: modules a parser build must not import (numba ~0.3 s, cv2, matplotlib; scipy.spatial ~0.4 s via robocal.geometry)
HEAVY = ("numba", "matplotlib", "cv2", "scipy.optimize", "scipy.spatial", "skimage")
#: where each exported name came from when the package imported its submodules eagerly
SOURCES = {
    "kernel": ("FlowConfig", "FrameFlow", "compute_flow", "match_blocks", "match_sequence"),
    "model": ("SensorArray", "seed_array"),
    "odometry": ("Odometry", "SensorSteps", "dead_reckon", "fuse_steps"),
    "calibrate": ("ArrayCalibration", "calibrate_array"),
    "evaluate": ("evaluate_trajectory", "rpe_lengths", "rpe_per_distance", "ate"),
}
ALL = [
    "FlowConfig", "FrameFlow", "compute_flow", "match_blocks", "match_sequence",
    "SensorArray", "seed_array", "Odometry", "SensorSteps", "dead_reckon", "fuse_steps",
    "ArrayCalibration", "calibrate_array", "evaluate_trajectory", "rpe_lengths", "rpe_per_distance", "ate",
]


def _run(code: str):
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_cli_import_and_help_import_no_heavy_module():
    code = f"""
import argparse, json, sys
import {PKG}.cli as cli
after_import = [m for m in {HEAVY!r} if m in sys.modules]
p = argparse.ArgumentParser(prog="robocal flow")
cli.RIG.add_commands(p)
p.format_help()
for a in p._actions:
    if isinstance(getattr(a, "choices", None), dict):
        for sp in a.choices.values():
            sp.format_help()
after_help = [m for m in {HEAVY!r} if m in sys.modules]
rig_modules = sorted(m for m in sys.modules if m.startswith("{PKG}."))
print(json.dumps([after_import, after_help, rig_modules]))
"""
    after_import, after_help, rig_modules = _run(code)
    assert after_import == []
    assert after_help == []
    assert rig_modules == [f"{PKG}.cli"]


def test_main_help_and_usage_error_import_no_heavy_module():
    for argv in (["flow", "--help"], ["flow", "simulate", "--help"], ["flow", "odometry"],
                 ["flow", "simulate", "--texture", "carpet"],
                 ["flow", "simulate", "--duration", "-1", "--out", "/nonexistent/never-written"]):
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
    assert pkg.__all__ == ALL
    assert sorted(n for names in SOURCES.values() for n in names) == sorted(ALL)
    for module, names in SOURCES.items():
        sub = importlib.import_module(f"{PKG}.{module}")
        for name in names:
            assert getattr(pkg, name) is getattr(sub, name), name
    assert set(ALL) <= set(dir(pkg))
    ns = {}
    exec(f"from {PKG} import *", ns)
    assert sorted(k for k in ns if not k.startswith("__")) == sorted(ALL)


def test_no_exported_name_is_a_submodule_name():
    """A submodule named like an exported name would replace it as a package attribute once imported."""
    submodules = {m.name for m in pkgutil.iter_modules(pkg.__path__)}
    assert set(SOURCES) | {"cli", "simulate", "workflow"} <= submodules
    assert not set(pkg.__all__) & submodules


def test_exported_names_with_every_submodule_imported_first():
    """Fresh interpreter: import every submodule, then ``from package import name`` for each name."""
    code = f"""
import importlib, json, pkgutil, types
import {PKG} as pkg
subs = sorted(m.name for m in pkgutil.iter_modules(pkg.__path__))
for s in subs:
    importlib.import_module("{PKG}." + s)
sources = {SOURCES!r}
bad = []
for module, names in sources.items():
    sub = importlib.import_module("{PKG}." + module)
    for name in names:
        ns = {{}}
        exec("from {PKG} import " + name, ns)
        if ns[name] is not getattr(sub, name) or isinstance(ns[name], types.ModuleType):
            bad.append(name)
print(json.dumps([subs, bad]))
"""
    subs, bad = _run(code)
    assert set(SOURCES) <= set(subs)
    assert bad == []


def test_exported_names_before_any_submodule():
    """Fresh interpreter: the names first (lazy path), then the submodules; same objects."""
    code = f"""
import importlib, json
from {PKG} import *
import {PKG} as pkg
got = {{n: globals()[n] for n in pkg.__all__}}
bad = []
for module, names in {SOURCES!r}.items():
    sub = importlib.import_module("{PKG}." + module)
    bad += [n for n in names if got[n] is not getattr(sub, n)]
print(json.dumps(bad))
"""
    assert _run(code) == []


def test_submodules_are_attributes_and_unknown_names_raise():
    assert pkg.kernel is importlib.import_module(f"{PKG}.kernel")
    try:
        pkg.no_such_name
    except AttributeError as exc:
        assert "no_such_name" in str(exc)
    else:
        raise AssertionError("no AttributeError")
    assert not hasattr(pkg, "_private_missing")


def test_cli_textures_equal_the_simulator_ones():
    """cli repeats them (the ``--texture`` choices) so that building the parser does not import the simulator."""
    from robocal.rigs.flow import cli, simulate

    assert cli.TEXTURES == simulate.TEXTURES
