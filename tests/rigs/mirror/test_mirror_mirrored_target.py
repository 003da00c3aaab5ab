"""Planar targets seen in a mirror (issue 14): detection in mirrored order, the handedness test and its fix."""

import numpy as np
import pytest

from robocal.camera import CameraModel, ChessboardTarget, detect_target, render_target_view
from robocal.errors import InconsistentDataError
from robocal.geometry import matrix_from_rotvec, transform_from
from robocal.rigs.mirror.mirrored_target import check_mirrored_order, detect_mirrored_target, target_orientation

W, H = 640, 480
# principal point at the image centre and no distortion: the mirror view is then exactly the view of the
# reflected (right-handed) camera flipped left-right, which is how it is rendered here
CAM = CameraModel(600.0, 600.0, (W - 1) / 2, (H - 1) / 2, np.zeros(5), W, H)
TARGET = ChessboardTarget(6, 9, 0.03)


@pytest.fixture(scope="module")
def mirror_view():
    """Image of a 6 x 9 chessboard behind the camera seen in a mirror 0.5 m in front, and the true corners."""
    T_c_b = transform_from(matrix_from_rotvec([np.pi + 0.2, 0.15, 0.1]), [-0.12, -0.08, -0.1])
    n = np.array([0.05, -0.03, 1.0])
    n /= np.linalg.norm(n)
    d = 0.5
    Hm = np.eye(3) - 2.0 * np.outer(n, n)
    F = np.diag([-1.0, 1.0, 1.0])
    T_v = transform_from(F @ Hm @ T_c_b[:3, :3], F @ (Hm @ T_c_b[:3, 3] + 2 * d * n))
    img = np.ascontiguousarray(render_target_view(CAM, TARGET, T_v)[:, ::-1])
    Xc = TARGET.object_points() @ T_c_b[:3, :3].T + T_c_b[:3, 3]
    return img, CAM.project(Xc @ Hm.T + 2 * d * n)


def test_detected_in_mirrored_order(mirror_view):
    img, uv_true = mirror_view
    det = detect_mirrored_target(img, TARGET, name="mirror view")
    assert det is not None and det.order.startswith("mirrored")
    assert len(det.ids) == TARGET.n_points
    # ids name the physical corners: the core detector's accuracy on a noise-free render (measured 0.04 px)
    assert np.abs(det.image_points - uv_true[det.ids]).max() < 0.2
    assert target_orientation(CAM, det.object_points, det.image_points)[0] == -1
    check_mirrored_order(CAM, det.object_points, det.image_points)  # passes


def test_unflipped_detection_is_refused_with_the_fix(mirror_view):
    img, uv_true = mirror_view
    det = detect_target(img, TARGET, name="mirror view")
    assert det is not None  # the trap: a chessboard is found in the mirror image, labelled as a direct view
    assert np.abs(det.image_points - uv_true[det.ids]).max() > 10.0  # tens of px: wrong corners
    with pytest.raises(InconsistentDataError, match=r"unmirrored order .* Fix: detect on the flipped image .* "
                                                    r"id i\*9\+j -> i\*9\+\(8-j\)"):
        check_mirrored_order(CAM, det.object_points, det.image_points, what="mirror view", cols=9)
    # the fix named: renumber each row; then the order is a mirror view's and the corners are the physical
    # ones, up to the chessboard's own 180 deg labelling ambiguity (which a direct view has too)
    i, j = np.divmod(det.ids, TARGET.cols)
    fixed = i * TARGET.cols + (TARGET.cols - 1 - j)
    check_mirrored_order(CAM, TARGET.object_points(fixed), det.image_points)
    err = min(np.abs(det.image_points - uv_true[fixed]).max(),
              np.abs(det.image_points - uv_true[TARGET.n_points - 1 - fixed]).max())
    assert err < 0.2


def test_a_target_file_in_the_wrong_order_is_refused(mirror_view):
    img, _ = mirror_view
    det = detect_mirrored_target(img, TARGET)
    wrong = det.object_points * [-1.0, 1.0, 1.0]  # target points given with x the other way
    with pytest.raises(InconsistentDataError, match="unmirrored order"):
        check_mirrored_order(CAM, wrong, det.image_points)
