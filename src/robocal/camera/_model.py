"""Pinhole camera with Brown–Conrady distortion, exactly OpenCV's model.

Camera frame: x right, y down, z forward (optical axis). Pixel convention as
OpenCV: the centre of the top-left pixel is ``(0, 0)``, ``u`` to the right,
``v`` down. With normalised coordinates ``x = X/Z, y = Y/Z`` and
``r^2 = x^2 + y^2``:

.. math::

    x_d = x (1 + k_1 r^2 + k_2 r^4 + k_3 r^6) + 2 p_1 x y + p_2 (r^2 + 2 x^2)

    y_d = y (1 + k_1 r^2 + k_2 r^4 + k_3 r^6) + p_1 (r^2 + 2 y^2) + 2 p_2 x y

    u = f_x x_d + c_x, \\quad v = f_y y_d + c_y

which is what ``cv2.projectPoints`` computes for 5 distortion coefficients.
With 8 or 12 coefficients (OpenCV's rational and thin-prism models) the
radial factor is ``(1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 +
k6 r^6)`` and ``x_d += s1 r^2 + s2 r^4``, ``y_d += s3 r^2 + s4 r^4``, as in
OpenCV's ``projectPoints`` (14 coefficients: only with ``tau_x = tau_y = 0``,
the tilted sensor is not implemented).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.errors import DegenerateGeometryError, FileFormatError, InputError, ShapeError
from robocal.validation import check_array, check_transform

__all__ = [
    "CameraModel",
    "camera_from_document",
    "dist_from_opencv",
    "check_principal_point",
    "principal_point_warnings",
    "OPENCV_DIST_TERMS",
    "BROWN_CONRADY_MODELS",
    "PRINCIPAL_POINT_OFF_CENTRE",
    "FOCAL_MAX_PX",
]

#: OpenCV distortion vector lengths and what their terms beyond (k1, k2, p1, p2, k3) are (the cv2 flag).
OPENCV_DIST_TERMS = {
    4: "",
    5: "",
    8: "k4, k5, k6 (the rational model, CALIB_RATIONAL_MODEL)",
    12: "k4..k6, s1..s4 (CALIB_RATIONAL_MODEL / CALIB_THIN_PRISM_MODEL)",
    14: "k4..k6, s1..s4, tau_x, tau_y (CALIB_TILTED_MODEL)",
}
#: ROS ``distortion_model`` values that are OpenCV's Brown-Conrady model (the only one implemented).
BROWN_CONRADY_MODELS = ("plumb_bob", "rational_polynomial", "radtan", "pinhole-brown-conrady")
#: A principal point farther than this fraction of the image size from the centre is warned about.
PRINCIPAL_POINT_OFF_CENTRE = 0.2
#: Focal lengths [px] at or above this are refused (see CameraModel): 1e6 px is a 0.06 deg field of view.
FOCAL_MAX_PX = 1e6
#: Keys of the distortion vector, in the order :func:`camera_from_document` looks for them.
_DIST_KEYS = ("dist", "dist_coeffs", "distortion_coefficients", "D")

#: Newton iterations / tolerance of :meth:`CameraModel.undistort_points` (normalised units).
_UNDISTORT_MAX_ITER = 50
_UNDISTORT_TOL = 1e-14


def _where(mask: np.ndarray, limit: int = 8) -> str:
    idx = np.argwhere(mask)
    items = [tuple(int(i) for i in row) if len(row) > 1 else int(row[0]) for row in idx[:limit]]
    more = f" and {len(idx) - limit} more" if len(idx) > limit else ""
    return f"{items}{more}"


def dist_from_opencv(values) -> np.ndarray:
    """robocal's distortion vector from an OpenCV one of any of OpenCV's lengths.

    OpenCV writes 4, 5, 8, 12 or 14 coefficients (:data:`OPENCV_DIST_TERMS`).
    Returns ``(k1, k2, p1, p2, k3)`` (5,) when the terms beyond k3 are all
    zero (or absent), else the 8 or 12 terms as given (rational ``k4..k6``,
    thin prism ``s1..s4``; a 14-term vector shortened to 12 when its tilt is
    zero). Raises :class:`~robocal.errors.InputError` for any other length and
    for a non-zero tilt ``tau_x, tau_y`` (CALIB_TILTED_MODEL, not implemented).
    """
    d = check_array(values, "dist").reshape(-1)
    n = d.shape[0]
    if n not in OPENCV_DIST_TERMS:
        raise InputError(f"an OpenCV distortion vector has 4, 5, 8, 12 or 14 values (k1, k2, p1, p2[, k3[, ...]]), "
                         f"got {n} values")
    if n == 14 and np.any(d[12:] != 0.0):
        raise InputError(f"14 coefficients with non-zero tilt tau_x, tau_y (CALIB_TILTED_MODEL): robocal's camera "
                         f"model has no tilted sensor; calibrate without that flag (got {d[12:].tolist()})")
    if n > 5 and np.any(d[5:] != 0.0):
        return d[:12].copy() if n == 14 else d.copy()
    return np.append(d, 0.0) if n == 4 else d[:5].copy()


def _pp_offset(camera: "CameraModel", width, height) -> np.ndarray:
    """Principal point offset from the centre of a ``width x height`` image, as fractions of the size."""
    size = np.array([width, height], dtype=float)
    return np.abs(np.array([camera.cx, camera.cy]) - (size - 1.0) / 2.0) / size


def check_principal_point(camera: "CameraModel") -> None:
    """Reject a camera whose principal point lies outside its ``width x height`` image.

    That is the sign of an image size that does not belong to the camera
    matrix: a calibration at another resolution, or width and height swapped
    (``img.shape[:2]`` is ``(height, width)``, cv2's ``imageSize`` is
    ``(width, height)``). Raises :class:`~robocal.errors.InputError`.
    :func:`camera_from_document` calls it on every camera it reads.
    """
    W, H = camera.width, camera.height
    if -0.5 <= camera.cx <= W - 0.5 and -0.5 <= camera.cy <= H - 0.5:
        return
    hint = ""
    if -0.5 <= camera.cx <= H - 0.5 and -0.5 <= camera.cy <= W - 0.5:
        hint = " (width and height swapped?)"
    raise InputError(f"principal point (cx, cy) = ({camera.cx:.6g}, {camera.cy:.6g}) px lies outside the "
                     f"{W} x {H} px image{hint}: width/height must be the size of the images this camera matrix "
                     "was calibrated at")


def principal_point_warnings(camera: "CameraModel", *, params=("camera",)) -> list:
    """Warn when the principal point is far from the image centre (an image size of another camera?).

    Returns a list of :class:`~robocal.diagnostics.Diagnostic` (code
    ``inconsistent_data``): none when the principal point is within
    :data:`PRINCIPAL_POINT_OFF_CENTRE` of the size from the centre, unless
    width and height look swapped (a swap moves a centred principal point by
    only 12-17 % on a 4:3 image, so it is told apart by being near the centre
    of the swapped size).
    """
    from robocal.diagnostics import Diagnostic

    off = _pp_offset(camera, camera.width, camera.height)
    swapped = _pp_offset(camera, camera.height, camera.width)
    is_swap = off.max() > 0.08 and swapped.max() < off.max() / 3
    if off.max() <= PRINCIPAL_POINT_OFF_CENTRE and not is_swap:
        return []
    hint = "; with width and height swapped it would be near the centre" if is_swap else ""
    return [Diagnostic("inconsistent_data", f"camera: the principal point ({camera.cx:.6g}, {camera.cy:.6g}) px is "
                       f"{off[0]:.0%} of the width and {off[1]:.0%} of the height off the centre of the "
                       f"{camera.width} x {camera.height} px image{hint}: check that width/height belong to this "
                       "camera matrix", params=tuple(params))]


@dataclass(frozen=True, eq=False)
class CameraModel:
    """Pinhole camera with OpenCV Brown–Conrady distortion.

    Parameters
    ----------
    fx, fy : float
        Focal lengths [px].
    cx, cy : float
        Principal point [px] (OpenCV pixel-centre convention).
    dist : array_like, shape (4,), (5,), (8,), (12,) or (14,)
        ``(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, tau_x, tau_y]]]])``,
        OpenCV order; stored read-only, as ``(5,)`` when four or five are
        given (``k3 = 0`` when four), else as given (14 terms: the tilt
        ``tau_x, tau_y`` must be 0).
    width, height : int
        Image size [px].

    Notes
    -----
    Frozen; compare with ``==`` (value equality) and copy-with-changes with
    :func:`dataclasses.replace`.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    width: int = 640
    height: int = 480

    def __post_init__(self):
        for name in ("fx", "fy", "cx", "cy"):
            val = check_array(getattr(self, name), f"CameraModel.{name}")
            if val.ndim != 0:
                raise InputError(f"CameraModel.{name} must be a single number [px], got shape {val.shape}")
            object.__setattr__(self, name, float(val))
        for name in ("fx", "fy"):
            if not getattr(self, name) > 0:
                raise InputError(f"CameraModel.{name} must be > 0 [px], got {getattr(self, name)!r}")
            # 1e6 px is a 0.06 deg field of view over 1000 px (a 5 m lens on 5 um pixels): beyond it the
            # number is a unit slip or garbage, and K's condition number (~f^2) defeats the solvers.
            if not getattr(self, name) < FOCAL_MAX_PX:
                raise InputError(f"CameraModel.{name} must be < {FOCAL_MAX_PX:.0e} px (a field of view of "
                                 f"{np.degrees(1000 / FOCAL_MAX_PX):.2g} deg over 1000 px), got "
                                 f"{getattr(self, name):.6g}: a focal length in other units, or not a focal length")
        dist = check_array(self.dist, "CameraModel.dist")
        if dist.ndim != 1 or dist.shape[0] not in OPENCV_DIST_TERMS:
            raise InputError(
                f"CameraModel.dist must be (k1, k2, p1, p2[, k3]) with shape (4,) or (5,), got shape {dist.shape} "
                "(OpenCV's longer vectors, 8, 12 or 14 terms, are accepted too)"
            )
        if dist.shape[0] == 14 and np.any(dist[12:] != 0.0):
            raise InputError(f"CameraModel.dist: the tilted-sensor terms tau_x, tau_y (CALIB_TILTED_MODEL) are not "
                             f"implemented, they must be 0, got {dist[12:].tolist()}")
        if dist.shape[0] == 4:
            dist = np.append(dist, 0.0)
        dist = dist.copy()
        dist.flags.writeable = False
        object.__setattr__(self, "dist", dist)
        for name in ("width", "height"):
            val = getattr(self, name)
            if isinstance(val, (bool, np.bool_)) or not isinstance(val, (int, np.integer)):
                if isinstance(val, (float, np.floating)) and float(val).is_integer():
                    val = int(val)
                else:
                    raise InputError(f"CameraModel.{name} must be an integer number of pixels, got {val!r}")
            if val <= 0:
                raise InputError(f"CameraModel.{name} must be > 0 [px], got {val}")
            object.__setattr__(self, name, int(val))

    # -- value semantics ---------------------------------------------------
    def _key(self) -> tuple:
        return (self.fx, self.fy, self.cx, self.cy, tuple(self.dist.tolist()), self.width, self.height)

    def __eq__(self, other):
        if not isinstance(other, CameraModel):
            return NotImplemented
        return self._key() == other._key()

    def __hash__(self):
        return hash(self._key())

    def __repr__(self):
        d = ", ".join(f"{v:.6g}" for v in self.dist)
        return (
            f"CameraModel(fx={self.fx:.6g}, fy={self.fy:.6g}, cx={self.cx:.6g}, cy={self.cy:.6g}, "
            f"dist=({d}), width={self.width}, height={self.height})"
        )

    # -- matrices ----------------------------------------------------------
    @property
    def K(self) -> np.ndarray:
        """Intrinsic matrix, shape (3, 3) [px]."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` [px], OpenCV's ``imageSize`` order."""
        return (self.width, self.height)

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.dist != 0.0))

    @classmethod
    def from_matrix(cls, K, dist=(0.0, 0.0, 0.0, 0.0, 0.0), width: int = 640, height: int = 480) -> "CameraModel":
        """From a 3x3 intrinsic matrix (zero skew) and OpenCV distortion coefficients.

        ``K`` may also be the 9 numbers of a ROS ``CameraInfo`` (row-major).
        ``dist``: any OpenCV length (4, 5, 8, 12, 14), extra terms zero (see
        :func:`dist_from_opencv`).
        """
        K = check_array(K, "K")
        if K.shape == (9,):
            K = K.reshape(3, 3)
        if K.shape != (3, 3):
            raise InputError(f"K must have shape (3, 3) (or 9 numbers, row-major), got {K.shape}")
        if abs(K[0, 1]) > 1e-12 * abs(K[0, 0]) or np.any(K[2] != [0.0, 0.0, 1.0]) or K[1, 0] != 0.0:
            raise InputError(f"K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew), got {K.tolist()}")
        return cls(K[0, 0], K[1, 1], K[0, 2], K[1, 2], dist_from_opencv(dist), width, height)

    # -- distortion in normalised coordinates ------------------------------
    def distort_normalized(self, xy) -> np.ndarray:
        """Apply the distortion to normalised coordinates, shape (..., 2) -> (..., 2)."""
        xy = np.asarray(xy, dtype=float)
        xd, yd = self._distort_with_jacobian(xy[..., 0], xy[..., 1])[:2]
        return np.stack([xd, yd], axis=-1)

    def _distort_with_jacobian(self, x, y):
        d = np.zeros(12)
        d[:min(12, self.dist.size)] = self.dist[:12]
        k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = d
        r2 = x * x + y * y
        num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
        radial = num / den
        # d radial / d r2 (quotient rule; den = 1 without the rational terms)
        dnum = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
        dden = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
        drad = (dnum * den - num * dden) / (den * den)
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) + r2 * (s1 + s2 * r2)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y + r2 * (s3 + s4 * r2)
        dpx = s1 + 2.0 * s2 * r2  # d (thin prism x) / d r2
        dpy = s3 + 2.0 * s4 * r2
        dxd_dx = radial + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x + 2.0 * x * dpx
        dxd_dy = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y + 2.0 * y * dpx
        dyd_dx = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y + 2.0 * x * dpy
        dyd_dy = radial + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x + 2.0 * y * dpy
        return xd, yd, dxd_dx, dxd_dy, dyd_dx, dyd_dy

    def pixel_from_normalized(self, xy) -> np.ndarray:
        """Pixels of normalised (undistorted) coordinates ``(X/Z, Y/Z)``, shape (..., 2) -> (..., 2)."""
        xy = check_array(xy, "xy", shape=(2,))
        d = self.distort_normalized(xy)
        return np.stack([self.fx * d[..., 0] + self.cx, self.fy * d[..., 1] + self.cy], axis=-1)

    def undistort_points(self, uv, *, check: bool = False) -> np.ndarray:
        """Normalised coordinates ``(X/Z, Y/Z)`` of pixels, shape (..., 2) -> (..., 2).

        Inverts the distortion by Newton's method (converged to ~1e-14 in
        normalised units, i.e. round trip error ~1e-11 px). Where the
        distortion polynomial cannot be inverted (far outside the field of
        view of a strongly distorted lens) the result is NaN, or, with
        ``check=True``, a :class:`DegenerateGeometryError` naming the indices.
        """
        uv = check_array(uv, "uv", shape=(2,))
        xd = (uv[..., 0] - self.cx) / self.fx
        yd = (uv[..., 1] - self.cy) / self.fy
        if not self.has_distortion:
            return np.stack([xd, yd], axis=-1)
        x, y = xd.copy(), yd.copy()
        converged = np.zeros(xd.shape, dtype=bool)
        for _ in range(_UNDISTORT_MAX_ITER):
            fx_, fy_, a, b, c, d = self._distort_with_jacobian(x, y)
            ex, ey = fx_ - xd, fy_ - yd
            det = a * d - b * c
            with np.errstate(divide="ignore", invalid="ignore"):
                dx = (d * ex - b * ey) / det
                dy = (a * ey - c * ex) / det
            # Damp wild steps so iterates stay in the polynomial's monotone region.
            step = np.hypot(dx, dy)
            scale = np.minimum(1.0, 0.5 * (1.0 + np.hypot(x, y)) / np.where(step > 0, step, 1.0))
            scale = np.where(np.isfinite(scale), scale, 0.0)
            x = x - np.where(np.isfinite(dx), dx * scale, 0.0)
            y = y - np.where(np.isfinite(dy), dy * scale, 0.0)
            converged = (step <= _UNDISTORT_TOL * (1.0 + np.hypot(x, y))) & (det > 0)
            if np.all(converged):
                break
        res = np.hypot(*(self.distort_normalized(np.stack([x, y], axis=-1)) - np.stack([xd, yd], axis=-1)).T).T
        ok = converged | (res <= 1e-12 * (1.0 + np.hypot(xd, yd)))
        _, _, a, b, c, d = self._distort_with_jacobian(x, y)
        ok &= (a * d - b * c) > 0
        if not np.all(ok):
            if check:
                raise DegenerateGeometryError(
                    f"uv: distortion cannot be inverted at indices {_where(~ok)} (outside the lens model's valid region)"
                )
            x = np.where(ok, x, np.nan)
            y = np.where(ok, y, np.nan)
        return np.stack([x, y], axis=-1)

    normalized_from_pixel = undistort_points

    def rays_from_pixels(self, uv) -> np.ndarray:
        """Camera-frame rays ``(x, y, 1)`` through pixels, shape (..., 2) -> (..., 3) (not unit length)."""
        xy = self.undistort_points(uv)
        return np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)

    # -- projection --------------------------------------------------------
    def _check_front(self, p: np.ndarray, check: bool, name: str) -> np.ndarray:
        z = p[..., 2]
        behind = ~(z > 0)
        if check and np.any(behind):
            raise DegenerateGeometryError(
                f"{name}: points must be in front of the camera (z > 0); z <= 0 at indices {_where(behind)}"
            )
        return behind

    def project(self, p_cam, *, check: bool = True) -> np.ndarray:
        """Project camera-frame points to pixels, shape (..., 3) -> (..., 2) [px].

        Identical to ``cv2.projectPoints`` with zero pose. Points with
        ``z <= 0`` raise :class:`DegenerateGeometryError` naming their
        indices; with ``check=False`` their pixels are NaN instead (so
        ``np.isfinite(uv[..., 0])`` is the "in front" mask).
        """
        p = check_array(p_cam, "p_cam", shape=(3,))
        behind = self._check_front(p, check, "p_cam")
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = p[..., :2] / p[..., 2:3]
        d = self.distort_normalized(xy)
        uv = np.stack([self.fx * d[..., 0] + self.cx, self.fy * d[..., 1] + self.cy], axis=-1)
        if np.any(behind):
            uv[behind] = np.nan
        return uv

    def project_jacobian(self, p_cam, *, check: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Pixels and their analytic derivative w.r.t. the camera-frame point.

        Returns
        -------
        uv : ndarray, shape (..., 2) [px]
        J : ndarray, shape (..., 2, 3) [px/m]
            ``J[..., i, j] = d uv_i / d p_cam_j``.
        """
        p = check_array(p_cam, "p_cam", shape=(3,))
        behind = self._check_front(p, check, "p_cam")
        with np.errstate(divide="ignore", invalid="ignore"):
            iz = 1.0 / p[..., 2]
            x = p[..., 0] * iz
            y = p[..., 1] * iz
        xd, yd, a, b, c, d = self._distort_with_jacobian(x, y)
        uv = np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=-1)
        # d(x, y)/dP = [[1/Z, 0, -x/Z], [0, 1/Z, -y/Z]]
        J = np.empty(p.shape[:-1] + (2, 3))
        J[..., 0, 0] = self.fx * a * iz
        J[..., 0, 1] = self.fx * b * iz
        J[..., 0, 2] = -self.fx * (a * x + b * y) * iz
        J[..., 1, 0] = self.fy * c * iz
        J[..., 1, 1] = self.fy * d * iz
        J[..., 1, 2] = -self.fy * (c * x + d * y) * iz
        if np.any(behind):
            uv[behind] = np.nan
            J[behind] = np.nan
        return uv, J

    def project_points(self, p_obj, T_cam_obj, *, check: bool = True) -> np.ndarray:
        """Project object-frame points seen at pose ``T_cam_obj``, (..., 3) -> (..., 2) [px].

        ``T_cam_obj`` (..., 4, 4) broadcasts against the points' leading
        dimensions (NumPy rules): one pose for every point, one pose per
        point, or, for V views of the same N points, ``T[:, None]`` (V, 1, 4, 4)
        with ``p_obj`` (N, 3) -> (V, N, 2).
        """
        p = check_array(p_obj, "p_obj", shape=(3,))
        T = check_transform(T_cam_obj, "T_cam_obj")
        try:  # only to name the shapes: einsum below broadcasts the same way
            np.broadcast_shapes(T.shape[:-2], p.shape[:-1])
        except ValueError:
            raise ShapeError(f"T_cam_obj {T.shape} does not broadcast against p_obj {p.shape}; for V views of "
                             "the same N points pass T_cam_obj[:, None] (V, 1, 4, 4)") from None
        p_cam = np.einsum("...ij,...j->...i", T[..., :3, :3], p) + T[..., :3, 3]
        try:
            return self.project(p_cam, check=check)
        except DegenerateGeometryError as exc:
            raise DegenerateGeometryError(exc.message.replace("p_cam:", "p_obj (at T_cam_obj):")) from None

    def in_image(self, uv, margin: float = 0.0) -> np.ndarray:
        """Mask of pixels inside the image with ``margin`` [px] to spare, (..., 2) -> (...) bool.

        The image spans ``[-0.5, width - 0.5] x [-0.5, height - 0.5]`` (pixel
        edges, OpenCV centre convention). NaN pixels are outside.
        """
        uv = check_array(uv, "uv", shape=(2,), finite=False)
        u, v = uv[..., 0], uv[..., 1]
        lo = -0.5 + margin
        return (u >= lo) & (v >= lo) & (u <= self.width - 0.5 - margin) & (v <= self.height - 0.5 - margin)

    # -- serialisation -----------------------------------------------------
    def to_dict(self) -> dict:
        """Plain dict for YAML/JSON: ``fx, fy, cx, cy`` [px], ``dist`` (dimensionless), ``width, height`` [px]."""
        return {
            "model": "pinhole-brown-conrady",
            "units": {"pixel": "px"},
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "dist": [float(v) for v in self.dist],
            "width": self.width,
            "height": self.height,
        }

    @classmethod
    def from_dict(cls, d: dict, *, source: str = "<camera>") -> "CameraModel":
        """Inverse of :meth:`to_dict`; also accepts the OpenCV/ROS layout (see :func:`camera_from_document`)."""
        from robocal.io import Document

        return camera_from_document(Document(d, source))

    @classmethod
    def from_document(cls, doc) -> "CameraModel":
        """From a :class:`robocal.io.Document` section (see :func:`camera_from_document`)."""
        return camera_from_document(doc)


def _matrix_field(doc, key: str, shape):
    raw = doc.raw(key)
    if isinstance(raw, dict) and "data" in raw:
        sub = doc.sub(key)
        data = sub.array("data", kind="pixel" if key == "camera_matrix" else None)
        rows, cols = raw.get("rows"), raw.get("cols")
        if rows is not None and cols is not None:
            if data.size != rows * cols:
                raise doc.error(key, f"data has {data.size} values, rows x cols = {rows} x {cols}")
            data = data.reshape(rows, cols)
        return data.reshape(shape) if shape is not None and data.size == int(np.prod(shape)) else data
    return doc.array(key, kind="pixel" if key == "camera_matrix" else None)


def camera_from_document(doc) -> CameraModel:
    """Read a :class:`CameraModel` from a :class:`robocal.io.Document` section, with the checks every rig needs.

    Two layouts are accepted (pixel quantities may carry ``unit: px`` or a
    ``units: {pixel: px}`` default; no other unit is valid for them):

    * robocal's own (as written by :meth:`CameraModel.to_dict`)::

        fx: 600.0          # px
        fy: 600.0
        cx: 319.5
        cy: 239.5
        dist: [k1, k2, p1, p2, k3]   # optional, OpenCV order
        width: 640
        height: 480

    * OpenCV / ROS ``camera_info`` style::

        image_width: 640   # or width; or image_size / resolution: [width, height] (cv2's imageSize order)
        image_height: 480  # or height
        camera_matrix: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]   # or {rows: 3, cols: 3, data: [...]},
                                                               # or K: 9 numbers, row-major (CameraInfo)
        dist_coeffs: [k1, k2, p1, p2, k3]   # or distortion_coefficients: {data: [...]}, or D: [...]
        distortion_model: plumb_bob         # optional (ROS)

    Checks (:class:`~robocal.errors.InputError` naming the file and field):

    * ``distortion_model``, when given, must be Brown-Conrady
      (:data:`BROWN_CONRADY_MODELS`): a fisheye calibration is refused;
    * the distortion vector has one of OpenCV's lengths, with any terms beyond
      k3 exactly zero (:func:`dist_from_opencv`; the message names the cv2 flag);
    * the camera matrix is ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``;
    * the principal point lies inside the image (:func:`check_principal_point`):
      otherwise the image size belongs to another resolution or is swapped.
      A principal point far off the centre is only warned about, by
      :func:`principal_point_warnings` (the caller decides where warnings go).
    """
    from robocal.errors import RobocalError

    def _size(*names):
        for n in names:
            if n in doc:
                return doc.int(n, minimum=1)
        for alias in ("image_size", "resolution"):
            if alias in doc:
                size = doc.raw(alias)
                if (not isinstance(size, (list, tuple)) or len(size) != 2
                        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in size)):
                    raise doc.error(alias, f"must be [width, height] in px (cv2's imageSize order), got {size!r}")
                v = size[0] if names[0] == "width" else size[1]
                if not (float(v).is_integer() and v >= 1):
                    raise doc.error(alias, f"must be [width, height], integers >= 1 [px], got {size!r}")
                return int(v)
        raise doc.error(names[0], "is missing (image size in px)")

    try:
        model = doc.raw("distortion_model", default=None)
        if model is not None and str(model).lower() not in BROWN_CONRADY_MODELS:
            raise doc.error("distortion_model", f"{model!r} is not supported: robocal's camera is OpenCV's pinhole "
                            f"model with (k1, k2, p1, p2[, k3]) ({', '.join(BROWN_CONRADY_MODELS[:2])}); a fisheye "
                            "(equidistant) calibration needs its images undistorted first", InputError)
        width = _size("width", "image_width")
        height = _size("height", "image_height")
        dist_key = next((k for k in _DIST_KEYS if k in doc), None)
        dist = np.zeros(5)
        if dist_key is not None:
            try:
                dist = dist_from_opencv(_matrix_field(doc, dist_key, None))
            except InputError as exc:
                if exc.source is not None:
                    raise
                raise doc.error(dist_key, exc.message, InputError) from None
        if "camera_matrix" in doc or "K" in doc:
            key = "camera_matrix" if "camera_matrix" in doc else "K"
            K = _matrix_field(doc, key, (3, 3))
            if K.shape == (9,):
                K = K.reshape(3, 3)  # a ROS CameraInfo echo: 9 numbers, row-major
            if K.shape != (3, 3):
                raise doc.error(key, f"must have shape (3, 3) (or 9 numbers, row-major), got {K.shape}")
            try:
                cam = CameraModel.from_matrix(K, dist, width, height)
            except InputError as exc:
                raise doc.error(key, exc.message) from None
        else:
            vals = {}
            for name in ("fx", "fy", "cx", "cy"):
                vals[name] = doc.float(name, kind="pixel", positive=name in ("fx", "fy"))
            cam = CameraModel(dist=dist, width=width, height=height, **vals)
    except RobocalError as exc:
        if exc.source is None:
            raise FileFormatError(f"camera: {exc.message}", source=doc.source) from None
        raise
    try:
        check_principal_point(cam)
    except InputError as exc:
        raise InputError(f"field '{doc.prefix or 'camera'}': {exc.message}", source=doc.source) from None
    return cam
