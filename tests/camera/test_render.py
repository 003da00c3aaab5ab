import cv2
import numpy as np
import pytest

from robocal.camera import (
    CameraModel,
    Checkerboard,
    DotPattern,
    MarkerRectangle,
    PlaneTexture,
    add_blur_and_noise,
    render_planar_target,
    render_plane_texture,
)
from robocal.errors import InputError
from robocal.geometry import transform_from_rotvec

PLAIN = CameraModel(500.0, 500.0, 319.5, 239.5, (0, 0, 0, 0), 640, 480)
BIG = Checkerboard(3, 3, 0.1, margin=0.0)


def _frontal(edge_u):
    # Board x = 0 (an edge between two squares) at image column u = edge_u, depth 1 m.
    return transform_from_rotvec([0, 0, 0], [(edge_u - PLAIN.cx) / PLAIN.fx, -0.1, 1.0])


@pytest.mark.parametrize("frac", [0.0, 0.13, 0.37, 0.5, 0.81])
@pytest.mark.parametrize("supersample", [1, 4])
def test_edge_pixel_is_its_area_coverage(frac, supersample):
    """A pixel cut by an edge gets exactly the covered fraction (box filter), to one grey level."""
    edge_u = 299.5 + frac  # pixel 300 spans [299.5, 300.5]
    img = render_planar_target(PLAIN, _frontal(edge_u), BIG, black=0, white=255, supersample=supersample)
    # row 280: board y = 0.181 -> squares row 2; left of x = 0 is square column 1 ((2+1) odd: white)... or black:
    left, right = int(img[280, 295]), int(img[280, 305])
    assert {left, right} == {0, 255}
    expect = left * frac + right * (1 - frac)
    assert abs(int(img[280, 300]) - expect) <= 1.0
    # neighbours untouched by the edge
    assert img[280, 299] == left and img[280, 301] == right


def test_corner_pixel_of_x_junction_is_mean_grey():
    # An X-junction at the centre of a pixel: two black and two white quarters.
    T = transform_from_rotvec([0, 0, 0], [0.5 / 500, 0.5 / 500, 1.0])  # corner 0 at pixel centre (320, 240)
    img = render_planar_target(PLAIN, T, Checkerboard(3, 3, 0.05), black=0, white=254)
    assert abs(int(img[240, 320]) - 127) <= 1
    assert img[239, 319] == 0 and img[241, 321] == 0 and img[239, 321] == 254


def test_renders_only_near_the_target_and_onto_images():
    T = transform_from_rotvec([0.2, 0.1, 0], [0.0, 0.0, 0.8])
    board = Checkerboard(4, 5, 0.02)
    img = render_planar_target(PLAIN, T, board, background=77)
    uv = PLAIN.project_points(board.outline(with_margin=True), T)
    lo, hi = np.floor(uv.min(0)).astype(int) - 1, np.ceil(uv.max(0)).astype(int) + 1
    outside = np.ones(img.shape, bool)
    outside[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1] = False
    assert np.all(img[outside] == 77)
    assert img.dtype == np.uint8 and img.shape == (480, 640)
    # drawing onto an image keeps what is not covered
    base = np.full((480, 640), 10, np.uint8)
    base[0:5, 0:5] = 200
    both = render_planar_target(PLAIN, T, board, image=base)
    assert np.all(both[0:5, 0:5] == 200)
    inner = np.round(PLAIN.project_points(board.object_points(), T)).astype(int)
    assert np.array_equal(both[inner[:, 1], inner[:, 0]], img[inner[:, 1], inner[:, 0]])


def test_target_behind_camera_or_edge_on_draws_nothing():
    board = Checkerboard(4, 5, 0.02)
    behind = transform_from_rotvec([0, 0, 0], [0, 0, -0.5])
    assert np.all(render_planar_target(PLAIN, behind, board, background=50) == 50)
    edge_on = transform_from_rotvec([0, np.pi / 2, 0], [0, 0, 0.5])
    assert np.all(render_planar_target(PLAIN, edge_on, board, background=50) == 50)


def test_distorted_render_puts_dots_where_project_says():
    cam = CameraModel(600, 605, 321.3, 238.7, (-0.28, 0.11, 8e-4, -6e-4, -0.02), 640, 480)
    centers = np.array([[x, y] for x in np.linspace(-0.25, 0.25, 5) for y in np.linspace(-0.18, 0.18, 4)])
    dots = DotPattern(centers, 0.006)
    T = transform_from_rotvec([0.05, -0.05, 0], [0, 0, 0.6])
    truth = cam.project_points(np.column_stack([centers, np.zeros(len(centers))]), T)
    for u, v in truth:
        i0, j0 = int(round(v)) - 12, int(round(u)) - 12
        # only the patch the centroid is taken from is drawn (its pixels are the full render's)
        img = render_planar_target(cam, T, dots, background=255, black=0, white=255, supersample=2,
                                   roi=(i0, i0 + 25, j0, j0 + 25))
        patch = 255.0 - img[i0 : i0 + 25, j0 : j0 + 25].astype(float)
        jj, ii = np.meshgrid(np.arange(25) + j0, np.arange(25) + i0)
        cu, cv = (patch * jj).sum() / patch.sum(), (patch * ii).sum() / patch.sum()
        # distortion/perspective shift a disc's centroid by ~1e-3 px at this size
        assert np.hypot(cu - u, cv - v) < 0.03


