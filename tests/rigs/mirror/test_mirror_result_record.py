"""The result record (robocal.rigs.mirror.result): T_r_c as a pose with its std, the mirror poses as
nuisance parameters in diagnostics, the solver record, the truth check, and the report drawn from it alone."""

import json

import numpy as np
import pytest

from robocal.estimation import truth_check
from robocal.io import load_result
from robocal.rigs.mirror.calibrate import calibrate, predicted_covariance
from robocal.rigs.mirror.report import build_report
from robocal.rigs.mirror.result import SOLVER_FIELDS, TRUTH_NAMES, pose_error, result_from_calibration
from robocal.rigs.mirror.simulate import default_setup, simulate_observations
from robocal.rigs.mirror.workflow import summary


@pytest.fixture(scope="module")
def two_placements():
    rng = np.random.default_rng(5)
    cam, scene = default_setup(2, rng)
    obs = simulate_observations(cam, scene, rng, sigma_px=0.5)
    return cam, scene, obs, calibrate(cam, scene.rectangle, scene.body_points_r, obs, sigma_px=0.5)


def test_T_r_c_is_a_pose_with_the_left_std_of_the_covariance(two_placements, tmp_path):
    cam, scene, obs, cal = two_placements
    res = result_from_calibration(cal, truth=scene.T_r_c, sigma_px=0.5)
    (tmp_path / "result.json").write_text(json.dumps(res.to_dict()))
    back = load_result(tmp_path / "result.json")
    pose = back.pose("T_r_c")
    assert pose.rotation_std == "left" and back.poses["T_r_c"]["parent"] == "robot"
    np.testing.assert_array_equal(pose.T, cal.T_r_c)  # JSON floats round-trip exactly
    np.testing.assert_array_equal(pose.std_rotation, np.sqrt(np.diag(cal.cov)[:3]))
    np.testing.assert_array_equal(pose.std_translation, np.sqrt(np.diag(cal.cov)[3:]))
    assert not any(k in back.estimate for k in ("T_r_c", "t_r_c", "q_r_c", "rotvec_r_c", "T_c_m"))
    assert set(back.diagnostics["solver"]) == set(SOLVER_FIELDS)
    # the truth check is the NEES of the left error under the reported covariance
    expect = truth_check(pose_error(cal.T_r_c, scene.T_r_c), cal.cov, names=TRUTH_NAMES)
    assert back.diagnostics["truth_check"]["nees"] == pytest.approx(expect.nees, rel=1e-12)
    assert summary(back).startswith("t_r_c = [") and "rotation std" in summary(back)


def test_mirror_poses_carry_the_std_of_their_block_of_the_joint_covariance(two_placements):
    cam, scene, obs, cal = two_placements
    mp = result_from_calibration(cal).diagnostics["mirror_poses"]
    assert [m["image"] for m in mp] == [o.name for o in obs]
    np.testing.assert_array_equal(np.array([m["T_c_m"] for m in mp]), cal.T_c_m)
    # the block order of the full covariance is rot_rc, t_rc, rot_cm (K x 3), t_cm (K x 3). Evaluated at the
    # estimate it differs from the solver's, whose rotation parameters are steps theta from the start's
    # reference rotations, by the left Jacobian J_l(theta) = I - skew(theta) / 2 + ...: a std moves by at most
    # ~|theta| times the largest std of its block
    full = predicted_covariance(cam, scene.rectangle, scene.body_points_r, cal.T_r_c, cal.T_c_m, obs, 0.5, full=True)
    K = len(obs)
    var = np.diag(full)
    for k, m in enumerate(mp):
        want_r, want_t = np.sqrt(var[6 + 3 * k:9 + 3 * k]), np.sqrt(var[6 + 3 * K + 3 * k:9 + 3 * K + 3 * k])
        theta = np.linalg.norm(cal.lsq.params["rot_cm"][k])
        np.testing.assert_allclose(m["std_rotvec"], want_r, rtol=1e-9, atol=theta * want_r.max())
        np.testing.assert_allclose(m["std_translation"], want_t, rtol=1e-9, atol=theta * want_t.max())
    # (rotation and translation std differ ~10x here: a swapped block order would not pass)


def test_without_the_joint_refinement_mirror_poses_have_no_std_and_the_report_says_so(two_placements):
    cam, scene, obs, _ = two_placements
    cal = calibrate(cam, scene.rectangle, scene.body_points_r, obs, sigma_px=0.5, refine=False)
    res = result_from_calibration(cal)
    assert all(m["std_rotvec"] is None and m["std_translation"] is None for m in res.diagnostics["mirror_poses"])
    assert "solver" not in res.diagnostics
    html = build_report(res).to_html()
    assert "No joint refinement" in html


def test_a_result_written_before_schema_2_still_gives_its_report(two_placements, tmp_path):
    # the old vocabulary: bare 4x4 T_r_c, t_r_c, q_r_c, rotvec_r_c, a K x 4 x 4 T_c_m stack, no mirror_poses
    cam, scene, obs, cal = two_placements
    d = result_from_calibration(cal).to_dict()
    d["schema"] = "robocal.result/1"
    pose = d["estimate"]
    d["estimate"] = {"T_r_c": cal.T_r_c.tolist(), "t_r_c": cal.T_r_c[:3, 3].tolist(), "q_r_c": [0.0, 0.0, 0.0, 1.0],
                     "rotvec_r_c": pose["T_r_c.rotvec"], "T_c_m": cal.T_c_m.tolist()}
    d["std"] = {"t_r_c": d["std"]["T_r_c.translation"], "rotvec_r_c": d["std"]["T_r_c.rotvec"]}
    d["units"] = {"T_r_c": "m", "t_r_c": "m", "q_r_c": "1", "rotvec_r_c": "rad", "T_c_m": "m"}
    del d["poses"], d["diagnostics"]["mirror_poses"]
    (tmp_path / "old.json").write_text(json.dumps(d))
    old = load_result(tmp_path / "old.json")
    with pytest.raises(KeyError):
        old.pose("T_r_c")
    html = build_report(old).to_html()
    new = build_report(result_from_calibration(cal)).to_html()
    # the parameter table (first table of the page) is the same; the mirror-pose std is unknown ("-")
    first = lambda h: h[h.index("<table"):h.index("</table>")]  # noqa: E731
    assert first(html) == first(new)
    assert html.count("<td>-</td>") > new.count("<td>-</td>")
