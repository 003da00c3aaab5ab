"""Wahba/Kabsch rotation and Umeyama rigid fit: exactness, Cramer-Rao efficiency,
agreement with OpenCV, degenerate input."""

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import array_shapes, arrays
from scipy.spatial.transform import Rotation

from robocal.errors import DegenerateGeometryError, InputError, NonFiniteError, NotEnoughDataError, RobocalError, ShapeError
from robocal.geometry import (
    apply_transform,
    householder_from_normal,
    matrix_from_rotvec,
    rigid_fit,
    rigid_fit_covariance,
    rigid_fit_rotation_crb,
    rotvec_from_matrix,
    wahba_rotation,
)

R_TRUE = matrix_from_rotvec([0.7, -1.1, 0.4])
T_TRUE = np.array([0.3, -0.2, 1.5])
# Coplanar 4-point design (a 0.4 m x 0.2 m rectangle in z = 0, off the origin):
# S = diag(a, b, 0) is anisotropic, so a wrong frame for the bound would show.
SQUARE = np.array([[0.0, 0.0, 0.0], [0.4, 0.0, 0.0], [0.4, 0.2, 0.0], [0.0, 0.2, 0.0]]) + [0.5, 0.3, 0.0]
SIGMA = 1e-3  # 1 mm on every target coordinate
N_TRIALS = 10000


@pytest.fixture(scope="module")
def monte_carlo():
    """N_TRIALS noisy copies of the transformed design, fitted in one batched call."""
    rng = np.random.default_rng(20240611)
    Y = apply_transform(np.block([[R_TRUE, T_TRUE[:, None]], [0, 0, 0, 1]]), SQUARE)
    Y = Y + SIGMA * rng.normal(size=(N_TRIALS, 4, 3))
    fit = rigid_fit(SQUARE, Y)
    delta = rotvec_from_matrix(R_TRUE.T @ fit.R)  # rotation error in the "from" frame
    eps = fit.t - T_TRUE
    return Y, fit, delta, eps


def test_exact_recovery_batched_and_scaled():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(3, 10, 3))
    R = matrix_from_rotvec(rng.normal(size=(3, 3)))
    t = rng.normal(size=(3, 3))
    Y = np.einsum("bij,bnj->bni", R, X) + t[:, None, :]
    fit = rigid_fit(X, Y)
    np.testing.assert_allclose(fit.R, R, atol=1e-12)
    np.testing.assert_allclose(fit.t, t, atol=1e-12)
    np.testing.assert_allclose(fit.residuals, 0.0, atol=1e-12)
    assert fit.T_to_from.shape == (3, 4, 4) and fit.rms.shape == (3,)
    np.testing.assert_allclose(apply_transform(fit.T_to_from[:, None], X), Y, atol=1e-12)
    single = rigid_fit(X[1], Y[1])
    np.testing.assert_allclose(single.R, fit.R[1], atol=1e-14)
    assert isinstance(single.rms, float) and isinstance(single.scale, float)
    sim = rigid_fit(X, 2.5 * (Y - t[:, None, :]) + t[:, None, :], with_scale=True)
    np.testing.assert_allclose(sim.scale, 2.5, rtol=1e-12)
    np.testing.assert_allclose(sim.R, R, atol=1e-12)
    np.testing.assert_allclose(sim.T_to_from[:, :3, :3], 2.5 * R, atol=1e-12)


def test_zero_weight_points_are_ignored():
    rng = np.random.default_rng(2)
    X = rng.normal(size=(8, 3))
    Y = X @ R_TRUE.T + T_TRUE + 1e-3 * rng.normal(size=(8, 3))
    Y[5] += 10.0  # gross outlier
    w = np.ones(8)
    w[5] = 0.0
    full = rigid_fit(X, Y, w)
    drop = rigid_fit(np.delete(X, 5, 0), np.delete(Y, 5, 0))
    np.testing.assert_allclose(full.R, drop.R, atol=1e-12)
    np.testing.assert_allclose(full.t, drop.t, atol=1e-12)
    assert full.rms == pytest.approx(drop.rms, rel=1e-12)
    # the noise estimate's degrees of freedom count only the points that are used
    assert full.sigma_hat == pytest.approx(drop.sigma_hat, rel=1e-12)


