"""SO(3) log map and its Jacobians in plain NumPy, for the hand-eye hot paths.

:func:`robocal.geometry.rotvec_from_matrix` goes through SciPy's ``Rotation``,
which validates and re-orthogonalises every batch: ~0.2 ms a call whatever
the batch size, more than the rest of a 15-pose refinement step. The closed
forms and the refinement call the log map a dozen times per calibration on
products of already validated rotations, so they use :func:`log_so3` below
(~20 us on 15 matrices). It agrees with SciPy to ~1e-15 rad on orthonormal
matrices (tests/handeye/test_handeye_refine.py), including near the half-turn.

Conventions: rotation vectors ``theta k`` (rad), ``exp(w + d) = exp(J_l(w) d) exp(w)``
to first order (J. Sola, J. Deray, D. Atchuthan, "A micro Lie theory for state
estimation in robotics", arXiv:1812.01537, eqs. 143-146).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["log_so3", "exp_so3", "left_jacobian", "left_jacobian_inverse", "skew3"]

_I3 = np.eye(3)
_I3.flags.writeable = False      # shared: every use below makes a new array from it


def _coefficients1(w) -> tuple[np.ndarray, float, float, float]:
    """One rotation vector (3,): ``[w]x``, ``t``, ``sin t / t``, ``(1 - cos t) / t^2`` with Python floats (a
    refinement step takes a handful of single-vector maps; NumPy's per-call overhead would dominate)."""
    x, y, z = float(w[0]), float(w[1]), float(w[2])
    t = math.sqrt(x * x + y * y + z * z)
    if t < 1e-4:
        a, b = 1.0 - t * t / 6.0, 0.5 - t * t / 24.0
    else:
        a, b = math.sin(t) / t, 2.0 * (math.sin(t / 2) / t) ** 2
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]), t, a, b


def skew3(v: np.ndarray) -> np.ndarray:
    """``[v]_x`` (..., 3, 3) of v (..., 3), without validation (internal callers pass float arrays)."""
    # one gather and one product (a 0 sign on the diagonal) instead of a zero fill and six assignments
    return (v[..., _SKEW_SRC] * _SKEW_SIGN).reshape(v.shape + (3,))


# [v]x row-major: 0, -v2, v1 / v2, 0, -v0 / -v1, v0, 0 (the diagonal's source is arbitrary, its sign 0)
_SKEW_SRC = np.array([0, 2, 1, 2, 0, 0, 1, 0, 0])
_SKEW_SIGN = np.array([0.0, -1.0, 1.0, 1.0, 0.0, -1.0, -1.0, 1.0, 0.0])


# the axis of a rotation matrix flattened row-major: R21 - R12, R02 - R20, R10 - R01
_VEE_A, _VEE_B = np.array([7, 2, 3]), np.array([5, 6, 1])


def log_so3(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) of rotation matrices (..., 3, 3), rad, angle in [0, pi].

    The angle from ``atan2(|vee(R - R^T)| / 2, (tr R - 1) / 2)`` (accurate at every angle); the axis
    from the antisymmetric part below 0.75 pi and from the symmetric part ``(R + R^T)/2 - cos t I =
    (1 - cos t) k k^T`` above it, where the antisymmetric part vanishes (its sign still picks the axis'
    direction; at exactly pi both are valid).
    """
    R = np.asarray(R, dtype=float)
    # (issue 16) few NumPy calls: on the 15-105 matrices of a hand-eye call their count is the cost
    Rf = R.reshape(R.shape[:-2] + (9,))
    v = Rf[..., _VEE_A] - Rf[..., _VEE_B]
    s2 = np.sqrt(np.einsum("...i,...i->...", v, v))        # 2 sin t
    c2 = Rf[..., 0] + Rf[..., 4] + Rf[..., 8] - 1.0         # 2 cos t
    th = np.arctan2(s2, c2)
    small = th < 1e-4
    # theta / (2 sin theta), its series below 1e-4 rad (error < 1e-17)
    f = np.where(small, 0.5 + th * th / 12.0, th / np.where(small, 1.0, s2)) if small.any() else th / s2
    out = f[..., None] * v
    big = th > 0.75 * np.pi
    if np.any(big):
        Rb, thb, vb = R[big], th[big], v[big]
        cb = np.cos(thb)
        d = (np.diagonal(Rb, axis1=-2, axis2=-1) - cb[:, None]) / (1.0 - cb[:, None])   # k_j^2
        j = np.argmax(d, axis=-1)
        n = np.arange(len(j))
        col = 0.5 * (Rb[n, :, j] + Rb[n, j, :])            # (1 - cos t) k_j k, symmetric part's column j
        col[n, j] = Rb[n, j, j] - cb
        k = col / np.linalg.norm(col, axis=-1, keepdims=True)
        k *= np.where(np.einsum("ni,ni->n", k, vb) < 0, -1.0, 1.0)[:, None]
        out[big] = thb[:, None] * k
    return out


def exp_so3(w: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of rotation vectors (..., 3), rad (Rodrigues, series below 1e-4 rad)."""
    w = np.asarray(w, dtype=float)
    if w.shape == (3,):
        K, _, a, b = _coefficients1(w)
        return _I3 + a * K + b * (K @ K)
    th = np.linalg.norm(w, axis=-1)[..., None, None]
    K = skew3(w)
    small = th < 1e-4
    ths = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th * th / 6.0, np.sin(ths) / ths)
    b = np.where(small, 0.5 - th * th / 24.0, 2.0 * (np.sin(ths / 2) / ths) ** 2)    # (1 - cos t) / t^2
    return _I3 + a * K + b * (K @ K)


