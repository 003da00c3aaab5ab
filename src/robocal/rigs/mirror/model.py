"""Frames and geometry of the plane-mirror "foot-eye" calibration (seed 002).

Frames (seed 002 §1, patent CN 101096101 [S2]; docs/rigs/mirror.md)
---------------------------------------
``c``
    camera: optical centre, x right, y down, z along the optical axis.
``m``
    mirror: origin at the top-left marker A, ``x_m`` along AB (the rectangle's
    width), ``y_m`` along AD (its height), both in the mirror plane,
    ``z_m = x_m x y_m``. With A, B, C, D seen clockwise in the image (A top
    left, B top right) ``z_m`` points away from the camera, into the mirror.
``om``
    auxiliary frame on the back face: same origin, ``x_om = -x_m``,
    ``y_om = y_m``, ``z_om = -z_m`` — ``m`` rotated 180 deg about ``y``.
``ri``
    mirror image of the robot frame: origin at the image of ``O_r``, ``y_ri``,
    ``z_ri`` the images of ``y_r``, ``z_r`` and ``x_ri`` *opposite* to the
    image of ``x_r`` (which keeps ``ri`` right-handed). A body point
    ``(x, y, z)_r`` therefore has ``ri`` coordinates ``(-x, y, z)``.
``r``
    robot body: origin mid-way between the axle centres, ``y_r`` along the
    axle, ``z_r`` up, ``x_r`` forward.

Transforms follow ``docs/conventions.md``: ``T_a_b`` maps points from ``b``
into ``a``; the patent's ``(R_ab, T_ab)`` with ``X_a = R_ab X_b + T_ab`` is the
4x4 ``T_a_b``. Lengths are metres.

The patent's chain (seed 002 §2, eqs. [1]-[7])::

    T_c_m   <- PnP of the four mirror markers                      [1]
    T_c_ri  <- PnP of the imaged body points, object set (-x, y, z) [2]
    T_m_ri  =  T_c_m^-1 T_c_ri                                     [3]
    T_om_r  =  mirror-symmetric counterpart of T_m_ri              [4]
    T_m_om  =  rotation of 180 deg about y                         [5]
    T_m_r   =  T_m_om T_om_r                                       [6]
    T_c_r   =  T_c_m T_m_r,  T_r_c = T_c_r^-1                      [7]

Eq. [4] is an image in the published text. Written out (see
:func:`patent_compose`), the symmetry gives ``R_om_r = F R_m_ri F`` and
``T_om_r = F T_m_ri`` with ``F = diag(-1, 1, 1)`` — *not* plain equality:
``om`` and ``ri`` are each the mirror image of ``m`` and ``r`` with their x
axis flipped, and the flip has to be undone on both sides. Taking the two
equal (as a paraphrase of the patent reads) gives a wrong ``T_c_r``; the test
suite checks both statements.

The compact form (docs/rigs/mirror.md): with the mirror plane ``n . x = d`` in ``c``
(``n = R_c_m e_z``, ``d = n . t_c_m``) and ``H = I - 2 n n^T``,

.. math:: R_{cr} = H R_{cri} F, \\qquad t_{cr} = H t_{cri} + 2 d n .
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.camera import MarkerRectangle
from robocal.errors import DegenerateGeometryError, InputError, ShapeError
from robocal.geometry import (
    apply_transform,
    householder_from_normal,
    invert_transform,
    reflect_frame,
    reflect_points,
    rotation_from_transform,
    transform_from,
    translation_from_transform,
)
from robocal.validation import check_points, check_transform

__all__ = [
    "F_X",
    "T_M_OM",
    "marker_object_points",
    "ri_from_r_points",
    "mirror_plane",
    "PatentSteps",
    "patent_compose",
    "householder_compose",
    "virtual_transform",
    "MirrorScene",
    "PoseCovarianceStd",
]

#: ``F = diag(-1, 1, 1)``: the x flip that turns a mirror image back into a right-handed frame.
F_X = np.diag([-1.0, 1.0, 1.0])

#: ``T_m_om``: ``om`` rotated 180 deg about its y axis is ``m`` (seed 002 eq. [5]).
T_M_OM = transform_from(np.diag([-1.0, 1.0, -1.0]), np.zeros(3))


def marker_object_points(width: float, height: float) -> np.ndarray:
    """Corners A (origin, top left), B (+x), C (+x +y), D (+y) in ``m``, shape (4, 3)."""
    w, h = float(width), float(height)
    return np.array([[0.0, 0.0, 0.0], [w, 0.0, 0.0], [w, h, 0.0], [0.0, h, 0.0]])


def ri_from_r_points(p_r) -> np.ndarray:
    """Body points in the mirror-image frame ``ri``: ``(x, y, z)_r -> (-x, y, z)``.

    This is the object model for the PnP of the reflected body points
    (seed 002 §2.2, spec step 2). Shape ``(..., 3)`` in, same out.
    """
    p = np.asarray(p_r, dtype=float)
    if p.shape[-1:] != (3,):
        raise ShapeError(f"body points must have shape (..., 3), got {p.shape}")
    return p * np.array([-1.0, 1.0, 1.0])


def mirror_plane(T_c_m) -> tuple[np.ndarray, float]:
    """Mirror plane ``{x : n . x = d}`` in the camera frame from the marker pose.

    ``n = R_c_m e_z`` (pointing away from the camera when the markers are seen
    in the documented order), ``d = n . t_c_m`` (metres; > 0 when the camera
    faces the mirror's front).
    """
    T = np.asarray(T_c_m, dtype=float)
    n = T[..., :3, 2]
    d = np.sum(n * T[..., :3, 3], axis=-1)
    return n, d


@dataclass(frozen=True)
class PatentSteps:
    """Every intermediate transform of the patent's chain (seed 002 eqs. [1]-[7]).

    All 4x4, metres; see the module docstring for the frames.
    """

    T_c_m: np.ndarray
    T_c_ri: np.ndarray
    T_m_ri: np.ndarray
    T_om_r: np.ndarray
    T_m_om: np.ndarray
    T_m_r: np.ndarray
    T_c_r: np.ndarray
    T_r_c: np.ndarray

    def as_dict(self) -> dict:
        return {k: np.asarray(getattr(self, k)) for k in self.__dataclass_fields__}


def _pose(T, name):
    T = np.asarray(T, dtype=float)
    if T.shape[-2:] != (4, 4):
        raise ShapeError(f"{name} must have shape (..., 4, 4), got {T.shape}")
    return T


def patent_compose(T_c_m, T_c_ri, *, literal_eq4: bool = False) -> PatentSteps:
    """The patent's method, step by step: ``(T_c_m, T_c_ri) -> T_c_r``.

    Parameters
    ----------
    T_c_m : array_like, shape (..., 4, 4)
        Mirror frame in the camera (markers' PnP, seed 002 eq. [1]).
    T_c_ri : array_like, shape (..., 4, 4)
        Mirror-image robot frame in the camera (body points' PnP with the
        object set ``(-x, y, z)``, eq. [2]).
    literal_eq4 : bool
        Take ``(R_om_r, T_om_r) = (R_m_ri, T_m_ri)`` literally, as a
        paraphrase of eq. [4] reads. Wrong in general; kept so that a test can
        show it (and the docs can say why the default differs).

    Returns
    -------
    PatentSteps

    Notes
    -----
    Eq. [4]. ``ri`` is the reflection ``M`` of ``r`` with x flipped and ``om``
    is the reflection of ``m`` with x flipped (its axes ``-x_m, y_m, -z_m``
    are the images of ``m``'s axes, negated in x). With poses in any world
    frame, ``P_ri = M P_r F`` and ``P_om = M P_m F``; hence
    ``T_om_r = P_om^-1 P_r = F (P_m^-1 M P_r) = F T_m_ri F``, i.e.
    ``R_om_r = F R_m_ri F`` and ``t_om_r = F t_m_ri``: "the relation of r to om
    mirrors that of ri to m" (seed 002 §2.4), with both flips undone.
    """
    T_c_m = _pose(T_c_m, "T_c_m")
    T_c_ri = _pose(T_c_ri, "T_c_ri")
    T_m_ri = invert_transform(T_c_m) @ T_c_ri  # eq. [3]
    if literal_eq4:
        T_om_r = T_m_ri.copy()
    else:
        F4 = np.diag([-1.0, 1.0, 1.0, 1.0])
        T_om_r = F4 @ T_m_ri @ F4  # eq. [4] (F4 = F4^-1)
    T_m_r = T_M_OM @ T_om_r  # eqs. [5], [6]: R_mr = R_mom R_omr, T_mr = R_mom T_omr
    T_c_r = T_c_m @ T_m_r  # eq. [7]
    return PatentSteps(
        T_c_m=T_c_m,
        T_c_ri=T_c_ri,
        T_m_ri=T_m_ri,
        T_om_r=T_om_r,
        T_m_om=np.broadcast_to(T_M_OM, T_m_r.shape).copy(),
        T_m_r=T_m_r,
        T_c_r=T_c_r,
        T_r_c=invert_transform(T_c_r),
    )


def householder_compose(T_c_m, T_c_ri) -> np.ndarray:
    """Compact form: ``R_cr = H R_cri F``, ``t_cr = H t_cri + 2 d n`` (docs/rigs/mirror.md).

    ``n, d`` from :func:`mirror_plane`. Returns ``T_c_r`` (..., 4, 4).
    """
    T_c_m = _pose(T_c_m, "T_c_m")
    T_c_ri = _pose(T_c_ri, "T_c_ri")
    n, d = mirror_plane(T_c_m)
    H = householder_from_normal(n)
    R = H @ rotation_from_transform(T_c_ri) @ F_X
    t = np.einsum("...ij,...j->...i", H, translation_from_transform(T_c_ri)) + 2.0 * np.asarray(d)[..., None] * n
    return transform_from(R, t)


def virtual_transform(T_c_r, n, d) -> np.ndarray:
    """``T_c_ri``: the mirror-image robot frame for a mirror plane ``n . x = d`` in ``c``.

    The reflection is an involution, so this is also the inverse of
    :func:`householder_compose` for a fixed plane.
    """
    return reflect_frame(T_c_r, n, d, flip_axis=0)


@dataclass
class MirrorScene:
    """A simulated (or nominal) scene: robot, camera, and K mirror placements.

    Parameters
    ----------
    T_c_r : array_like, shape (4, 4)
        Robot frame in the camera (the unknown of the calibration), metres.
    T_c_m : array_like, shape (K, 4, 4) or (4, 4)
        Marker frame of each mirror placement in the camera.
    body_points_r : array_like, shape (N, 3)
        Feature points on the robot body in ``r``, metres.
    rectangle : robocal.camera.MarkerRectangle
        The four mirror markers (seed 002: 0.366 x 0.256 m).
    """

    T_c_r: np.ndarray
    T_c_m: np.ndarray
    body_points_r: np.ndarray
    rectangle: MarkerRectangle = field(default_factory=lambda: MarkerRectangle(0.366, 0.256))

    def __post_init__(self):
        self.T_c_r = check_transform(self.T_c_r, "T_c_r")
        T = check_transform(self.T_c_m, "T_c_m")
        self.T_c_m = T[None] if T.ndim == 2 else T
        if self.T_c_m.ndim != 3:
            raise ShapeError(f"T_c_m must have shape (K, 4, 4), got {T.shape}")
        self.body_points_r = check_points(self.body_points_r, "body_points_r")
        n, d = self.planes()
        if np.any(d <= 0):
            k = int(np.flatnonzero(d <= 0)[0])
            raise DegenerateGeometryError(f"mirror placement {k}: the camera is behind the mirror (d = {d[k]:.4g} m)")
        side = np.einsum("kj,nj->kn", n, self.body_points_c()) - d[:, None]
        if np.any(side >= 0):
            k, i = map(int, np.argwhere(side >= 0)[0])
            raise InputError(f"mirror placement {k}: body point {i} is behind the mirror plane")

    @property
    def n_placements(self) -> int:
        return int(self.T_c_m.shape[0])

    @property
    def T_r_c(self) -> np.ndarray:
        return invert_transform(self.T_c_r)

    def planes(self) -> tuple[np.ndarray, np.ndarray]:
        """Mirror planes ``(n (K, 3), d (K,))`` in the camera frame."""
        return mirror_plane(self.T_c_m)

    def T_c_ri(self) -> np.ndarray:
        """Mirror-image robot frames, (K, 4, 4)."""
        n, d = self.planes()
        return virtual_transform(self.T_c_r[None], n, d)

    def markers_c(self) -> np.ndarray:
        """Marker corners in the camera frame, (K, 4, 3)."""
        return apply_transform(self.T_c_m[:, None], self.rectangle.object_points()[None])

    def body_points_c(self) -> np.ndarray:
        """Real body points in the camera frame, (N, 3)."""
        return apply_transform(self.T_c_r, self.body_points_r)

    def virtual_points_c(self) -> np.ndarray:
        """Mirror images of the body points in the camera frame, (K, N, 3)."""
        n, d = self.planes()
        return reflect_points(self.body_points_c()[None], n[:, None], d[:, None])


class PoseCovarianceStd:
    """``std_rotation`` / ``std_translation`` of a camera-pose estimate from its ``cov`` (6, 6) of
    ``(rotvec [rad] as a left perturbation, t_rc [m])``: the one definition the patent path's
    :class:`~robocal.rigs.mirror.calibrate.MirrorCalibration` and the markerless answers share."""

    @property
    def std_rotation(self) -> np.ndarray:
        """Per-axis std of the rotation [rad], (3,)."""
        return np.sqrt(np.diag(self.cov)[:3])

    @property
    def std_translation(self) -> np.ndarray:
        """Per-axis std of ``t_rc`` [m], (3,)."""
        return np.sqrt(np.diag(self.cov)[3:])
