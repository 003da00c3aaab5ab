import dataclasses

import cv2
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from opencv_reference import opencv

from robocal.camera import CameraModel, camera_from_document
from robocal.errors import DegenerateGeometryError, FileFormatError, InputError, NonFiniteError, ShapeError
from robocal.geometry import transform_from_rotvec
from robocal.io import parse_document


def test_project_matches_opencv(cam, points_in_view):
    rng = np.random.default_rng(1)
    p = points_in_view(cam, rng, 200)
    # include points well outside the image too: the model is the same polynomial
    p = np.vstack([p, rng.uniform([-0.6, -0.5, 0.5], [0.6, 0.5, 1.0], (100, 3))])
    ref = cv2.projectPoints(p, np.zeros(3), np.zeros(3), cam.K, cam.dist)[0].reshape(-1, 2)
    assert np.max(np.abs(cam.project(p) - ref)) < 1e-9


def test_project_points_matches_opencv_with_pose(cam):
    rng = np.random.default_rng(2)
    p = rng.uniform(-0.1, 0.1, (30, 3))
    rvec, tvec = np.array([0.3, -0.2, 0.1]), np.array([0.02, -0.01, 0.6])
    ref = cv2.projectPoints(p, rvec, tvec, cam.K, cam.dist)[0].reshape(-1, 2)
    got = cam.project_points(p, transform_from_rotvec(rvec, tvec))
    assert np.max(np.abs(got - ref)) < 1e-9


def test_project_points_broadcasts_poses(cam):
    # V views of the same N points in one call, each matching OpenCV's projectPoints
    rng = np.random.default_rng(5)
    p = rng.uniform(-0.1, 0.1, (30, 3))
    rv, tv = rng.normal(size=(4, 3)) * 0.2, np.c_[rng.normal(size=(4, 2)) * 0.02, np.full(4, 0.6)]
    T = transform_from_rotvec(rv, tv)
    uv = cam.project_points(p, T[:, None])
    assert uv.shape == (4, 30, 2)
    for k in range(4):
        ref = cv2.projectPoints(p, rv[k], tv[k], cam.K, cam.dist)[0].reshape(-1, 2)
        assert np.max(np.abs(uv[k] - ref)) < 1e-9
    with pytest.raises(ShapeError, match=r"T_cam_obj\[:, None\]"):
        cam.project_points(p, T)  # (4, 4, 4) against (30, 3): which pose for which point?


def test_project_is_vectorised_over_batches(cam, points_in_view):
    p = points_in_view(cam, np.random.default_rng(3), 24).reshape(2, 3, 4, 3)
    uv = cam.project(p)
    assert uv.shape == (2, 3, 4, 2)
    assert np.allclose(uv.reshape(-1, 2), cam.project(p.reshape(-1, 3)), atol=0, rtol=0)


def test_project_jacobian_matches_finite_differences(cam, points_in_view):
    p = points_in_view(cam, np.random.default_rng(4), 20)
    uv, J = cam.project_jacobian(p)
    assert np.allclose(uv, cam.project(p), rtol=0, atol=1e-12)
    h = 1e-6
    J_fd = np.empty_like(J)
    for k in range(3):
        dp = np.zeros(3)
        dp[k] = h
        J_fd[..., k] = (cam.project(p + dp) - cam.project(p - dp)) / (2 * h)
    assert np.max(np.abs(J - J_fd)) < 1e-5 * np.max(np.abs(J))


def test_behind_camera_raises_with_indices(cam):
    p = np.array([[0, 0, 1.0], [0, 0, 0.0], [0.1, 0, -1.0], [0, 0, 2.0]])
    with pytest.raises(DegenerateGeometryError, match=r"\[1, 2\]"):
        cam.project(p)
    uv = cam.project(p, check=False)
    assert np.isfinite(uv[[0, 3]]).all() and np.isnan(uv[[1, 2]]).all()
    with pytest.raises(DegenerateGeometryError):
        cam.project_jacobian(p)
    with pytest.raises(DegenerateGeometryError, match="p_obj"):
        cam.project_points(p, np.eye(4))


