"""A small renderer: planar patterns seen by a :class:`CameraModel`, for simulation.

Exact under lens distortion: every (sub-)pixel is undistorted to its ray,
the ray is intersected with the target plane (a homography in normalised
coordinates), and the pattern is evaluated in plane coordinates. Each pixel
averages ``supersample x supersample`` samples, each of which anti-aliases the
pattern's straight edges over its own footprint (a one-sample box), so edges
are smooth and unbiased. Only the pixels whose footprint meets the target are
evaluated.
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from robocal.camera._model import CameraModel
from robocal.camera._targets import PlaneTexture
from robocal.errors import InputError
from robocal.validation import check_array, check_transform

__all__ = ["render_planar_target", "render_plane_texture", "add_blur_and_noise", "blank_image"]


@lru_cache(maxsize=8)
def _corner_grid(camera: CameraModel) -> np.ndarray:
    """Normalised coordinates of every pixel corner, shape (H+1, W+1, 2); NaN where not invertible."""
    u = np.arange(camera.width + 1) - 0.5
    v = np.arange(camera.height + 1) - 0.5
    uu, vv = np.meshgrid(u, v)
    g = camera.undistort_points(np.stack([uu, vv], axis=-1))
    g.flags.writeable = False
    return g


def _check_camera(camera):
    from robocal.camera._fisheye import FisheyeCamera

    if not isinstance(camera, (CameraModel, FisheyeCamera)):
        raise InputError(f"camera must be a robocal.camera.CameraModel or FisheyeCamera, got {type(camera).__name__}")


def _fisheye_distort_with_jacobian(camera, x, y):
    """Equidistant model (cv2.fisheye): distorted normalised ``(xd, yd)`` of ``(x, y)`` and d(xd, yd)/d(x, y).

    ``xd = s(r) x``, ``s = theta_d / r``, ``theta = atan r``, ``theta_d = theta (1 + k1 theta^2 + ... + k4 theta^8)``;
    ``ds/dr = (theta_d'(theta) / (1 + r^2) - s) / r``, which goes to 0 at the axis (written so there).
    """
    k1, k2, k3, k4 = (float(v) for v in camera.k)
    r = np.hypot(x, y)
    th = np.arctan(r)
    t2 = th * th
    poly = 1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))
    dpoly = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))  # d(theta * poly) / d theta
    small = r < 1e-8
    rs = np.where(small, 1.0, r)
    s = np.where(small, 1.0, th * poly / rs)
    ds_r = np.where(small, 0.0, (dpoly / (1 + r * r) - s) / rs)  # ds/dr
    ux, uy = np.where(small, 0.0, x / rs), np.where(small, 0.0, y / rs)
    return (s * x, s * y, s + x * ds_r * ux, x * ds_r * uy, y * ds_r * ux, s + y * ds_r * uy)


def _distortion_with_jacobian(camera):
    """The camera's ``(x, y) -> (xd, yd, dxd/dx, dxd/dy, dyd/dx, dyd/dy)``, or None without distortion."""
    from robocal.camera._fisheye import FisheyeCamera

    if isinstance(camera, FisheyeCamera):
        return lambda x, y: _fisheye_distort_with_jacobian(camera, x, y)
    return camera._distort_with_jacobian if camera.has_distortion else None


def _check_pattern(target):
    if not (callable(getattr(target, "shade", None)) and callable(getattr(target, "extent", None))):
        raise InputError(
            f"target must be a planar pattern with extent() and shade(x, y, dx, dy) "
            f"(Checkerboard, MarkerRectangle, DotPattern, PlaneTexture), got {type(target).__name__}"
        )


def blank_image(camera: CameraModel, background: float = 128.0) -> np.ndarray:
    """A uniform uint8 image of the camera's size."""
    _check_camera(camera)
    return np.full((camera.height, camera.width), int(round(float(background))), dtype=np.uint8)


def add_blur_and_noise(image, *, blur_sigma: float = 0.0, noise_sigma: float = 0.0, rng=None) -> np.ndarray:
    """Gaussian blur (``blur_sigma`` [px]) then additive Gaussian noise (``noise_sigma`` [grey levels]).

    Returns a uint8 image (rounded and clipped to 0..255). ``rng`` (an
    ``np.random.Generator``) is required when ``noise_sigma > 0``.
    """
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 2:
        raise InputError(f"image must be a 2-D grey image (H, W), got shape {img.shape}")
    blur_sigma = float(blur_sigma)
    noise_sigma = float(noise_sigma)
    if not blur_sigma >= 0 or not noise_sigma >= 0:
        raise InputError(f"blur_sigma and noise_sigma must be >= 0, got {blur_sigma!r} and {noise_sigma!r}")
    if blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_sigma, borderType=cv2.BORDER_REPLICATE)
    if noise_sigma > 0:
        if not isinstance(rng, np.random.Generator):
            raise InputError("noise_sigma > 0 needs rng, an np.random.Generator (no global random state)")
        img = img + rng.normal(0.0, noise_sigma, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _plane_coords(Hinv: np.ndarray, xy: np.ndarray):
    """Plane coordinates of normalised points and the 'in front' flag (homography)."""
    w0 = Hinv[0, 0] * xy[..., 0] + Hinv[0, 1] * xy[..., 1] + Hinv[0, 2]
    w1 = Hinv[1, 0] * xy[..., 0] + Hinv[1, 1] * xy[..., 1] + Hinv[1, 2]
    w2 = Hinv[2, 0] * xy[..., 0] + Hinv[2, 1] * xy[..., 1] + Hinv[2, 2]
    front = w2 > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        return w0 / w2, w1 / w2, front


def render_planar_target(
    camera: CameraModel,
    T_cam_target,
    target,
    *,
    supersample: int | None = None,
    blur_sigma: float = 0.0,
    noise_sigma: float = 0.0,
    rng: np.random.Generator | None = None,
    background: float = 128.0,
    black: float = 20.0,
    white: float = 235.0,
    image=None,
    roi=None,
) -> np.ndarray:
    """Render a planar pattern seen by ``camera`` at pose ``T_cam_target``.

    Parameters
    ----------
    camera : CameraModel
    T_cam_target : array_like, shape (4, 4)
        Maps target-frame points (pattern in its z = 0 plane) into the camera frame [m].
    target : Checkerboard, MarkerRectangle, DotPattern, PlaneTexture or any planar pattern
        Anything with ``extent()`` and ``shade(x, y, dx, dy)`` (see
        :mod:`robocal.camera._targets`). Both faces of the plane show the pattern.
    supersample : int, optional
        Samples per pixel along each axis (pixel = mean of s x s samples).
        Default: 1 for patterns that anti-alias their own edges analytically
        (``analytic_aa = True``: Checkerboard, MarkerRectangle, DotPattern —
        their straight edges are box-filtered over the sample footprint;
        measured detection RMS 0.018 px at s = 1 vs 0.015 px at s = 4, at
        1/9 of the time), 4 otherwise (textures).
    blur_sigma : float
        Gaussian blur of the whole output image [px] (optics/defocus).
    noise_sigma : float
        Additive Gaussian noise [grey levels], drawn from ``rng``.
    rng : np.random.Generator, optional
        Required when ``noise_sigma > 0``.
    background : float
        Grey level where no target is drawn (ignored when ``image`` is given).
    black, white : float
        Grey levels of reflectance 0 and 1.
    image : array_like, shape (height, width), optional
        Draw onto this (uint8 or float) image instead of a uniform background.
        To draw several targets, render each with ``blur_sigma = noise_sigma =
        0`` onto the previous image and blur/noise only in the last call (or
        call :func:`add_blur_and_noise`): blur and noise apply to the whole
        output image.
    roi : (row0, row1, col0, col1), optional
        Draw only the pixels ``[row0:row1, col0:col1]`` (a region of interest,
        clipped to the image); the others keep the background or ``image``.
        Each pixel is computed on its own, so the drawn pixels are exactly
        those of a full render; only ``blur_sigma`` (applied to the whole
        output) mixes in the undrawn surroundings within ~3 sigma of the
        region's edge. For checks that look at a few small patches of a
        costly render (fine supersampling of a large target).

    Returns
    -------
    ndarray of uint8, shape (height, width)
    """
    _check_camera(camera)
    _check_pattern(target)
    T = check_transform(T_cam_target, "T_cam_target")
    if T.ndim != 2:
        raise InputError(f"T_cam_target must have shape (4, 4), got {T.shape}")
    if supersample is None:
        supersample = 1 if getattr(target, "analytic_aa", False) else 4
    if isinstance(supersample, bool) or not isinstance(supersample, (int, np.integer)) or not 1 <= supersample <= 16:
        raise InputError(f"supersample must be an integer in 1..16, got {supersample!r}")
    s = int(supersample)
    if image is None:
        canvas = np.full((camera.height, camera.width), float(background))
    else:
        canvas = check_array(image, "image").astype(np.float64, copy=True)
        if canvas.shape != (camera.height, camera.width):
            raise InputError(
                f"image must have shape (height, width) = ({camera.height}, {camera.width}), got {canvas.shape}"
            )
    if noise_sigma and noise_sigma > 0 and not isinstance(rng, np.random.Generator):
        raise InputError("noise_sigma > 0 needs rng, an np.random.Generator (no global random state)")
    if roi is not None:
        roi = check_array(roi, "roi")
        if roi.shape != (4,) or not np.all(roi == np.round(roi)) or roi[0] > roi[1] or roi[2] > roi[3]:
            raise InputError(f"roi must be whole pixel bounds (row0, row1, col0, col1) with row0 <= row1 and "
                             f"col0 <= col1, got {roi.tolist()}")

    # Homography from the target plane to normalised coordinates: [x, y, 1] ~ [r1 r2 t] [X, Y, 1].
    Hmat = np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]])
    if abs(np.linalg.det(Hmat)) < 1e-15 * max(1.0, np.linalg.norm(T[:3, 3])) ** 3:
        return add_blur_and_noise(canvas, blur_sigma=blur_sigma, noise_sigma=noise_sigma, rng=rng)  # seen edge-on
    Hinv = np.linalg.inv(Hmat)

    xmin, xmax, ymin, ymax = target.extent()
    window = _window(camera, T, (xmin, xmax, ymin, ymax))
    if window is not None and roi is not None:
        r0, r1, c0, c1 = (int(v) for v in roi)
        window = (max(window[0], r0), min(window[1], r1), max(window[2], c0), min(window[3], c1))
        if window[0] >= window[1] or window[2] >= window[3]:
            window = None
    if window is None:
        return add_blur_and_noise(canvas, blur_sigma=blur_sigma, noise_sigma=noise_sigma, rng=rng)
    wr0, wr1, wc0, wc1 = window
    grid = _corner_grid(camera)[wr0 : wr1 + 1, wc0 : wc1 + 1]
    GX, GY, front = _plane_coords(Hinv, grid)
    front &= np.isfinite(GX) & np.isfinite(GY)
    # A pixel is drawn if its four corners see the plane in front of the camera and its
    # plane-coordinate box meets the target's extent.
    cell_ok = front[:-1, :-1] & front[1:, :-1] & front[:-1, 1:] & front[1:, 1:]
    with np.errstate(invalid="ignore"):
        cx_lo = np.fmin(np.fmin(GX[:-1, :-1], GX[1:, :-1]), np.fmin(GX[:-1, 1:], GX[1:, 1:]))
        cx_hi = np.fmax(np.fmax(GX[:-1, :-1], GX[1:, :-1]), np.fmax(GX[:-1, 1:], GX[1:, 1:]))
        cy_lo = np.fmin(np.fmin(GY[:-1, :-1], GY[1:, :-1]), np.fmin(GY[:-1, 1:], GY[1:, 1:]))
        cy_hi = np.fmax(np.fmax(GY[:-1, :-1], GY[1:, :-1]), np.fmax(GY[:-1, 1:], GY[1:, 1:]))
        hit = cell_ok & (cx_hi >= xmin) & (cx_lo <= xmax) & (cy_hi >= ymin) & (cy_lo <= ymax)
    rows = np.flatnonzero(hit.any(axis=1))
    cols = np.flatnonzero(hit.any(axis=0))
    if rows.size:
        r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
        view = canvas[wr0:wr1, wc0:wc1]
        _draw(camera, Hinv, target, grid, GX, GY, view, (wr0, wc0), r0, r1, c0, c1, s, hit[r0:r1, c0:c1], black, white)
    return add_blur_and_noise(canvas, blur_sigma=blur_sigma, noise_sigma=noise_sigma, rng=rng)


