"""Point and vector registration: Wahba/Kabsch rotation, Umeyama/Horn rigid fit.

These closed forms are the references every seed-specific solver is compared
against (e.g. the projector rig's Gibbs-vector initialisation, seed 000
eqs. 15-23). Everything is vectorised over leading batch dimensions, so a
Monte Carlo study of thousands of fits is one call.

Both 3D (``(..., N, 3)``: SE(3), 3x3 rotation) and planar (``(..., N, 2)``:
SE(2), 2x2 rotation by one angle) point sets are accepted; the dimension is
read from the last axis. In 2D the rotation has the closed form
``theta = atan2(sum w (x~ cross y~), sum w (x~ . y~))`` (Kabsch/Umeyama
restricted to the plane, a proper rotation by construction), so collinear
points are fine -- a line fixes the angle; only coincident points (or a
reflected copy with no preferred rotation) are degenerate.

Noise model used by the bounds: the *target* points are observed with
isotropic Gaussian noise, ``points_to[i] = R @ points_from[i] + t + e_i`` with
``e_i ~ N(0, sigma**2 / w_i * I)`` (I of size 3 or 2); the model points
``points_from`` are exact.
Under this model the weighted least-squares fit below is the maximum-likelihood
estimate, so its covariance approaches the Cramer-Rao bound for small noise.

SciPy's ``Rotation.align_vectors`` solves the unbatched Wahba problem but not
the rigid (centred, scaled, batched) case, and OpenCV's ``estimateAffine3D``
has no weights; hence the short SVD code here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.errors import DegenerateGeometryError, InputError, NotEnoughDataError, ShapeError
from robocal.geometry._so3 import skew
from robocal.validation import check_array

__all__ = [
    "RigidFit",
    "wahba_rotation",
    "rigid_fit",
    "rigid_fit_rotation_crb",
    "rigid_fit_covariance",
]

#: Default relative tolerance on singular values below which a point/vector
#: set is treated as rank deficient (collinear, parallel, coincident).
RTOL = 1e-9


@dataclass(frozen=True)
class RigidFit:
    """Result of :func:`rigid_fit` (arrays carry the batch shape ``B`` of the input).

    ``D`` is the point dimension: 3 for SE(3) fits, 2 for planar SE(2) fits.

    Attributes
    ----------
    T_to_from : ndarray, shape (B..., D + 1, D + 1)
        Homogeneous transform mapping ``points_from`` onto ``points_to`` (4x4
        in 3D, 3x3 in 2D). With ``with_scale=True`` its DxD block is
        ``scale * R`` (a similarity).
    R : ndarray, shape (B..., D, D)
        Proper rotation (det = +1).
    t : ndarray, shape (B..., D)
        Translation, in the "to" frame (the input's length unit).
    scale : float or ndarray, shape (B...)
        Similarity scale (1.0 unless ``with_scale=True``).
    rms : float or ndarray, shape (B...)
        Root of the (weighted) mean squared residual norm,
        ``sqrt(sum w_i |r_i|^2 / sum w_i)``, in the input's length unit.
    residuals : ndarray, shape (B..., N, D)
        ``points_to - (scale * R @ points_from + t)``.
    sigma_hat : float or ndarray, shape (B...)
        Per-coordinate noise standard deviation of a unit-weight point estimated
        from the residuals, ``sqrt(sum w_i |r_i|^2 / dof)`` with
        ``dof = 3 N - 6`` in 3D and ``2 N - 3`` in 2D (one less with scale),
        ``N`` counting the points of non-zero weight; NaN when there are no
        degrees of freedom. Feed it to :func:`rigid_fit_covariance`.
    """

    T_to_from: np.ndarray
    R: np.ndarray
    t: np.ndarray
    scale: float | np.ndarray
    rms: float | np.ndarray
    residuals: np.ndarray
    sigma_hat: float | np.ndarray

    @property
    def dim(self) -> int:
        """Point dimension ``D``: 3 for an SE(3) fit, 2 for a planar SE(2) fit."""
        return int(self.R.shape[-1])

    @property
    def angle(self) -> float | np.ndarray:
        """Rotation angle of a 2D fit, rad in (-pi, pi], shape (B...): ``R = [[c, -s], [s, c]]``.

        Raises :class:`~robocal.errors.InputError` for a 3D fit (use
        :func:`robocal.geometry.rotvec_from_matrix` on :attr:`R` there).
        """
        if self.dim != 2:
            raise InputError("RigidFit.angle is defined for 2D fits only, got a 3D fit; "
                             "use rotvec_from_matrix(fit.R) for a 3D rotation")
        return _scalar(np.arctan2(self.R[..., 1, 0], self.R[..., 0, 0]))


def _scalar(x: np.ndarray):
    return float(x) if np.ndim(x) == 0 else x


def _check_weights(weights, n: int) -> np.ndarray | None:
    """Non-negative weights of shape (..., n), or None when none were given."""
    if weights is None:
        return None
    w = check_array(weights, "weights", shape=(n,))
    if np.any(w < 0):
        raise InputError(f"weights must be >= 0, got {float(w[w < 0].reshape(-1)[0])!r}")
    return w


def _check_points_nd(x, name: str) -> np.ndarray:
    """``x`` as float64 of shape ``(..., N, 3)`` or ``(..., N, 2)`` (the dimension is read from it)."""
    x = check_array(x, name)
    if x.ndim < 2 or x.shape[-1] not in (2, 3):
        raise ShapeError(f"{name} must have shape (..., N, 3) or (..., N, 2), got {tuple(x.shape)}")
    return x


def _check_pair(a, b, name_a: str, name_b: str, weights):
    """Broadcast paired point/vector sets ``(..., N, D)`` (D = 2 or 3, the same in both) and weights."""
    a = _check_points_nd(a, name_a)
    dim = a.shape[-1]
    b = check_array(b, name_b)
    if b.ndim < 2 or b.shape[-1] != dim:
        raise ShapeError(f"{name_b} must have shape (..., N, {dim}) like {name_a}, got {tuple(b.shape)}")
    if a.shape[-2] != b.shape[-2]:
        raise ShapeError(f"{name_a} and {name_b} must hold the same number of points, got {a.shape[-2]} and {b.shape[-2]}")
    try:
        lead = np.broadcast_shapes(a.shape[:-2], b.shape[:-2])
    except ValueError:
        raise ShapeError(f"batch shapes of {name_a} {a.shape[:-2]} and {name_b} {b.shape[:-2]} do not broadcast") from None
    n = a.shape[-2]
    w = _check_weights(weights, n)
    if w is None:
        w = np.ones(lead + (n,))
    else:
        try:
            lead = np.broadcast_shapes(lead, w.shape[:-1])
        except ValueError:
            raise ShapeError(f"weights batch shape {w.shape[:-1]} does not broadcast with {lead}") from None
        if w.shape[:-1] != lead:
            w = np.broadcast_to(w, lead + (n,))
    if a.shape[:-2] != lead:
        a = np.broadcast_to(a, lead + a.shape[-2:])
    if b.shape[:-2] != lead:
        b = np.broadcast_to(b, lead + b.shape[-2:])
    return a, b, w


def _where(idx) -> str:
    return "" if len(idx) == 0 else f" (batch index {tuple(int(i) for i in idx)})"


def _require_rank2(sv: np.ndarray, what: str, rtol: float) -> None:
    """Raise if singular values ``sv (..., 3)`` (descending) show rank < 2."""
    if np.all(sv[..., 1] > rtol * sv[..., 0]):  # fast path: the usual case
        return
    s1 = sv[..., 0]
    ratio = sv[..., 1] / np.where(s1 > 0, s1, 1.0)
    bad = ratio <= rtol
    idx = tuple(np.argwhere(bad)[0]) if bad.ndim else ()
    if s1[idx] == 0:
        raise DegenerateGeometryError(f"{what} have zero spread (all identical or zero){_where(idx)}")
    raise DegenerateGeometryError(
        f"{what} are collinear: second singular value is {float(ratio[idx]):.3g} of the first "
        f"(tolerance {rtol:.1g}); the rotation about their common line is undetermined{_where(idx)}"
    )


def _kabsch(H: np.ndarray):
    """Rotation maximising ``tr(R^T H)`` with the det = -1 guard; also the singular values."""
    U, s, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0, 1.0, d)
    D = np.ones(H.shape[:-1])
    D[..., -1] = d
    return (U * D[..., None, :]) @ Vt, s, d


def _rot2(c, s) -> np.ndarray:
    """2x2 rotation matrices ``[[c, -s], [s, c]]`` from cosine/sine arrays of shape (B...)."""
    c, s = np.asarray(c, dtype=float), np.asarray(s, dtype=float)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _planar_rotation(a, b, w, what: str, rtol: float):
    """Best 2D rotation taking vectors ``a`` onto ``b`` (both (..., N, 2)): ``(R, |z|)``.

    ``z = sum_i w_i (a_i . b_i, a_i x b_i)`` (the complex sum ``sum w conj(a) b``):
    ``tr(R(theta)^T B) = |z| cos(theta - arg z)`` with ``B = sum w b a^T``, so
    ``theta = arg z`` is the unique maximiser unless ``z = 0``. By Cauchy-Schwarz
    ``|z| <= sqrt(sum w |a|^2 sum w |b|^2)``; a ratio <= ``rtol`` is refused.
    """
    re = np.einsum("...n,...n->...", w, (a * b).sum(axis=-1))
    im = np.einsum("...n,...n->...", w, a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0])
    mag = np.hypot(re, im)
    bound = np.sqrt(np.einsum("...n,...n->...", w, (a * a).sum(-1)) * np.einsum("...n,...n->...", w, (b * b).sum(-1)))
    bad = ~(mag > rtol * bound) | ~(bound > 0)
    if np.any(bad):
        idx = tuple(np.argwhere(bad)[0]) if bad.ndim else ()
        ratio = float(mag[idx] / bound[idx]) if bound[idx] > 0 else 0.0
        raise DegenerateGeometryError(
            f"{what} determine no rotation: |sum w (a.b, a x b)| is {ratio:.3g} of its bound "
            f"(tolerance {rtol:.1g}); every angle fits equally well (zero vectors, or one set a "
            f"mirror image of the other){_where(idx)}"
        )
    return _rot2(re / mag, im / mag), mag


def wahba_rotation(vectors_from, vectors_to, weights=None, *, rtol: float = RTOL) -> np.ndarray:
    """Optimal rotation between two sets of paired vectors (Wahba's problem).

    Finds the proper rotation minimising
    ``sum_i w_i |vectors_to[i] - R @ vectors_from[i]|^2`` by the SVD of
    ``B = sum_i w_i to_i from_i^T = U S V^T``:
    ``R = U diag(1, 1, det(U V^T)) V^T`` (Kabsch; the ``det`` factor keeps R a
    rotation instead of a reflection). No centring: for point sets use
    :func:`rigid_fit`.

    In 2D (vectors of shape ``(..., N, 2)``) the answer is the rotation by
    ``theta = atan2(sum w (a x b), sum w (a . b))`` (``a`` from, ``b`` to);
    one non-zero pair suffices.

    Parameters
    ----------
    vectors_from : array_like, shape (..., N, 3) or (..., N, 2)
        Vectors in the "from" frame.
    vectors_to : array_like, shape (..., N, 3) or (..., N, 2)
        The same vectors observed in the "to" frame (same dimension). Batch
        shapes broadcast.
    weights : array_like, shape (..., N), optional
        Non-negative weights (inverse relative variances). Default: all 1.
    rtol : float
        Relative tolerance on the second singular value of ``B`` (3D), or on
        ``|sum w (a . b, a x b)| / sqrt(sum w |a|^2 sum w |b|^2)`` (2D).

    Returns
    -------
    R_to_from : ndarray, shape (..., 3, 3) or (..., 2, 2)

    Raises
    ------
    DegenerateGeometryError
        3D: ``B`` has rank < 2 (fewer than two non-parallel vectors, in either
        set): the rotation is then not unique. 2D: all vectors zero, or no
        preferred angle (``z = 0`` above).
    NotEnoughDataError
        Fewer than 2 vectors (3D) or none (2D).

    References
    ----------
    G. Wahba, "A least squares estimate of satellite attitude", SIAM Review 7(3), 1965;
    W. Kabsch, Acta Cryst. A32, 1976.
    """
    a, b, w = _check_pair(vectors_from, vectors_to, "vectors_from", "vectors_to", weights)
    if a.shape[-1] == 2:
        if a.shape[-2] < 1:
            raise NotEnoughDataError("wahba_rotation in 2D needs at least 1 non-zero vector, got 0")
        return _planar_rotation(a, b, w, "vectors", rtol)[0]
    if a.shape[-2] < 2:
        raise NotEnoughDataError(f"wahba_rotation needs at least 2 non-parallel vectors, got {a.shape[-2]}")
    B = np.einsum("...n,...ni,...nj->...ij", w, b, a)
    R, s, _ = _kabsch(B)
    _require_rank2(s, "vectors (weighted cross-covariance B = sum w to from^T)", rtol)
    return R


def rigid_fit(points_from, points_to, weights=None, *, with_scale: bool = False, rtol: float = RTOL) -> RigidFit:
    """Least-squares rigid (or similarity) transform between paired point sets.

    Minimises ``sum_i w_i |points_to[i] - (s R @ points_from[i] + t)|^2`` in
    closed form: centre both sets on their weighted centroids, solve the
    rotation by Kabsch on the cross-covariance, then (optionally) the scale
    ``s = tr(D Sigma) / sum_i w_i |x_i - x_bar|^2`` and ``t = y_bar - s R x_bar``.

    **2D (SE(2)).** Points of shape ``(..., N, 2)`` give a planar fit: with
    ``z = sum_i w_i (x~_i . y~_i, x~_i x y~_i)`` (centred points, ``x`` the
    scalar 2D cross product) the rotation angle is ``theta = atan2(z_1, z_0)``,
    the scale ``|z| / sum_i w_i |x~_i|^2`` and ``t = y_bar - s R x_bar``. Two
    distinct points suffice and collinear points are fine; coincident points
    (zero spread) in either set are refused. ``RigidFit.angle`` gives theta.

    Parameters
    ----------
    points_from : array_like, shape (..., N, 3) or (..., N, 2)
        Model points (frame "from"): in 3D N >= 3, not collinear; in 2D
        N >= 2, not all coincident.
    points_to : array_like, shape (..., N, 3) or (..., N, 2)
        Measured points (frame "to"), same dimension as ``points_from``. Batch
        shapes broadcast, so a whole Monte Carlo study can be fitted in one call.
    weights : array_like, shape (..., N), optional
        Non-negative weights (inverse relative variances of the target points).
    with_scale : bool
        Also estimate a uniform scale (Umeyama's similarity).
    rtol : float
        Relative tolerance for the degeneracy checks: on singular values
        (collinearity, 3D); on the RMS spread about the centroid relative to
        the largest coordinate (coincidence, 2D) and on ``|z|`` relative to its
        Cauchy-Schwarz bound (2D).

    Returns
    -------
    RigidFit
        3D: ``R`` (..., 3, 3), ``t`` (..., 3), ``T_to_from`` (..., 4, 4).
        2D: ``R`` (..., 2, 2), ``t`` (..., 2), ``T_to_from`` (..., 3, 3).

    Raises
    ------
    NotEnoughDataError
        Fewer than 3 points (3D) or 2 points (2D) with non-zero weight.
    DegenerateGeometryError
        3D: collinear or coincident points in either set, or a rank < 2
        cross-covariance. 2D: coincident points in either set, or no preferred
        rotation (``z = 0``: e.g. the target is a mirror image of the model).

    References
    ----------
    S. Umeyama, IEEE TPAMI 13(4), 1991; B. K. P. Horn, JOSA A 4(4), 1987.
    """
    x, y, w = _check_pair(points_from, points_to, "points_from", "points_to", weights)
    if x.shape[-1] == 2:
        return _rigid_fit_2d(x, y, w, with_scale, rtol)
    n_used = np.count_nonzero(w > 0, axis=-1)
    if x.shape[-2] < 3 or np.any(n_used < 3):
        got = x.shape[-2] if x.shape[-2] < 3 else int(np.min(n_used))
        raise NotEnoughDataError(f"rigid_fit needs at least 3 non-collinear points with non-zero weight, got {got}")
    wsum, wcol, xbar, ybar, xc, yc = _weighted_centring(x, y, w)
    sw = np.sqrt(wcol)
    # Singular values of the weighted centred point sets (one batched call)
    # name the failing side; the scatter matrices would square the ratio and
    # lose the distinction between 1e-9 and round-off.
    sv = np.linalg.svd(np.stack([sw * xc, sw * yc]), compute_uv=False)
    _require_rank2(sv[0], "points_from", rtol)
    _require_rank2(sv[1], "points_to", rtol)
    H = np.swapaxes(wcol * yc, -1, -2) @ xc
    R, s, d = _kabsch(H)
    _require_rank2(s, "point pairs (cross-covariance of the centred sets)", rtol)
    if with_scale:
        var_x = (w * (xc * xc).sum(axis=-1)).sum(axis=-1)
        scale = (s[..., 0] + s[..., 1] + d * s[..., 2]) / var_x
    else:
        scale = np.ones(R.shape[:-2])
    return _fit_result(x, y, w, xbar, ybar, R, scale, wsum, n_used, with_scale)


def _fit_result(x, y, w, xbar, ybar, R, scale, wsum, n_used, with_scale) -> RigidFit:
    """Translation, residuals and the record for a fitted rotation (any dimension ``D``)."""
    dim = x.shape[-1]
    sR = scale[..., None, None] * R
    t = ybar - (sR @ xbar[..., :, None])[..., 0]
    res = y - (x @ np.swapaxes(sR, -1, -2) + t[..., None, :])
    wr2 = (w * (res * res).sum(axis=-1)).sum(axis=-1)
    # residual degrees of freedom: D per used point, minus the transform's D(D+1)/2 (+1 for scale)
    dof = dim * n_used - dim * (dim + 1) // 2 - (1 if with_scale else 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma_hat = np.where(dof > 0, np.sqrt(wr2 / np.maximum(dof, 1)), np.nan)
    T = np.zeros(R.shape[:-2] + (dim + 1, dim + 1))
    T[..., :dim, :dim] = sR
    T[..., :dim, dim] = t
    T[..., dim, dim] = 1.0
    return RigidFit(
        T_to_from=T,
        R=R,
        t=t,
        scale=_scalar(scale),
        rms=_scalar(np.sqrt(wr2 / wsum)),
        residuals=res,
        sigma_hat=_scalar(sigma_hat),
    )


def _require_spread_2d(xc, x, w, name: str, rtol: float) -> np.ndarray:
    """Weighted sum of squared distances to the centroid ``sum w |x~|^2`` (...); raise if zero.

    The set is coincident when its RMS spread is <= ``rtol`` times its largest
    coordinate among points of non-zero weight (all points at one position, up
    to round-off).
    """
    spread2 = np.einsum("...n,...n->...", w, (xc * xc).sum(axis=-1))
    wsum = w.sum(axis=-1)
    size = np.max(np.abs(x) * (w > 0)[..., None], axis=(-2, -1))
    bad = ~(np.sqrt(spread2 / wsum) > rtol * size)
    if np.any(bad):
        idx = tuple(np.argwhere(bad)[0]) if bad.ndim else ()
        raise DegenerateGeometryError(
            f"{name} have zero spread (all points coincide; RMS distance to their centroid "
            f"{float(np.sqrt(spread2[idx] / wsum[idx])):.3g}, coordinates up to {float(size[idx]):.3g}): "
            f"a 2D rotation needs two distinct points{_where(idx)}"
        )
    return spread2


def _weighted_centring(x, y, w):
    """Weight sums, weights as a column, weighted centroids and centred points of both sets."""
    wsum = w.sum(axis=-1)
    wcol = w[..., :, None]
    xbar = (wcol * x).sum(axis=-2) / wsum[..., None]
    ybar = (wcol * y).sum(axis=-2) / wsum[..., None]
    return wsum, wcol, xbar, ybar, x - xbar[..., None, :], y - ybar[..., None, :]


def _rigid_fit_2d(x, y, w, with_scale: bool, rtol: float) -> RigidFit:
    """Planar (SE(2) / similarity) branch of :func:`rigid_fit`; inputs already broadcast."""
    n_used = np.count_nonzero(w > 0, axis=-1)
    if x.shape[-2] < 2 or np.any(n_used < 2):
        got = x.shape[-2] if x.shape[-2] < 2 else int(np.min(n_used))
        raise NotEnoughDataError(f"rigid_fit in 2D needs at least 2 distinct points with non-zero weight, got {got}")
    wsum, _, xbar, ybar, xc, yc = _weighted_centring(x, y, w)
    var_x = _require_spread_2d(xc, x, w, "points_from", rtol)
    _require_spread_2d(yc, y, w, "points_to", rtol)
    R, mag = _planar_rotation(xc, yc, w, "point pairs (centred)", rtol)
    scale = mag / var_x if with_scale else np.ones(R.shape[:-2])
    return _fit_result(x, y, w, xbar, ybar, R, scale, wsum, n_used, with_scale)


def _check_model(points_from, sigma, weights):
    """``x (..., N, D)`` (D = 3 or 2), ``sigma (...)`` and ``w (..., N)`` broadcast together."""
    x = _check_points_nd(points_from, "points_from")
    dim = x.shape[-1]
    sigma = check_array(sigma, "sigma")
    if np.any(~(sigma > 0)):
        raise InputError(f"sigma must be > 0, got {sigma.tolist()!r}")
    n = x.shape[-2]
    w = _check_weights(weights, n)
    if w is None:
        w = np.ones(n)
    try:
        lead = np.broadcast_shapes(x.shape[:-2], w.shape[:-1], sigma.shape)
    except ValueError:
        raise ShapeError(f"batch shapes of points_from {x.shape[:-2]}, weights {w.shape[:-1]} and sigma "
                         f"{sigma.shape} do not broadcast") from None
    used = np.count_nonzero(w, axis=-1)
    need = 3 if dim == 3 else 2
    if np.any(used < need):
        raise NotEnoughDataError(
            f"a {dim}D rigid fit needs at least {need} points with non-zero weight, got {int(np.min(used))}")
    x = np.broadcast_to(x, lead + (n, dim))
    w = np.broadcast_to(w, lead + (n,))
    return x, np.broadcast_to(sigma, lead), w


def _centred(x, w):
    """Model points centred on their weighted centroid, after the degeneracy check
    (collinear in 3D, coincident in 2D)."""
    xc = x - ((w[..., None] * x).sum(axis=-2) / w.sum(axis=-1)[..., None])[..., None, :]
    if x.shape[-1] == 2:
        _require_spread_2d(xc, x, w, "points_from", RTOL)
    else:
        _require_rank2(np.linalg.svd(np.sqrt(w)[..., None] * xc, compute_uv=False), "points_from", RTOL)
    return xc


def rigid_fit_rotation_crb(points_from, sigma, weights=None) -> np.ndarray:
    """Cramer-Rao bound of the rotation error of a rigid fit (small angles, rad^2).

    .. math:: C_\\delta = \\sigma^2 (\\operatorname{tr}(S) I - S)^{-1},
              \\quad S = \\sum_i w_i \\tilde x_i \\tilde x_i^T

    with ``x~_i`` the model points centred on their weighted centroid.

    Derivation: write the estimate as ``R_hat = R exp([delta]_x)``, so
    ``delta`` is the rotation error vector **in the "from" (model) frame**
    (``delta = rotvec(R.T @ R_hat)``). To first order the predicted target
    point moves by ``R (delta x x_i) = -R [x_i]_x delta``; the translation
    absorbs the centroid, leaving the Fisher information
    ``(1/sigma^2) sum_i w_i [x~_i]_x^T [x~_i]_x = (tr S I - S) / sigma^2``
    (``R`` drops out since ``R^T R = I``). Expressed in the "to" frame the
    covariance is ``R C R^T``. The mean squared rotation error
    ``E|delta|^2`` is bounded by ``trace(C)``.

    **2D.** For planar points ``(..., N, 2)`` the rotation error is one angle
    ``delta = theta_hat - theta`` (rad; ``R_hat = R Rot(delta)``). The predicted
    point moves by ``R J x_i delta`` with ``J = [[0, -1], [1, 0]]``, so after
    the translation absorbs the centroid the bound is

    .. math:: \\operatorname{var}(\\delta) \\ge \\sigma^2 / \\sum_i w_i |\\tilde x_i|^2,

    returned as a ``(..., 1, 1)`` matrix so that the rotation block of
    :func:`rigid_fit_covariance` reads the same in 2D and 3D.

    Parameters
    ----------
    points_from : array_like, shape (..., N, 3) or (..., N, 2)
        Model points (exact); leading axes are independent designs.
    sigma : float or array_like, shape (...)
        Per-coordinate noise standard deviation of a unit-weight target point
        (same length unit as the points).
    weights : array_like, shape (..., N), optional
        Inverse relative variances: point i has noise ``sigma / sqrt(w_i)``.

    Returns
    -------
    ndarray, shape (..., 3, 3) or (..., 1, 1)
        Covariance bound of ``delta`` (rad^2): 3x3 in 3D, 1x1 (the angle's
        variance) in 2D.

    Raises
    ------
    DegenerateGeometryError
        Collinear model points in 3D (the rotation about their line is
        undetermined); coincident model points in 2D.
    """
    x, sigma, w = _check_model(points_from, sigma, weights)
    xc = _centred(x, w)
    if x.shape[-1] == 2:
        spread2 = np.einsum("...n,...n->...", w, (xc * xc).sum(axis=-1))
        return (sigma**2 / spread2)[..., None, None]
    S = np.einsum("...n,...ni,...nj->...ij", w, xc, xc)
    tr = np.trace(S, axis1=-2, axis2=-1)[..., None, None]
    return sigma[..., None, None] ** 2 * np.linalg.inv(tr * np.eye(3) - S)


def rigid_fit_covariance(points_from, R_to_from, sigma, weights=None) -> np.ndarray:
    """First-order covariance of a rigid fit's (rotation error, translation error).

    Parameters follow :func:`rigid_fit_rotation_crb`: ``R_hat = R exp([delta]_x)``
    with ``delta`` (rad) in the "from" frame, and ``t_hat = t + epsilon`` with
    ``epsilon`` in the "to" frame (the input's length unit). The Jacobian of the
    predicted target point ``R x_i + t`` with respect to ``(delta, epsilon)`` is
    ``[-R [x_i]_x, I]``; the covariance is the inverse Fisher information
    ``(sum_i w_i J_i^T J_i / sigma^2)^{-1}``. Its rotation block equals
    :func:`rigid_fit_rotation_crb`; the off-diagonal blocks are non-zero when the
    model centroid is away from the "from" origin. The scale of a similarity
    fit is not included.

    In 2D (points ``(..., N, 2)``, ``R_to_from`` 2x2) the parameters are the
    angle error ``delta`` (rad, ``R_hat = R Rot(delta)``) and ``epsilon``
    (2-vector); the Jacobian rows are ``[R J x_i, I]`` with
    ``J = [[0, -1], [1, 0]]``.

    Parameters
    ----------
    points_from : array_like, shape (..., N, 3) or (..., N, 2)
    R_to_from : array_like, shape (..., 3, 3) or (..., 2, 2)
        The fitted rotation (``RigidFit.R``); leading axes broadcast with the points'.
    sigma : float or array_like, shape (...)
        Unit-weight noise std per coordinate (e.g. ``RigidFit.sigma_hat``).
    weights : array_like, shape (..., N), optional

    Returns
    -------
    ndarray, shape (..., 6, 6) or (..., 3, 3)
        3D: covariance of ``(delta_x, delta_y, delta_z, eps_x, eps_y, eps_z)``.
        2D: covariance of ``(delta, eps_x, eps_y)`` (rad and length units).
    """
    x, sigma, w = _check_model(points_from, sigma, weights)
    dim = x.shape[-1]
    R = check_array(R_to_from, "R_to_from", shape=(dim, dim))
    try:
        lead = np.broadcast_shapes(x.shape[:-2], R.shape[:-2])
    except ValueError:
        raise ShapeError(f"R_to_from batch shape {R.shape[:-2]} does not broadcast with {x.shape[:-2]}") from None
    x, w, sigma = np.broadcast_to(x, lead + x.shape[-2:]), np.broadcast_to(w, lead + w.shape[-1:]), \
        np.broadcast_to(sigma, lead)
    _centred(x, w)  # the degeneracy check
    if dim == 2:
        J = np.zeros(lead + (x.shape[-2], 2, 3))
        Jx = np.stack([-x[..., 1], x[..., 0]], axis=-1)  # J @ x_i
        J[..., 0] = (R[..., None, :, :] @ Jx[..., :, None])[..., 0]
        J[..., 1:] = np.eye(2)
    else:
        J = np.zeros(lead + (x.shape[-2], 3, 6))
        J[..., :3] = -R[..., None, :, :] @ skew(x)
        J[..., 3:] = np.eye(3)
    F = np.einsum("...n,...nki,...nkj->...ij", w, J, J) / sigma[..., None, None] ** 2
    return np.linalg.inv(F)
