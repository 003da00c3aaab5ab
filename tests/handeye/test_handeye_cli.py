"""The ``robocal handeye`` commands on the example pose lists, their errors, simulate -> calibrate."""

import json
from pathlib import Path

import numpy as np

from robocal.cli.main import main
from robocal.estimation import truth_check
from robocal.geometry import PoseWithCovariance
from robocal.handeye.cli import HANDEYE
from robocal.io import load_result
from report_pages import bare_matrices, rebuilt_equal

EX = Path(__file__).resolve().parents[2] / "examples" / "lineprofiler"


def test_declared_by_the_core():
    assert HANDEYE.name == "handeye" and HANDEYE.calibrate.startswith("robocal.handeye.")


def test_handeye_example(tmp_path, capsys):
    cal = tmp_path / "cal"
    assert main(["handeye", "calibrate", str(EX / "gripper_poses.csv"), str(EX / "target_poses.csv"),
                 "--method", "park", "--out", str(cal)]) == 0
    assert "T_gripper_cam translation [mm] (park+refine): " in capsys.readouterr().out
    res = json.loads((cal / "result.json").read_text())
    assert np.allclose(res["estimate"]["T_gripper_cam.translation"], [0.035, 0.06, 0.12], atol=2e-3)
    result = load_result(cal / "result.json")
    assert list(result.poses) == ["T_gripper_cam", "T_base_target"] and bare_matrices(result) == []
    # the fixed target is estimated with X by the refinement: it has a std too
    assert all(0 < v < 1e-2 for v in res["std"]["T_base_target.translation"])
    assert len(res["diagnostics"]["closure_residuals"]["rotation_rad"]) == 16
    page = rebuilt_equal(cal, tmp_path / "rep", "handeye", capsys)
    assert "Closed-form solvers compared" in page and all(m in page for m in ("tsai", "horaud", "daniilidis"))


def test_cli_bad_input_is_one_line(tmp_path, capsys):
    bad = tmp_path / "p.csv"
    bad.write_text("t [s], x [m], y [m], z [m], qx, qy, qz, qw\n0, 0, 0, 0, 0, 0, 0.5, 0.5\n")
    assert main(["handeye", "calibrate", str(bad), str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "unit quaternion" in capsys.readouterr().err


def test_handeye_robot_world_example(tmp_path, capsys):
    # the same two pose lists give AX = ZB: T_gripper_cam and T_base_target together
    rw = tmp_path / "rw"
    assert main(["handeye", "robot-world", str(EX / "gripper_poses.csv"), str(EX / "target_poses.csv"),
                 "--out", str(rw)]) == 0
    assert "T_gripper_cam translation [mm]: 34.677 +/- 0.884, 59.593 +/- 0.288, 120.272 +/- 0.181" \
        in capsys.readouterr().out
    res = json.loads((rw / "result.json").read_text())
    assert res["method"] == "robot-world shah+refine"
    result = load_result(rw / "result.json")
    assert set(result.poses) == {"T_target_base", "T_cam_gripper", "T_base_target", "T_gripper_cam"}
    assert bare_matrices(result) == []
    # 'robocal report' rebuilds a robot-world result through the handeye workflow as well
    rebuilt_equal(rw, tmp_path / "rep", "handeye", capsys)
    T = result.pose("T_gripper_cam").T
    assert np.allclose(T[:3, 3], [0.035, 0.06, 0.12], atol=2e-3)  # 0.2 mm / 1 mrad pose noise, 16 poses
    assert all(v is not None and 0 < v < 3e-3 for v in res["std"]["T_cam_gripper.translation"])
    assert np.allclose(result.pose("T_base_target").T @ result.pose("T_target_base").T, np.eye(4), atol=1e-12)
    # the inverses carry their std too (first order through the inverse), and the CLI prints it
    st = np.array(res["std"]["T_gripper_cam.translation"])
    assert np.all((st > 0) & (st < 3e-3)) and len(res["std"]["T_gripper_cam.rotvec"]) == 3
    assert np.all(np.abs(T[:3, 3] - [0.035, 0.06, 0.12]) < 4 * st)


def test_handeye_simulate_calibrate_recovers_the_truth(tmp_path, capsys):
    """``handeye simulate`` writes the two lists and their truth; ``calibrate`` finds X within its std (NEES)."""
    import yaml

    sim, cal = tmp_path / "sim", tmp_path / "cal"
    assert main(["handeye", "simulate", "--seed", "3", "--out", str(sim)]) == 0
    assert main(["handeye", "calibrate", str(sim / "gripper_poses.csv"), str(sim / "target_poses.csv"),
                 "--out", str(cal)]) == 0
    capsys.readouterr()
    truth = yaml.safe_load((sim / "truth.yaml").read_text())
    pose = PoseWithCovariance.from_result(load_result(cal / "result.json"), "T_gripper_cam")
    T_true = np.eye(4)
    T_true[:3, :3], T_true[:3, 3] = truth["T_gripper_cam"]["rotation"], truth["T_gripper_cam"]["translation"]
    err = pose.error_to(T_true).vector           # on the result's (left) side, as the std
    check = truth_check(err, pose.std)
    assert check.passed, check.to_dict()
    # and the check can fail: the same errors against a std 10x too small
    assert not truth_check(err, pose.std / 10).passed