def _window(camera: CameraModel, T: np.ndarray, extent) -> tuple[int, int, int, int] | None:
    """Pixel window ``(r0, r1, c0, c1)`` that can contain the target; None if it is surely not seen.

    When the whole target outline is in front of the camera and inside the
    lens model's invertible region, the image of the (convex) target is
    bounded by the image of its outline; otherwise fall back to the whole image.
    """
    full = (0, camera.height, 0, camera.width)
    xmin, xmax, ymin, ymax = extent
    t = np.linspace(0.0, 1.0, 33)
    xs = np.concatenate([xmin + (xmax - xmin) * t, np.full(33, xmax), xmax - (xmax - xmin) * t, np.full(33, xmin)])
    ys = np.concatenate([np.full(33, ymin), ymin + (ymax - ymin) * t, np.full(33, ymax), ymax - (ymax - ymin) * t])
    p = np.column_stack([xs, ys, np.zeros_like(xs)]) @ T[:3, :3].T + T[:3, 3]
    if not np.all(p[:, 2] > 0):
        return full
    xy = p[:, :2] / p[:, 2:3]
    uv = camera.project(p)
    back = camera.undistort_points(uv)
    if not np.all(np.abs(back - xy) <= 1e-9 * (1.0 + np.abs(xy))):
        return full
    # Edges bulge between samples under distortion: pad generously.
    lo = np.floor(uv.min(axis=0)).astype(int) - 3
    hi = np.ceil(uv.max(axis=0)).astype(int) + 4
    c0, r0 = max(lo[0], 0), max(lo[1], 0)
    c1, r1 = min(hi[0], camera.width), min(hi[1], camera.height)
    if c0 >= c1 or r0 >= r1:
        return None
    return (r0, r1, c0, c1)


