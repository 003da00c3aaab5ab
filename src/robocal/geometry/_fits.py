"""Geometric fits of lines, planes, circles and spheres.

"Geometric" means the fits minimise orthogonal (Euclidean) point-to-shape
distances, which is the maximum-likelihood criterion for isotropic Gaussian
point noise. Algebraic fits (Kasa's circle, the linear sphere) are biased on
short arcs and small caps; here they only provide starting values (Hyper fit
for circles), refined by :func:`scipy.optimize.least_squares`.

Every fit returns a frozen dataclass with the fit, the residuals, their RMS
and first-order standard deviations computed as ``sigma_hat^2 (J^T J)^{-1}``
with ``sigma_hat`` estimated from the residuals (sampling error only: it does
not account for model error such as a non-circular part).

Degenerate input raises :class:`~robocal.errors.NotEnoughDataError` (too few
points) or :class:`~robocal.errors.DegenerateGeometryError` (coincident,
collinear, coplanar points), naming the offending singular-value ratio.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import ConvergenceError, DegenerateGeometryError, InputError, NotEnoughDataError, ShapeError
from robocal.geometry._registration import _scalar  # 0-d -> float: unbatched fits keep float fields
from robocal.geometry._so3 import matrix_from_rotvec
from robocal.validation import check_array

__all__ = [
    "LineFit",
    "PlaneFit",
    "Circle2DFit",
    "Circle3DFit",
    "SphereFit",
    "fit_line",
    "fit_plane",
    "fit_circle_2d",
    "fit_circle_3d",
    "fit_sphere",
]

#: Relative singular-value tolerance for collinear / coplanar / coincident points.
RTOL = 1e-9
#: A parameter whose standard deviation exceeds this fraction of its value is "weakly determined".
WEAK_REL_STD = 0.1


@dataclass(frozen=True)
class LineFit:
    """Line ``point + s * direction``; ``residuals`` are orthogonal distances (N,) >= 0.

    ``direction_cov`` (D, D) is the covariance of the unit direction,
    ``point_cov`` (D, D) that of ``point`` across the line (its position along
    the line is a free choice: the centroid).
    """

    point: np.ndarray
    direction: np.ndarray
    rms: float
    residuals: np.ndarray
    direction_cov: np.ndarray
    point_cov: np.ndarray


@dataclass(frozen=True)
class PlaneFit:
    """Plane ``{x : normal . x = d}``, ``normal`` oriented so that ``d >= 0``.

    ``residuals`` (N,) are signed distances ``normal . p - d``; ``normal_cov``
    (3, 3) is the covariance of the unit normal, ``d_std`` the std of ``d``.
    """

    normal: np.ndarray
    d: float
    centroid: np.ndarray
    rms: float
    residuals: np.ndarray
    normal_cov: np.ndarray
    d_std: float


@dataclass(frozen=True)
class Circle2DFit:
    """Circle in the plane. ``residuals`` (N,) are ``|p - centre| - radius``.

    ``cov`` (3, 3) is the covariance of ``(cx, cy, radius)``; ``std`` its
    square-rooted diagonal (NaN with exactly 3 points: no redundancy).
    """

    centre: np.ndarray
    radius: float
    rms: float
    residuals: np.ndarray
    cov: np.ndarray
    std: np.ndarray
    warnings: tuple[Diagnostic, ...] = field(default_factory=tuple)


@dataclass(frozen=True)
class Circle3DFit:
    """Circle in space: ``centre`` (3,), unit ``axis`` (3,) normal to its plane, ``radius``.

    ``residuals`` (N,) are the 3D distances from the points to the circle;
    ``centre_cov`` (3, 3), ``axis_cov`` (3, 3) and ``radius_std`` come from the
    joint geometric refinement.
    """

    centre: np.ndarray
    axis: np.ndarray
    radius: float
    rms: float
    residuals: np.ndarray
    centre_cov: np.ndarray
    axis_cov: np.ndarray
    radius_std: float
    warnings: tuple[Diagnostic, ...] = field(default_factory=tuple)


@dataclass(frozen=True)
class SphereFit:
    """Sphere; ``residuals`` (N,) are ``|p - centre| - radius``.

    ``cov`` is (4, 4) over ``(cx, cy, cz, radius)``, or (3, 3) over the centre
    when the radius was given (then ``radius_std`` is 0).
    """

    centre: np.ndarray
    radius: float
    rms: float
    residuals: np.ndarray
    cov: np.ndarray
    centre_std: np.ndarray
    radius_std: float
    radius_fixed: bool
    warnings: tuple[Diagnostic, ...] = field(default_factory=tuple)


# ----------------------------------------------------------------------------- helpers


def _points(points, dims: tuple[int, ...], min_count: int, what: str, *, batched: bool = False) -> np.ndarray:
    arr = check_array(points, "points", shape=("N", None), min_ndim=2)
    if (arr.ndim != 2 and not batched) or arr.shape[-1] not in dims:
        want = " or ".join(f"({'..., ' if batched else ''}N, {d})" for d in dims)
        raise ShapeError(f"points must have shape {want}, got {tuple(arr.shape)}")
    if arr.shape[-2] < min_count:
        raise NotEnoughDataError(f"{what} needs at least {min_count} points, got {arr.shape[-2]}")
    if arr.size == 0:
        raise NotEnoughDataError(f"{what} got an empty batch of point sets, shape {tuple(arr.shape)}")
    return arr


def _first_bad(mask: np.ndarray) -> str:
    """' (set (i, j))' naming the first flagged batch entry, '' when unbatched."""
    if mask.ndim == 0:
        return ""
    return f" (point set {tuple(int(i) for i in np.argwhere(mask)[0])})"


def _spread(p: np.ndarray, rank: int, shape: str, rtol: float):
    """Centroid and SVD of the centred points, batched over leading axes; raise if rank < ``rank``."""
    c = p.mean(axis=-2)
    _, s, Vt = np.linalg.svd(p - c[..., None, :], full_matrices=False)
    bad = s[..., 0] == 0
    if np.any(bad):
        raise DegenerateGeometryError(f"points all coincide{_first_bad(bad)}: cannot fit a {shape}")
    for k, word in ((1, "collinear"), (2, "coplanar")):
        if rank > k:
            ratio = s[..., k] / s[..., 0]
            bad = ratio <= rtol
            if np.any(bad):
                r = float(ratio[tuple(np.argwhere(bad)[0])] if bad.ndim else ratio)
                raise DegenerateGeometryError(
                    f"points are {word}{_first_bad(bad)} ({'second' if k == 1 else 'third'} singular value "
                    f"{r:.3g} of the first, tolerance {rtol:.1g}): cannot fit a {shape}"
                )
    return c, s, Vt


def _orient(v: np.ndarray) -> np.ndarray:
    """Deterministic sign, batched over leading axes: largest-magnitude component positive."""
    big = np.take_along_axis(v, np.argmax(np.abs(v), axis=-1)[..., None], axis=-1)
    return np.where(big >= 0, v, -v)


def _lsq_cov(J: np.ndarray, r: np.ndarray, n_params: int) -> np.ndarray:
    """``sigma_hat^2 (J^T J)^{-1}``; NaN when there are no degrees of freedom.

    From the SVD of ``J`` (``V diag(1/s^2) V^T``), not by inverting ``J^T J``:
    a nearly collinear arc or a nearly flat cap squares an already large
    condition number, and the inverse then returned tiny or negative
    variances for a radius the points hardly constrain. A direction with no
    information at all (``s < 1e-13 s_max``) makes every variance infinite.
    """
    dof = r.size - n_params
    if dof <= 0:
        return np.full((J.shape[1], J.shape[1]), np.nan)
    s2 = float(r @ r) / dof
    _, sv, Vt = np.linalg.svd(J, full_matrices=False)
    if sv[-1] <= 1e-13 * sv[0]:
        return np.full((J.shape[1], J.shape[1]), np.inf)
    return s2 * (Vt.T / sv**2) @ Vt


def _warnings(ls, checks: list[tuple[str, float, float]]) -> tuple[Diagnostic, ...]:
    out = []
    if ls.status <= 0:
        out.append(Diagnostic("not_converged", f"geometric refinement stopped: {ls.message}"))
    weak = [f"{name} (std {std:.3g} vs {abs(val):.3g})" for name, val, std in checks if std > WEAK_REL_STD * abs(val)]
    if weak:
        out.append(
            Diagnostic(
                "weakly_determined",
                "the points determine poorly: " + ", ".join(weak) + " (short arc / small cap or high noise)",
                params=tuple(name for name, val, std in checks if std > WEAK_REL_STD * abs(val)),
            )
        )
    return tuple(out)


def _positive_radius(r: float, shape: str) -> None:
    if not r > 0:
        raise ConvergenceError(f"the geometric {shape} fit diverged to a non-positive radius ({r:.3g}, normalised units)")


def _solve(fun, jac, x0):
    # 'lm' (MINPACK) is the textbook geometric-fit solver; tight tolerances
    # because the problem is tiny and well-scaled (we normalise the points).
    from scipy.optimize import least_squares  # here: scipy.optimize costs ~0.3 s to import (issue 16)

    return least_squares(fun, x0, jac=jac, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=400)


# ----------------------------------------------------------------------------- line and plane


def fit_line(points, *, rtol: float = RTOL) -> LineFit:
    """Orthogonal-distance (total least squares) line through 2D or 3D points.

    The line passes through the centroid along the first right singular vector
    of the centred points; it minimises the sum of squared orthogonal distances.

    Parameters
    ----------
    points : array_like, shape (..., N, 2) or (..., N, 3)
        N >= 2 points, not all coincident; leading axes are independent point
        sets (Monte Carlo studies fit them in one call).
    rtol : float
        Relative tolerance for "all points coincide".

    Returns
    -------
    LineFit
        ``direction`` is oriented with its largest-magnitude component positive;
        with leading axes every field gains them (``rms`` becomes an array).
    """
    p = _points(points, (2, 3), 2, "fit_line", batched=True)
    c, s, Vt = _spread(p, 1, "line", rtol)
    d = _orient(Vt[..., 0, :])
    q = p - c[..., None, :]
    off = q - np.einsum("...n,...d->...nd", np.einsum("...nd,...d->...n", q, d), d)
    dist = np.linalg.norm(off, axis=-1)
    n, D = p.shape[-2:]
    dof = (D - 1) * (n - 2)
    s2 = np.sum(dist**2, axis=-1) / dof if dof > 0 else np.full(p.shape[:-2], np.nan)
    P = np.eye(D) - d[..., :, None] * d[..., None, :]
    s0 = s[..., 0][..., None, None]
    return LineFit(
        point=c,
        direction=d,
        rms=_scalar(np.sqrt(np.mean(dist**2, axis=-1))),
        residuals=dist,
        direction_cov=(s2[..., None, None] / s0) / s0 * P,  # (two divisions: s0**2 may underflow)
        point_cov=s2[..., None, None] / n * P,
    )


def fit_plane(points, *, rtol: float = RTOL) -> PlaneFit:
    """Orthogonal-distance plane through 3D points (smallest right singular vector).

    Parameters
    ----------
    points : array_like, shape (..., N, 3)
        N >= 3 points, not collinear; leading axes are independent point sets.

    Returns
    -------
    PlaneFit
        With leading axes every field gains them (``d``, ``rms``, ``d_std`` become arrays).
    """
    p = _points(points, (3,), 3, "fit_plane", batched=True)
    c, s, Vt = _spread(p, 2, "plane", rtol)
    nrm = Vt[..., 2, :]
    d = np.einsum("...i,...i->...", nrm, c)
    flip = (d < 0) | ((d == 0) & np.any(_orient(nrm) != nrm, axis=-1))
    nrm = np.where(flip[..., None], -nrm, nrm)
    d = np.where(flip, -d, d)
    r = np.einsum("...ni,...i->...n", p - c[..., None, :], nrm)
    n = p.shape[-2]
    s2 = np.sum(r**2, axis=-1) / (n - 3) if n > 3 else np.full(p.shape[:-2], np.nan)
    # A tilt of the normal towards in-plane direction v_k is resisted by the spread s_k along it.
    v0 = Vt[..., 0, :] / s[..., 0, None]
    v1 = Vt[..., 1, :] / s[..., 1, None]
    ncov = s2[..., None, None] * (v0[..., :, None] * v0[..., None, :] + v1[..., :, None] * v1[..., None, :])
    return PlaneFit(
        normal=nrm,
        d=_scalar(d),
        centroid=c,
        rms=_scalar(np.sqrt(np.mean(r**2, axis=-1))),
        residuals=r,
        normal_cov=ncov,
        d_std=_scalar(np.sqrt(s2 / n + np.einsum("...i,...ij,...j->...", c, ncov, c))),
    )


# ----------------------------------------------------------------------------- circles


def _hyper_circle(q: np.ndarray) -> tuple[np.ndarray, float]:
    """Hyper algebraic circle fit (no essential bias) of centred, scaled points."""
    z = np.sum(q * q, axis=1)
    Z = np.column_stack([z, q, np.ones(len(q))])
    M = Z.T @ Z / len(q)
    xm, ym = q.mean(axis=0)
    zm = z.mean()
    Nh = np.array([[8 * zm, 4 * xm, 4 * ym, 2], [4 * xm, 1, 0, 0], [4 * ym, 0, 1, 0], [2, 0, 0, 0]])
    from scipy.linalg import eig

    _, V = eig(M, Nh)
    V = np.real(V)
    # Of the pencil's eigenvectors only those with A^T N A > 0 satisfy the
    # constraint; among them the best has the least A^T M A / A^T N A.
    num = np.einsum("ik,ij,jk->k", V, M, V)
    den = np.einsum("ik,ij,jk->k", V, Nh, V)
    ok = den > 1e-14 * np.abs(V).max(axis=0) ** 2
    if not np.any(ok):
        raise DegenerateGeometryError("the algebraic circle fit found no admissible solution (degenerate points)")
    k = np.flatnonzero(ok)[np.argmin(num[ok] / den[ok])]
    a, b, c, dd = V[:, k]
    if abs(a) < 1e-12 * np.abs(V[:, k]).max():
        raise DegenerateGeometryError("points lie on a straight line within noise: cannot fit a circle")
    centre = -np.array([b, c]) / (2 * a)
    r2 = (b * b + c * c - 4 * a * dd) / (4 * a * a)
    return centre, float(np.sqrt(max(r2, 0.0)))


def fit_circle_2d(points, *, rtol: float = RTOL) -> Circle2DFit:
    """Geometric (orthogonal-distance) circle fit in 2D.

    Starts from the Hyper algebraic fit (Al-Sharadqah & Chernov 2009, free of
    the essential bias that makes Kasa's fit shrink circles on short arcs),
    then minimises ``sum (|p_i - c| - r)^2`` by Levenberg-Marquardt with an
    analytic Jacobian.

    Parameters
    ----------
    points : array_like, shape (N, 2)
        N >= 3 points, not collinear.

    Returns
    -------
    Circle2DFit

    References
    ----------
    A. Al-Sharadqah, N. Chernov, "Error analysis for circle fitting algorithms",
    Electron. J. Statist. 3, 2009.
    """
    p = _points(points, (2,), 3, "a circle fit")
    c0, s, _ = _spread(p, 2, "circle", rtol)
    scale = s[0] / np.sqrt(len(p))
    q = (p - c0) / scale
    centre, r = _hyper_circle(q)

    def fun(x):
        return np.linalg.norm(q - x[:2], axis=1) - x[2]

    def jac(x):
        dq = q - x[:2]
        rho = np.maximum(np.linalg.norm(dq, axis=1), 1e-300)
        return np.column_stack([-dq / rho[:, None], -np.ones(len(q))])

    ls = _solve(fun, jac, np.r_[centre, r])
    x = ls.x
    _positive_radius(x[2], "circle")
    res = fun(x) * scale
    cov = _lsq_cov(jac(x), res / scale, 3) * scale**2
    std = np.sqrt(np.diag(cov))
    radius = float(x[2] * scale)
    return Circle2DFit(
        centre=c0 + x[:2] * scale,
        radius=radius,
        rms=float(np.sqrt(np.mean(res**2))),
        residuals=res,
        cov=cov,
        std=std,
        warnings=_warnings(ls, [("radius", radius, std[2])]),
    )


def _tangent_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.eye(3)[np.argmin(np.abs(n))]
    b1 = np.cross(n, a)
    b1 /= np.linalg.norm(b1)
    return b1, np.cross(n, b1)


def fit_circle_3d(points, *, rtol: float = RTOL) -> Circle3DFit:
    """Geometric circle fit in 3D: plane fit, 2D circle in the plane, joint refinement.

    The plane and in-plane circle give the start; then centre (3), axis
    (2 tangent angles) and radius are refined together on the 3D point-to-circle
    residuals ``(h_i, rho_i - r)`` (height above the circle's plane, in-plane
    radial error), so the plane is not fitted independently of the circle.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        N >= 3 points, not collinear (an arc, e.g. a target ball on a rotating
        joint, seed 004 MCT step 1).

    Returns
    -------
    Circle3DFit
        ``axis`` is oriented with its largest-magnitude component positive.
    """
    p = _points(points, (3,), 3, "a circle fit")
    _spread(p, 2, "circle", rtol)
    plane = fit_plane(p, rtol=rtol)
    b1, b2 = _tangent_basis(plane.normal)
    uv = (p - plane.centroid) @ np.column_stack([b1, b2])
    c2 = fit_circle_2d(uv, rtol=rtol)
    scale = max(c2.radius, np.sqrt(np.mean(np.sum(uv**2, axis=1))))
    c_start = plane.centroid + c2.centre[0] * b1 + c2.centre[1] * b2
    n0 = plane.normal
    q = (p - c_start) / scale

    def parts(x):
        n = matrix_from_rotvec(x[3] * b1 + x[4] * b2) @ n0
        dq = q - x[:3]
        h = dq @ n
        u = dq - h[:, None] * n
        rho = np.linalg.norm(u, axis=1)
        return n, dq, h, u, rho

    def fun(x):
        _, _, h, _, rho = parts(x)
        return np.concatenate([h, rho - x[5]])

    # Analytic Jacobian about the axis n (rotation increments along n's own
    # tangent basis), used for the final covariance: d n / d a_k = t_k x n.
    def jac_at(x, n):
        t1, t2 = _tangent_basis(n)
        _, dq, h, u, rho = parts(x)
        uh = u / np.maximum(rho, 1e-300)[:, None]
        m = len(q)
        J = np.zeros((2 * m, 6))
        J[:m, :3] = -n
        J[m:, :3] = -uh
        for k, tk in enumerate((t1, t2)):
            dn = np.cross(tk, n)
            J[:m, 3 + k] = dq @ dn
            J[m:, 3 + k] = -h * (uh @ dn)
        J[m:, 5] = -1.0
        return J

    from scipy.optimize import least_squares

    ls = least_squares(fun, np.r_[0.0, 0.0, 0.0, 0.0, 0.0, c2.radius / scale], method="lm", xtol=1e-12, ftol=1e-12)
    x = ls.x
    _positive_radius(x[5], "3D circle")
    n, _, h, _, rho = parts(x)
    r_res = np.concatenate([h, rho - x[5]])
    cov = _lsq_cov(jac_at(x, n), r_res, 6) * scale**2
    t1, t2 = _tangent_basis(n)
    Tn = np.column_stack([np.cross(t1, n), np.cross(t2, n)])  # axis change per tangent angle
    axis_cov = Tn @ (cov[3:5, 3:5] / scale**2) @ Tn.T
    dist = np.hypot(h, rho - x[5]) * scale
    radius = float(x[5] * scale)
    rstd = float(np.sqrt(cov[5, 5]))
    axis = _orient(n)
    return Circle3DFit(
        centre=c_start + x[:3] * scale,
        axis=axis,
        radius=radius,
        rms=float(np.sqrt(np.mean(dist**2))),
        residuals=dist,
        centre_cov=cov[:3, :3],
        axis_cov=axis_cov,
        radius_std=rstd,
        warnings=_warnings(ls, [("radius", radius, rstd)]),
    )


# ----------------------------------------------------------------------------- sphere


def fit_sphere(points, radius=None, *, rtol: float = RTOL) -> SphereFit:
    """Geometric sphere fit, optionally with a known radius.

    The linear (algebraic) fit ``|p|^2 = 2 c.p + k`` gives the start; the
    geometric residuals ``|p_i - c| - r`` are then minimised by
    Levenberg-Marquardt (over ``c`` only when ``radius`` is given, e.g. a
    calibrated precision ball, seed 004).

    Parameters
    ----------
    points : array_like, shape (N, 3)
        N >= 4 points, not coplanar. (Coplanar points on a sphere of known
        radius leave two mirror-image centres, so they are refused as well.)
    radius : float, optional
        Known radius (> 0), same unit as the points.

    Returns
    -------
    SphereFit
    """
    p = _points(points, (3,), 4, "a sphere fit")
    if radius is not None:
        radius = float(check_array(radius, "radius"))
        if not radius > 0:
            raise InputError(f"radius must be > 0, got {radius!r}")
    c0, s, _ = _spread(p, 3, "sphere", rtol)
    scale = s[0] / np.sqrt(len(p))
    q = (p - c0) / scale
    A = np.column_stack([2 * q, np.ones(len(q))])
    sol, *_ = np.linalg.lstsq(A, np.sum(q * q, axis=1), rcond=None)
    centre = sol[:3]
    r0 = float(np.sqrt(max(sol[3] + centre @ centre, 1e-12)))
    fixed = radius is not None

    def fun(x):
        r = radius / scale if fixed else x[3]
        return np.linalg.norm(q - x[:3], axis=1) - r

    def jac(x):
        dq = q - x[:3]
        rho = np.maximum(np.linalg.norm(dq, axis=1), 1e-300)
        J = -dq / rho[:, None]
        return J if fixed else np.column_stack([J, -np.ones(len(q))])

    ls = _solve(fun, jac, centre if fixed else np.r_[centre, r0])
    x = ls.x
    if not fixed:
        _positive_radius(x[3], "sphere")
    res = fun(x) * scale
    cov = _lsq_cov(jac(x), res / scale, x.size) * scale**2
    std = np.sqrt(np.diag(cov))
    r_hat = radius if fixed else float(x[3] * scale)
    rstd = 0.0 if fixed else float(std[3])
    return SphereFit(
        centre=c0 + x[:3] * scale,
        radius=r_hat,
        rms=float(np.sqrt(np.mean(res**2))),
        residuals=res,
        cov=cov,
        centre_std=std[:3],
        radius_std=rstd,
        radius_fixed=fixed,
        warnings=_warnings(ls, [] if fixed else [("radius", r_hat, rstd)]),
    )
