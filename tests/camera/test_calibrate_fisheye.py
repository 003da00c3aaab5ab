"""FisheyeCamera projects like cv2.fisheye.projectPoints; calibrate_intrinsics(model='fisheye') fits it."""

import cv2
import numpy as np
import pytest

from robocal.camera import Checkerboard, FisheyeCamera, calibrate_intrinsics, projection_uncertainty
from robocal.camera import simulate_target_views
from robocal.camera._calibrate import fisheye_flag
from robocal.errors import DegenerateGeometryError, InputError
from robocal.estimation import truth_check

CAM = FisheyeCamera(300.0, 302.0, 321.3, 238.7, (0.05, -0.02, 0.008, -0.001), 640, 480)


def test_projection_matches_opencv_fisheye():
    rng = np.random.default_rng(0)
    # up to ~80 deg off the axis, and the axis itself (the theta_d / r limit)
    p = np.vstack([np.column_stack([rng.uniform(-2, 2, (300, 2)), rng.uniform(0.35, 2, 300)]), [[0.0, 0.0, 1.0]]])
    ref = cv2.fisheye.projectPoints(p.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), CAM.K,
                                    np.array(CAM.k))[0].reshape(-1, 2)
    np.testing.assert_allclose(CAM.project(p), ref, rtol=0, atol=1e-9)  # same double-precision formula
    np.testing.assert_allclose(CAM.undistort_points(ref), p[:, :2] / p[:, 2:], rtol=0, atol=1e-10)
    with pytest.raises(DegenerateGeometryError):
        CAM.project([0.0, 0.0, -1.0])
    with pytest.raises(InputError, match="4 values"):
        FisheyeCamera(300.0, 300.0, 320.0, 240.0, (0.1, 0.0, 0.0), 640, 480)


def test_calibrate_fisheye_against_truth_and_opencv():
    views, _ = simulate_target_views(CAM, Checkerboard(6, 9, 0.03).object_points(), 15, np.random.default_rng(3),
                                     noise_px=0.3, distance=(0.2, 0.5))
    cal = calibrate_intrinsics(views, CAM.size, model="fisheye")
    assert isinstance(cal.camera, FisheyeCamera) and cal.labels[4:] == ("k1", "k2", "k3", "k4")
    chk = truth_check(cal.values - np.array([300.0, 302.0, 321.3, 238.7, *CAM.k]), cal.cov, names=list(cal.labels))
    assert chk.passed, chk
    rms, K, D, _, _ = cv2.fisheye.calibrate(
        [v.object_points.reshape(1, -1, 3) for v in cal.views], [v.image_points.reshape(1, -1, 2) for v in cal.views],
        CAM.size, None, None, flags=fisheye_flag("CALIB_RECOMPUTE_EXTRINSIC") | fisheye_flag("CALIB_FIX_SKEW"),
        criteria=(cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-10))
    cv = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *D.ravel()])
    # the same optimum: within 5 % of a std (solver tolerances), RMS no worse (cv2's per corner = sqrt 2 x ours)
    assert np.all(np.abs(cal.values - cv) < 0.05 * cal.std_array), (cal.values - cv) / cal.std_array
    assert cal.rms * np.sqrt(2) <= rms * (1 + 1e-6)
    pu = projection_uncertainty(cal, grid_step_px=80)
    assert np.all(np.isfinite(pu.std)) and np.all(pu.std > 0)


def test_fisheye_jacobian_matches_finite_differences():
    from robocal.camera._calibrate import _fisheye_start, _fit, _model_labels

    views, _ = simulate_target_views(CAM, Checkerboard(6, 9, 0.03).object_points(), 3, np.random.default_rng(4),
                                     distance=(0.2, 0.5))
    labels = _model_labels("fisheye")
    fixed = np.zeros(8, bool)
    _, x0, p0 = _fisheye_start(views, CAM.size, fixed, labels)
    prob, _ = _fit(views, x0, p0, fixed, labels, outlier_sigma=5.0)
    chk = prob.check_jacobian()
    assert chk.max_rel_error < 1e-5, chk  # 3-point differences: ~1e-8 relative truncation
