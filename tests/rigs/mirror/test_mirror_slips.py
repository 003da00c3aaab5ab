"""Slips in a mirror input (issue 18): each named in one line through the CLI, exit 2.

Before: points in m declared mm gave an answer metres off with exit 0 (rectangle), or OpenCV's SQPnP
assertion text (body points); a body model in the mirror-image frame exited 0 with a warning.
"""

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal.cli.main import main
from robocal.rigs.mirror.simulate import default_setup, simulate_observations
from robocal.rigs.mirror.slips import check_body_span

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "mirror" / "published_single.yaml"


def _input(tmp_path, edit):
    doc = yaml.safe_load(EXAMPLE.read_text())
    edit(doc)
    p = tmp_path / "in.yaml"
    p.write_text(yaml.safe_dump(doc, sort_keys=False))
    return p


def _body_m(doc):
    doc["body_points"] = [[v / 1000 for v in p] for p in doc["body_points"]]


def _rect_m(doc):
    doc["mirror_rectangle"] = {k: v / 1000 for k, v in doc["mirror_rectangle"].items()}


def _mirrored(doc):  # the body model given in the mirror-image frame ri (x not flipped back)
    doc["body_points"] = [[-p[0], p[1], p[2]] for p in doc["body_points"]]


def _swapped_xy(doc):  # columns x and y swapped: the same error up to a rotation
    doc["body_points"] = [[p[1], p[0], p[2]] for p in doc["body_points"]]


@pytest.mark.parametrize("edit, expected", [
    (_body_m, r"`body_points` looks like m, not mm: with x1000 the factor between the body points' span and a "
              r"typical robot's 0.45 m drops from 81\d to 1.2\d "),
    (_rect_m, r"`mirror_rectangle` looks like m, not mm \(or `body_points` 1000x too large: the images fix only the "
              r"ratio of the two\): with x1000 the camera's distance from the nearest body point drops from 3.\d+ to "
              r"0.0\d+ m"),
    (_mirrored, r"`body_points` look mirrored \(placement 0; given in the mirror-image frame ri, an axis sign flipped "
                r"or two axes swapped: .*\): with x negated the body-point reprojection RMS drops from 1.\d+ to 0.\d+ px"),
    (_swapped_xy, r"`body_points` look mirrored .* with x negated the body-point reprojection RMS drops"),
], ids=["body_m_as_mm", "rectangle_m_as_mm", "body_in_frame_ri", "body_xy_swapped"])
def test_slip_is_one_line_and_exit_2(tmp_path, capsys, edit, expected):
    inp = _input(tmp_path, edit)
    assert main(["mirror", "calibrate", str(inp), "--out", str(tmp_path / "cal")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith(f"robocal: error: {inp}: ")
    assert re.search(expected, err), err
    assert "OpenCV" not in err and "--accept-implausible" in err
    assert not (tmp_path / "cal" / "result.json").exists()


def test_accept_implausible_writes_the_result_with_a_warning(tmp_path, capsys):
    inp = _input(tmp_path, _rect_m)
    assert main(["mirror", "calibrate", str(inp), "--accept-implausible", "--out", str(tmp_path / "cal")]) == 0
    res = json.loads((tmp_path / "cal" / "result.json").read_text())
    assert res["warnings"][0]["code"] == "implausible_input"
    assert res["warnings"][0]["params"] == ["mirror_rectangle_m_as_mm"]
    # the answer for the data as given: the camera metres from the body (the slip's effect, kept)
    assert np.linalg.norm(res["estimate"]["T_r_c.translation"]) > 1.0  # [m]; the truth is 0.65 m from the odometry centre


def test_correct_inputs_pass_every_check(tmp_path, capsys):
    # the example and a 4-placement simulation: no implausible_input, no error
    assert main(["mirror", "calibrate", str(EXAMPLE), "--out", str(tmp_path / "cal")]) == 0
    res = json.loads((tmp_path / "cal" / "result.json").read_text())
    assert "implausible_input" not in [w["code"] for w in res["warnings"]]
    from robocal.rigs.mirror.calibrate import calibrate

    rng = np.random.default_rng(5)
    cam, scene = default_setup(4, rng)
    obs = simulate_observations(cam, scene, rng, sigma_px=0.5)
    cal = calibrate(cam, scene.rectangle, scene.body_points_r, obs, sigma_px=0.5)
    assert "implausible_input" not in [w.code for w in cal.warnings]


def test_body_span_without_declared_units_names_the_factor():
    P = np.array([[0.45, -0.25, 0.05], [0.57, 0.1, 0.16], [0.52, 0.12, 0.2]]) * 1e-3
    from robocal.errors import ImplausibleInputError

    with pytest.raises(ImplausibleInputError, match=r"`body_points` looks 1000x too small \(a unit slip\): with "
                                                    r"x1000"):
        check_body_span(P)
    assert check_body_span(P * 1e3) == []
    w = check_body_span(P, accept=True)
    assert [d.code for d in w] == ["implausible_input"]
