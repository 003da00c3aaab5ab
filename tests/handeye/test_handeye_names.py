"""Warnings name POSES (numbers from 0 in file order, and times when the files have them), never motion pairs."""

import json

import numpy as np

from robocal.cli.main import main
from robocal.geometry import matrix_from_rotvec
from robocal.handeye import calibrate_hand_eye, simulate_eye_in_hand
from robocal.io import write_poses


def _outlier_lists(tmp_path, bad=7, n=20):
    """Simulated lists whose sensor pose ``bad`` is turned 3.8 deg (~60x the 1 mrad noise)."""
    sim = simulate_eye_in_hand(np.random.default_rng(4), n)
    Tc = sim.T_cam_target.copy()
    Tc[bad, :3, :3] = matrix_from_rotvec([0.06, 0.0, 0.03]) @ Tc[bad, :3, :3]
    t = np.arange(n) * 0.1
    return write_poses(tmp_path / "g.csv", sim.T_base_gripper, t), write_poses(tmp_path / "c.csv", Tc, t), Tc, sim


def test_an_outlier_pose_is_named_by_number_and_time(tmp_path, capsys):
    g, c, _, _ = _outlier_lists(tmp_path)
    assert main(["handeye", "calibrate", str(g), str(c), "--out", str(tmp_path / "cal")]) == 0
    err = capsys.readouterr().err
    warns = {w["code"]: w for w in json.loads((tmp_path / "cal" / "result.json").read_text())["warnings"]}
    # pose 7 is in 19 of the 190 pairs; the pairs it spoils must not show up as motion indices
    assert warns["inconsistent_data"]["indices"] == [7]
    assert warns["outliers"]["indices"] == [7]
    for code in ("inconsistent_data", "outliers"):
        assert warns[code]["message"].startswith("pose 7 (t = 0.700 s): ")
        assert f"[{code}] pose 7 (t = 0.700 s)" in err        # the terminal shows them


def test_robot_world_names_the_outlier_pose(tmp_path, capsys):
    g, c, _, _ = _outlier_lists(tmp_path)
    assert main(["handeye", "robot-world", str(g), str(c), "--out", str(tmp_path / "rw")]) == 0
    err = capsys.readouterr().err
    warns = {w["code"]: w for w in json.loads((tmp_path / "rw" / "result.json").read_text())["warnings"]}
    assert warns["outliers"]["indices"] == [7]
    assert "[outliers] pose 7 (t = 0.700 s)" in err


def test_without_times_poses_are_named_by_number_and_consecutive_pairs_name_the_pose(tmp_path):
    _, _, Tc, sim = _outlier_lists(tmp_path, bad=11, n=40)
    for pairs in ("auto", "consecutive"):
        res = calibrate_hand_eye(sim.T_base_gripper, Tc, pairs=pairs)
        bad = [w for w in res.warnings if w.code == "inconsistent_data"]
        # consecutive pairs: pose 11 spoils (10, 11) and (11, 12); its neighbours only one of their two
        assert bad and bad[0].indices == (11,) and bad[0].message.startswith("pose 11: "), res.warnings
