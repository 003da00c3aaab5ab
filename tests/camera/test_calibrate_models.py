"""CameraModel with OpenCV's 8/12/14-term distortion projects as cv2.projectPoints; calibrate_intrinsics fits them."""

import cv2
import numpy as np
import pytest

from robocal.camera import CameraModel, Checkerboard, calibrate_intrinsics, simulate_target_views
from robocal.errors import InputError

RATIONAL = (0.35, -0.12, 4e-4, -3e-4, 0.02, 0.62, -0.05, 0.03)
PRISM = (*RATIONAL, 2e-3, -4e-4, -1.5e-3, 3e-4)


@pytest.mark.parametrize("dist", [RATIONAL, PRISM, (*PRISM, 0.0, 0.0)], ids=["8", "12", "14-untilted"])
def test_projection_matches_opencv(dist):
    cam = CameraModel(600.0, 605.0, 321.3, 238.7, dist, 640, 480)
    rng = np.random.default_rng(5)
    p = np.column_stack([rng.uniform(-0.5, 0.5, (200, 2)), rng.uniform(0.5, 2.0, 200)])
    ref = cv2.projectPoints(p.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, np.array(dist))[0].reshape(-1, 2)
    # both evaluate the same polynomial in double precision: round-off ~1e-13 px at these magnitudes
    np.testing.assert_allclose(cam.project(p), ref, rtol=0, atol=1e-9)
    uv, J = cam.project_jacobian(p)
    h = 1e-6
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        fd = (cam.project(p + e) - cam.project(p - e)) / (2 * h)
        np.testing.assert_allclose(J[:, :, j], fd, rtol=0, atol=1e-4)  # central differences, h = 1 um
    xy = cam.undistort_points(uv)
    np.testing.assert_allclose(xy, p[:, :2] / p[:, 2:], rtol=0, atol=1e-11)


def test_tilted_model_and_bad_lengths_refused():
    with pytest.raises(InputError, match="tilted"):
        CameraModel(600.0, 600.0, 320.0, 240.0, (*PRISM, 0.01, 0.0), 640, 480)
    with pytest.raises(InputError, match="got shape \\(6,\\)"):
        CameraModel(600.0, 600.0, 320.0, 240.0, np.zeros(6), 640, 480)


@pytest.mark.parametrize("model,dist", [("opencv8", RATIONAL), ("opencv12", PRISM)])
def test_calibrate_rational_and_thin_prism(model, dist):
    cam = CameraModel(600.0, 605.0, 321.3, 238.7, dist, 640, 480)
    views, _ = simulate_target_views(cam, Checkerboard(6, 9, 0.03).object_points(), 20, np.random.default_rng(8),
                                     noise_px=0.2)
    cal = calibrate_intrinsics(views, cam.size, model=model)
    assert cal.labels[-1] == ("k6" if model == "opencv8" else "s4") and cal.camera.dist.size == len(dist)
    # the rational terms trade against each other (numerator against denominator): that is named, and the
    # estimate is judged by what the data determine, the shape of the projection. A uniform shift is the
    # principal point trading against the views' rotation (cx std ~1 px, mrcal's point): it is removed and
    # checked against that std. Over the middle 80 % of the image, covered densely (20 views x ~50 corners at
    # 0.2 px), the rest is measured at 0.13 px for this seed; 0.3 px is far below the 1-10 px of a wrong shape.
    assert {"rank_deficient", "weakly_determined"} & set(cal.warning_codes()), cal.warnings
    uu, vv = np.meshgrid(np.linspace(64, 576, 12), np.linspace(48, 432, 9))
    rays = np.append(cam.undistort_points(np.stack([uu, vv], -1)), np.ones((9, 12, 1)), axis=-1)
    e = cal.camera.project(rays) - cam.project(rays)
    if model == "opencv8":
        assert np.max(np.abs(e - e.mean(axis=(0, 1)))) < 0.3
        assert abs(cal.values[2] - cam.cx) < 3 * cal.std["cx"] and abs(cal.values[3] - cam.cy) < 3 * cal.std["cy"]
    else:
        # thin prism s1, s3 trade against the principal point and the views' rotation (a shift of the whole
        # image, here ~5 px, that the poses absorb): the ray's pixel is not determined; the terms are named
        # and the principal point's std says so (cx std ~4 px vs ~1 px with opencv8)
        assert {"s1", "s3"} <= {p for d in cal.warnings for p in d.params}, cal.warnings
        assert abs(cal.values[2] - cam.cx) < 4 * cal.std["cx"] and cal.std["cx"] > 2.0
    flags = cv2.CALIB_RATIONAL_MODEL | (cv2.CALIB_THIN_PRISM_MODEL if model == "opencv12" else 0)
    rms, *_ = cv2.calibrateCamera([v.object_points.astype(np.float32) for v in cal.views],
                                  [v.image_points.astype(np.float32) for v in cal.views], cam.size, None, None,
                                  flags=flags)
    # equal-noise views pass the homogeneity test: one noise level, cv2's objective. cv2's rms is per corner
    # (sqrt 2 x ours); ours may only be lower (cv2 stops on float32 input, ~1e-6)
    assert len(set(cal.view_sigma.values())) == 1, cal.view_sigma
    assert cal.rms * np.sqrt(2) <= rms * (1 + 1e-6)
