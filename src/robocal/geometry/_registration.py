"""Point and vector registration: Wahba/Kabsch rotation, Umeyama/Horn rigid fit.

These closed forms are the references every seed-specific solver is compared
against (e.g. the projector rig's Gibbs-vector initialisation, seed 000
eqs. 15-23). Everything is vectorised over leading batch dimensions, so a
Monte Carlo study of thousands of fits is one call.

Noise model used by the bounds: the *target* points are observed with
isotropic Gaussian noise, ``points_to[i] = R @ points_from[i] + t + e_i`` with
``e_i ~ N(0, sigma**2 / w_i * I)``; the model points ``points_from`` are exact.
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

    Attributes
    ----------
    T_to_from : ndarray, shape (B..., 4, 4)
        Homogeneous transform mapping ``points_from`` onto ``points_to``. With
        ``with_scale=True`` its 3x3 block is ``scale * R`` (a similarity).
    R : ndarray, shape (B..., 3, 3)
        Proper rotation (det = +1).
    t : ndarray, shape (B..., 3)
        Translation, in the "to" frame.
    scale : float or ndarray, shape (B...)
        Similarity scale (1.0 unless ``with_scale=True``).
    rms : float or ndarray, shape (B...)
        Root of the (weighted) mean squared 3D residual norm,
        ``sqrt(sum w_i |r_i|^2 / sum w_i)``, in the input's length unit.
    residuals : ndarray, shape (B..., N, 3)
        ``points_to - (scale * R @ points_from + t)``.
    sigma_hat : float or ndarray, shape (B...)
        Per-coordinate noise standard deviation of a unit-weight point estimated
        from the residuals, ``sqrt(sum w_i |r_i|^2 / (3 N - 6 [- 1]))``; NaN when
        there are no degrees of freedom. Feed it to :func:`rigid_fit_covariance`.
    """

    T_to_from: np.ndarray
    R: np.ndarray
    t: np.ndarray
    scale: float | np.ndarray
    rms: float | np.ndarray
    residuals: np.ndarray
    sigma_hat: float | np.ndarray


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


def _check_pair(a, b, name_a: str, name_b: str, weights):
    a = check_array(a, name_a, shape=("N", 3), min_ndim=2)
    b = check_array(b, name_b, shape=("N", 3), min_ndim=2)
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


