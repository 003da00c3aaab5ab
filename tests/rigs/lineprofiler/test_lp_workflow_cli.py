"""The lineprofiler and handeye commands on the example files, their errors, the demo."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from robocal.cli.main import main
from robocal.errors import FileFormatError, ShapeError
from robocal.estimation import truth_check
from robocal.geometry import rotvec_from_matrix
from robocal.io import load_result
from robocal.rigs.lineprofiler.calibrate import calibrate_file
from robocal.rigs.lineprofiler.cli import HANDEYE, RIG
from robocal.workflow import DemoContext

EX = Path(__file__).resolve().parents[3] / "examples" / "lineprofiler"


def _page(path: Path) -> str:
    # the one line that differs between two builds of a report: when it was made
    return re.sub(r"<p class='meta'>.*?</p>", "", path.read_text())


def _rebuilt_equal(cal: Path, out: Path, rig: str, capsys) -> str:
    """``robocal <rig> report`` and ``robocal report`` rebuild the page ``calibrate`` wrote; returns it."""
    first = _page(cal / "report.html")
    assert main([rig, "report", str(cal / "result.json"), "--out", str(out / "rig")]) == 0
    assert main(["report", str(cal / "result.json"), "--out", str(out / "any")]) == 0
    capsys.readouterr()
    assert _page(out / "rig" / "report.html") == first
    assert _page(out / "any" / "report.html") == first
    return first


def _bare_matrices(result) -> list[str]:
    """Estimate keys holding a 3x3 / 4x4 matrix that is not a pose's rotation (the vocabulary forbids them)."""
    return [k for k, v in result.estimate.items() if np.shape(v) in ((3, 3), (4, 4))
            and not (k.endswith(".rotation") and k[: -len(".rotation")] in result.poses)]


def test_calibrate_example_names_undetermined_component(tmp_path, capsys):
    cal = tmp_path / "cal"
    assert main(["lineprofiler", "calibrate", str(EX / "fpdp_input.yaml"), "--out", str(cal)]) == 0
    assert "T_E_L translation [mm] (fpdp+geometric): 34.982 +/- 0.033, undetermined, 119.996 +/- 0.056" \
        in capsys.readouterr().out
    res = json.loads((cal / "result.json").read_text())
    assert res["estimate"]["T_E_L.translation"][1] is None  # never a silent 0
    assert res["std"]["T_E_L.translation"][1] is None and res["estimate"]["fpdp.T_E_L.translation"][1] is None
    assert "X.ty" in res["diagnostics"]["undetermined"]
    assert any(w["code"] == "rank_deficient" for w in res["warnings"])
    assert abs(res["estimate"]["T_E_L.translation"][0] - 0.035) < 2e-4
    result = load_result(cal / "result.json")
    assert list(result.poses) == ["T_E_L", "fpdp.T_E_L"] and _bare_matrices(result) == []
    assert result.poses["T_E_L"] == {"rotation_std": "left", "parent": "end effector E", "child": "laser L"}
    # the rebuilt report keeps the sections drawn from the fit (they were lost on 'report' before)
    page = _rebuilt_equal(cal, tmp_path / "rep", "lineprofiler", capsys)
    for title in ("Residuals", "FPDP circle cuts (seed Table 1)", "Solver (geometric refinement)",
                  "T_E_L rotation vector x"):
        assert title in page, title


def test_calibrate_with_joint_sigma(tmp_path):
    for f in ("fpdp_input.yaml", "fpdp_profiles.csv"):
        (tmp_path / f).write_bytes((EX / f).read_bytes())
    y = tmp_path / "fpdp_input.yaml"
    y.write_text(y.read_text() + "joint_sigma: [0.02, 0.00035, 0.02]  # mm, rad (no angle unit given), mm\n")
    assert main(["lineprofiler", "calibrate", str(y), "--out", str(tmp_path / "o")]) == 0
    res = json.loads((tmp_path / "o" / "result.json").read_text())
    d = res["diagnostics"]
    assert d["joint_noise_modelled"] and len(d["joint_corrections"]) == d["n_profiles_used"]
    assert res["estimate"]["T_E_L.translation"][1] is None and res["std"]["T_E_L.translation"][1] is None
    assert abs(res["estimate"]["T_E_L.translation"][0] - 0.035) < 4 * res["std"]["T_E_L.translation"][0]
    y.write_text(y.read_text().replace("joint_sigma: [0.02, 0.00035, 0.02]", "joint_sigma: [0.02, -0.1, 0.02]"))
    with pytest.raises(FileFormatError, match="joint_sigma"):
        calibrate_file(y)
    y.write_text(y.read_text().replace("joint_sigma: [0.02, -0.1, 0.02]", "joint_sigma: [0.02, 0.1]"))
    with pytest.raises(ShapeError, match="joint_sigma"):
        calibrate_file(y)


