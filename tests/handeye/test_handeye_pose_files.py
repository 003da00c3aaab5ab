"""The pose files users have, through the command (issue 13): the reader says which form it found."""

import json

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from robocal.cli.main import main
from robocal.handeye import simulate_eye_in_hand, transform_error


def test_tum_robot_log_and_opencv_camera_poses(tmp_path, capsys):
    sim = simulate_eye_in_hand(np.random.default_rng(9), 12)
    t = 100.0 + 0.5 * np.arange(12)
    q = Rotation.from_matrix(sim.T_base_gripper[:, :3, :3]).as_quat()
    g = tmp_path / "robot.txt"
    g.write_text("# timestamp tx ty tz qx qy qz qw\n" + "".join(
        " ".join(f"{v:.12g}" for v in (ti, *p, *qi)) + "\n" for ti, p, qi in zip(t, sim.T_base_gripper[:, :3, 3], q)))
    c = tmp_path / "camera.yml"
    fs = cv2.FileStorage(str(c), cv2.FILE_STORAGE_WRITE)
    for i, T in enumerate(sim.T_cam_target):
        fs.write(f"T_cam_target_{i}", T)
    fs.release()
    assert main(["handeye", "calibrate", str(g), str(c), "--out", str(tmp_path / "cal")]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if ln.startswith("read "))
    assert "robot.txt: CSV without a header, 8 values a row: TUM t x y z qx qy qz qw" in line
    assert "camera.yml: OpenCV FileStorage: 12 4x4 matrices (T_cam_target_0 ... T_cam_target_11, m)" in line
    res = json.loads((tmp_path / "cal" / "result.json").read_text())
    assert set(res["diagnostics"]["pose_files"]) == {"robot.txt", "camera.yml"}
    T = np.eye(4)
    T[:3, :3] = res["estimate"]["T_gripper_cam.rotation"]
    T[:3, 3] = res["estimate"]["T_gripper_cam.translation"]
    rot, trans = transform_error(T, sim.X)
    assert rot < 3e-3 and trans < 3e-3     # 12 views at 1 mrad / 0.2 mm: X to ~0.5 mrad / ~1 mm
