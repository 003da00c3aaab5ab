"""Render -> detect -> PnP on images (the camera core's end-to-end test).

Measured (seeded poses below, 640x480, f = 600 px, k1 = -0.28, board 6x7
inner corners of 25 mm at 0.40-0.55 m): corner RMS vs CameraModel.project
~0.02 px clean, ~0.02-0.03 px with blur 0.7 px + noise 2 grey levels; PnP
rotation error < 0.03 deg, translation < 0.1 mm.
"""

import numpy as np
import pytest

from robocal.camera import CameraModel, Checkerboard, detect_checkerboard, render_planar_target, solve_pnp
from robocal.errors import DetectionError, InputError
from robocal.geometry import rotation_angle, transform_from_rotvec

CAM = CameraModel(600.0, 605.0, 321.3, 238.7, (-0.28, 0.11, 8e-4, -6e-4, -0.02), 640, 480)
BOARD = Checkerboard(6, 7, 0.025)  # rows + cols odd: orientation is unambiguous


def _poses(n, seed):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        rv = rng.normal(0.0, 0.3, 3)
        rv[2] = rng.uniform(-0.6, 0.6)
        t = np.array([rng.uniform(-0.09, -0.06), rng.uniform(-0.08, -0.05), rng.uniform(0.40, 0.55)])
        out.append(transform_from_rotvec(rv, t))
    return out


def _rms(a, b):
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


@pytest.mark.parametrize("blur, noise, limit", [(0.0, 0.0, 0.05), (0.7, 2.0, 0.06)])
def test_render_detect_recovers_corners_and_pose(blur, noise, limit):
    rng = np.random.default_rng(7)
    rms = []
    for T in _poses(5, 3):
        truth = CAM.project_points(BOARD.object_points(), T)
        assert CAM.in_image(truth, margin=20).all()
        img = render_planar_target(CAM, T, BOARD, blur_sigma=blur, noise_sigma=noise, rng=rng)
        uv = detect_checkerboard(img, BOARD)
        rms.append(_rms(uv, truth))
        sol = solve_pnp(CAM, BOARD.object_points(), uv)
        assert np.degrees(rotation_angle(sol.T_cam_obj[:3, :3] @ T[:3, :3].T)) < 0.05
        assert np.linalg.norm(sol.T_cam_obj[:3, 3] - T[:3, 3]) < 0.5e-3
    assert max(rms) < limit, rms


def test_sb_detector_and_unrefined_corners():
    T = _poses(1, 11)[0]
    img = render_planar_target(CAM, T, BOARD, blur_sigma=0.7)
    truth = CAM.project_points(BOARD.object_points(), T)
    assert _rms(detect_checkerboard(img, BOARD, method="sb"), truth) < 0.05
    raw = detect_checkerboard(img, BOARD, method="classic", refine=False)
    assert _rms(raw, truth) < 1.0


def test_full_output_names_corners_whose_refinement_wandered(monkeypatch):
    import cv2

    from robocal.camera import _detect

    # the search at full size, so the detector's estimate is refine=False's (the reduced search: below)
    monkeypatch.setattr(_detect, "DETECT_MAX_SIDE", 10**6)
    T = _poses(1, 11)[0]
    img = render_planar_target(CAM, T, BOARD, blur_sigma=0.7)
    clean, info = detect_checkerboard(img, BOARD, method="classic", full_output=True)
    assert info["detector"] == "classic" and info["unrefined"] == ()
    raw = detect_checkerboard(img, BOARD, method="classic", refine=False)
    # the shift is reported per corner in the returned order: |refined - pixel-level|
    assert info["refine_shift"].shape == (BOARD.n_corners,)
    assert np.allclose(info["refine_shift"], np.linalg.norm(clean - raw, axis=1), atol=1e-4)
    assert info["refine_shift"].max() < 1.0
    real = cv2.cornerSubPix

    def wander(image, corners, *a):  # cornerSubPix meets an edge: corner 5 of the detector moves 20 px
        out = real(image, corners, *a)
        out[5, 0, 0] += 20.0
        return out

    monkeypatch.setattr(cv2, "cornerSubPix", wander)
    uv, info = detect_checkerboard(img, BOARD, method="classic", full_output=True)
    (k,) = info["unrefined"]
    assert info["refine_shift"][k] > 15.0  # reported although the corner kept the detector's pixel
    assert np.array_equal(uv[k], raw[k]) and not np.array_equal(uv[k], clean[k])  # the detector's pixel
    others = np.delete(np.arange(len(uv)), k)
    assert np.allclose(uv[others], clean[others])