def test_texture_renders_a_detectable_aruco_marker():
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    marker = cv2.aruco.generateImageMarker(dictionary, 7, 60)
    border = np.full((80, 80), 255, np.uint8)
    border[10:70, 10:70] = marker
    T = transform_from_rotvec([0.3, -0.2, 0.1], [-0.04, -0.03, 0.5])
    img = render_plane_texture(PLAIN, T, border, 0.08)
    corners, ids, _ = cv2.aruco.ArucoDetector(dictionary).detectMarkers(img)
    assert ids is not None and ids.ravel().tolist() == [7]
    # marker corners are texture pixels 10 and 70 of 80 -> plane 0.01 .. 0.07 m
    p = np.array([[0.01, 0.01, 0], [0.07, 0.01, 0], [0.07, 0.07, 0], [0.01, 0.07, 0]])
    assert np.max(np.abs(corners[0].reshape(4, 2) - PLAIN.project_points(p, T))) < 1.0
    # the texture object itself is a planar pattern too
    tex = PlaneTexture(border, (0.08, 0.08), interpolation="linear")
    assert tex.extent() == (0.0, 0.08, 0.0, 0.08)


def test_marker_rectangle_renders_four_dots():
    m = MarkerRectangle(0.2, 0.1, marker_radius=0.01)
    T = transform_from_rotvec([0, 0, 0], [-0.1, -0.05, 0.7])
    img = render_planar_target(PLAIN, T, m, background=200)
    n, _ = cv2.connectedComponents((img < 100).astype(np.uint8))
    assert n - 1 == 4


def test_blur_and_noise():
    T = transform_from_rotvec([0, 0, 0], [-0.05, -0.05, 0.6])
    board = Checkerboard(4, 5, 0.02)
    clean = render_planar_target(PLAIN, T, board)
    noisy = render_planar_target(PLAIN, T, board, noise_sigma=3.0, rng=np.random.default_rng(1))
    d = noisy.astype(float) - clean
    assert 2.7 < d[100:140, 100:140].std() < 3.3  # background region
    blurred = render_planar_target(PLAIN, T, board, blur_sigma=1.5)
    assert np.abs(np.diff(blurred.astype(float), axis=1)).max() < np.abs(np.diff(clean.astype(float), axis=1)).max()
    again = add_blur_and_noise(clean, blur_sigma=1.5)
    assert np.abs(again.astype(int) - blurred).max() <= 1  # blurred before vs after rounding


def test_render_bad_inputs():
    board = Checkerboard(4, 5, 0.02)
    T = transform_from_rotvec([0, 0, 0], [0, 0, 0.6])
    with pytest.raises(InputError, match="rng"):
        render_planar_target(PLAIN, T, board, noise_sigma=1.0)
    with pytest.raises(InputError, match="planar pattern"):
        render_planar_target(PLAIN, T, "board")
    with pytest.raises(InputError, match=r"image must have shape \(height, width\) = \(480, 640\)"):
        render_planar_target(PLAIN, T, board, image=np.zeros((10, 10)))
    with pytest.raises(InputError, match="supersample"):
        render_planar_target(PLAIN, T, board, supersample=0)
    with pytest.raises(InputError, match="T_cam_target"):
        render_planar_target(PLAIN, np.eye(3), board)
    with pytest.raises(InputError, match="camera"):
        render_planar_target(None, T, board)
    with pytest.raises(InputError, match="texture image"):
        render_plane_texture(PLAIN, T, np.zeros((3, 3, 3)), 0.1)


