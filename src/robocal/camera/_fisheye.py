"""Equidistant fisheye camera (Kannala-Brandt), exactly OpenCV's ``cv2.fisheye`` model.

With ``a = X/Z``, ``b = Y/Z``, ``r = sqrt(a^2 + b^2)`` and the angle from the
optical axis ``theta = atan(r)`` (Kannala & Brandt, "A generic camera model
and calibration method for conventional, wide-angle, and fish-eye lenses",
IEEE PAMI 28(8), 2006, eq. 6, with four terms as in OpenCV):

.. math::

    \\theta_d = \\theta (1 + k_1 \\theta^2 + k_2 \\theta^4 + k_3 \\theta^6 + k_4 \\theta^8)

    u = f_x \\frac{\\theta_d}{r} a + c_x, \\quad v = f_y \\frac{\\theta_d}{r} b + c_y

which is ``cv2.fisheye.projectPoints`` with zero skew. Camera frame and
pixel convention as :class:`~robocal.camera.CameraModel`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.errors import DegenerateGeometryError, InputError
from robocal.validation import check_array, check_transform

__all__ = ["FisheyeCamera"]

_UNDISTORT_MAX_ITER = 50
_UNDISTORT_TOL = 1e-14


@dataclass(frozen=True, eq=False)
class FisheyeCamera:
    """Equidistant fisheye camera: focal lengths, principal point [px], ``k = (k1, k2, k3, k4)``, image size [px].

    Projects points in front of the camera (``z > 0``) like
    ``cv2.fisheye.projectPoints`` (no skew). Frozen; compare with ``==``.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    k: np.ndarray = field(default_factory=lambda: np.zeros(4))
    width: int = 640
    height: int = 480

    def __post_init__(self):
        for name in ("fx", "fy", "cx", "cy"):
            val = check_array(getattr(self, name), f"FisheyeCamera.{name}")
            if val.ndim != 0:
                raise InputError(f"FisheyeCamera.{name} must be a single number [px], got shape {val.shape}")
            object.__setattr__(self, name, float(val))
        for name in ("fx", "fy"):
            if not getattr(self, name) > 0:
                raise InputError(f"FisheyeCamera.{name} must be > 0 [px], got {getattr(self, name)!r}")
        k = check_array(self.k, "FisheyeCamera.k").reshape(-1)
        if k.shape != (4,):
            raise InputError(f"FisheyeCamera.k must be (k1, k2, k3, k4), 4 values, got {k.shape[0]}")
        k = k.copy()
        k.flags.writeable = False
        object.__setattr__(self, "k", k)
        for name in ("width", "height"):
            val = getattr(self, name)
            if isinstance(val, (float, np.floating)) and float(val).is_integer():
                val = int(val)
            if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val <= 0:
                raise InputError(f"FisheyeCamera.{name} must be an integer number of pixels > 0, got {val!r}")
            object.__setattr__(self, name, int(val))

    def _key(self):
        return (self.fx, self.fy, self.cx, self.cy, tuple(self.k.tolist()), self.width, self.height)

    def __eq__(self, other):
        return self._key() == other._key() if isinstance(other, FisheyeCamera) else NotImplemented

    def __hash__(self):
        return hash(self._key())

    def __repr__(self):
        k = ", ".join(f"{v:.6g}" for v in self.k)
        return (f"FisheyeCamera(fx={self.fx:.6g}, fy={self.fy:.6g}, cx={self.cx:.6g}, cy={self.cy:.6g}, k=({k}), "
                f"width={self.width}, height={self.height})")

    @property
    def K(self) -> np.ndarray:
        """Intrinsic matrix, shape (3, 3) [px]."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist(self) -> np.ndarray:
        """``k`` under the name cv2 calls ``D``."""
        return self.k

    @property
    def size(self) -> tuple[int, int]:
        return (self.width, self.height)

    def _theta_d(self, theta):
        k1, k2, k3, k4 = self.k
        t2 = theta * theta
        return theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))

    def project(self, p_cam, *, check: bool = True) -> np.ndarray:
        """Camera-frame points to pixels, (..., 3) -> (..., 2) [px]; ``z <= 0`` raises (or NaN with ``check=False``)."""
        p = check_array(p_cam, "p_cam", shape=(3,))
        behind = ~(p[..., 2] > 0)
        if check and np.any(behind):
            raise DegenerateGeometryError(f"p_cam: points must be in front of the camera (z > 0); z <= 0 at "
                                          f"{int(behind.sum())} points")
        with np.errstate(divide="ignore", invalid="ignore"):
            a, b = p[..., 0] / p[..., 2], p[..., 1] / p[..., 2]
            r = np.hypot(a, b)
            # on the axis theta_d / r -> 1 (OpenCV's limit too)
            scale = np.where(r > 1e-15, self._theta_d(np.arctan(r)) / np.where(r > 1e-15, r, 1.0), 1.0)
        uv = np.stack([self.fx * scale * a + self.cx, self.fy * scale * b + self.cy], axis=-1)
        if np.any(behind):
            uv[behind] = np.nan
        return uv

    def project_points(self, p_obj, T_cam_obj, *, check: bool = True) -> np.ndarray:
        """Object-frame points seen at pose ``T_cam_obj`` (4, 4), broadcast as in CameraModel."""
        p = check_array(p_obj, "p_obj", shape=(3,))
        T = check_transform(T_cam_obj, "T_cam_obj")
        return self.project(np.einsum("...ij,...j->...i", T[..., :3, :3], p) + T[..., :3, 3], check=check)

    def undistort_points(self, uv) -> np.ndarray:
        """Normalised ``(X/Z, Y/Z)`` of pixels, (..., 2) -> (..., 2); NaN beyond 90 deg or where theta_d folds.

        Solves ``theta_d(theta) = |(u - cx) / fx, (v - cy) / fy|`` by Newton's
        method (to 1e-14 rad).
        """
        uv = check_array(uv, "uv", shape=(2,))
        xd = np.stack([(uv[..., 0] - self.cx) / self.fx, (uv[..., 1] - self.cy) / self.fy], axis=-1)
        rd = np.hypot(xd[..., 0], xd[..., 1])
        k1, k2, k3, k4 = self.k
        theta = np.minimum(rd, np.pi / 2)
        for _ in range(_UNDISTORT_MAX_ITER):
            t2 = theta * theta
            f = self._theta_d(theta) - rd
            df = 1.0 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
            step = f / df
            theta = theta - step
            if np.all(np.abs(step) < _UNDISTORT_TOL):
                break
        t2 = theta * theta
        df = 1.0 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
        ok = (theta >= 0) & (theta < np.pi / 2) & (df > 0) & (np.abs(self._theta_d(theta) - rd) < 1e-10)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(rd > 1e-15, np.tan(theta) / np.where(rd > 1e-15, rd, 1.0), 1.0)
        out = xd * s[..., None]
        out[~ok] = np.nan
        return out

    def in_image(self, uv, margin: float = 0.0) -> np.ndarray:
        """Mask of pixels inside the image with ``margin`` [px] to spare (pixel edges, OpenCV convention)."""
        uv = check_array(uv, "uv", shape=(2,), finite=False)
        u, v = uv[..., 0], uv[..., 1]
        lo = -0.5 + margin
        return (u >= lo) & (v >= lo) & (u <= self.width - 0.5 - margin) & (v <= self.height - 0.5 - margin)

    def to_dict(self) -> dict:
        """Plain dict: ``model: fisheye-kannala-brandt``, ``fx, fy, cx, cy`` [px], ``k`` (k1..k4), size [px]."""
        return {"model": "fisheye-kannala-brandt", "units": {"pixel": "px"}, "fx": self.fx, "fy": self.fy,
                "cx": self.cx, "cy": self.cy, "k": [float(v) for v in self.k], "width": self.width,
                "height": self.height}