def test_order_checkerboard_corners_undoes_any_grid_symmetry():
    from robocal.camera import order_checkerboard_corners

    T = _poses(1, 11)[0]
    img = render_planar_target(CAM, T, BOARD, blur_sigma=0.7)
    uv = detect_checkerboard(img, BOARD)
    g = uv.reshape(BOARD.rows, BOARD.cols, 2)
    for h in (g[::-1], g[:, ::-1], g[::-1, ::-1]):
        assert np.array_equal(order_checkerboard_corners(img, h.reshape(-1, 2), BOARD), uv)
        assert np.array_equal(order_checkerboard_corners(None, h.reshape(-1, 2), BOARD, expected_uv=uv + 2.0), uv)


def test_orientation_of_asymmetric_board_upside_down():
    # rows + cols odd: a 180-degree in-plane turn is still resolved from the square colours.
    T = transform_from_rotvec([0.0, 0.0, np.pi], [0.08, 0.07, 0.5])
    img = render_planar_target(CAM, T, BOARD)
    truth = CAM.project_points(BOARD.object_points(), T)
    assert _rms(detect_checkerboard(img, BOARD), truth) < 0.05


def test_symmetric_board_needs_expected_uv():
    board = Checkerboard(5, 7, 0.025)  # rows + cols even: 180-degree symmetric
    T = transform_from_rotvec([0.1, 0.0, np.pi + 0.2], [0.08, 0.05, 0.5])
    img = render_planar_target(CAM, T, board)
    truth = CAM.project_points(board.object_points(), T)
    guess = transform_from_rotvec([0.1, 0.0, np.pi + 0.25], [0.07, 0.05, 0.52])
    expected = CAM.project_points(board.object_points(), guess)
    assert _rms(detect_checkerboard(img, board, expected_uv=expected), truth) < 0.05
    # without it, the documented convention: corner 0 nearest the image's top-left
    conv = detect_checkerboard(img, board)
    assert _rms(conv, truth[::-1]) < 0.05
    assert conv[0].sum() < conv[-1].sum()


def test_square_grid_rotated_90_degrees():
    board = Checkerboard(5, 5, 0.025)  # odd: a 90-degree turn changes the corner square's colour
    T = transform_from_rotvec([0.0, 0.0, np.pi / 2], [0.05, -0.05, 0.5])
    img = render_planar_target(CAM, T, board)
    truth = CAM.project_points(board.object_points(), T)
    assert _rms(detect_checkerboard(img, board, expected_uv=truth + 3.0), truth) < 0.05
    got = detect_checkerboard(img, board)
    assert min(_rms(got, truth), _rms(got, truth[::-1])) < 0.05


def test_mirrored_image_with_expected_uv():
    T = _poses(1, 5)[0]
    img = render_planar_target(CAM, T, BOARD)[:, ::-1]
    truth = CAM.project_points(BOARD.object_points(), T)
    truth[:, 0] = CAM.width - 1 - truth[:, 0]
    assert _rms(detect_checkerboard(img, BOARD, expected_uv=truth), truth) < 0.05


def test_detection_failures_are_clear():
    blank = np.full((480, 640), 128, np.uint8)
    with pytest.raises(DetectionError, match="no 6x7 checkerboard .* in image of size 640x480"):
        detect_checkerboard(blank, BOARD, method="classic")
    T = transform_from_rotvec([0, 0, 0], [0.15, 0.0, 0.5])  # half out of the image
    with pytest.raises(DetectionError):
        detect_checkerboard(render_planar_target(CAM, T, BOARD), BOARD)  # auto: classic then sb
    with pytest.raises(InputError, match="Checkerboard"):
        detect_checkerboard(blank, "board")
    with pytest.raises(InputError, match="grey"):
        detect_checkerboard(np.zeros((4, 480, 640)), BOARD)
    with pytest.raises(InputError, match="expected_uv"):
        img = render_planar_target(CAM, _poses(1, 1)[0], BOARD)
        detect_checkerboard(img, BOARD, expected_uv=np.zeros((5, 2)))


# -- a large image is searched reduced, refined at full size --

CAM2 = CameraModel(1200.0, 1210.0, 642.6, 477.4, (-0.28, 0.11, 8e-4, -6e-4, -0.02), 1280, 960)


@pytest.fixture(scope="module")
def large_view():
    T = _poses(1, 11)[0]
    img = render_planar_target(CAM2, T, BOARD, blur_sigma=0.7, noise_sigma=2.0, rng=np.random.default_rng(5))
    return img, CAM2.project_points(BOARD.object_points(), T)