@settings(max_examples=150, deadline=None)
@given(
    u=st.floats(0.0, 639.0),
    v=st.floats(0.0, 479.0),
    k1=st.floats(-0.35, 0.2),
    k2=st.floats(-0.1, 0.15),
    p1=st.floats(-2e-3, 2e-3),
    p2=st.floats(-2e-3, 2e-3),
)
def test_undistort_round_trip_property(u, v, k1, k2, p1, p2):
    # Only lenses whose radial distortion stays monotone out to beyond the image
    # corner (r_d = 0.667 here) are invertible there; others fold over (see the NaN test).
    r = np.linspace(0.0, 3.0, 3001)
    rd = r * (1 + k1 * r**2 + k2 * r**4)
    fold = np.flatnonzero(np.diff(rd) <= 0)
    assume(fold.size == 0 or rd[: fold[0] + 1].max() > 0.75)
    cam = CameraModel(600.0, 600.0, 319.5, 239.5, (k1, k2, p1, p2, 0.0), 640, 480)
    xy = cam.undistort_points([u, v])
    assert np.all(np.isfinite(xy))
    back = cam.pixel_from_normalized(xy)
    assert np.max(np.abs(back - [u, v])) < 1e-9


def test_undistort_agrees_with_opencv_and_round_trips(cam, points_in_view):
    p = points_in_view(cam, np.random.default_rng(5), 300, margin=0.0)
    uv = cam.project(p)
    xy = cam.undistort_points(uv)
    assert np.max(np.abs(xy - p[:, :2] / p[:, 2:])) < 1e-12
    # OpenCV 5 dropped undistortPointsIter: there opencv replays the values recorded from 4.x
    ref = opencv.undistortPointsIter(uv.reshape(-1, 1, 2), cam.K, cam.dist, None, None,
                                     (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)).reshape(-1, 2)
    assert np.max(np.abs(ref - xy)) < 1e-8
    rays = cam.rays_from_pixels(uv)
    assert np.allclose(cam.project(rays), uv, atol=1e-9, rtol=0)


def test_undistort_outside_valid_region_is_nan_or_raises():
    # Strong barrel distortion folds over beyond r ~ 1.3: a pixel far out has no preimage.
    cam = CameraModel(300.0, 300.0, 319.5, 239.5, (-0.5, 0.0, 0.0, 0.0), 640, 480)
    far = np.array([[319.5 + 300 * 0.9, 239.5], [320.0, 240.0]])
    xy = cam.undistort_points(far)
    assert np.isnan(xy[0]).all() and np.isfinite(xy[1]).all()
    with pytest.raises(DegenerateGeometryError, match=r"\[0\]"):
        cam.undistort_points(far, check=True)


def test_in_image(cam):
    uv = np.array([[-0.5, -0.5], [639.5, 479.5], [-0.6, 10], [10, 480.0], [np.nan, 3.0], [5.0, 5.0]])
    assert cam.in_image(uv).tolist() == [True, True, False, False, False, True]
    assert cam.in_image(uv, margin=10).tolist() == [False, False, False, False, False, False]


def test_K_dist_and_value_semantics(cam):
    assert cam.K.shape == (3, 3) and cam.K[0, 0] == 600 and cam.K[1, 2] == 238.7
    assert cam.dist.shape == (5,)
    with pytest.raises(ValueError):
        cam.dist[0] = 1.0  # read-only
    four = CameraModel(1, 1, 0, 0, (0.1, 0.2, 0.3, 0.4), 10, 10)
    assert four.dist.tolist() == [0.1, 0.2, 0.3, 0.4, 0.0]
    other = dataclasses.replace(cam, fx=601.0)
    assert other != cam and other.fx == 601.0
    assert dataclasses.replace(cam) == cam and hash(dataclasses.replace(cam)) == hash(cam)
    assert CameraModel.from_matrix(cam.K, cam.dist, 640, 480) == cam


@pytest.mark.parametrize(
    "kwargs, err, match",
    [
        (dict(fx=-1.0), InputError, "fx must be > 0"),
        (dict(fy=np.nan), NonFiniteError, "fy"),
        (dict(dist=(0.1, 0.2, 0.3)), InputError, r"shape \(4,\) or \(5,\), got shape \(3,\)"),
        (dict(width=0), InputError, "width must be > 0"),
        (dict(height=480.5), InputError, "height must be an integer"),
        (dict(cx="abc"), InputError, r"cx must be a number, got a string \(.abc.\)"),
    ],
)
def test_constructor_rejects_bad_values(kwargs, err, match):
    base = dict(fx=500.0, fy=500.0, cx=320.0, cy=240.0, dist=(0, 0, 0, 0), width=640, height=480)
    base.update(kwargs)
    with pytest.raises(err, match=match):
        CameraModel(**base)


