import numpy as np
import pytest

from robocal.camera import CameraModel


@pytest.fixture
def cam():
    """640x480 camera with a realistic barrel distortion."""
    return CameraModel(600.0, 605.0, 321.3, 238.7, (-0.28, 0.11, 8e-4, -6e-4, -0.02), 640, 480)


@pytest.fixture
def cam_plain():
    return CameraModel(500.0, 500.0, 319.5, 239.5, (0.0, 0.0, 0.0, 0.0), 640, 480)


@pytest.fixture
def points_in_view():
    return _points_in_view


def _points_in_view(camera, rng, n, z=(0.4, 1.2), margin=5.0):
    """Camera-frame points whose projections fall inside the image."""
    uv = rng.uniform([margin, margin], [camera.width - 1 - margin, camera.height - 1 - margin], (n, 2))
    xy = camera.undistort_points(uv)
    depth = rng.uniform(*z, n)
    return np.column_stack([xy * depth[:, None], depth])