def test_large_image_is_searched_reduced_and_refined_at_full_size(large_view, monkeypatch):
    from robocal.camera import _detect

    img, truth = large_view
    uv, info = detect_checkerboard(img, BOARD, full_output=True)
    # searched reduced (here at 320x240, scale 4; a coarser OpenCV might need 640x480)
    assert info["scale"] in (2, 4) and info["detector"] == "classic" and info["unrefined"] == ()
    # The same noise-limited accuracy as at 640x480 (test_render_detect_recovers_corners_and_pose).
    assert _rms(uv, truth) < 0.06
    # the reduced search only seeds the refinement: from the full-size detector's corners it converges to
    # the same saddle points (cornerSubPix stops at a 1e-5 px step; measured max difference 3e-5 px,
    # float32 coordinates of a 1280 px image resolve 6e-5 px)
    monkeypatch.setattr(_detect, "DETECT_MAX_SIDE", 10**6)
    full, info_full = detect_checkerboard(img, BOARD, full_output=True)
    assert info_full["scale"] == 1
    assert np.max(np.linalg.norm(uv - full, axis=1)) < 2e-3
    # refine=False is the detector's own output: never the reduced search
    assert detect_checkerboard(img, BOARD, method="classic", refine=False, full_output=True)[1]["scale"] == 1


def test_board_not_found_reduced_is_searched_finer_down_to_full_size(large_view, monkeypatch):
    import cv2

    img, truth = large_view
    real = cv2.findChessboardCorners
    seen = []

    def blind_when_small(image, *a, **k):  # a board too small to be seen in the reduced image
        seen.append(image.shape)
        return (False, None) if image.shape[1] < 1000 else real(image, *a, **k)

    monkeypatch.setattr(cv2, "findChessboardCorners", blind_when_small)
    uv, info = detect_checkerboard(img, BOARD, full_output=True)
    assert seen == [(240, 320), (480, 640), (960, 1280)] and info["scale"] == 1 and info["detector"] == "classic"
    assert _rms(uv, truth) < 0.06


def test_grid_outliers_name_the_corner_off_the_grid():
    from robocal.camera._detect import _grid_outliers

    board = Checkerboard(6, 9, 0.025)
    T = transform_from_rotvec([0.5, -0.4, 0.2], [-0.1, -0.06, 0.4])  # tilted ~37 deg, strong distortion
    uv = CAM.project_points(board.object_points(), T)
    assert not _grid_outliers(uv, board).any()
    for k in (0, 22, 53):  # a board corner, an interior corner, the last corner
        bad = uv.copy()
        bad[k] += 0.3 * np.linalg.norm(uv[1] - uv[0])
        assert np.flatnonzero(_grid_outliers(bad, board)).tolist() == [k]


def test_a_reduced_corner_off_the_grid_sends_the_search_finer(monkeypatch):
    import cv2

    T = _poses(1, 11)[0]
    img = render_planar_target(CAM, T, BOARD, blur_sigma=0.7)
    truth = CAM.project_points(BOARD.object_points(), T)
    real = cv2.findChessboardCorners

    def off_when_small(image, *a, **k):  # the reduced search returns one corner inside a square
        found, c = real(image, *a, **k)
        if found and image.shape[1] < CAM.width:
            c = c.copy()
            c[20, 0] += 5.0  # reduced px: ~0.5 of a square, out of the refinement's reach
        return found, c

    monkeypatch.setattr(cv2, "findChessboardCorners", off_when_small)
    uv, info = detect_checkerboard(img, BOARD, full_output=True)
    assert info["scale"] == 1 and info["unrefined"] == ()
    assert _rms(uv, truth) < 0.05


def test_a_corner_that_wanders_from_the_reduced_estimate_sends_the_search_finer(monkeypatch):
    import cv2

    T = _poses(1, 11)[0]
    img = render_planar_target(CAM, T, BOARD, blur_sigma=0.7)
    real, calls = cv2.cornerSubPix, []

    def wander_first(image, corners, *a):  # from the reduced search's estimate, corner 5 meets an edge
        out = real(image, corners, *a)
        calls.append(1)
        if len(calls) == 1:
            out[5, 0, 0] += 20.0
        return out

    monkeypatch.setattr(cv2, "cornerSubPix", wander_first)
    uv, info = detect_checkerboard(img, BOARD, full_output=True)
    assert len(calls) == 2 and info["scale"] == 1 and info["unrefined"] == ()
    assert _rms(uv, CAM.project_points(BOARD.object_points(), T)) < 0.05
