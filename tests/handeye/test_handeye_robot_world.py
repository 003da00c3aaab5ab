"""robot-world (AX = ZB, issue 13): --setup and --pairs, outliers named by pose number in the terminal, the
result and the report."""

import json

import numpy as np

from robocal.cli.main import main
from robocal.geometry import PoseWithCovariance, matrix_from_rotvec
from robocal.handeye import simulate_eye_in_hand
from robocal.io import load_result, write_poses
from truth_files import truth_pose


def test_robot_world_eye_to_hand_names_its_frames(tmp_path, capsys):
    sim, rw = tmp_path / "sim", tmp_path / "rw"
    assert main(["handeye", "simulate", "--setup", "eye-to-hand", "--poses", "20", "--seed", "3",
                 "--out", str(sim)]) == 0
    assert main(["handeye", "robot-world", str(sim / "gripper_poses.csv"), str(sim / "target_poses.csv"),
                 "--setup", "eye-to-hand", "--pairs", "consecutive", "--out", str(rw)]) == 0
    out = capsys.readouterr().out
    assert "T_base_cam translation [mm]: " in out and "T_base_cam rotation std [mrad]" in out
    res = load_result(rw / "result.json")
    assert set(res.poses) == {"T_target_gripper", "T_cam_base", "T_gripper_target", "T_base_cam"}
    assert res.diagnostics["setup"] == "eye-to-hand" and res.diagnostics["pairs"] == "consecutive"
    assert len(res.diagnostics["closure_residuals"]["rotation_rad"]) == 20
    for name in ("T_base_cam", "T_gripper_target"):
        pose = PoseWithCovariance.from_result(res, name)
        err = pose.error_to(truth_pose(sim / "truth.yaml", name))
        # 1 mrad / 0.2 mm per view, 20 views; the inverses' stds by first-order propagation. 12
        # components: a 4.5-sigma bound fails by chance < 1e-4 (the seed gives at most ~2 sigma)
        assert np.all(np.abs(err.vector) < 4.5 * pose.std), (name, err.vector / pose.std)
    # the eye-to-hand lists taken as eye-in-hand are refused in one line (exit 2), naming the set-up
    assert main(["handeye", "robot-world", str(sim / "gripper_poses.csv"), str(sim / "target_poses.csv"),
                 "--out", str(tmp_path / "wrong")]) == 2
    assert "--setup" in capsys.readouterr().err


def test_robot_world_outlier_named_in_terminal_result_and_report(tmp_path, capsys):
    n, bad = 20, 7
    s = simulate_eye_in_hand(np.random.default_rng(4), n)
    Tc = s.T_cam_target.copy()
    Tc[bad, :3, :3] = matrix_from_rotvec([0.06, 0.0, 0.03]) @ Tc[bad, :3, :3]     # 3.8 deg, ~60x the noise
    g = write_poses(tmp_path / "g.csv", s.T_base_gripper)                       # no times: named by number
    c = write_poses(tmp_path / "c.csv", Tc)
    assert main(["handeye", "robot-world", str(g), str(c), "--pairs", "all", "--out", str(tmp_path / "rw")]) == 0
    err = capsys.readouterr().err
    assert "[outliers] pose 7: " in err
    warns = {w["code"]: w for w in json.loads((tmp_path / "rw" / "result.json").read_text())["warnings"]}
    assert warns["outliers"]["indices"] == [7]
    assert "pose 7: the closure A X = Z B of this pose is an outlier" in (tmp_path / "rw" / "report.html").read_text()
    d = json.loads((tmp_path / "rw" / "result.json").read_text())["diagnostics"]
    rot = np.asarray(d["closure_residuals"]["rotation_rad"])
    assert int(np.argmax(rot)) == bad                   # the per-pose figure shows it too