def test_wahba_matches_scipy_align_vectors_weighted():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(12, 3))
    b = a @ R_TRUE.T + 0.05 * rng.normal(size=(12, 3))
    w = rng.uniform(0.1, 3.0, 12)
    R = wahba_rotation(a, b, w)
    ref, _ = Rotation.align_vectors(b, a, weights=w)
    np.testing.assert_allclose(R, ref.as_matrix(), atol=1e-10)
    np.testing.assert_allclose(wahba_rotation(a[:2], a[:2] @ R_TRUE.T), R_TRUE, atol=1e-12)  # 2 vectors suffice


def test_det_guard_returns_a_rotation_for_mirrored_data():
    # Mirrored targets: the unconstrained orthogonal optimum is a reflection.
    rng = np.random.default_rng(4)
    X = rng.normal(size=(20, 3))
    Y = X @ householder_from_normal([0.2, 0.9, -0.3]).T
    U, _, Vt = np.linalg.svd((Y - Y.mean(0)).T @ (X - X.mean(0)))
    assert np.linalg.det(U @ Vt) < 0  # a naive Kabsch would return a reflection here
    fit = rigid_fit(X, Y)
    assert np.linalg.det(fit.R) == pytest.approx(1.0)
    # ... and the guarded answer is the best rotation: no random rotation does better
    cost = lambda R, t: np.sum((Y - X @ R.T - t) ** 2)
    best = cost(fit.R, fit.t)
    Rs = Rotation.random(500, random_state=5).as_matrix()
    others = [cost(R, Y.mean(0) - R @ X.mean(0)) for R in Rs]
    assert best <= min(others)
    np.testing.assert_allclose(wahba_rotation(X, Y), Rotation.align_vectors(Y, X)[0].as_matrix(), atol=1e-10)


def test_rotation_rmse_attains_cramer_rao_bound(monte_carlo):
    """Issue 'Foundation' item 2: MC rotation MSE within 5 % of tr(sigma^2 (tr S I - S)^-1).

    With N_TRIALS = 10000 and this design (bound eigenvalues 5 : 1.25 : 1), the
    relative standard error of the mean squared error is ~ 1.0 %, so 5 % is
    > 4 standard errors: a 5 % miss is a real inefficiency, not chance.
    """
    _, fit, delta, _ = monte_carlo
    crb = rigid_fit_rotation_crb(SQUARE, SIGMA)
    mse = np.mean(np.sum(delta**2, axis=1))
    lam = np.linalg.eigvalsh(crb)
    rel_se = np.sqrt(2 * np.sum(lam**2) / np.sum(lam) ** 2 / N_TRIALS)
    assert 0.05 > 4 * rel_se
    ratio = mse / np.trace(crb)
    assert abs(ratio - 1) < 0.05, f"MC rotation MSE / CRB trace = {ratio:.4f}"
    # The bound is per direction too, in the *from* frame: whiten and compare with I.
    L = np.linalg.cholesky(crb)
    z = np.linalg.solve(L, delta.T)
    np.testing.assert_allclose(np.cov(z), np.eye(3), atol=0.06)
    # the same covariance expressed in the to frame is R C R^T
    d_to = rotvec_from_matrix(fit.R @ R_TRUE.T)
    np.testing.assert_allclose(d_to, delta @ R_TRUE.T, atol=1e-9)


def test_rigid_fit_covariance_matches_monte_carlo(monte_carlo):
    _, fit, delta, eps = monte_carlo
    C = rigid_fit_covariance(SQUARE, R_TRUE, SIGMA)
    crb = rigid_fit_rotation_crb(SQUARE, SIGMA)
    np.testing.assert_allclose(C[:3, :3], crb, rtol=1e-10, atol=1e-10 * np.abs(crb).max())
    assert np.abs(C[:3, 3:]).max() > 0.1 * np.sqrt(C[0, 0] * C[3, 3])  # off-origin design: correlated
    L = np.linalg.cholesky(C)
    z = np.linalg.solve(L, np.column_stack([delta, eps]).T)
    # SE of whitened (co)variances ~ sqrt(2 / 10000) = 0.014
    np.testing.assert_allclose(np.cov(z), np.eye(6), atol=0.06)
    # sigma_hat^2 is unbiased: 6 dof per fit, mean over trials
    assert np.mean(fit.sigma_hat**2) / SIGMA**2 == pytest.approx(1.0, abs=0.05)