def test_plane_reaching_behind_the_camera_is_drawn_pixel_exact():
    # A floor-like plane seen at a grazing angle that extends behind the camera
    # (no bounding outline): every pixel's colour is its ray's plane point's colour.
    cam = CameraModel(600, 605, 321.3, 238.7, (-0.28, 0.11, 8e-4, -6e-4, -0.02), 640, 480)
    board = Checkerboard(30, 30, 0.1, margin=0.0)
    T = transform_from_rotvec([1.45, 0.0, 0.0], [-1.5, 0.15, -0.5])
    img = render_planar_target(cam, T, board, black=0, white=255, background=128)
    rng = np.random.default_rng(3)
    uv = rng.uniform([1, 1], [638, 478], (800, 2)).round()
    R, t = T[:3, :3], T[:3, 3]

    def plane_point(q):
        rays = cam.rays_from_pixels(q)
        lam = (R[:, 2] @ t) / (rays @ R[:, 2])
        return (lam[:, None] * rays - t) @ R, lam  # target-frame points, depth along the ray

    p, lam = plane_point(uv)
    ok = lam > 0
    refl, alpha = board.shade(p[:, 0], p[:, 1], 1e-9, 1e-9)
    # away from edges only: the pixel's footprint on the plane (very long near the
    # horizon) must not reach a square edge
    foot = np.zeros(len(uv))
    for d in ([0.6, 0], [-0.6, 0], [0, 0.6], [0, -0.6]):
        q, lq = plane_point(uv + d)
        foot = np.maximum(foot, np.where(lq > 0, np.abs(q - p)[:, :2].max(axis=1), np.inf))
    fx, fy = (p[:, 0] / 0.1) % 1, (p[:, 1] / 0.1) % 1
    clear = ok & (np.minimum(np.minimum(fx, 1 - fx), np.minimum(fy, 1 - fy)) * 0.1 > foot) & (alpha == 1)
    assert clear.sum() > 50
    got = img[uv[clear, 1].astype(int), uv[clear, 0].astype(int)]
    assert np.array_equal(got, np.where(refl[clear] > 0.5, 255, 0))
    behind = ~ok
    assert behind.sum() > 50 and np.all(img[uv[behind, 1].astype(int), uv[behind, 0].astype(int)] == 128)


# Black square (texels 2..5 of 8) on a white texture 0.08 m wide: at 1 m a texel is 5 px.
SQUARE_TEX = np.full((8, 8), 255, np.uint8)
SQUARE_TEX[2:6, 2:6] = 0


def _square_edge_errors(img, T):
    """Per row (column) across each side of the square: measured minus true edge position [px].

    A row segment across one straight edge, white on one side and black on
    the other, holds exactly the white area left (right) of the edge: the
    edge's mean position over the row's height, which is its position at the
    row's centre. The truth is the projected side evaluated there.
    """
    f = img.astype(float) / 255.0
    sq = np.array([[0.02, 0.02, 0], [0.06, 0.02, 0], [0.06, 0.06, 0], [0.02, 0.06, 0]])
    uv = PLAIN.project_points(sq, T)
    errs = []
    for k in range(4):
        p, d = uv[k], uv[(k + 1) % 4] - uv[k]
        steep = abs(d[0]) < abs(d[1])  # a near-vertical side is measured along rows
        along, across = (1, 0) if steep else (0, 1)
        lo, hi = sorted([p[along], p[along] + d[along]])
        for t in range(int(np.ceil(lo + 0.2 * (hi - lo))), int(np.floor(hi - 0.2 * (hi - lo))) + 1):
            true = p[across] + (t - p[along]) * d[across] / d[along]
            a = int(round(true)) - 3
            seg = f[t, a : a + 7] if steep else f[a : a + 7, t]
            assert {seg[0], seg[-1]} == {0.0, 1.0}  # one clean edge inside the segment
            meas = a - 0.5 + seg.sum() if seg[0] == 1.0 else a + 6.5 - seg.sum()
            errs.append(meas - true)
    return np.array(errs)


@pytest.mark.parametrize("supersample", [2, 4])
@pytest.mark.parametrize(
    "T",
    [
        # fronto-parallel, sides parallel to the pixel grid at +0.13 px / +0.37 px from a pixel boundary
        transform_from_rotvec([0, 0, 0], [-0.04 + 0.13 / 500, -0.04 + 0.37 / 500, 1.0]),
        # tilted 0.6 rad out of the image plane and turned: sides slanted in the image, perspective
        transform_from_rotvec([0.35, -0.45, 0.2], [-0.03, -0.05, 0.8]),
    ],
    ids=["fronto", "tilted"],
)
def test_nearest_texture_is_area_sampled_edges_exact(T, supersample):
    """PlaneTexture("nearest") places texel edges to < 0.01 px; point sampling puts them on the sub-sample grid."""
    img = render_planar_target(PLAIN, T, PlaneTexture(SQUARE_TEX, 0.08), supersample=supersample, black=0, white=255)
    err = _square_edge_errors(img, T)
    assert len(err) > 40
    # measured: max 0.0014 px fronto (uint8 rounding), 0.0074 / 0.0042 px tilted at s = 2 / 4
    assert np.abs(err).max() < 0.01
    assert abs(err.mean()) < 0.002
    # Reference, the former point-sampled "nearest": an edge parallel to the pixel grid snaps to
    # the 1/s px sub-sample grid (0.13 px off at s = 2, 0.12 px at s = 4, the same on every row);
    # a slanted edge is jagged by the same amount (max per row 0.21 / 0.078 px at s = 2 / 4).
    ref = _square_edge_errors(render_planar_target(PLAIN, T, PlaneTexture(SQUARE_TEX, 0.08, interpolation="point"),
                                                   supersample=supersample, black=0, white=255), T)
    assert np.abs(ref).max() > 0.05