def test_handeye_example(tmp_path, capsys):
    cal = tmp_path / "cal"
    assert main(["handeye", "calibrate", str(EX / "gripper_poses.csv"), str(EX / "target_poses.csv"),
                 "--method", "park", "--out", str(cal)]) == 0
    assert "T_gripper_cam translation [mm] (park+refine): " in capsys.readouterr().out
    res = json.loads((cal / "result.json").read_text())
    assert np.allclose(res["estimate"]["T_gripper_cam.translation"], [0.035, 0.06, 0.12], atol=2e-3)
    result = load_result(cal / "result.json")
    assert list(result.poses) == ["T_gripper_cam", "T_base_target"] and _bare_matrices(result) == []
    # the fixed target is estimated with X by the refinement: it has a std too
    assert all(0 < v < 1e-2 for v in res["std"]["T_base_target.translation"])
    assert len(res["diagnostics"]["closure_residuals"]["rotation_rad"]) == 16
    page = _rebuilt_equal(cal, tmp_path / "rep", "handeye", capsys)
    assert "Closed-form solvers compared" in page and all(m in page for m in ("tsai", "horaud", "daniilidis"))


def test_cli_bad_input_is_one_line(tmp_path, capsys):
    bad = tmp_path / "p.csv"
    bad.write_text("t [s], x [m], y [m], z [m], qx, qy, qz, qw\n0, 0, 0, 0, 0, 0, 0.5, 0.5\n")
    assert main(["handeye", "calibrate", str(bad), str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "unit quaternion" in capsys.readouterr().err


def test_rigs_registered_and_demo(tmp_path):
    assert RIG.name == "lineprofiler" and HANDEYE.name == "handeye"
    out = RIG.step("demo")(DemoContext(tmp_path, np.random.default_rng(2026), progress=False))
    assert out.passed, out.summary
    assert "undetermined" in out.summary


def test_calibrate_mct_example(tmp_path, capsys):
    assert main(["lineprofiler", "calibrate", str(EX / "mct_input.yaml"), "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "result.json").read_text())
    assert res["method"] == "mct" and not res["diagnostics"]["undetermined"]
    t = np.array(res["estimate"]["T_E_L.translation"])
    st = np.array(res["std"]["T_E_L.translation"])
    assert np.all((st > 5e-6) & (st < 3e-4))
    assert np.all(np.abs(t - [0.035, 0.06, 0.12]) < 4 * st)  # simulated truth in the file's comment
    assert "+/-" in capsys.readouterr().out
    d = res["diagnostics"]
    assert d["encoder_sigma_m"] == 5e-6  # the documented default
    assert set(d["covariance"]["std_by_source"]) == {"tracker", "heights", "block scan", "P3 encoder"}
    result = load_result(tmp_path / "result.json")
    # the intermediate frames are poses too, derived: no std of their own
    assert list(result.poses) == ["T_E_L", "T_T_L", "T_T_E", "T_T_B", "T_L_B"] and _bare_matrices(result) == []
    assert result.pose("T_T_L").std_rotation is None
    np.testing.assert_allclose(result.pose("T_T_E").T @ result.pose("T_E_L").T, result.pose("T_T_L").T,
                               atol=1e-12)  # eq. 5, X = T_T_E^-1 T_T_L: rounding only
    page = _rebuilt_equal(tmp_path, tmp_path / "rep", "lineprofiler", capsys)
    assert "P3 encoder sigma per scan profile 5.0 um" in page and "block-scan fit residuals" in page


def _mct_copy(tmp_path):
    for f in EX.glob("mct_*"):
        (tmp_path / f.name).write_bytes(f.read_bytes())
    return tmp_path / "mct_input.yaml"


@pytest.mark.parametrize("file, edit, message", [
    ("mct_block.csv", lambda s: s.replace("\n2, ", "\n3, ", 1), "must be 0, 1 or 2"),
    ("mct_block.csv", lambda s: "\n".join(ln for ln in s.splitlines() if not ln.startswith("1, ") or
                                          ln.endswith("0")) + "\n", "face 1 has"),
    ("mct_arc.csv", lambda s: s.replace("q1 [mm], q2 [deg], q3 [mm]", "a [mm], b [deg], c [mm]"), "joint columns"),
    ("mct_input.yaml", lambda s: s.replace("sigma: 0.02", "sigma: -0.02"), "heights.sigma"),
    ("mct_input.yaml", lambda s: s.replace("block_size: [60.000", "block_size: [0"), "block_size"),
    ("mct_input.yaml", lambda s: s.replace("method: mct", "method: tracker"), "method"),
    ("mct_input.yaml", lambda s: s.replace("# arm_sigma: {length: 0.3", "arm_sigma: {length: -0.3"), "arm_sigma"),
    ("mct_input.yaml", lambda s: s.replace("# encoder_sigma: 0.005", "encoder_sigma: -0.005"), "encoder_sigma"),
    ("mct_scan.csv", lambda s: s.replace("\n0, ", "\n0.5, ", 1), "line 2"),
    ("mct_scan.csv", lambda s: s.replace("q3 [mm]", "q3 [deg]"), "joint 3 is prismatic"),
    ("mct_arc.csv", lambda s: "\n".join(s.splitlines()[:3]) + "\n", "mct_arc.csv: 2 tracker reading(s)"),
])
def test_mct_input_errors_are_one_line(tmp_path, capsys, file, edit, message):
    yaml_path = _mct_copy(tmp_path)
    f = tmp_path / file
    f.write_text(edit(f.read_text()))
    assert main(["lineprofiler", "calibrate", str(yaml_path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err


def test_handeye_robot_world_example(tmp_path, capsys):
    # the same two pose lists give AX = ZB: T_gripper_cam and T_base_target together
    assert main(["handeye", "robot-world", str(EX / "gripper_poses.csv"), str(EX / "target_poses.csv"),
                 "--out", str(tmp_path)]) == 0
    assert "T_gripper_cam translation [mm]: 35.187 +/- 1.108, 59.455 +/- 0.390, 120.385 +/- 0.248" \
        in capsys.readouterr().out
    res = json.loads((tmp_path / "result.json").read_text())
    assert res["method"] == "robot-world shah+refine"
    result = load_result(tmp_path / "result.json")
    assert set(result.poses) == {"T_target_base", "T_cam_gripper", "T_base_target", "T_gripper_cam"}
    assert _bare_matrices(result) == []
    # 'robocal report' rebuilds a robot-world result through the handeye workflow as well
    _rebuilt_equal(tmp_path, tmp_path / "rep", "handeye", capsys)
    T = result.pose("T_gripper_cam").T
    assert np.allclose(T[:3, 3], [0.035, 0.06, 0.12], atol=2e-3)  # 0.2 mm / 1 mrad pose noise, 16 poses
    assert all(v is not None and 0 < v < 3e-3 for v in res["std"]["T_cam_gripper.translation"])
    assert np.allclose(result.pose("T_base_target").T @ result.pose("T_target_base").T, np.eye(4), atol=1e-12)
    # the inverses carry their std too (first order through the inverse), and the CLI prints it
    st = np.array(res["std"]["T_gripper_cam.translation"])
    assert np.all((st > 0) & (st < 3e-3)) and len(res["std"]["T_gripper_cam.rotvec"]) == 3
    assert np.all(np.abs(T[:3, 3] - [0.035, 0.06, 0.12]) < 4 * st)


def test_mct_arm_sigma_enters_the_covariance(tmp_path):
    yaml_path = _mct_copy(tmp_path)
    yaml_path.write_text(yaml_path.read_text().replace("# arm_sigma: {length: 0.3", "arm_sigma: {length: 0.3"))
    assert main(["lineprofiler", "calibrate", str(yaml_path), "--out", str(tmp_path / "o")]) == 0
    res = json.loads((tmp_path / "o" / "result.json").read_text())
    assert res["diagnostics"]["arm_dh_sigma"] == pytest.approx({"length_m": 3e-4, "angle_rad": np.deg2rad(0.1)})
    # 0.3 mm of arm error dominates the 0.03-0.08 mm the tracker and the scan leave
    assert all(v > 2.5e-4 for v in np.array(res["std"]["T_E_L.translation"])[[0, 2]])


def test_handeye_simulate_calibrate_recovers_the_truth(tmp_path, capsys):
    """``handeye simulate`` writes the two lists and their truth; ``calibrate`` finds X within its std (NEES)."""
    import yaml

    sim, cal = tmp_path / "sim", tmp_path / "cal"
    assert main(["handeye", "simulate", "--seed", "3", "--out", str(sim)]) == 0
    assert main(["handeye", "calibrate", str(sim / "gripper_poses.csv"), str(sim / "target_poses.csv"),
                 "--out", str(cal)]) == 0
    capsys.readouterr()
    truth = yaml.safe_load((sim / "truth.yaml").read_text())
    pose = load_result(cal / "result.json").pose("T_gripper_cam")
    R, t = np.array(truth["T_gripper_cam"]["rotation"]), np.array(truth["T_gripper_cam"]["translation"])
    err = np.r_[rotvec_from_matrix(pose.T[:3, :3] @ R.T), pose.T[:3, 3] - t]   # left rotation error, as the std
    check = truth_check(err, np.r_[pose.std_rotation, pose.std_translation])
    assert check.passed, check.to_dict()
    # and the check can fail: the same errors against a std 10x too small
    assert not truth_check(err, np.r_[pose.std_rotation, pose.std_translation] / 10).passed
