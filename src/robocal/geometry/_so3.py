"""Rotations: thin, vectorised helpers over :class:`scipy.spatial.transform.Rotation`.

Conventions (see ``docs/conventions.md``):

* rotation matrices act on column vectors, ``p_a = R_a_b @ p_b``;
* quaternions are **scalar-last** ``(x, y, z, w)`` like SciPy and ROS;
* rotation vectors (axis-angle) are ``theta * k`` in radians;
* Gibbs vectors (Rodrigues parameters) are ``r = tan(theta/2) k``.

Everything accepts leading batch dimensions ``(..., 3, 3)`` / ``(..., 3)``.
"""

from __future__ import annotations

import numpy as np

from robocal._deprecation import deprecated_alias
from robocal.errors import DegenerateGeometryError, ShapeError
from robocal.validation import check_array

__all__ = [
    "skew",
    "unskew",
    "matrix_from_angle",
    "rotx",
    "roty",
    "rotz",
    "matrix_from_rotvec",
    "rotvec_from_matrix",
    "matrix_from_quaternion",
    "quaternion_from_matrix",
    "matrix_from_euler",
    "euler_from_matrix",
    "matrix_from_gibbs",
    "gibbs_from_matrix",
    "compose_gibbs",
    "rotation_angle",
    "rotation_distance",
    "project_to_rotation",
    "small_rotation_update",
    "so3_left_jacobian",
    "wrap_angle",
]


def _tail(a, tail: tuple, name: str) -> np.ndarray:
    """``a`` as a float array whose trailing shape is ``tail``, else a ShapeError.

    The light check of the small hot-path helpers (skew, transform_from, ...):
    a wrong shape otherwise surfaces as an IndexError or a silent broadcast
    deep in NumPy. Values are not scanned (NaN in, NaN out): the
    ``check_*`` validators at a workflow's boundary do that once.
    """
    a = np.asarray(a, dtype=float)
    if a.shape[a.ndim - len(tail):] != tail or a.ndim < len(tail):
        want = "(..., " + ", ".join(map(str, tail)) + ")"
        raise ShapeError(f"{name} must have shape {want}, got {a.shape}")
    return a


def _rotation():
    """SciPy's ``Rotation``, imported on first use: scipy.spatial costs ~0.2 s, paid by every command that
    imports robocal.geometry otherwise (issue 16: the flow rig's 2D paths never rotate in 3D)."""
    from scipy.spatial.transform import Rotation

    return Rotation


def _batched(fn, arr: np.ndarray, tail: int) -> np.ndarray:
    """Apply a SciPy Rotation constructor/export to any leading batch shape."""
    lead = arr.shape[: arr.ndim - tail]
    flat = arr.reshape((-1,) + arr.shape[arr.ndim - tail :])
    if not flat.flags.writeable:
        flat = flat.copy()  # SciPy 1.11-1.13's Rotation refuses read-only buffers
    out = fn(flat)
    return out.reshape(lead + out.shape[1:])


