"""The OpenCV 4 reference replay (tests/support/opencv_reference.py) answers only the inputs it recorded."""

import cv2
import numpy as np
import pytest
from opencv_reference import FIXTURE, _Recorded


def test_replay_returns_the_recorded_output_and_refuses_other_inputs(cam, points_in_view):
    # the inputs of test_model.py::test_undistort_agrees_with_opencv_and_round_trips
    uv = cam.project(points_in_view(cam, np.random.default_rng(5), 300, margin=0.0))
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    replay = _Recorded(FIXTURE).replay("undistortPointsIter")
    ref = replay(uv.reshape(-1, 1, 2), cam.K, cam.dist, None, None, crit).reshape(-1, 2)
    # cv2's fixed-point iteration to 1e-15 vs robocal's Newton to 1e-14 (normalised units)
    assert np.max(np.abs(ref - cam.undistort_points(uv))) < 1e-8
    with pytest.raises(AssertionError, match="no OpenCV 4 output for these inputs"):
        replay((uv + 1e-3).reshape(-1, 1, 2), cam.K, cam.dist, None, None, crit)
    with pytest.raises(AssertionError, match="no OpenCV 4 output"):
        replay(uv[::-1].reshape(-1, 1, 2), cam.K, cam.dist, None, None, crit)  # same values, other order