def test_bad_point_inputs(cam):
    with pytest.raises(ShapeError, match=r"p_cam must have shape \(\.\.\., 3\), got \(4, 2\)"):
        cam.project(np.ones((4, 2)))
    with pytest.raises(NonFiniteError, match="p_cam"):
        cam.project([[0, 0, np.nan]])
    with pytest.raises(ShapeError, match="uv"):
        cam.undistort_points(np.ones((3, 3)))
    with pytest.raises(InputError, match="T_cam_obj"):
        cam.project_points(np.ones((2, 3)), np.ones((4, 4)))


def test_dict_round_trip_and_opencv_layout(cam):
    d = cam.to_dict()
    assert d["units"] == {"pixel": "px"}
    assert CameraModel.from_dict(d) == cam
    ocv = parse_document(
        """
image_width: 640
image_height: 480
camera_matrix: {rows: 3, cols: 3, data: [600.0, 0, 321.3, 0, 605.0, 238.7, 0, 0, 1]}
distortion_coefficients: {rows: 1, cols: 5, data: [-0.28, 0.11, 0.0008, -0.0006, -0.02]}
"""
    )
    assert camera_from_document(ocv) == cam
    nested = parse_document(
        "camera_matrix: [[600.0, 0, 321.3], [0, 605.0, 238.7], [0, 0, 1]]\n"
        "dist_coeffs: [-0.28, 0.11, 0.0008, -0.0006, -0.02]\nwidth: 640\nheight: 480\n"
    )
    assert CameraModel.from_document(nested) == cam
    inline = parse_document("fx: {value: 600, unit: px}\nfy: 605\ncx: 321.3\ncy: 238.7\nwidth: 640\nheight: 480\n")
    assert CameraModel.from_document(inline).dist.tolist() == [0.0] * 5


@pytest.mark.parametrize(
    "text, match",
    [
        ("fx: 600\nfy: 600\ncx: 1\nwidth: 640\nheight: 480\n", "'cy': is missing"),
        ("fx: {value: 6, unit: mm}\nfy: 600\ncx: 1\ncy: 1\nwidth: 640\nheight: 480\n", "'fx'.*pixel"),
        ("fx: 600\nfy: 600\ncx: 1\ncy: 1\nheight: 480\n", "'width': is missing"),
        ("fx: 600\nfy: 600\ncx: 1\ncy: 1\nwidth: 640\nheight: 480\ndist: [1, 2, 3]\n", "'dist'.*got 3 values"),
        ("camera_matrix: [[1, 0, 2], [0, 1, 2]]\nwidth: 640\nheight: 480\n", r"'camera_matrix'.*\(3, 3\)"),
        ("camera_matrix: [[1, 0.5, 2], [0, 1, 2], [0, 0, 1]]\nwidth: 640\nheight: 480\n", "no skew"),
    ],
)
def test_document_errors_name_the_field(text, match):
    from robocal.errors import RobocalError

    with pytest.raises(RobocalError, match=match) as info:
        CameraModel.from_document(parse_document(text, source="cam.yaml"))
    assert "cam.yaml" in str(info.value)


# ---------------------------------------------------------------- loader checks every rig gets
_K = "camera_matrix: [[600.0, 0, 321.3], [0, 605.0, 238.7], [0, 0, 1]]\nwidth: 640\nheight: 480\n"
_D = [-0.28, 0.11, 0.0008, -0.0006, -0.02]