def left_jacobian(w: np.ndarray) -> np.ndarray:
    """``J_l(w)`` (..., 3, 3): ``I + (1 - cos t)/t^2 [w]x + (t - sin t)/t^3 [w]x^2`` (Sola et al. eq. 145)."""
    w = np.asarray(w, dtype=float)
    if w.shape == (3,):
        K, t, a, b = _coefficients1(w)      # (1 - cos t)/t^2 = b, (t - sin t)/t^3 = (1 - a)/t^2
        c = 1.0 / 6.0 - t * t / 120.0 if t < 1e-4 else (1.0 - a) / (t * t)
        return _I3 + b * K + c * (K @ K)
    th = np.linalg.norm(w, axis=-1)[..., None, None]
    K = skew3(w)
    small = th < 1e-4
    ths = np.where(small, 1.0, th)
    # 1 - cos t as 2 sin^2(t/2): no cancellation at small angles
    a = np.where(small, 0.5 - th * th / 24.0, 2.0 * (np.sin(ths / 2) / ths) ** 2)
    b = np.where(small, 1.0 / 6.0 - th * th / 120.0, (ths - np.sin(ths)) / ths**3)
    return _I3 + a * K + b * (K @ K)


def left_jacobian_inverse(w: np.ndarray) -> np.ndarray:
    """``J_l(w)^-1`` (..., 3, 3): ``I - [w]x / 2 + (1/t^2 - (1 + cos t) / (2 t sin t)) [w]x^2`` (Sola et al.
    eq. 146; its coefficient by a series below 0.03 rad). ``J_r(w)^-1 = J_l(w)^-T``."""
    w = np.asarray(w, dtype=float)
    th2 = np.einsum("...i,...i->...", w, w)[..., None, None]
    th = np.sqrt(th2)
    K = skew3(w)
    # the coefficient's series 1/12 + t^2/720 + t^4/30240 below 0.03 rad (the next term, t^6/1209600, is
    # < 6e-16 there; the closed form loses ~eps/t^2 to cancellation: 2.5e-13 at 0.03 rad). One branch
    # when every angle is on one side of the cut, as a calibration's residuals are.
    small = th < _JINV_SERIES
    if small.all():
        c = 1.0 / 12.0 + th2 * (1.0 / 720.0 + th2 / 30240.0)
    elif not small.any():
        c = 1.0 / th2 - (1.0 + np.cos(th)) / (2.0 * th * np.sin(th))
    else:
        ths = np.where(small, 1.0, th)
        c = np.where(small, 1.0 / 12.0 + th2 * (1.0 / 720.0 + th2 / 30240.0),
                     1.0 / ths**2 - (1.0 + np.cos(ths)) / (2.0 * ths * np.sin(ths)))
    return _I3 - 0.5 * K + c * (K @ K)


_JINV_SERIES = 0.03
