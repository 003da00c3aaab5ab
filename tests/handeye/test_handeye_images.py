"""Images in (issue 13): rendered views -> each view's pose with its covariance -> X, in both set-ups."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from robocal.cli.main import main
from robocal.geometry import PoseWithCovariance, matrix_from_rotvec
from robocal.handeye import SETUPS, calibrate_hand_eye, simulate_eye_in_hand, transform_error
from robocal.io import load_result
from truth_files import truth_pose


@pytest.mark.parametrize("setup", ["eye-in-hand", "eye-to-hand"])
def test_rendered_views_calibrate_end_to_end(tmp_path, capsys, setup):
    sim, cal = tmp_path / "sim", tmp_path / "cal"
    assert main(["handeye", "simulate-images", "--setup", setup, "--poses", "8", "--seed", "1",
                 "--out", str(sim)]) == 0
    blank = sim / "images" / "view_05.png"                      # one image without the board
    cv2.imwrite(str(blank), np.full((480, 640), 128, np.uint8))
    assert main(["handeye", "calibrate-images", "--images", str(sim / "images"), "--robot",
                 str(sim / "robot_poses.csv"), "--camera", str(sim / "camera.yaml"), "--target",
                 str(sim / "target.yaml"), "--setup", setup, "--out", str(cal)]) == 0
    cap = capsys.readouterr()
    xname, yname = SETUPS[setup]["X"][0], SETUPS[setup]["Y"][0]
    assert f"{xname} translation [mm]" in cap.out and "7 of 8 images of a chessboard" in cap.out
    assert "view_05.png: target not found" in cap.err           # named, its robot pose dropped
    res = load_result(cal / "result.json")
    views = res.diagnostics["views"]
    assert [v["pose"] for v in views] == [0, 1, 2, 3, 4, 6, 7]
    assert yname in res.poses
    for name in (xname,):          # the target pose is in the detector's corner numbering (images.py)
        est = PoseWithCovariance.from_result(res, name)
        err = est.error_to(truth_pose(sim / "truth.yaml", name))
        # rendered views (1 grey level of noise, 0.02-0.03 px corner RMS, pixel sigma floored at 0.05 px):
        # X to ~10-70 um / 0.1 mrad; each component within 5 of its own std (6 components)
        assert np.all(np.abs(err.vector) < 5 * est.std), (name, err.vector / est.std)
        assert err.translation < 5e-4 and err.rotation < 2e-3


def test_per_view_stds_down_weight_a_bad_view():
    sim = simulate_eye_in_hand(np.random.default_rng(12), 12, noise=False)
    Tc = sim.T_cam_target.copy()
    rng = np.random.default_rng(5)
    Tc[:, :3, :3] = matrix_from_rotvec(rng.normal(size=(12, 3)) * 1e-4) @ Tc[:, :3, :3]
    Tc[:, :3, 3] += rng.normal(size=(12, 3)) * 2e-5
    Tc[4, :3, :3] = matrix_from_rotvec([0.02, -0.015, 0.01]) @ Tc[4, :3, :3]   # one view 200x worse
    Tc[4, :3, 3] += [4e-3, -3e-3, 2e-3]
    sig = np.tile([1e-4, 2e-5], (12, 1))
    sig[4] = [2e-2, 4e-3]                                        # ... and said so by its covariance
    plain = calibrate_hand_eye(sim.T_base_gripper, Tc)
    weighted = calibrate_hand_eye(sim.T_base_gripper, Tc, pose_sigmas=sig)
    e_plain = transform_error(plain.X, sim.X)
    e_w = transform_error(weighted.X, sim.X)
    # the bad view pulls the equal-weight fit by ~1/12 of its 25 mrad / 5 mm error; weighted 200x down it
    # moves X by ~1/500 of it: the noise of the other views (~0.05 mrad / 10 um) is what remains
    assert e_w[0] < e_plain[0] / 5 and e_w[1] < e_plain[1] / 5, (e_plain, e_w)
    with pytest.raises(Exception, match="pose_sigmas must be"):
        calibrate_hand_eye(sim.T_base_gripper, Tc, pose_sigmas=sig[:5])


EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "handeye"


def test_calibrate_with_an_image_folder_is_calibrate_images(tmp_path, capsys):
    # issue 13's form of the command (calibrate ROBOT --images DIR ...) and calibrate-images: one loader, so the
    # same estimate to the last bit on the committed example (6 rendered views)
    a, b = tmp_path / "a", tmp_path / "b"
    files = ["--camera", str(EXAMPLE / "camera.yaml"), "--target", str(EXAMPLE / "target.yaml")]
    assert main(["handeye", "calibrate", str(EXAMPLE / "robot_poses.csv"), "--images", str(EXAMPLE / "images"),
                 *files, "--out", str(a)]) == 0
    assert main(["handeye", "calibrate-images", "--robot", str(EXAMPLE / "robot_poses.csv"), "--images",
                 str(EXAMPLE / "images"), *files, "--out", str(b)]) == 0
    ra, rb = load_result(a / "result.json"), load_result(b / "result.json")
    xa, xb = PoseWithCovariance.from_result(ra, "T_gripper_cam"), PoseWithCovariance.from_result(rb, "T_gripper_cam")
    assert np.array_equal(xa.T, xb.T) and np.array_equal(xa.std, xb.std)
    assert ra.method == rb.method and ra.method.endswith("+cov")        # each view weighted by its covariance
    assert len(ra.diagnostics["views"]) == 6 and ra.inputs == rb.inputs
    assert abs(xa.T[0, 3] - 0.035) < 5 * xa.std[3]                      # truth 35 mm (examples/handeye/truth.yaml)


@pytest.mark.parametrize("argv, match", [
    (["--images", "{ex}/images", "--camera", "{ex}/camera.yaml", "--target", "{ex}/target.yaml"],
     "--images DIR needs the robot poses"),
    (["{ex}/robot_poses.csv", "--images", "{tmp}/nowhere", "--camera", "{ex}/camera.yaml", "--target",
      "{ex}/target.yaml"], "no such folder; with --bag, --images names an image topic"),
    (["{ex}/robot_poses.csv", "--images", "{ex}/images"], "needs --camera CAM and --target TARGET.yaml"),
])
def test_an_image_folder_without_what_it_needs_is_one_line(tmp_path, capsys, argv, match):
    argv = [a.format(ex=EXAMPLE, tmp=tmp_path) for a in argv]
    assert main(["handeye", "calibrate", *argv, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0], err
