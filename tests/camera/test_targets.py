import numpy as np
import pytest

from robocal.camera import Checkerboard, MarkerRectangle
from robocal.errors import InputError


def test_checkerboard_object_points_row_major():
    b = Checkerboard(rows=4, cols=6, square=0.03)
    p = b.object_points()
    assert p.shape == (24, 3) and np.all(p[:, 2] == 0)
    assert np.allclose(p[1], [0.03, 0, 0])  # along a row first (x)
    assert np.allclose(p[6], [0, 0.03, 0])  # next row
    assert np.allclose(p[-1], [5 * 0.03, 3 * 0.03, 0])
    assert b.pattern_size == (6, 4) and b.n_corners == 24
    assert (b.squares_x, b.squares_y) == (7, 5)
    assert b.symmetric and not Checkerboard(4, 5, 0.01).symmetric and Checkerboard(4, 4, 0.01).symmetric and Checkerboard(3, 5, 0.01).symmetric


def test_from_squares_and_outline():
    b = Checkerboard.from_squares(5, 7, 0.02)
    assert (b.rows, b.cols) == (6, 4)
    o = b.outline()
    assert np.allclose(o[:, :2], [[-0.02, -0.02], [0.08, -0.02], [0.08, 0.12], [-0.02, 0.12]])
    assert np.allclose(b.extent(), (-0.04, 0.10, -0.04, 0.14))  # one-square quiet zone
    assert np.allclose(b.outline(with_margin=True)[2, :2], [0.10, 0.14])
    sq = b.black_squares()
    assert sq.shape == (18, 4, 3)  # 35 squares, corner square black -> 18 black
    assert np.allclose(sq[0, 0], [-0.02, -0.02, 0])


def test_checkerboard_shade_colours():
    b = Checkerboard(4, 6, 0.03)
    s = b.square
    x = np.array([-0.5, 0.5, 1.5, 0.5, -1.5, 8.0]) * s
    y = np.array([-0.5, -0.5, -0.5, 0.5, 2.0, 2.0]) * s
    refl, alpha = b.shade(x, y, 1e-4, 1e-4)
    assert refl.tolist() == [0.0, 1.0, 0.0, 0.0, 1.0, 1.0]
    assert alpha.tolist() == [1, 1, 1, 1, 1, 0]
    # exactly on an edge between black and white: half covered
    r, _ = b.shade(np.array([0.0]), np.array([-0.5 * s]), 1e-4, 1e-4)
    assert r[0] == pytest.approx(0.5)


@pytest.mark.parametrize(
    "args, match",
    [
        ((1, 5, 0.02), "rows"),
        ((4, 2.5, 0.02), "cols"),
        ((4, 5, -0.02), "square"),
        ((4, 5, np.nan), "square"),
    ],
)
def test_checkerboard_rejects_bad_values(args, match):
    with pytest.raises(InputError, match=match):
        Checkerboard(*args)


def test_marker_rectangle_order():
    m = MarkerRectangle(0.4, 0.3)
    assert np.allclose(m.object_points()[:, :2], [[0, 0], [0.4, 0], [0.4, 0.3], [0, 0.3]])
    with pytest.raises(InputError, match="width"):
        MarkerRectangle(0, 0.3)
