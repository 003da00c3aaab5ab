"""Both set-ups named (issue 13): --setup eye-in-hand | eye-to-hand, the frames in the result."""

import json

import numpy as np
import pytest
import yaml

from robocal.cli.main import main
from robocal.errors import ImplausibleInputError, InputError
from robocal.geometry import PoseWithCovariance
from robocal.handeye import calibrate_hand_eye, simulate_eye_to_hand
from robocal.io import load_result
from truth_files import truth_pose


def test_eye_to_hand_round_trip_names_its_frames(tmp_path, capsys):
    sim, cal = tmp_path / "sim", tmp_path / "cal"
    assert main(["handeye", "simulate", "--setup", "eye-to-hand", "--poses", "20", "--seed", "3",
                 "--out", str(sim)]) == 0
    assert main(["handeye", "calibrate", str(sim / "gripper_poses.csv"), str(sim / "target_poses.csv"),
                 "--setup", "eye-to-hand", "--out", str(cal)]) == 0
    out = capsys.readouterr().out
    assert "T_base_cam translation [mm] (tsai+refine): " in out
    res = load_result(cal / "result.json")
    assert set(res.poses) == {"T_base_cam", "T_gripper_target"}
    assert res.diagnostics["setup"] == "eye-to-hand"
    for name in ("T_base_cam", "T_gripper_target"):
        err = PoseWithCovariance.from_result(res, name).error_to(truth_pose(sim / "truth.yaml", name))
        std = PoseWithCovariance.from_result(res, name).std
        # 1 mrad / 0.2 mm per view over 20 views: each component within 4.5 of its own std (the stds are
        # the refinement's first-order ones; 12 components, so a 4.5-sigma bound fails by chance < 1e-4)
        assert np.all(np.abs(err.vector) < 4.5 * std), (name, err.vector / std)
    assert yaml.safe_load((sim / "truth.yaml").read_text())["setup"] == "eye-to-hand"


def test_the_wrong_setup_is_named():
    sim = simulate_eye_to_hand(np.random.default_rng(2), 16)
    with pytest.raises(ImplausibleInputError) as e:
        calibrate_hand_eye(sim.T_base_gripper, sim.T_cam_target)       # eye-to-hand lists, eye-in-hand set-up
    assert e.value.slip == "gripper_poses_inverted" and "--setup" in str(e.value)
    res = calibrate_hand_eye(sim.T_base_gripper, sim.T_cam_target, setup="eye-to-hand")
    assert res.names == ("T_base_cam", "T_gripper_target") and not res.warnings
    with pytest.raises(InputError, match="setup must be one of eye-in-hand, eye-to-hand, got 'eye-on-hand'"):
        calibrate_hand_eye(sim.T_base_gripper, sim.T_cam_target, setup="eye-on-hand")


def test_eye_in_hand_result_keeps_its_names(tmp_path, capsys):
    sim, cal = tmp_path / "sim", tmp_path / "cal"
    assert main(["handeye", "simulate", "--poses", "8", "--out", str(sim)]) == 0
    assert main(["handeye", "calibrate", str(sim / "gripper_poses.csv"), str(sim / "target_poses.csv"),
                 "--out", str(cal)]) == 0
    capsys.readouterr()
    d = json.loads((cal / "result.json").read_text())
    assert d["diagnostics"]["setup"] == "eye-in-hand"
    assert {"T_gripper_cam", "T_base_target"} <= set(load_result(cal / "result.json").poses)
