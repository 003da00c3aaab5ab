"""Shared pieces of the kinematics package: elementary screw motions and twist columns.

Every calibration parameter and every joint variable of a chain or tree enters
the pose as one *elementary screw motion* (a rotation about, or a translation
along, a fixed line) inside a product of transforms::

    T_ref_src = L @ exp(xi * v) @ R

Its derivative is then a twist of ``T_ref_src``: with ``u`` the unit direction
and ``c`` a point of the screw line, both in frame ``ref``, and ``p`` the origin
of frame ``src`` in ``ref``,

* rotation:    ``d t / dv = u x (p - c)``,  ``d R / dv @ R^T = [u]_x``;
* translation: ``d t / dv = u``,            rotation part 0.

Columns are stacked ``[d t; omega]`` (the geometric-Jacobian order ``[v; w]``),
both expressed in ``ref``. This one rule gives the joint Jacobian, the D-H
parameter Jacobian and the derivative w.r.t. URDF origins, exactly and without
finite differences (the least-squares layer gets exact Jacobians cheaply).
"""

from __future__ import annotations

import math

import numpy as np

from robocal.errors import InputError, ShapeError
from robocal.geometry import euler_from_matrix, matrix_from_euler
from robocal.validation import check_array, check_transform

__all__: list[str] = []

JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed")
_TYPE_ALIASES = {
    "r": "revolute",
    "revolute": "revolute",
    "continuous": "continuous",
    "p": "prismatic",
    "prismatic": "prismatic",
    "f": "fixed",
    "fixed": "fixed",
}


def normalise_joint_type(kind, name: str) -> str:
    """Map ``'R'``/``'P'``/``'F'`` or a full name to a canonical joint type."""
    key = str(kind).strip().lower()
    if key not in _TYPE_ALIASES:
        raise InputError(
            f"{name} must be one of 'revolute', 'continuous', 'prismatic', 'fixed' (or R/P/F), got {kind!r}"
        )
    return _TYPE_ALIASES[key]


def check_limits(limits, name: str):
    """``None`` or a ``(lower, upper)`` pair of floats with lower <= upper."""
    if limits is None:
        return None
    arr = check_array(limits, name, shape=(2,))
    if arr.ndim != 1:
        raise ShapeError(f"{name} must have shape (2,), got {arr.shape}")
    if arr[0] > arr[1]:
        raise InputError(f"{name} must satisfy lower <= upper, got ({arr[0]:g}, {arr[1]:g})")
    return (float(arr[0]), float(arr[1]))


def check_scalar(x, name: str) -> float:
    """A finite float."""
    arr = check_array(x, name)
    if arr.ndim != 0:
        raise ShapeError(f"{name} must be a scalar, got shape {arr.shape}")
    return float(arr)


def lo_hi(x: np.ndarray) -> tuple[float, float]:
    """Min and max of a float64 array, NaN when it holds one (the fast paths' check, issue 16).

    ``argmin`` / ``argmax`` are C loops without the ufunc-reduction set-up: about a quarter of the cost
    of ``np.min`` on 100 values, as fast at 10^6; a NaN is their answer when there is one.
    """
    f = x if x.ndim == 1 else x.reshape(-1)
    return f[f.argmin()], f[f.argmax()]


def finite_fast(x: np.ndarray) -> bool:
    """Whether a non-empty float64 array holds no NaN or inf (a NaN fails both comparisons, an inf one)."""
    lo, hi = lo_hi(x)
    return bool(lo > -math.inf and hi < math.inf)


def check_q(q, joint_names) -> np.ndarray:
    """Joint values ``(..., n)``: float64, finite, last axis one value per joint."""
    n = len(joint_names)
    if (type(q) is np.ndarray and q.dtype == np.float64 and q.ndim and q.shape[-1] == n
            and (not q.size or finite_fast(q))):
        # The common call, a float64 array: O(1) checks and one reduction. Issue 16: a per-element
        # isfinite mask cost as much as the FK of a short chain.
        return q
    arr = check_array(q, "q")
    if arr.ndim == 0 or arr.shape[-1] != n:
        names = ", ".join(joint_names) if n <= 12 else f"{', '.join(joint_names[:12])}, ..."
        raise ShapeError(f"q must have shape (..., {n}) (one value per joint: {names}), got {arr.shape}")
    return arr


def optional_transform(T, name: str) -> np.ndarray | None:
    """``None`` stays ``None`` (meaning identity); otherwise a checked 4x4 copy."""
    if T is None:
        return None
    T = check_transform(T, name)
    if T.shape != (4, 4):
        raise ShapeError(f"{name} must have shape (4, 4), got {T.shape}")
    return T.copy()


