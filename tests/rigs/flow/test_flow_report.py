"""report: every flow result (calibrate, odometry, evaluate) rebuilds its page from result.json alone."""

import json
import re
import shutil
from pathlib import Path

import pytest

from robocal.cli.main import main

EX = Path(__file__).resolve().parents[3] / "examples" / "flow"


def _run(argv, capsys):
    code = main([str(a) for a in argv])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _page(path: Path) -> str:
    # the one line that may differ between two builds: when the page was made
    return re.sub(r"<p class='meta'>.*?</p>", "", path.read_text())


def _rebuilt_equal(tmp_path, capsys, folder: Path) -> None:
    first = _page(folder / "report.html")
    for argv, out in ((["flow", "report"], tmp_path / f"{folder.name}-rep"), (["report"], tmp_path / f"{folder.name}-rep2")):
        code, _, err = _run([*argv, folder / "result.json", "--out", out], capsys)
        assert code == 0, err
        assert _page(out / "report.html") == first


def test_odometry_and_evaluate_reports_rebuild_from_the_result(tmp_path, capsys):
    odo, ev = tmp_path / "odo", tmp_path / "ev"
    code, _, err = _run(["flow", "odometry", EX / "loop" / "run.yaml", "--out", odo, "--no-progress"], capsys)
    assert code == 0, err
    page = _page(odo / "report.html")
    assert "Trajectory" in page and page.count("<img") == 3      # trajectories, velocity, quality
    _rebuilt_equal(tmp_path, capsys, odo)
    res = json.loads((odo / "result.json").read_text())
    assert set(res["estimate"]) <= set(res["units"])
    # the stored plot series are thinned: result.json stays small for a long log
    assert (odo / "result.json").stat().st_size < 500_000
    assert len(res["diagnostics"]["plots"]["velocity"]["t"]) <= 1001
    code, _, err = _run(["flow", "evaluate", EX / "loop" / "run.yaml", "--out", ev, "--no-progress"], capsys)
    assert code == 0, err
    assert "ATE [mm]" in _page(ev / "report.html")
    _rebuilt_equal(tmp_path, capsys, ev)
    # and both read in a 1400 px browser window (tests/support/browser.py; skipped without Chromium)
    from browser import check_page, chromium_executable

    if chromium_executable() is not None:
        assert check_page(odo / "report.html") == [] and check_page(ev / "report.html") == []


def test_a_run_without_reference_still_gets_its_trajectory_drawn(tmp_path, capsys):
    d = tmp_path / "run"
    shutil.copytree(EX / "loop", d)
    text = (d / "run.yaml").read_text()
    assert "reference: truth.csv" in text and "wheel: wheel.csv" in text
    (d / "run.yaml").write_text(text.replace("reference: truth.csv\n", ""))
    code, out, err = _run(["flow", "odometry", d / "run.yaml", "--out", tmp_path / "odo", "--no-progress"], capsys)
    assert code == 0, err
    assert "ATE" not in out
    res = json.loads((tmp_path / "odo" / "result.json").read_text())
    assert set(res["diagnostics"]["plots"]["trajectories"]) == {"flow odometry", "wheel odometry"}
    page = _page(tmp_path / "odo" / "report.html")
    assert "no reference" in page and "ATE [mm]" not in page and page.count("<img") == 3
    _rebuilt_equal(tmp_path, capsys, tmp_path / "odo")


def test_calibrate_report_has_the_core_solver_section_and_residual_histogram(tmp_path, capsys):
    cal = tmp_path / "cal"
    code, out, err = _run(["flow", "calibrate", EX / "calibration" / "run.yaml", "--out", cal, "--no-progress"], capsys)
    assert code == 0, err
    assert "wrote array_calibrated.yaml" in out and "+/- kernel systematic" in out
    page = _page(cal / "report.html")
    assert "Solver" in page and "outlier threshold [sigma]" in page and "Gaussian of their RMS" in page
    d = json.loads((cal / "result.json").read_text())["diagnostics"]
    # the Bonferroni threshold of robocal.estimation (the calibration's old default was 3 sigma)
    assert d["solver"]["outlier_sigma"] > 3.0
    assert d["window_s"] == pytest.approx(0.1) and set(d["window_residuals"]) == {"s60", "s120", "s270"}
    _rebuilt_equal(tmp_path, capsys, cal)


def test_a_flow_result_of_an_unknown_method_is_one_line_exit_2(tmp_path, capsys):
    from robocal.io import CalibrationResult, write_result

    write_result(tmp_path / "result.json", CalibrationResult(rig="flow", method="magic", estimate={}))
    code, _, err = _run(["report", tmp_path / "result.json", "--out", tmp_path / "r"], capsys)
    assert code == 2 and "'magic'" in err and err.count("\n") == 1