def test_bound_and_covariance_are_batched():
    # one call over 4 x 5 designs (each with its own fitted rotation and sigma) equals 20 calls
    rng = np.random.default_rng(9)
    X = rng.uniform(-0.3, 0.3, size=(4, 5, 6, 3))
    R = matrix_from_rotvec(rng.normal(size=(4, 5, 3)))
    sig = rng.uniform(0.5e-3, 2e-3, size=(4, 5))
    w = rng.uniform(0.5, 2.0, size=(6,))
    crb, cov = rigid_fit_rotation_crb(X, sig, w), rigid_fit_covariance(X, R, sig, w)
    assert crb.shape == (4, 5, 3, 3) and cov.shape == (4, 5, 6, 6)
    for i, j in ((0, 0), (3, 4), (2, 1)):
        np.testing.assert_allclose(crb[i, j], rigid_fit_rotation_crb(X[i, j], sig[i, j], w), rtol=1e-12)
        np.testing.assert_allclose(cov[i, j], rigid_fit_covariance(X[i, j], R[i, j], sig[i, j], w), rtol=1e-12)
    X[1, 2] = np.linspace(0, 1, 6)[:, None] * [1.0, 2.0, 3.0]  # one collinear design: named
    with pytest.raises(DegenerateGeometryError, match=r"collinear.*batch index \(1, 2\)"):
        rigid_fit_rotation_crb(X, sig)


def test_weighted_fit_attains_weighted_bound():
    rng = np.random.default_rng(6)
    X = rng.uniform(-0.3, 0.3, size=(6, 3))
    w = np.array([4.0, 1.0, 0.25, 1.0, 9.0, 0.5])
    n = 4000
    Y = X @ R_TRUE.T + T_TRUE + SIGMA / np.sqrt(w)[:, None] * rng.normal(size=(n, 6, 3))
    fit = rigid_fit(X, Y, w)
    delta = rotvec_from_matrix(R_TRUE.T @ fit.R)
    ratio = np.mean(np.sum(delta**2, 1)) / np.trace(rigid_fit_rotation_crb(X, SIGMA, w))
    assert abs(ratio - 1) < 0.06, ratio
    unweighted = rigid_fit(X, Y)
    d_u = rotvec_from_matrix(R_TRUE.T @ unweighted.R)
    assert np.mean(np.sum(d_u**2, 1)) > 1.2 * np.mean(np.sum(delta**2, 1))  # weights matter here


def test_agrees_with_opencv_estimate_affine3d(monte_carlo):
    """Same data as the CRB test, every trial: cv2 (Umeyama, force_rotation=True) vs ours."""
    Y, fit, _, _ = monte_carlo
    sim = rigid_fit(SQUARE, Y[:1000], with_scale=True)
    worst = 0.0
    for k in range(1000):
        M, scale = cv2.estimateAffine3D(SQUARE, Y[k], force_rotation=True)
        # OpenCV returns [R | t] with the scale applied to t only.
        worst = max(
            worst,
            np.abs(M[:, :3] - fit.R[k]).max(),
            np.abs(M[:, 3] - sim.t[k]).max(),
            abs(scale - sim.scale[k]),
        )
    assert worst < 1e-9, worst


# ----------------------------------------------------------------------------- degenerate input