def rot_axis(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotation about a unit ``axis`` (3,) by ``angle`` (...) as (..., 4, 4) (Rodrigues)."""
    c = np.cos(angle)[..., None, None]
    s = np.sin(angle)[..., None, None]
    x, y, z = axis
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    T = np.zeros(np.shape(angle) + (4, 4))
    T[..., :3, :3] = np.eye(3) + s * K + (1.0 - c) * (K @ K)
    T[..., 3, 3] = 1.0
    return T


def trans_axis(axis: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Translation along a unit ``axis`` (3,) by ``dist`` (...) as (..., 4, 4)."""
    dist = np.asarray(dist, dtype=float)
    T = np.zeros(dist.shape + (4, 4))
    T[..., 0, 0] = T[..., 1, 1] = T[..., 2, 2] = T[..., 3, 3] = 1.0
    T[..., :3, 3] = dist[..., None] * axis
    return T


def joint_motion(kind: str, axis: np.ndarray, value) -> np.ndarray:
    """Motion of a joint of type ``kind`` by ``value`` (rad or m), (..., 4, 4)."""
    if kind == "prismatic":
        return trans_axis(axis, value)
    return rot_axis(axis, np.asarray(value, dtype=float))


def transform_from_xyz_rpy(xyz, rpy) -> np.ndarray:
    """URDF origin: ``Trans(xyz) @ Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (fixed-axis rpy), (4, 4)."""
    T = np.eye(4)
    T[:3, :3] = matrix_from_euler("xyz", np.asarray(rpy, dtype=float))
    T[:3, 3] = xyz
    return T


def xyz_rpy_from_transform(T) -> np.ndarray:
    """Inverse of :func:`transform_from_xyz_rpy`: ``[x, y, z, roll, pitch, yaw]``."""
    T = np.asarray(T, dtype=float)
    return np.concatenate([T[:3, 3], euler_from_matrix("xyz", T[:3, :3])])


# Local screws of an xyz-rpy origin, in the order x, y, z, roll, pitch, yaw.
ORIGIN_PARAM_SUFFIXES = ("x", "y", "z", "roll", "pitch", "yaw")


def origin_screws(G_parent: np.ndarray, xyz_rpy: np.ndarray):
    """Screws (frame, local axis, revolute) of the six xyz/rpy parameters of an origin.

    ``G_parent`` (..., 4, 4) is the frame the origin is attached to, in the
    reference frame. The factor order ``Tx Ty Tz Rz(yaw) Ry(pitch) Rx(roll)``
    puts the translations along the parent axes, yaw about the parent z
    through the new origin, pitch about the yawed y, roll about the final x.
    """
    x, y, z, roll, pitch, yaw = xyz_rpy
    e = np.eye(3)
    G_t = G_parent @ trans_axis(e[0], x) @ trans_axis(e[1], y) @ trans_axis(e[2], z)
    G_yaw = G_t @ rot_axis(e[2], np.asarray(yaw))
    G_pitch = G_yaw @ rot_axis(e[1], np.asarray(pitch))
    return [
        (G_parent, e[0], False),
        (G_parent, e[1], False),
        (G_parent, e[2], False),
        (G_pitch, e[0], True),  # roll axis: x of the frame after yaw and pitch
        (G_yaw, e[1], True),
        (G_t, e[2], True),
    ]


def screw_column(G: np.ndarray, local_axis: np.ndarray, revolute: bool, p: np.ndarray) -> np.ndarray:
    """Twist column ``[d t; omega]`` (..., 6) of one elementary screw (see module doc).

    Parameters
    ----------
    G : ndarray, shape (..., 4, 4)
        A frame on the screw line, in the reference frame.
    local_axis : ndarray, shape (3,)
        Unit screw direction in ``G``'s own coordinates.
    revolute : bool
        Rotation (True) or translation (False).
    p : ndarray, shape (..., 3)
        Origin of the moved frame in the reference frame.
    """
    u = G[..., :3, :3] @ local_axis
    out = np.empty(np.broadcast_shapes(u.shape, p.shape)[:-1] + (6,))
    if revolute:
        out[..., :3] = np.cross(u, p - G[..., :3, 3])
        out[..., 3:] = u
    else:
        out[..., :3] = u
        out[..., 3:] = 0.0
    return out


def fast_inverse(T: np.ndarray) -> np.ndarray:
    """Rigid inverse without re-validation (internal, arrays already float)."""
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ T[..., :3, 3:4])[..., 0]
    out[..., 3, 3] = 1.0
    return out
