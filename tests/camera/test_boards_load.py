"""Target files: schema, units, errors naming the file and field; object points by id."""

import numpy as np
import pytest

from robocal.camera._boards import ArucoGridTarget, CharucoTarget, ChessboardTarget, load_target
from robocal.errors import FileFormatError, InputError, UnitError


def _write(tmp_path, text, name="target.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_chessboard_inline_unit_and_object_points(tmp_path):
    t = load_target(_write(tmp_path, "type: chessboard\nrows: 6\ncols: 9\nsquare: {value: 25, unit: mm}\n"))
    assert isinstance(t, ChessboardTarget) and (t.rows, t.cols) == (6, 9)
    assert t.square == pytest.approx(0.025, abs=1e-15)
    p = t.object_points()
    assert p.shape == (54, 3) and np.all(p[:, 2] == 0)
    # id = i * cols + j at (j * square, i * square)
    np.testing.assert_allclose(t.object_points(np.array([10]))[0], [1 * 0.025, 1 * 0.025, 0.0], atol=1e-15)


def test_charuco_document_units_and_ids(tmp_path):
    text = "units: {length: mm}\ntype: charuco\nrows: 7\ncols: 5\nsquare: 40\nmarker: 30\ndictionary: DICT_5X5_100\n"
    t = load_target(_write(tmp_path, text))
    assert isinstance(t, CharucoTarget) and t.n_points == 6 * 4
    assert (t.square, t.marker) == pytest.approx((0.04, 0.03), abs=1e-15)
    # the same corners, in the same id order, as OpenCV's board
    np.testing.assert_allclose(t.object_points(), t.cv_board.getChessboardCorners(), atol=1e-7)


def test_aruco_grid_apriltag_matches_opencv(tmp_path):
    text = ("type: aruco_grid\nrows: 2\ncols: 3\nmarker: {value: 4, unit: cm}\n"
            "separation: {value: 10, unit: mm}\ndictionary: DICT_APRILTAG_36h11\n")
    t = load_target(_write(tmp_path, text))
    assert isinstance(t, ArucoGridTarget) and t.n_points == 24
    ref = np.asarray(t.cv_board.getObjPoints(), dtype=float).reshape(-1, 3)
    np.testing.assert_allclose(t.object_points(), ref, atol=1e-7)


@pytest.mark.parametrize(
    "text, cls, field",
    [
        ("type: chessboard\nrows: 6\ncols: 9\nsquare: 25\n", UnitError, "square"),
        ("type: chessbord\nrows: 6\ncols: 9\nsquare: {value: 25, unit: mm}\n", FileFormatError, "type"),
        ("type: chessboard\nrows: 6\ncol: 9\nsquare: {value: 25, unit: mm}\n", FileFormatError, "col"),
        ("type: chessboard\nrows: six\ncols: 9\nsquare: {value: 25, unit: mm}\n", FileFormatError, "rows"),
        ("type: charuco\nrows: 7\ncols: 5\nsquare: {value: 40, unit: mm}\nmarker: {value: 30, unit: mm}\n"
         "dictionary: DICT_5X5_1000000\n", FileFormatError, "dictionary"),
        ("type: aruco_grid\nrows: 2\ncols: 3\nmarker: {value: 4, unit: cm}\n", FileFormatError, "separation"),
    ],
)
def test_errors_name_file_and_field(tmp_path, text, cls, field):
    p = _write(tmp_path, text)
    with pytest.raises(cls) as exc:
        load_target(p)
    msg = str(exc.value)
    assert str(p) in msg and f"'{field}'" in msg and "\n" not in msg


def test_inconsistent_boards_refused_naming_the_numbers(tmp_path):
    text = ("type: charuco\nrows: 7\ncols: 5\nsquare: {value: 30, unit: mm}\nmarker: {value: 30, unit: mm}\n")
    with pytest.raises(FileFormatError, match=r"target.yaml.*marker \(30 mm\) must be smaller than the square"):
        load_target(_write(tmp_path, text))
    with pytest.raises(InputError, match="needs ids up to 299, dictionary DICT_4X4_50 has 50"):
        ArucoGridTarget(10, 30, 0.02, 0.005, "DICT_4X4_50")