def test_fisheye_render_puts_dots_where_project_says():
    from robocal.camera import FisheyeCamera

    cam = FisheyeCamera(260.0, 259.0, 320.5, 240.5, [0.05, -0.01, 0.003, -0.001], 640, 480)
    # dots out to ~60 deg off axis, where the equidistant image is squeezed hardest
    centers = np.array([[x, y] for x in np.linspace(-0.45, 0.45, 5) for y in np.linspace(-0.3, 0.3, 4)])
    radius = 0.008
    dots = DotPattern(centers, radius)
    T = transform_from_rotvec([0.05, -0.05, 0], [0, 0, 0.3])

    def image_of(p2):  # plane points (..., 2) -> pixels
        return cam.project(np.concatenate([p2, np.zeros(p2.shape[:-1] + (1,))], -1) @ T[:3, :3].T + T[:3, 3])

    # the exact centroid of each dot's image: the disc's points weighted by the mapping's area scale |det J|
    # (the fisheye squeezes a disc so that its image's centroid is ~0.04 px from the image of its centre)
    g = np.linspace(-1, 1, 161)
    gx, gy = np.meshgrid(g, g)
    inside = gx**2 + gy**2 <= 1
    disc = np.column_stack([gx[inside], gy[inside]]) * radius
    h = 1e-6
    for c in centers:
        p = c + disc
        q = image_of(p)
        ju, jv = (image_of(p + [h, 0]) - q) / h, (image_of(p + [0, h]) - q) / h
        area = np.abs(ju[:, 0] * jv[:, 1] - ju[:, 1] * jv[:, 0])
        u, v = (q * area[:, None]).sum(0) / area.sum()
        i0, j0 = int(round(v)) - 12, int(round(u)) - 12
        # 8x8 samples per pixel: at 2x2 the area sampling of a disc squeezed 2:1 shifts its centroid by
        # 0.024 px. Only the 25x25 patch the centroid is taken from is drawn (roi): its pixels are those of
        # the whole image's render (test_roi_draws_exactly_the_full_renders_pixels), at 1/200 of the samples
        img = render_planar_target(cam, T, dots, background=255, black=0, white=255, supersample=8,
                                   roi=(i0, i0 + 25, j0, j0 + 25))
        patch = 255.0 - img[i0 : i0 + 25, j0 : j0 + 25].astype(float)
        jj, ii = np.meshgrid(np.arange(25) + j0, np.arange(25) + i0)
        cu, cv = (patch * jj).sum() / patch.sum(), (patch * ii).sum() / patch.sum()
        # measured 7.8e-3 px at worst (8x8 area sampling of the squeezed disc, grey levels rounded to integers)
        assert np.hypot(cu - u, cv - v) < 0.015, (c, cu - u, cv - v)


@pytest.mark.parametrize("fisheye", [False, True])
def test_roi_draws_exactly_the_full_renders_pixels(fisheye):
    from robocal.camera import FisheyeCamera

    cam = (FisheyeCamera(130.0, 129.5, 160.5, 120.5, [0.05, -0.01, 0.003, -0.001], 320, 240) if fisheye
           else CameraModel(300, 302.5, 160.6, 119.4, (-0.28, 0.11, 8e-4, -6e-4, -0.02), 320, 240))
    T = transform_from_rotvec([0.3, -0.2, 0.1], [0.01, -0.02, 0.35])
    board = Checkerboard(5, 6, 0.03)
    full = render_planar_target(cam, T, board, supersample=2, background=77)
    # a region cutting through the board, one reaching past the image's edge, one off the board
    for roi in [(60, 130, 90, 170), (-10, 50, 250, 400), (0, 5, 0, 5)]:
        part = render_planar_target(cam, T, board, supersample=2, background=77, roi=roi)
        r0, r1, c0, c1 = max(roi[0], 0), min(roi[1], 240), max(roi[2], 0), min(roi[3], 320)
        # pixel for pixel, not to a tolerance: each pixel is computed from its own samples only
        np.testing.assert_array_equal(part[r0:r1, c0:c1], full[r0:r1, c0:c1])
        outside = np.ones(full.shape, bool)
        outside[r0:r1, c0:c1] = False
        assert np.all(part[outside] == 77)
    assert np.any(full[60:130, 90:170] != 77)  # the first region does hold board pixels
    with pytest.raises(InputError, match="roi must be whole pixel bounds"):
        render_planar_target(cam, T, board, roi=(10, 5, 0, 5))