def test_collinear_points_raise_named_error():
    line = np.outer(np.linspace(0, 1, 5), [1.0, 2.0, -0.5]) + [0.1, 0.2, 0.3]
    other = np.random.default_rng(7).normal(size=(5, 3))
    with pytest.raises(DegenerateGeometryError, match=r"points_from are collinear: second singular value"):
        rigid_fit(line, other)
    with pytest.raises(DegenerateGeometryError, match=r"points_to are collinear"):
        rigid_fit(other, line)
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        rigid_fit_rotation_crb(line, 1e-3)
    parallel = np.outer([1.0, -2.0, 0.5, 3.0], [0.3, 0.1, -0.7])
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        wahba_rotation(parallel, parallel @ R_TRUE.T)
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        wahba_rotation(other[:4], parallel)  # parallel on the "to" side only
    with pytest.raises(DegenerateGeometryError, match="zero spread"):
        rigid_fit(np.ones((4, 3)), other[:4])
    # the offending element of a batch is named
    batch = np.stack([other, line])
    with pytest.raises(DegenerateGeometryError, match=r"batch index \(1,\)"):
        rigid_fit(batch, other)


def test_too_few_points_and_bad_arguments():
    X = np.random.default_rng(8).normal(size=(4, 3))
    with pytest.raises(NotEnoughDataError, match="at least 3"):
        rigid_fit(X[:2], X[:2])
    with pytest.raises(NotEnoughDataError, match="at least 3"):
        rigid_fit(X, X, [1.0, 1.0, 0.0, 0.0])
    with pytest.raises(NotEnoughDataError, match="at least 2"):
        wahba_rotation(X[:1], X[:1])
    with pytest.raises(ShapeError, match="same number of points"):
        rigid_fit(X, X[:3])
    with pytest.raises(ShapeError, match=r"points_from must have shape \(\.\.\., N, 3\) or \(\.\.\., N, 2\), got \(4, 1\)"):
        rigid_fit(X[:, :1], X[:, :1])
    with pytest.raises(ShapeError, match=r"points_to must have shape \(\.\.\., N, 2\) like points_from, got \(4, 3\)"):
        rigid_fit(X[:, :2], X)  # 2D model, 3D target
    with pytest.raises(InputError, match="weights must be >= 0"):
        rigid_fit(X, X, [1.0, -1.0, 1.0, 1.0])
    with pytest.raises(InputError, match="sigma"):
        rigid_fit_rotation_crb(X, 0.0)
    Xn = X.copy()
    Xn[2, 1] = np.nan
    with pytest.raises(NonFiniteError, match="points_to"):
        rigid_fit(X, Xn)


@settings(max_examples=80, deadline=None)
@given(
    arrays(
        np.float64,
        array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=5),
        elements=st.one_of(st.floats(-10, 10), st.just(np.nan), st.just(np.inf), st.just(0.0)),
    ),
    st.booleans(),
)
def test_fuzzed_input_fits_or_raises_a_named_error(X, with_scale):
    """Any shape / NaN / repeated-value input: a valid fit or a RobocalError, nothing else."""
    Y = X[..., ::-1] + 1.0
    try:
        R = wahba_rotation(X, Y)
        np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-9)
    except RobocalError:
        pass
    try:
        fit = rigid_fit(X, Y, with_scale=with_scale)
    except RobocalError:
        return
    assert np.all(np.isfinite(fit.T_to_from))
    np.testing.assert_allclose(np.linalg.det(fit.R), 1.0, atol=1e-9)


# ----------------------------------------------------------------------------- 2D (SE(2))