def _draw(camera, Hinv, target, grid, GX, GY, canvas, offset, r0, r1, c0, c1, s, hit, black, white):
    """Draw into ``canvas`` (a window at pixel ``offset`` of the image); r0.. are window indices."""
    bh, bw = r1 - r0, c1 - c0
    # Sub-sample offsets inside a pixel (in pixel units from its top-left corner).
    off = (np.arange(s) + 0.5) / s
    g00 = grid[r0:r1, c0:c1][:, None, :, None, :]
    g01 = grid[r0:r1, c0 + 1 : c1 + 1][:, None, :, None, :]
    g10 = grid[r0 + 1 : r1 + 1, c0:c1][:, None, :, None, :]
    g11 = grid[r0 + 1 : r1 + 1, c0 + 1 : c1 + 1][:, None, :, None, :]
    a = off[None, None, None, :, None]  # along u
    b = off[None, :, None, None, None]  # along v
    xy = (1 - a) * (1 - b) * g00 + a * (1 - b) * g01 + (1 - a) * b * g10 + a * b * g11  # (bh, s, bw, s, 2)
    distort = _distortion_with_jacobian(camera)
    if distort is not None:
        # Bilinear interpolation of the undistortion map is off by up to ~3e-4 px
        # (strong distortion, image corner). One Newton step at each pixel centre
        # gives the exact ray there (~1e-12); adding that correction to all the
        # pixel's samples leaves only its variation inside the pixel (~1e-7 px).
        centre = 0.25 * (g00 + g01 + g10 + g11)[:, 0, :, 0, :]  # (bh, bw, 2)
        uu = offset[1] + c0 + np.arange(bw)[None, :]
        vv = offset[0] + r0 + np.arange(bh)[:, None]
        xd_t = (uu - camera.cx) / camera.fx
        yd_t = (vv - camera.cy) / camera.fy
        x, y = centre[..., 0], centre[..., 1]
        fx_, fy_, ja, jb, jc, jd = distort(x, y)
        ex, ey = fx_ - xd_t, fy_ - yd_t
        det = ja * jd - jb * jc
        with np.errstate(divide="ignore", invalid="ignore"):
            corr = -np.stack([(jd * ex - jb * ey) / det, (ja * ey - jc * ex) / det], axis=-1)
        xy = xy + corr[:, None, :, None, :]
    X, Y, front = _plane_coords(Hinv, xy)
    # Footprint of one sample along the plane's x and y edge normals [m]:
    # |grad_pixel X| / s, from the pixel-corner grid.
    gx = GX[r0 : r1 + 1, c0 : c1 + 1]
    gy = GY[r0 : r1 + 1, c0 : c1 + 1]
    dXdu = 0.5 * ((gx[:-1, 1:] - gx[:-1, :-1]) + (gx[1:, 1:] - gx[1:, :-1]))
    dXdv = 0.5 * ((gx[1:, :-1] - gx[:-1, :-1]) + (gx[1:, 1:] - gx[:-1, 1:]))
    dYdu = 0.5 * ((gy[:-1, 1:] - gy[:-1, :-1]) + (gy[1:, 1:] - gy[1:, :-1]))
    dYdv = 0.5 * ((gy[1:, :-1] - gy[:-1, :-1]) + (gy[1:, 1:] - gy[:-1, 1:]))
    dx = (np.hypot(dXdu, dXdv) / s)[:, None, :, None]
    dy = (np.hypot(dYdu, dYdv) / s)[:, None, :, None]
    good = front & np.isfinite(X) & np.isfinite(Y) & hit[:, None, :, None]
    Xs = np.where(good, X, np.inf)
    Ys = np.where(good, Y, np.inf)
    dxs = np.broadcast_to(np.where(np.isfinite(dx) & (dx > 0), dx, 1.0), X.shape)
    dys = np.broadcast_to(np.where(np.isfinite(dy) & (dy > 0), dy, 1.0), X.shape)
    with np.errstate(invalid="ignore"):
        refl, alpha = target.shade(Xs, Ys, dxs, dys)
    refl = np.broadcast_to(np.asarray(refl, dtype=float), X.shape)
    alpha = np.where(good, np.broadcast_to(np.asarray(alpha, dtype=float), X.shape), 0.0)
    alpha = np.nan_to_num(alpha, nan=0.0)
    grey = black + (white - black) * np.nan_to_num(refl, nan=1.0)
    mean_alpha = alpha.mean(axis=(1, 3))
    mean_col = (alpha * grey).mean(axis=(1, 3))
    region = canvas[r0:r1, c0:c1]
    canvas[r0:r1, c0:c1] = mean_col + (1.0 - mean_alpha) * region


def render_plane_texture(
    camera: CameraModel,
    T_cam_plane,
    texture_image,
    size_m,
    *,
    origin=(0.0, 0.0),
    interpolation: str = "nearest",
    **kwargs,
) -> np.ndarray:
    """Render an image laid on a plane (an ArUco marker, a poster, ...).

    ``texture_image`` (H, W) uint8 or float in [0, 1] covers
    ``origin + [0, size_x] x [0, size_y]`` [m] of the plane's z = 0 plane,
    columns along +x, rows along +y (see :class:`PlaneTexture`);
    ``size_m`` is its width or ``(width, height)``. Other keyword arguments
    as :func:`render_planar_target` (texture 0..255 maps to ``black..white``).
    """
    tex = PlaneTexture(texture_image, size_m, origin=origin, interpolation=interpolation)
    return render_planar_target(camera, T_cam_plane, tex, **kwargs)
