"""A command's fixed cost (issue 16): what ``robocal flow odometry --no-report`` imports and builds.

Wall-clock limits would flake on a shared CI machine; what the time is made
of does not: the modules a command imports (each robocal module with
dataclasses costs ~1 ms per class, ``html`` ~3 ms, ``tempfile`` ~3 ms with
``random``, ``difflib`` ~2 ms) and the argparse parsers it builds. These
tests pin the gains, in a fresh interpreter (this one has imported
everything).
"""

import argparse
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from robocal.cli._common import LazySubParsers

EX = Path(__file__).resolve().parents[2] / "examples" / "flow"

#: imported by nothing the odometry command runs without a report: the geometric fits and the pose
#: covariance (7 dataclasses; the command needs wrap_angle and rigid_fit only), the report (html), the
#: helpers of rare paths (a misspelt key's "did you mean", the metadata cache's rewrite)
NOT_ON_THE_PATH = ("robocal.geometry._fits", "robocal.geometry._pose_cov", "robocal.geometry._reflection",
                   "robocal.geometry._se3", "robocal.report", "robocal.rigs.flow.simulate", "html", "difflib",
                   "tempfile", "importlib.metadata")


@pytest.fixture(scope="module")
def odometry_modules(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("startup")
    out = tmp / "odo"
    # a warm metadata cache, as after a command's first run (the first reads importlib.metadata)
    env = {**os.environ, "ROBOCAL_CACHE_DIR": str(tmp / "cache")}
    subprocess.run([sys.executable, "-c", "import robocal; robocal.__version__"], check=True, env=env, timeout=300)
    code = f"""
import contextlib, io, json, sys
from robocal.cli.main import main
with contextlib.redirect_stdout(io.StringIO()):
    rc = main(['flow', 'odometry', {str(EX / 'frames' / 'run.yaml')!r}, '--no-report', '--no-progress',
               '--out', {str(out)!r}])
print(json.dumps([rc, sorted(sys.modules)]))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    rc, modules = json.loads(proc.stdout.strip().splitlines()[-1])
    assert rc == 0 and (out / "result.json").is_file() and not (out / "report.html").exists()
    return set(modules)


def test_odometry_without_a_report_imports_only_what_it_runs(odometry_modules):
    # the run did need robocal.geometry (ATE: rigid_fit, wrap_angle): the facade gave it two submodules
    assert {"robocal.geometry._so3", "robocal.geometry._registration"} <= odometry_modules
    assert sorted(m for m in NOT_ON_THE_PATH if m in odometry_modules) == []


def _toy_parser(built: list) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="toy")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", action=LazySubParsers)
    for name in ("alpha", "beta"):
        def build(p, name=name):
            built.append(name)
            p.add_argument("--level", type=int, default=1, help=f"{name}'s level")
            p.set_defaults(func=name)
        sub.add_parser(name, help=f"the {name} command", aliases=[name[:2]], build=build)
    return parser


def test_lazy_sub_parsers_build_only_the_command_parsed():
    built = []
    parser = _toy_parser(built)
    assert built == []                       # declared, listed, not built
    assert "alpha" in parser.format_help() and "the beta command" in parser.format_help()
    args = parser.parse_args(["beta", "--level", "3"])
    assert (args.command, args.level, args.func) == ("beta", 3, "beta")
    assert built == ["beta"]
    assert parser.parse_args(["be"]).func == "beta" and built == ["beta"]  # an alias shares the parser


def test_lazy_sub_parsers_give_built_parsers_however_they_are_read():
    built = []
    parser = _toy_parser(built)
    choices = next(a for a in parser._actions if isinstance(a, LazySubParsers)).choices
    assert all(isinstance(p, argparse.ArgumentParser) for p in choices.values())
    assert all(isinstance(p, argparse.ArgumentParser) for _, p in choices.items())
    assert choices.get("al") is choices["alpha"] and choices.get("gamma") is None
    assert sorted(built) == ["alpha", "beta"]
    assert "alpha's level" in choices["alpha"].format_help()
    with pytest.raises(SystemExit):          # an unknown command: argparse's usage error, as before
        parser.parse_args(["gamma"])


def test_the_geometry_facade_exports_what_its_submodules_define():
    import robocal.geometry as geometry

    subs = ("_so3", "_se3", "_reflection", "_registration", "_fits", "_pose_cov")
    modules = [importlib.import_module(f"robocal.geometry.{s}") for s in subs]
    assert geometry.__all__ == [n for m in modules for n in m.__all__]   # the eager package's order
    assert all(getattr(geometry, n) is getattr(m, n) for m in modules for n in m.__all__)
    assert set(geometry.__all__) | set(subs) <= set(dir(geometry))
    assert geometry._fits is modules[4]
    with pytest.raises(AttributeError, match="no_such_name"):
        geometry.no_such_name  # noqa: B018


def test_the_program_exits_with_mains_status_and_freezes_what_lives_to_the_end(monkeypatch):
    """``robocal._program.run`` (the launcher, ``python -m robocal``) exits with :func:`main`'s status, the
    collector on while the command runs and the live objects frozen so that the interpreter's shutdown does
    not walk them all (issue 16: ~25 ms after a 30 s flow log)."""
    import gc

    from robocal import _program
    from robocal.cli import main as cli_main

    seen = []
    monkeypatch.setattr(cli_main, "main", lambda: seen.append(gc.isenabled()) or 2)
    try:
        with pytest.raises(SystemExit) as exc:
            _program.run()
        assert exc.value.code == 2 and seen == [True] and gc.isenabled() and gc.get_freeze_count() > 0
    finally:
        gc.unfreeze()


def test_the_launcher_runs_the_program():
    launcher = Path(sys.executable).parent / "robocal"
    if not launcher.is_file():
        pytest.skip("robocal is not installed with its launcher here")
    assert "robocal._program" in launcher.read_text(errors="replace")