def rot2(theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


# A planar design off the origin (so rotation and translation errors correlate).
PLANAR = np.array([[0.0, 0.0], [0.4, 0.0], [0.4, 0.2], [0.0, 0.2], [0.2, 0.35]]) + [0.5, 0.3]
THETA_TRUE, T2_TRUE = 2.1, np.array([-0.4, 1.2])


def test_2d_exact_recovery_batched_scaled_and_weighted():
    rng = np.random.default_rng(21)
    X = rng.normal(size=(4, 7, 2))
    theta = np.array([0.3, -2.5, np.pi - 1e-9, -np.pi + 1e-9])  # near +-180 deg too
    t = rng.normal(size=(4, 2))
    Y = np.einsum("bij,bnj->bni", rot2(theta), X) + t[:, None, :]
    fit = rigid_fit(X, Y)
    assert fit.R.shape == (4, 2, 2) and fit.t.shape == (4, 2) and fit.T_to_from.shape == (4, 3, 3)
    assert fit.residuals.shape == (4, 7, 2) and fit.dim == 2
    np.testing.assert_allclose(fit.R, rot2(theta), atol=1e-12)
    np.testing.assert_allclose(fit.t, t, atol=1e-12)
    np.testing.assert_allclose(np.cos(fit.angle - theta), 1.0, atol=1e-12)
    np.testing.assert_allclose(fit.residuals, 0.0, atol=1e-12)
    homog = np.concatenate([X, np.ones((4, 7, 1))], -1)
    np.testing.assert_allclose(np.einsum("bij,bnj->bni", fit.T_to_from, homog)[..., :2], Y, atol=1e-12)
    np.testing.assert_allclose(fit.T_to_from[:, 2], [[0, 0, 1]] * 4)
    single = rigid_fit(X[2], Y[2])
    assert isinstance(single.angle, float) and isinstance(single.rms, float)
    np.testing.assert_allclose(single.R, fit.R[2], atol=1e-14)
    sim = rigid_fit(X, 0.4 * (Y - t[:, None, :]) + t[:, None, :], with_scale=True)
    np.testing.assert_allclose(sim.scale, 0.4, rtol=1e-12)
    np.testing.assert_allclose(sim.R, rot2(theta), atol=1e-12)
    np.testing.assert_allclose(sim.T_to_from[:, :2, :2], 0.4 * rot2(theta), atol=1e-12)
    # weights, broadcast over the batch, with an outlier switched off
    Yo = Y.copy()
    Yo[:, 3] += 5.0
    w = np.ones(7)
    w[3] = 0.0
    wfit = rigid_fit(X, Yo, w)
    np.testing.assert_allclose(wfit.R, rot2(theta), atol=1e-12)
    np.testing.assert_allclose(wfit.residuals[:, 3], 5.0, atol=1e-9)
    # a 2D wahba_rotation needs one vector only
    np.testing.assert_allclose(wahba_rotation([[1.0, 0.0]], [[0.0, 2.0]]), rot2(np.pi / 2), atol=1e-15)
    np.testing.assert_allclose(wahba_rotation(X, Y - t[:, None, :]), rot2(theta), atol=1e-12)


def test_2d_fit_is_the_least_squares_optimum_on_noisy_data():
    rng = np.random.default_rng(22)
    X = rng.normal(size=(6, 2))
    Y = X @ rot2(0.8).T + [1.0, -1.0] + 0.3 * rng.normal(size=(6, 2))
    w = rng.uniform(0.2, 3.0, size=6)
    fit = rigid_fit(X, Y, w)
    cost = lambda R, t: np.sum(w[:, None] * (Y - X @ R.T - t) ** 2)
    best = cost(fit.R, fit.t)
    xbar, ybar = w @ X / w.sum(), w @ Y / w.sum()
    grid = np.linspace(-np.pi, np.pi, 20001)
    others = [cost(R, ybar - R @ xbar) for R in rot2(grid)]
    assert best <= min(others) + 1e-12
    np.testing.assert_allclose(fit.rms, np.sqrt(best / w.sum()), rtol=1e-12)
    assert fit.sigma_hat == pytest.approx(np.sqrt(best / (2 * 6 - 3)), rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    arrays(np.float64, st.tuples(st.integers(2, 6), st.just(2)), elements=st.floats(-10, 10)),
    st.floats(-np.pi, np.pi),
    st.booleans(),
    st.booleans(),
)
def test_2d_never_returns_a_reflection(X, theta, mirror, with_scale):
    """Any 2D data -- including a mirror image of the model -- gives det R = +1 or a named error."""
    Y = X @ rot2(theta).T
    if mirror:
        Y = Y * [1.0, -1.0]
    try:
        fit = rigid_fit(X, Y, with_scale=with_scale)
    except DegenerateGeometryError:
        return
    np.testing.assert_allclose(np.linalg.det(fit.R), 1.0, atol=1e-12)
    np.testing.assert_allclose(fit.R.T @ fit.R, np.eye(2), atol=1e-12)
    assert np.all(np.isfinite(fit.T_to_from)) and fit.scale >= 0
    if not mirror and not with_scale:
        np.testing.assert_allclose(fit.residuals, 0.0, atol=1e-9 * max(1.0, np.abs(X).max()))


@pytest.fixture(scope="module")
def monte_carlo_2d():
    """N_TRIALS noisy copies of the transformed planar design, fitted in one batched call."""
    rng = np.random.default_rng(20261123)
    Y = PLANAR @ rot2(THETA_TRUE).T + T2_TRUE + SIGMA * rng.normal(size=(N_TRIALS, len(PLANAR), 2))
    fit = rigid_fit(PLANAR, Y)
    delta = np.angle(np.exp(1j * (fit.angle - THETA_TRUE)))  # wrapped angle error
    return fit, delta, fit.t - T2_TRUE


def test_2d_angle_std_attains_cramer_rao_bound(monte_carlo_2d):
    """MC angle variance vs sigma^2 / sum |x~_i|^2: relative SE of a variance over
    N_TRIALS = 10000 is sqrt(2 / N) = 1.4 %, so 5 % is > 3.5 standard errors."""
    fit, delta, _ = monte_carlo_2d
    crb = rigid_fit_rotation_crb(PLANAR, SIGMA)
    assert crb.shape == (1, 1)
    xc = PLANAR - PLANAR.mean(0)
    assert crb[0, 0] == pytest.approx(SIGMA**2 / np.sum(xc**2), rel=1e-12)
    ratio = np.mean(delta**2) / crb[0, 0]
    std_ratio = np.std(delta) / np.sqrt(crb[0, 0])
    assert abs(ratio - 1) < 0.05, f"MC angle MSE / CRB = {ratio:.4f}"
    assert abs(std_ratio - 1) < 0.025, f"MC angle std / CRB std = {std_ratio:.4f}"
    assert abs(np.mean(delta)) < 4 * np.sqrt(crb[0, 0] / N_TRIALS)  # unbiased


def test_2d_covariance_matches_monte_carlo(monte_carlo_2d):
    fit, delta, eps = monte_carlo_2d
    C = rigid_fit_covariance(PLANAR, rot2(THETA_TRUE), SIGMA)
    assert C.shape == (3, 3)
    assert C[0, 0] == pytest.approx(rigid_fit_rotation_crb(PLANAR, SIGMA)[0, 0], rel=1e-10)
    assert np.abs(C[0, 1:]).max() > 0.1 * np.sqrt(C[0, 0] * C[1, 1])  # off-origin design: correlated
    L = np.linalg.cholesky(C)
    z = np.linalg.solve(L, np.column_stack([delta, eps]).T)
    np.testing.assert_allclose(np.cov(z), np.eye(3), atol=0.06)
    # sigma_hat^2 is unbiased with 2 N - 3 degrees of freedom
    assert np.mean(fit.sigma_hat**2) / SIGMA**2 == pytest.approx(1.0, abs=0.05)


def test_2d_weighted_and_batched_bounds():
    rng = np.random.default_rng(23)
    X = rng.uniform(-0.3, 0.3, size=(6, 2))
    w = np.array([4.0, 1.0, 0.25, 1.0, 9.0, 0.5])
    n = 8000
    Y = X @ rot2(-0.6).T + [0.1, 0.2] + SIGMA / np.sqrt(w)[:, None] * rng.normal(size=(n, 6, 2))
    fit = rigid_fit(X, Y, w)
    ratio = np.mean((fit.angle + 0.6) ** 2) / rigid_fit_rotation_crb(X, SIGMA, w)[0, 0]
    assert abs(ratio - 1) < 0.07, ratio
    xc = X - w @ X / w.sum()
    assert rigid_fit_rotation_crb(X, SIGMA, w)[0, 0] == pytest.approx(SIGMA**2 / np.sum(w * np.sum(xc**2, 1)), rel=1e-12)
    # one call over a 3 x 4 batch of designs equals 12 calls
    Xb = rng.uniform(-0.3, 0.3, size=(3, 4, 5, 2))
    Rb = rot2(rng.uniform(-3, 3, size=(3, 4)))
    sig = rng.uniform(0.5e-3, 2e-3, size=(3, 4))
    crb, cov = rigid_fit_rotation_crb(Xb, sig), rigid_fit_covariance(Xb, Rb, sig)
    assert crb.shape == (3, 4, 1, 1) and cov.shape == (3, 4, 3, 3)
    for i, j in ((0, 0), (2, 3), (1, 2)):
        np.testing.assert_allclose(crb[i, j], rigid_fit_rotation_crb(Xb[i, j], sig[i, j]), rtol=1e-12)
        np.testing.assert_allclose(cov[i, j], rigid_fit_covariance(Xb[i, j], Rb[i, j], sig[i, j]), rtol=1e-12)


def test_2d_collinear_points_are_accepted():
    line = np.outer(np.linspace(-1.0, 2.0, 6), [0.6, 0.8]) + [0.3, -0.1]
    Y = line @ rot2(1.1).T + [2.0, 3.0]
    fit = rigid_fit(line, Y)
    assert fit.angle == pytest.approx(1.1, abs=1e-12)
    np.testing.assert_allclose(fit.t, [2.0, 3.0], atol=1e-12)
    assert rigid_fit(line[:2], Y[:2]).angle == pytest.approx(1.1, abs=1e-12)  # two points suffice
    # ... and its bound holds on a line too (a straight drive in ATE alignment)
    rng = np.random.default_rng(24)
    noisy = Y + SIGMA * rng.normal(size=(N_TRIALS, 6, 2))
    d = rigid_fit(line, noisy).angle - 1.1
    assert np.mean(d**2) / rigid_fit_rotation_crb(line, SIGMA)[0, 0] == pytest.approx(1.0, abs=0.05)
    C = rigid_fit_covariance(line, rot2(1.1), SIGMA)
    assert np.all(np.linalg.eigvalsh(C) > 0)


def test_2d_coincident_points_raise_named_error():
    other = np.random.default_rng(25).normal(size=(4, 2))
    same = np.tile([[1.5, -2.0]], (4, 1))
    with pytest.raises(DegenerateGeometryError, match=r"points_from have zero spread \(all points coincide"):
        rigid_fit(same, other)
    with pytest.raises(DegenerateGeometryError, match=r"points_to have zero spread"):
        rigid_fit(other, same)
    with pytest.raises(DegenerateGeometryError, match="zero spread"):
        rigid_fit(np.zeros((3, 2)), other[:3])
    # coincident up to round-off of a large offset is still coincident
    with pytest.raises(DegenerateGeometryError, match="zero spread"):
        rigid_fit(same + 1e6 + np.array([[0, 0], [1e-12, 0], [0, 0], [0, 0]]), other)
    # the two distinct points of a weighted set: only points of non-zero weight count
    with pytest.raises(DegenerateGeometryError, match="zero spread"):
        rigid_fit(np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]]), other[:3], [1.0, 1.0, 0.0])
    with pytest.raises(DegenerateGeometryError, match="zero spread"):
        rigid_fit_rotation_crb(same, 1e-3)
    with pytest.raises(DegenerateGeometryError, match="zero spread"):
        rigid_fit_covariance(same, np.eye(2), 1e-3)
    batch = np.stack([other, same])
    with pytest.raises(DegenerateGeometryError, match=r"batch index \(1,\)"):
        rigid_fit(batch, other)
    with pytest.raises(NotEnoughDataError, match="at least 2"):
        rigid_fit(other[:1], other[:1])
    with pytest.raises(NotEnoughDataError, match="at least 2"):
        rigid_fit(other, other, [1.0, 0.0, 0.0, 0.0])
    with pytest.raises(DegenerateGeometryError, match="determine no rotation"):
        wahba_rotation(np.zeros((2, 2)), other[:2])
    # a set and its mirror image with no preferred rotation: (1,0),(0,1) -> (1,0),(0,-1) about the centroid
    sq = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
    with pytest.raises(DegenerateGeometryError, match="determine no rotation"):
        rigid_fit(sq, sq * [1.0, -1.0])
    with pytest.raises(InputError, match="2D fits only"):
        rigid_fit(np.random.default_rng(1).normal(size=(4, 3)), np.random.default_rng(2).normal(size=(4, 3))).angle