@pytest.mark.parametrize(
    "dist, match",
    [
        (_D[:4], None),
        (_D, None),
        (_D + [0.0] * 3, None),  # 8, 12, 14 values with the extra terms exactly zero
        (_D + [0.0] * 7, None),
        (_D + [0.0] * 9, None),
        (_D[:3], r"'dist_coeffs': an OpenCV distortion vector has 4, 5, 8, 12 or 14 values .* got 3 values"),
        (_D + [0.0], r"4, 5, 8, 12 or 14 values .* got 6 values"),
        (_D + [0.01, 0.0, 0.0], "kept"),  # rational and thin-prism terms: CameraModel holds them
        (_D + [0.0] * 6 + [0.001], "kept"),
        (_D + [0.0] * 8 + [0.01], r"14 coefficients .*CALIB_TILTED_MODEL"),
    ],
)
def test_distortion_vector_has_an_opencv_length(dist, match):
    doc = parse_document(_K + f"dist_coeffs: {dist}\n", source="cam.yaml")
    if match == "kept":
        cam = camera_from_document(doc)
        assert cam.dist.tolist() == dist and CameraModel.from_matrix(cam.K, dist, 640, 480) == cam
        return
    if match is None:
        cam = camera_from_document(doc)
        assert np.allclose(cam.dist[:4], _D[:4]) and cam.dist.shape == (5,)
        assert CameraModel.from_matrix(cam.K, dist, 640, 480) == cam
        return
    with pytest.raises(InputError, match=match) as info:
        camera_from_document(doc)
    assert "cam.yaml" in str(info.value)
    with pytest.raises(InputError, match=match.split("': ")[-1]):
        CameraModel.from_matrix(np.eye(3), dist)  # the same check in code


def test_camera_matrix_layouts_and_distortion_model():
    ref = camera_from_document(parse_document(_K))
    flat = "K: [600.0, 0, 321.3, 0, 605.0, 238.7, 0, 0, 1]\nwidth: 640\nheight: 480\n"  # a ROS CameraInfo echo
    assert camera_from_document(parse_document(flat + "D: [0, 0, 0, 0, 0]\ndistortion_model: plumb_bob\n")) == ref
    data = "camera_matrix: {rows: 3, cols: 3, data: [600.0, 0, 321.3, 0, 605.0, 238.7, 0, 0, 1]}\n"
    assert camera_from_document(parse_document(data + "image_size: [640, 480]\n")) == ref  # cv2's (width, height)
    assert CameraModel.from_matrix(np.ravel(ref.K), width=640, height=480) == ref
    with pytest.raises(InputError, match=r"'distortion_model': 'equidistant' is not supported.*fisheye"):
        camera_from_document(parse_document(_K + "distortion_model: equidistant\nD: [0.1, 0.01, 0, 0]\n"))
    with pytest.raises(FileFormatError, match=r"'image_size': must be \[width, height\]"):
        camera_from_document(parse_document(data + "image_size: 640\n"))
    with pytest.raises(FileFormatError, match=r"'camera_matrix': .*\[0, 0, 1\]\] \(no skew\)"):
        camera_from_document(parse_document(_K.replace("[0, 0, 1]", "[0, 0, 2]")))


def test_principal_point_outside_the_image_is_refused_and_off_centre_warned():
    from robocal.camera import check_principal_point, principal_point_warnings
    from robocal.io import Document

    big = "camera_matrix: [[1600.0, 0, 959.5], [0, 1600.0, 719.5], [0, 0, 1]]\n"  # a 1920 x 1440 calibration
    doc = Document(parse_document(big + "image_size: [768, 576]\n").data, "in.yaml", "camera")
    with pytest.raises(InputError, match=r"field 'camera': principal point \(cx, cy\) = \(959.5, 719.5\) px lies "
                                         r"outside the 768 x 576 px image: width/height must be the size"):
        camera_from_document(doc)
    tall = CameraModel(800.0, 800.0, 500.0, 300.0, width=400, height=700)  # inside 700 x 400, not 400 x 700
    with pytest.raises(InputError, match=r"outside the 400 x 700 px image \(width and height swapped\?\)"):
        check_principal_point(tall)
    centred = CameraModel(800.0, 800.0, 383.5, 287.5, width=768, height=576)
    check_principal_point(centred)
    assert principal_point_warnings(centred) == []
    swapped = dataclasses.replace(centred, width=576, height=768)  # (height, width) given as (width, height)
    (w,) = principal_point_warnings(swapped)
    assert w.code == "inconsistent_data" and "width and height swapped it would be near the centre" in w.message
    (w,) = principal_point_warnings(dataclasses.replace(centred, cx=700.0))
    assert "41% of the width" in w.message and "swapped" not in w.message
