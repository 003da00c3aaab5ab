import argparse
import json

import numpy as np
import pytest

from robocal.cli import DemoOutcome, Rig
from robocal.cli.main import build_parser, main, run_demo
from robocal.errors import InputError
from robocal.io import CalibrationResult
from robocal.report import Section


def _toy_rig(fail_with=None, passed=True):
    def add_commands(p):
        sub = p.add_subparsers(dest="sub")
        c = sub.add_parser("calibrate")
        c.add_argument("input")

        def run(args):
            raise InputError("field 'x': must be > 0, got -1", source=args.input)

        c.set_defaults(func=run)

    def demo(ctx):
        if fail_with:
            raise fail_with
        x = ctx.rng.normal()
        return DemoOutcome(
            summary={"x": f"{x:.3f}"},
            passed=passed,
            sections=[Section("toy").text("hello")],
            result=CalibrationResult(rig="toy", method="m", estimate={"x": x}),
        )

    return Rig("toy", "a toy rig", "toy description", add_commands, demo)


def test_help_and_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert "robocal demo" in out and "examples:" in out
    with pytest.raises(SystemExit):
        main(["--version"])
    assert "robocal" in capsys.readouterr().out


def test_demo_writes_report_and_results(tmp_path, capsys):
    rigs = [_toy_rig()]
    args = argparse.Namespace(rigs=None, out=tmp_path / "demo", seed=1, no_progress=True)
    assert run_demo(args, rigs) == 0
    assert (tmp_path / "demo" / "report.html").is_file()
    res = json.loads((tmp_path / "demo" / "toy" / "result.json").read_text())
    assert res["schema"] == "robocal.result/1"
    out = capsys.readouterr().out
    assert "toy" in out and "ok" in out
    # same seed, same numbers
    args2 = argparse.Namespace(rigs=None, out=tmp_path / "demo2", seed=1, no_progress=True)
    run_demo(args2, rigs)
    res2 = json.loads((tmp_path / "demo2" / "toy" / "result.json").read_text())
    assert res2["estimate"] == res["estimate"]


def test_demo_reports_failed_checks(tmp_path):
    args = argparse.Namespace(rigs=None, out=tmp_path / "d", seed=1, no_progress=True)
    assert run_demo(args, [_toy_rig(passed=False)]) == 1
    assert run_demo(args, [_toy_rig(fail_with=InputError("bad"))]) == 1


def test_user_error_is_one_line_exit_2(tmp_path, capsys, monkeypatch):
    import robocal.cli.main as m

    monkeypatch.setattr(m, "discover_rigs", lambda: [_toy_rig()])
    code = main(["toy", "calibrate", "in.yaml"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("robocal: error: in.yaml: field 'x'")


def test_unknown_rig_in_demo_is_user_error(capsys):
    assert main(["demo", "--rigs", "nonexistent", "--no-progress"]) == 2
    assert "unknown rig" in capsys.readouterr().err


def test_parser_lists_installed_rigs():
    parser = build_parser()
    text = parser.format_help()
    assert "demo" in text


def test_usage_error_in_a_rig_subcommand_is_one_line_exit_2(capsys, monkeypatch):
    import robocal.cli.main as m

    monkeypatch.setattr(m, "discover_rigs", lambda: [_toy_rig()])
    with pytest.raises(SystemExit) as e:
        main(["toy", "calibrate"])  # missing INPUT: argparse's error, through the sub-parsers
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("robocal toy calibrate: error:") and "input" in err and "--help" in err
