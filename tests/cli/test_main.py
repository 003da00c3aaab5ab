import argparse
import json

import numpy as np
import pytest

from robocal.cli import DemoOutcome
from robocal.cli.main import build_parser, main, run_demo
from robocal.errors import InputError
from robocal.io import CalibrationResult
from robocal.report import Section
from robocal.workflow import Workflow


def _toy_rig(fail_with=None, passed=True):
    def load_input(path):
        raise InputError("field 'x': must be > 0, got -1", source=str(path))

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

    return _toy_workflow(load_input, demo=demo)


def _toy_workflow(load_input, *, demo=None, calibrate=None):
    """A rig whose calibrate fails in ``load_input`` (or in ``calibrate``)."""
    return Workflow("toy", "a toy rig", "toy description", load_input=load_input,
                    calibrate=calibrate or (lambda inp, **_: inp), to_result=lambda cal, inp: cal, demo=demo)


def test_help_and_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert "robocal demo" in out and "examples:" in out
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.startswith("robocal ")


def test_demo_writes_report_and_results(tmp_path, capsys):
    rigs = [_toy_rig()]
    args = argparse.Namespace(rigs=None, out=tmp_path / "demo", seed=1, no_progress=True)
    assert run_demo(args, rigs) == 0
    assert (tmp_path / "demo" / "report.html").is_file()
    res = json.loads((tmp_path / "demo" / "toy" / "result.json").read_text())
    assert res["schema"] == "robocal.result/2"
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

    monkeypatch.setattr(m, "discover_rigs", lambda names=None: [_toy_rig()])
    code = main(["toy", "calibrate", "in.yaml"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("robocal: error: in.yaml: field 'x'")


def test_unknown_rig_in_demo_is_user_error(capsys):
    assert main(["demo", "--rigs", "nonexistent", "--no-progress"]) == 2
    assert "nonexistent is not a rig with a demo" in capsys.readouterr().err
    # installed but without a demo, or an empty list: an error too, not a silent exit 0
    assert main(["demo", "--rigs", "handeye", "--no-progress"]) == 2
    assert main(["demo", "--rigs", ",", "--no-progress"]) == 2


def test_parser_lists_installed_rigs():
    from robocal.cli import discover_rigs

    text = build_parser().format_help()
    names = [r.name for r in discover_rigs()]
    assert {"projector", "humanoid", "mirror", "flow", "lineprofiler"} <= set(names)
    assert all(n in text for n in ["demo", *names])


def test_help_shows_only_meaningful_defaults(capsys):
    with pytest.raises(SystemExit):
        main(["demo", "--help"])
    out = capsys.readouterr().out
    assert "(default: None)" not in out and "(default: False)" not in out and "(default: 2026)" in out
    assert out.count("(default:") == 3  # --out's and --rigs' own texts, --seed's value


def test_out_that_is_a_file_or_cannot_be_made_is_one_line_exit_2(tmp_path, capsys, monkeypatch):
    import robocal.cli.main as m

    monkeypatch.setattr(m, "discover_rigs", lambda names=None: [_toy_rig()])
    afile = tmp_path / "f"
    afile.write_text("")
    for out in (afile, afile / "sub"):
        assert main(["demo", "--out", str(out), "--no-progress"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("robocal: error: --out: ") and str(afile) in err


def test_library_error_is_prefixed_with_the_input_file(capsys, monkeypatch):
    import robocal.cli.main as m

    rig = _toy_rig()

    def load_input(path):
        raise InputError("points 0 and 1 coincide")

    monkeypatch.setattr(m, "discover_rigs", lambda names=None: [_toy_workflow(load_input, demo=rig.demo)])
    assert main(["toy", "calibrate", "in.yaml"]) == 2
    assert capsys.readouterr().err == "robocal: error: in.yaml: points 0 and 1 coincide\n"


def test_usage_error_in_a_rig_subcommand_is_one_line_exit_2(capsys, monkeypatch):
    import robocal.cli.main as m

    monkeypatch.setattr(m, "discover_rigs", lambda names=None: [_toy_rig()])
    with pytest.raises(SystemExit) as e:
        main(["toy", "calibrate"])  # missing INPUT: argparse's error, through the sub-parsers
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("robocal toy calibrate: error:") and "input" in err and "--help" in err


def test_results_record_the_cli_command_and_api_results_none(tmp_path, monkeypatch):
    import robocal.cli.main as m

    monkeypatch.setattr(m, "discover_rigs", lambda names=None: [_toy_rig()])
    assert main(["demo", "--out", str(tmp_path / "d d"), "--no-progress"]) == 0
    res = json.loads((tmp_path / "d d" / "toy" / "result.json").read_text())
    assert res["command"] == f"robocal demo --out '{tmp_path / 'd d'}' --no-progress"  # quoted, re-runnable
    assert CalibrationResult(rig="toy", method="m", estimate={}).command == ""  # not pytest's argv


def test_a_rig_that_fails_to_import_is_skipped_with_a_warning(capsys, monkeypatch):
    from importlib.metadata import EntryPoint

    import robocal.cli._rig as r

    good = [ep for ep in r.entry_points(group="robocal.rigs") if ep.name == "projector"]
    broken = EntryPoint("broken", "robocal.cli._common:NO_SUCH_RIG", "robocal.rigs")  # AttributeError on load
    absent = EntryPoint("absent", "robocal_absent_rig.cli:RIG", "robocal.rigs")  # not in this build: silent
    monkeypatch.setattr(r, "entry_points", lambda group: [*good, broken, absent])
    rigs = r.discover_rigs()
    assert [x.name for x in rigs] == ["projector"]
    err = capsys.readouterr().err
    assert err.startswith("robocal: warning: rig 'broken' could not be loaded (") and err.count("\n") == 1


def test_a_rig_command_loads_only_that_rig(monkeypatch, capsys):
    import robocal.cli.main as m

    asked = []
    real = m.discover_rigs
    monkeypatch.setattr(m, "discover_rigs", lambda names=None: asked.append(names) or real(names))
    with pytest.raises(SystemExit):
        main(["projector", "--help"])
    assert asked == [["projector"]]
    assert "calibrate" in capsys.readouterr().out
    # anything else (the top-level help, demo, a misspelt rig) loads every rig
    assert m._invoked_rig(["--help"]) is None and m._invoked_rig(["demo"]) is None
    assert m._invoked_rig(["projektor", "calibrate"]) is None
    assert m._invoked_rig(["-h", "flow"]) == ["flow"]


def test_a_rigs_demo_stream_is_keyed_by_its_name_not_its_place(tmp_path):
    import dataclasses

    def x_of(rigs, out):
        args = argparse.Namespace(rigs=None, out=tmp_path / out, seed=5, no_progress=True)
        assert run_demo(args, rigs) == 0
        return json.loads((tmp_path / out / "toy" / "result.json").read_text())["estimate"]["x"]

    toy = _toy_rig()
    before = dataclasses.replace(toy, name="aaa")  # sorts and runs before "toy"
    alone, second = x_of([toy], "alone"), x_of([before, toy], "second")
    assert alone == second
    # and the stream is the rig's own: the other rig drew a different number
    assert json.loads((tmp_path / "second" / "aaa" / "result.json").read_text())["estimate"]["x"] != alone


@pytest.mark.parametrize("exc, says", [
    (MemoryError(), "out of memory"),
    (np.linalg.LinAlgError("Singular matrix"), "singular or ill-conditioned problem (Singular matrix)"),
    (UnicodeDecodeError("utf-8", b"\x89PNG", 0, 1, "invalid start byte"), "not UTF-8 text: byte 0x89 at offset 0"),
    (FloatingPointError("overflow encountered in multiply"), "overflowed or became undefined"),
    (RuntimeWarning("invalid value encountered in divide"), "overflowed or became undefined"),
])
def test_failures_user_data_provokes_are_one_line_naming_the_input(tmp_path, capsys, monkeypatch, exc, says):
    import warnings

    import robocal.cli.main as m

    inp = tmp_path / "room.yaml"
    inp.write_text("H: 1\n")

    def calibrate(inp, **_):
        warnings.warn("overflow encountered in square", RuntimeWarning)  # held back: the error line is the answer
        raise exc

    monkeypatch.setattr(m, "discover_rigs", lambda names=None: [_toy_workflow(lambda path: path, calibrate=calibrate)])
    assert main(["toy", "calibrate", str(inp)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"robocal: error: {inp}: ") and says in err, err


def test_a_negative_seed_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as e:
        main(["demo", "--seed", "-1", "--rigs", "x"])
    assert e.value.code == 2
    assert "expected a whole number >= 0, got -1" in capsys.readouterr().err