def wahba_rotation(vectors_from, vectors_to, weights=None, *, rtol: float = RTOL) -> np.ndarray:
    """Optimal rotation between two sets of paired vectors (Wahba's problem).

    Finds the proper rotation minimising
    ``sum_i w_i |vectors_to[i] - R @ vectors_from[i]|^2`` by the SVD of
    ``B = sum_i w_i to_i from_i^T = U S V^T``:
    ``R = U diag(1, 1, det(U V^T)) V^T`` (Kabsch; the ``det`` factor keeps R a
    rotation instead of a reflection). No centring: for point sets use
    :func:`rigid_fit`.

    Parameters
    ----------
    vectors_from : array_like, shape (..., N, 3)
        Vectors in the "from" frame.
    vectors_to : array_like, shape (..., N, 3)
        The same vectors observed in the "to" frame. Batch shapes broadcast.
    weights : array_like, shape (..., N), optional
        Non-negative weights (inverse relative variances). Default: all 1.
    rtol : float
        Relative tolerance on the second singular value of ``B``.

    Returns
    -------
    R_to_from : ndarray, shape (..., 3, 3)

    Raises
    ------
    DegenerateGeometryError
        If ``B`` has rank < 2 (fewer than two non-parallel vectors, in either
        set): the rotation is then not unique.
    NotEnoughDataError
        Fewer than 2 vectors.

    References
    ----------
    G. Wahba, "A least squares estimate of satellite attitude", SIAM Review 7(3), 1965;
    W. Kabsch, Acta Cryst. A32, 1976.
    """
    a, b, w = _check_pair(vectors_from, vectors_to, "vectors_from", "vectors_to", weights)
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

    Parameters
    ----------
    points_from : array_like, shape (..., N, 3)
        Model points (frame "from"), N >= 3, not collinear.
    points_to : array_like, shape (..., N, 3)
        Measured points (frame "to"). Batch shapes broadcast, so a whole Monte
        Carlo study can be fitted in one call.
    weights : array_like, shape (..., N), optional
        Non-negative weights (inverse relative variances of the target points).
    with_scale : bool
        Also estimate a uniform scale (Umeyama's similarity).
    rtol : float
        Relative tolerance on singular values for the collinearity checks.

    Returns
    -------
    RigidFit

    Raises
    ------
    NotEnoughDataError
        Fewer than 3 points (with non-zero weight).
    DegenerateGeometryError
        Collinear or coincident points in either set, or a rank < 2
        cross-covariance.

    References
    ----------
    S. Umeyama, IEEE TPAMI 13(4), 1991; B. K. P. Horn, JOSA A 4(4), 1987.
    """
    x, y, w = _check_pair(points_from, points_to, "points_from", "points_to", weights)
    n_used = np.count_nonzero(w > 0, axis=-1)
    if x.shape[-2] < 3 or np.any(n_used < 3):
        got = x.shape[-2] if x.shape[-2] < 3 else int(np.min(n_used))
        raise NotEnoughDataError(f"rigid_fit needs at least 3 non-collinear points with non-zero weight, got {got}")
    wsum = w.sum(axis=-1)
    wcol = w[..., :, None]
    xbar = (wcol * x).sum(axis=-2) / wsum[..., None]
    ybar = (wcol * y).sum(axis=-2) / wsum[..., None]
    xc = x - xbar[..., None, :]
    yc = y - ybar[..., None, :]
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
    sR = scale[..., None, None] * R
    t = ybar - (sR @ xbar[..., :, None])[..., 0]
    res = y - (x @ np.swapaxes(sR, -1, -2) + t[..., None, :])
    wr2 = (w * (res * res).sum(axis=-1)).sum(axis=-1)
    dof = 3 * x.shape[-2] - 6 - (1 if with_scale else 0)
    T = np.zeros(R.shape[:-2] + (4, 4))
    T[..., :3, :3] = sR
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return RigidFit(
        T_to_from=T,
        R=R,
        t=t,
        scale=_scalar(scale),
        rms=_scalar(np.sqrt(wr2 / wsum)),
        residuals=res,
        sigma_hat=_scalar(np.sqrt(wr2 / dof) if dof > 0 else np.full(wr2.shape, np.nan)),
    )


def _check_model(points_from, sigma, weights):
    """``x (..., N, 3)``, ``sigma (...)`` and ``w (..., N)`` broadcast together."""
    x = check_array(points_from, "points_from", shape=("N", 3), min_ndim=2)
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
    if np.any(used < 3):
        raise NotEnoughDataError(f"a rigid fit needs at least 3 points with non-zero weight, got {int(np.min(used))}")
    x = np.broadcast_to(x, lead + (n, 3))
    w = np.broadcast_to(w, lead + (n,))
    return x, np.broadcast_to(sigma, lead), w


def _centred(x, w):
    xc = x - ((w[..., None] * x).sum(axis=-2) / w.sum(axis=-1)[..., None])[..., None, :]
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

    Parameters
    ----------
    points_from : array_like, shape (..., N, 3)
        Model points (exact); leading axes are independent designs.
    sigma : float or array_like, shape (...)
        Per-coordinate noise standard deviation of a unit-weight target point
        (same length unit as the points).
    weights : array_like, shape (..., N), optional
        Inverse relative variances: point i has noise ``sigma / sqrt(w_i)``.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        Covariance bound of ``delta`` (rad^2).

    Raises
    ------
    DegenerateGeometryError
        Collinear model points (the rotation about their line is undetermined).
    """
    x, sigma, w = _check_model(points_from, sigma, weights)
    xc = _centred(x, w)
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

    Parameters
    ----------
    points_from : array_like, shape (..., N, 3)
    R_to_from : array_like, shape (..., 3, 3)
        The fitted rotation (``RigidFit.R``); leading axes broadcast with the points'.
    sigma : float or array_like, shape (...)
        Unit-weight noise std per coordinate (e.g. ``RigidFit.sigma_hat``).
    weights : array_like, shape (..., N), optional

    Returns
    -------
    ndarray, shape (..., 6, 6)
        Covariance of ``(delta_x, delta_y, delta_z, eps_x, eps_y, eps_z)``.
    """
    x, sigma, w = _check_model(points_from, sigma, weights)
    R = check_array(R_to_from, "R_to_from", shape=(3, 3))
    try:
        lead = np.broadcast_shapes(x.shape[:-2], R.shape[:-2])
    except ValueError:
        raise ShapeError(f"R_to_from batch shape {R.shape[:-2]} does not broadcast with {x.shape[:-2]}") from None
    x, w, sigma = np.broadcast_to(x, lead + x.shape[-2:]), np.broadcast_to(w, lead + w.shape[-1:]), \
        np.broadcast_to(sigma, lead)
    _centred(x, w)  # the degeneracy check
    J = np.zeros(lead + (x.shape[-2], 3, 6))
    J[..., :3] = -R[..., None, :, :] @ skew(x)
    J[..., 3:] = np.eye(3)
    F = np.einsum("...n,...nki,...nkj->...ij", w, J, J) / sigma[..., None, None] ** 2
    return np.linalg.inv(F)
