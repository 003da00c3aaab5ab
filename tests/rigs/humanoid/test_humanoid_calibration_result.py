"""The result record of a calibration: what the summary, the truth check and the report are built from."""

import re

import numpy as np
import pytest

from robocal.errors import ImplausibleInputError, InputError
from robocal.estimation import outlier_sigma
from robocal.io import load_result, write_result
from robocal.rigs.humanoid.calibrate import calibrate
from robocal.rigs.humanoid.calibration import summary_text
from robocal.rigs.humanoid.report import build_report


@pytest.fixture(scope="module")
def cal(model, corner_data):
    return calibrate(model, corner_data)


def test_truth_check_passes_on_the_truth_and_fails_on_a_shifted_one(cal, corner_data):
    truth = corner_data.truth.params
    good = cal.truth_check(truth)
    assert good.passed and good.dof == 21, str(good)
    # one parameter's truth 8 reported std away: NEES grows by ~64 (limit 46.8 for 21 dof)
    k = cal.labels.index("LKneePitch")
    shifted = truth.copy()
    shifted[k] += 8 * cal.std("LKneePitch")
    bad = cal.truth_check(shifted)
    assert not bad.passed and bad.worst[0] == "LKneePitch" and abs(bad.worst[1]) > 7


def test_summary_and_report_are_the_same_from_the_file(cal, corner_data, tmp_path):
    res = cal.to_result(truth=corner_data.truth.params)
    again = load_result(write_result(tmp_path / "result.json", res))
    text = summary_text(res)
    assert summary_text(again) == text
    # the same lines as the calibration's own summary, plus the truth check
    assert text.splitlines()[:-1] == cal.summary().splitlines()
    assert text.splitlines()[-1].startswith("simulation truth: NEES ")
    d = again.diagnostics
    assert d["truth_check"]["passed"] and set(d["simulation_truth"]) == set(res.estimate)
    assert d["outlier_sigma"] == outlier_sigma(d["n_corners_used"]) > 4.2  # Bonferroni over the 480 corners
    assert d["solver"]["outlier_sigma"] == d["outlier_sigma"]
    first, rebuilt = (build_report(r, base_dir=tmp_path).to_html() for r in (res, again))
    strip = lambda html: re.sub(r"<p class='meta'>.*?</p>", "", html)  # noqa: E731  (the time stamp)
    assert strip(first) == strip(rebuilt)
    assert "<h2>Simulation truth</h2>" in first and "<h2>Solver</h2>" in first


def test_a_non_finite_start_is_an_input_error_not_a_divergence(model, corner_data):
    x0 = np.zeros(len(model.parameter_labels()))
    x0[0] = np.nan
    with pytest.raises(InputError, match="x0: expected .* finite start values") as info:
        calibrate(model, corner_data, x0=x0)
    assert not isinstance(info.value, ImplausibleInputError)


def test_a_result_written_before_the_contract_still_gets_its_report(model, corner_data):
    # results of robocal before issue 20 have no solver record, n_solved, camera frame or threshold
    from robocal.io import CalibrationResult

    cal = calibrate(model, corner_data, parameters="all")  # rank deficient: the rank text names the gauge
    d = cal.to_result().to_dict()
    for k in ("solver", "n_solved", "camera_frame", "outlier_sigma"):
        del d["diagnostics"][k]
    html = build_report(CalibrationResult.from_dict(d), base_dir=None).to_html()
    assert "Jacobian rank 24 of 25 free parameters (4 not determined" in html
    assert "<h2>Solver</h2>" in html and "No iterative solver ran" not in html
