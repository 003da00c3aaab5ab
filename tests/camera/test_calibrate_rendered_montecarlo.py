"""The issue's Monte Carlo claim on RENDERED images: image -> detect_targets -> calibrate_intrinsics.

Each data set: 7 views of a 6x7 chessboard (20 mm squares, rows + cols odd, so
its orientation is measured) at 0.25-0.45 m, whole in a 320x240 image, drawn
by the renderer (exact under distortion), each view with its own blur
(0.5-1.6 px) and grey noise (1.5-6 levels on a 215-level contrast) as focus and
exposure vary in a real session, and 30 % vignetting. Corner errors are then
not the synthetic i.i.d. Gaussian of test_calibrate_montecarlo.py: they differ
by view (measured per-view RMS 0.024-0.062 px, 10-90 %), vignetting pulls
corners towards the centre (measured 0.004-0.014 px, growing with the radius)
and the detector misplaces a corner by pixels now and then.
"""

import numpy as np
import pytest

from robocal.camera import CameraModel, ChessboardTarget, calibrate_intrinsics, detect_targets, render_target_view
from robocal.camera._calibrate import _rodrigues

CAM = CameraModel(300.0, 302.5, 160.6, 119.4, (-0.28, 0.11, 8e-4, -6e-4, -0.02), 320, 240)
TARGET = ChessboardTarget(6, 7, 0.02)
VIEWS = 7
#: With honest stds each intrinsic's (RMSE / std)^2 is ~ chi-square(n) / n over n data sets: the ratio's
#: sampling std is ~1 / sqrt(2 n) (0.065 at 120). The issue's band 0.8-1.25 then fails a correct estimator
#: with probability 0.008 over all 9 intrinsics (0.02 at n = 100, the issue's minimum), and passes one whose
#: std is off by 1.4x in either direction with probability < 0.05 (1.5x: < 0.005). Measured on 500 sets
#: (bench_camera_calibrate.py --rendered): ratios 0.92-1.12. ~0.3 s CPU a set (render + detect 7 views
#: ~0.2 s, calibrate ~0.07 s with BLAS on one thread: a threaded BLAS on a busy machine costs several times that).
TRIALS = 120


def _poses(rng, n):
    """Board poses with the whole board and its quiet zone in the image (a chessboard is only detected whole)."""
    xmin, xmax, ymin, ymax = TARGET.board.extent()
    outline = np.array([[x, y, 0.0] for x in (xmin, xmax) for y in (ymin, ymax)])
    centre = TARGET.object_points().mean(axis=0)
    out = []
    while len(out) < n:
        pix = rng.uniform([0.3 * CAM.width, 0.3 * CAM.height], [0.7 * CAM.width, 0.7 * CAM.height])
        ray = np.append(CAM.undistort_points(pix), 1.0)
        T = np.eye(4)
        T[:3, :3] = _rodrigues(rng.uniform(-1, 1, 3) * [0.6, 0.6, 0.3])
        T[:3, 3] = ray / np.linalg.norm(ray) * rng.uniform(0.25, 0.45) - T[:3, :3] @ centre
        if np.all(CAM.in_image(CAM.project_points(outline, T, check=False), 1.0)):
            out.append(T)
    return out


def _data_set(rng):
    """``(views, poses)``: the detected corners of ``VIEWS`` rendered images (named ``view<i>.png``), the true poses."""
    poses = _poses(rng, VIEWS)
    images = [(f"view{i}.png", render_target_view(CAM, TARGET, T, rng, blur_sigma=rng.uniform(0.5, 1.6),
                                                  noise_sigma=rng.uniform(1.5, 6.0), vignetting=0.3))
              for i, T in enumerate(poses)]
    return detect_targets(images, TARGET).target_views(), poses


@pytest.mark.slow
def test_intrinsic_rmse_matches_reported_std_on_rendered_images():
    truth = np.array([CAM.fx, CAM.fy, CAM.cx, CAM.cy, *CAM.dist])
    errors, var, n_outliers = [], [], 0
    for k in range(TRIALS):
        cal = calibrate_intrinsics(_data_set(np.random.default_rng([12, k]))[0], CAM.size)
        errors.append(cal.values - truth)
        var.append(cal.std_array ** 2)
        n_outliers += len(cal.outliers)
    errors = np.array(errors)
    rmse = np.sqrt(np.mean(errors ** 2, axis=0))
    # reported std: RMS over the data sets (it varies with each set's geometry and noise)
    ratio = rmse / np.sqrt(np.mean(var, axis=0))
    assert np.all((ratio > 0.8) & (ratio < 1.25)), dict(zip(cal.labels, ratio.round(3)))
    # the error is noise, not bias: the vignetting's pull on the corners biases p2 by 0.22 RMSE (500 sets);
    # the mean's own std is RMSE / sqrt(120) = 0.09 RMSE, so 0.5 is 3 of them above that
    bias = np.abs(errors.mean(axis=0)) / rmse
    assert np.all(bias < 0.5), dict(zip(cal.labels, bias.round(2)))
    # each view is judged against its own noise: measured 26 corners removed in 500 sets (the detector's
    # misplaced ones); one noise level for all views removed 568, the tails of the noisier views
    assert n_outliers < 0.2 * TRIALS, n_outliers