def skew(v) -> np.ndarray:
    """Skew-symmetric matrix ``[v]_x`` with ``[v]_x @ u == cross(v, u)``.

    Parameters
    ----------
    v : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    v = _tail(v, (3,), "v")
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack(
        [np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], axis=-2
    )


def unskew(S) -> np.ndarray:
    """Inverse of :func:`skew` (uses the antisymmetric part), shape (..., 3)."""
    S = _tail(S, (3, 3), "S")
    return 0.5 * np.stack(
        [S[..., 2, 1] - S[..., 1, 2], S[..., 0, 2] - S[..., 2, 0], S[..., 1, 0] - S[..., 0, 1]], axis=-1
    )


def _elementary(angle, i: int, j: int) -> np.ndarray:
    a = np.asarray(angle, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    k = 3 - i - j
    R[..., k, k] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


#: Axis name -> the (i, j) plane an elementary rotation turns.
_AXES = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}


def matrix_from_angle(axis: str, angle) -> np.ndarray:
    """Rotation about the coordinate ``axis`` (``"x"``, ``"y"`` or ``"z"``) by ``angle`` (rad).

    Active, right-handed: ``matrix_from_angle("z", pi / 2) @ [1, 0, 0] == [0, 1, 0]``.
    Shape ``angle.shape + (3, 3)``.
    """
    if axis not in _AXES:
        raise ValueError(f"axis must be 'x', 'y' or 'z', got {axis!r}")
    return _elementary(angle, *_AXES[axis])


rotx = deprecated_alias(lambda angle: matrix_from_angle("x", angle), "rotx", call="matrix_from_angle('x', angle)")
roty = deprecated_alias(lambda angle: matrix_from_angle("y", angle), "roty", call="matrix_from_angle('y', angle)")
rotz = deprecated_alias(lambda angle: matrix_from_angle("z", angle), "rotz", call="matrix_from_angle('z', angle)")


def matrix_from_rotvec(rotvec) -> np.ndarray:
    """Rotation matrix from a rotation vector ``theta * k`` (rad), (..., 3) -> (..., 3, 3)."""
    r = check_array(rotvec, "rotvec", shape=(3,))
    return _batched(lambda f: _rotation().from_rotvec(f).as_matrix(), r, 1)


def rotvec_from_matrix(R) -> np.ndarray:
    """Rotation vector (rad) from a rotation matrix, (..., 3, 3) -> (..., 3)."""
    R = check_array(R, "R", shape=(3, 3))
    return _batched(lambda f: _rotation().from_matrix(f).as_rotvec(), R, 2)


def matrix_from_quaternion(q) -> np.ndarray:
    """Rotation matrix from a **scalar-last** quaternion ``(x, y, z, w)``.

    The quaternion is normalised; a zero quaternion raises.
    """
    q = check_array(q, "quaternion", shape=(4,))
    if np.any(np.linalg.norm(q, axis=-1) < 1e-12):
        raise DegenerateGeometryError("quaternion has zero norm")
    return _batched(lambda f: _rotation().from_quat(f).as_matrix(), q, 1)


def quaternion_from_matrix(R, *, canonical: bool = True) -> np.ndarray:
    """Scalar-last quaternion ``(x, y, z, w)`` from a rotation matrix.

    With ``canonical=True`` the sign is chosen so that ``w >= 0``.
    """
    R = check_array(R, "R", shape=(3, 3))
    return _batched(lambda f: _rotation().from_matrix(f).as_quat(canonical=canonical), R, 2)


def matrix_from_euler(seq: str, angles, *, degrees: bool = False) -> np.ndarray:
    """Rotation matrix from Euler angles; ``seq`` as in SciPy (``"xyz"`` extrinsic,
    ``"XYZ"`` intrinsic). ROS roll-pitch-yaw is ``"xyz"``."""
    a = check_array(angles, "angles", shape=(len(seq),))
    return _batched(lambda f: _rotation().from_euler(seq, f, degrees=degrees).as_matrix(), a, 1)


def euler_from_matrix(seq: str, R, *, degrees: bool = False) -> np.ndarray:
    """Euler angles from a rotation matrix (see :func:`matrix_from_euler`)."""
    R = check_array(R, "R", shape=(3, 3))
    return _batched(lambda f: _rotation().from_matrix(f).as_euler(seq, degrees=degrees), R, 2)


def matrix_from_gibbs(r) -> np.ndarray:
    """Rotation matrix from a Gibbs vector ``r = tan(theta/2) k`` (Cayley transform).

    ``R = I + 2 ([r]x + [r]x^2) / (1 + |r|^2)``; defined for every rotation
    except half-turns (theta = pi, where |r| is infinite).

    References
    ----------
    Seed 000, eqs. 15-19 (Rodrigues parameters).
    """
    r = check_array(r, "gibbs", shape=(3,))
    S = skew(r)
    n2 = np.sum(r * r, axis=-1)[..., None, None]
    return np.eye(3) + 2.0 * (S + S @ S) / (1.0 + n2)


def gibbs_from_matrix(R) -> np.ndarray:
    """Gibbs vector ``tan(theta/2) k`` of a rotation matrix.

    Raises
    ------
    DegenerateGeometryError
        For (near) half-turn rotations, where the Gibbs vector is unbounded.
    """
    R = check_array(R, "R", shape=(3, 3))
    tr = np.trace(R, axis1=-2, axis2=-1)
    denom = 1.0 + tr  # = 4 cos^2(theta/2)
    if np.any(denom < 1e-10):
        raise DegenerateGeometryError("Gibbs vector undefined for a rotation by pi (tan(theta/2) is infinite)")
    return 2.0 * unskew(R) / denom[..., None]


def compose_gibbs(r1, r2) -> np.ndarray:
    """Gibbs vector of the product ``R(r1) @ R(r2)`` (rotate by r2 first, then r1).

    .. math:: r_3 = r_1 \\otimes r_2 = \\frac{r_1 + r_2 + r_1 \\times r_2}{1 - r_1^T r_2}

    References
    ----------
    Seed 000, eq. 19 (same argument order as the seed).
    """
    r1 = check_array(r1, "r1", shape=(3,))
    r2 = check_array(r2, "r2", shape=(3,))
    denom = 1.0 - np.sum(r1 * r2, axis=-1)
    if np.any(np.abs(denom) < 1e-12):
        raise DegenerateGeometryError("composed rotation is a half-turn: its Gibbs vector is infinite")
    return (r1 + r2 + np.cross(r1, r2)) / denom[..., None]


def rotation_angle(R) -> np.ndarray:
    """Rotation angle in [0, pi] (rad) of (..., 3, 3) matrices, robust near 0 and pi."""
    R = _tail(R, (3, 3), "R")
    s = np.linalg.norm(unskew(R), axis=-1)
    c = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0)
    return np.arctan2(s, c)


def rotation_distance(R_a, R_b) -> np.ndarray:
    """Angle (rad) of ``R_a^T R_b``: the geodesic distance on SO(3)."""
    return rotation_angle(np.swapaxes(_tail(R_a, (3, 3), "R_a"), -1, -2) @ _tail(R_b, (3, 3), "R_b"))


def project_to_rotation(M) -> np.ndarray:
    """Nearest rotation matrix (Frobenius norm) to a 3x3 matrix, via SVD with det guard."""
    M = _tail(M, (3, 3), "M")
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    D = np.ones(M.shape[:-1])
    D[..., -1] = d
    return (U * D[..., None, :]) @ Vt


def small_rotation_update(R, omega, *, left: bool = True) -> np.ndarray:
    """Apply a rotation-vector increment: ``exp([w]x) R`` (left) or ``R exp([w]x)``."""
    dR = matrix_from_rotvec(omega)
    return dR @ R if left else R @ dR


def so3_left_jacobian(omega) -> np.ndarray:
    """SO(3) left Jacobian ``J_l(w)`` (..., 3, 3): ``exp(w + e) = exp(J_l(w) e) exp(w)`` to first order.

    ``J_l = I + (1 - cos t) / t^2 [w]x + (t - sin t) / t^3 [w]x^2``, ``t = |w|``
    (series below 1e-6 rad); the derivative of a left-perturbed rotation
    vector parameterisation.
    """
    v = np.asarray(omega, dtype=float)
    th = np.linalg.norm(v, axis=-1)[..., None, None]
    Kx = skew(v)
    small = th < 1e-6
    ths = np.where(small, 1.0, th)
    a = np.where(small, 0.5 - th**2 / 24.0, (1.0 - np.cos(ths)) / ths**2)
    b = np.where(small, 1.0 / 6.0 - th**2 / 120.0, (ths - np.sin(ths)) / ths**3)
    return np.eye(3) + a * Kx + b * (Kx @ Kx)


def wrap_angle(a):
    """Wrap angles (rad) to ``(-pi, pi]``, elementwise; ``ref + wrap_angle(a - ref)`` is the
    representative of ``a`` within half a turn of ``ref``."""
    a = np.asarray(a, dtype=float)
    w = np.mod(a + np.pi, 2.0 * np.pi) - np.pi
    return np.where(w == -np.pi, np.pi, w)
