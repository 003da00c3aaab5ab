import numpy as np
import pytest

from robocal.camera import Checkerboard, MarkerRectangle, PlaneTexture
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


def _exact_box_mean(img, size, origin, x, y, dx, dy):
    """Mean of the piecewise-constant texture over the part of the box on it (texel overlaps)."""
    h, w = img.shape
    sx, sy = size[0] / w, size[1] / h
    ex = origin[0] + sx * np.arange(w + 1)
    ey = origin[1] + sy * np.arange(h + 1)
    ox = np.clip(np.minimum(x + dx / 2, ex[1:]) - np.maximum(x - dx / 2, ex[:-1]), 0, None)
    oy = np.clip(np.minimum(y + dy / 2, ey[1:]) - np.maximum(y - dy / 2, ey[:-1]), 0, None)
    return (oy @ (img / 255.0) @ ox) / (oy.sum() * ox.sum())


@pytest.mark.parametrize("widths", [(0.001, 1.0), (1.0, 4.0), (0.001, 4.0)], ids=["small", "wide", "mixed"])
def test_plane_texture_nearest_is_the_exact_box_average(widths):
    """Each sample gets the exact area mean over its dx x dy box, for boxes narrower and wider than a texel."""
    rng = np.random.default_rng(5)
    img = rng.integers(0, 256, (5, 7)).astype(np.uint8)
    size, origin = (0.7, 0.4), (-0.1, 0.2)  # texels 0.1 x 0.08 m
    tex = PlaneTexture(img, size, origin=origin)
    n = 400
    x = rng.uniform(-0.12, 0.62, n)
    y = rng.uniform(0.18, 0.62, n)
    dx = rng.uniform(*widths, n) * 0.1
    dy = rng.uniform(*widths, n) * 0.08
    on = (x + dx / 2 > -0.1) & (x - dx / 2 < 0.6) & (y + dy / 2 > 0.2) & (y - dy / 2 < 0.6)
    refl, alpha = tex.shade(x[on], y[on], dx[on], dy[on])
    want = [_exact_box_mean(img, size, origin, *a) for a in zip(x[on], y[on], dx[on], dy[on])]
    assert on.sum() > 300
    assert np.allclose(refl, want, rtol=0, atol=1e-9)
    assert np.all((alpha >= 0) & (alpha <= 1))
    # samples off the plane (the renderer passes inf) read a finite value with zero coverage
    r, a = tex.shade(np.array([np.inf, -np.inf]), np.array([np.inf, 0.3]), 0.01, 0.01)
    assert np.all(np.isfinite(r)) and np.all(a == 0)


def test_plane_texture_linear_reads_texel_centres():
    img = np.array([[0, 255], [51, 102]], np.uint8)
    tex = PlaneTexture(img, 2.0, interpolation="linear")  # 1 m texels
    refl, _ = tex.shade(np.array([0.5, 1.5, 0.5, 1.0]), np.array([0.5, 0.5, 1.5, 0.5]), 0.01, 0.01)
    assert np.allclose(refl, [0.0, 1.0, 0.2, 0.5], atol=1e-2)
    with pytest.raises(InputError, match="interpolation"):
        PlaneTexture(img, 2.0, interpolation="cubic")
