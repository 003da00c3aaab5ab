"""solve(): fixtures against each method and Jacobian mode, textbook covariance, losses, cost history."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from robocal.estimation import Problem, solve

METHODS = ["lm", "trf", "dogbox"]
JACS = ["analytic", "2-point", "3-point"]


def test_linear_regression_matches_textbook(linear):
    p, X, y, _ = linear
    r = solve(p, method="lm")
    beta, rss, *_ = np.linalg.lstsq(X, y, rcond=None)
    s2 = rss[0] / (X.shape[0] - X.shape[1])
    cov = s2 * np.linalg.inv(X.T @ X)
    np.testing.assert_allclose(r.x, beta, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(r.cov, cov, rtol=1e-8)
    np.testing.assert_allclose(r.std_array, np.sqrt(np.diag(cov)), rtol=1e-8)
    assert r.residual_variance == pytest.approx(s2, rel=1e-10)
    assert r.dof == X.shape[0] - 3
    assert r.rank == 3 and r.success and not r.warnings
    np.testing.assert_allclose(r.residuals, X @ beta - y, atol=1e-12)
    d = np.sqrt(np.diag(cov))
    np.testing.assert_allclose(r.corr, cov / np.outer(d, d), atol=1e-10)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("jac", JACS)
@pytest.mark.parametrize("fixture", ["linear", "exponential", "circle"])
def test_methods_and_jacobians_agree(fixture, method, jac, request):
    p = request.getfixturevalue(fixture)[0]
    ref = solve(p, method="lm", jac="analytic", ftol=1e-12, xtol=1e-12, gtol=1e-12)
    r = solve(p, method=method, jac=jac, ftol=1e-12, xtol=1e-12, gtol=1e-12)
    assert r.success, r.message
    assert r.jac_method == jac
    np.testing.assert_allclose(r.x, ref.x, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(r.std_array, ref.std_array, rtol=1e-4)
    assert r.cost == pytest.approx(ref.cost, rel=1e-8)


def test_nonlinear_fit_lands_near_truth(exponential, circle):
    for p, truth in (exponential, circle):
        r = solve(p, method="trf")
        # within 4 reported sigma of the truth (one draw of noise)
        assert np.all(np.abs(r.x - truth) < 4 * r.std_array), (r.x, truth, r.std_array)


def test_cost_history_is_monotone_and_matches_iterations(exponential):
    p, _ = exponential
    for method in METHODS:
        r = solve(p, method=method, jac="2-point")
        h = r.cost_history
        assert len(h) == r.iterations + 1 >= 3
        assert np.all(np.diff(h) <= 1e-12 * h[0]), h
        assert h[0] == pytest.approx(0.5 * np.sum(p.residuals_at() ** 2))
        assert h[-1] == pytest.approx(r.cost)


def test_callback_sees_every_accepted_iterate_and_can_stop(exponential):
    p, _ = exponential
    seen = []
    r = solve(p, method="trf", callback=lambda it: seen.append((it.iteration, it.cost, it.params["b"].item())))
    assert [s[0] for s in seen] == list(range(len(seen)))
    np.testing.assert_allclose([s[1] for s in seen], r.cost_history[: len(seen)])
    r2 = solve(p, method="lm", callback=lambda it: it.iteration >= 2)
    assert r2.status == -2 and not r2.success
    assert "not_converged" in r2.warning_codes()
    assert r2.iterations == 2


def test_max_nfev_gives_not_converged(exponential):
    p, _ = exponential
    r = solve(p, method="trf", max_nfev=2)
    assert r.status == 0 and not r.success
    assert r.warning_codes()[0] == "not_converged"


def test_fixed_mask_keeps_values(linear):
    p, X, y, _ = linear
    p.set_x0("beta", [0.7, 0.0, 0.0]).set_fixed("beta", np.array([True, False, False]))
    r = solve(p, method="lm")
    assert r.params["beta"][0] == 0.7
    assert r.free_labels == ["b1", "b2"] and r.fixed_labels == ["b0"]
    beta12, *_ = np.linalg.lstsq(X[:, 1:], y - 0.7 * X[:, 0], rcond=None)
    np.testing.assert_allclose(r.x, beta12, rtol=1e-9)
    assert "b0" not in r.std
    assert r.block_std("beta")[0] == 0.0


def test_fixed_mask_at_add_block():
    t = np.linspace(0, 1, 10)
    p = Problem(lambda q: q["v"][0] + q["v"][1] * t + q["v"][2] * t**2 - (1 + 2 * t + 3 * t**2))
    p.add_block("v", [5.0, 0.0, 3.0], fixed=np.array([False, False, True]))
    r = solve(p)
    np.testing.assert_allclose(r.params["v"], [1.0, 2.0, 3.0], atol=1e-7)


def test_tied_parameters_equal_merged_column():
    # y = a x1 + b x2 with b tied to a  <=>  y = a (x1 + x2)
    rng = np.random.default_rng(5)
    x1, x2 = rng.normal(size=(2, 30))
    y = 1.5 * (x1 - x2) + rng.normal(0, 0.01, 30)
    p = Problem(lambda q: q["left"] * x1 + q["right"] * x2 - y,
                jacobian=lambda q: {"left": x1[:, None], "right": x2[:, None]})
    p.add_block("left", 0.0).add_block("right", 0.0).tie("right", "left", factor=-1.0)
    for jac in ("analytic", "2-point"):
        r = solve(p, jac=jac)
        z = x1 - x2
        a = z @ y / (z @ z)
        assert r.free_labels == ["left"]
        assert r.x[0] == pytest.approx(a, rel=1e-8)
        assert r.params["right"] == pytest.approx(-a, rel=1e-8)
        assert r.std["right"] == pytest.approx(r.std["left"])
        assert r.tied == {"right": ("left", -1.0)}


def test_robust_loss_downweights_gross_outlier(factories):
    p, X, y, truth = factories.linear(seed=4, n_obs=60)  # no natural >3 sigma draw
    clean = solve(p, method="trf")
    y[17] += 5.0  # 100 sigma
    plain = solve(p, method="trf")
    assert np.max(np.abs(plain.x - truth)) > 0.05
    assert 17 in plain.outliers
    for loss in ("huber", "soft_l1", "cauchy", "arctan"):
        r = solve(p, method="trf", loss=loss, f_scale=0.1)
        assert np.max(np.abs(r.x - truth)) < 0.05, loss
        assert list(r.outliers) == [17], loss
        assert np.max(np.abs(r.x - truth)) < 0.2 * np.max(np.abs(plain.x - truth))
        # the reported std is that of the inliers, not inflated by the outlier
        np.testing.assert_allclose(r.std_array, clean.std_array, rtol=0.3)
        assert plain.std_array[0] > 3 * clean.std_array[0]


def test_outliers_named_by_observation_index_in_2d(factories):
    # image-like residuals: (n_obs, 2); a 3-D point projected; two corrupted observations
    rng = np.random.default_rng(7)
    P = rng.uniform(-1, 1, (50, 2))
    obs = P + np.array([0.3, -0.2]) + rng.normal(0, 0.01, (50, 2))
    obs[[4, 31]] += [[0.2, 0.0], [0.0, -0.15]]
    p = Problem(lambda q: P + q["shift"] - obs, sigma=[0.01, 0.01])
    p.add_block("shift", [0.0, 0.0], unit="px")
    r = solve(p, method="trf", loss="soft_l1", f_scale=3.0)
    assert list(r.outliers) == [4, 31]
    out = [w for w in r.warnings if w.code == "outliers"][0]
    assert out.indices == (4, 31)
    assert "[4, 31]" in out.message
    assert r.obs_residuals().shape == (50, 2)
    assert r.rms_per_component["residuals"].shape == (2,)
    # absolute sigma: the known noise is the yardstick
    r2 = solve(p, method="trf", loss="soft_l1", f_scale=3.0, absolute_sigma=True)
    assert list(r2.outliers) == [4, 31]
    assert r2.residual_variance == 1.0


def test_outlier_rate_on_clean_gaussian_data_is_nominal(factories):
    # 3 sigma two-sided: 0.27 % expected; 2000 clean observations -> a handful at most
    p, *_ = factories.linear(seed=11, n_obs=2000)
    r = solve(p, method="lm")
    assert len(r.outliers) <= 15


def test_sigma_weighting_matches_weighted_least_squares():
    rng = np.random.default_rng(8)
    t = np.linspace(0, 1, 40)
    sig = np.where(t < 0.5, 0.01, 0.2)
    y = 1.0 + 2.0 * t + rng.normal(0, sig)
    X = np.column_stack([np.ones_like(t), t])
    p = Problem(lambda q: X @ q["b"] - y, jacobian=lambda q: {"b": X}, sigma=sig)
    p.add_block("b", [0.0, 0.0])
    r = solve(p, method="lm", absolute_sigma=True)
    W = np.diag(1 / sig**2)
    cov = np.linalg.inv(X.T @ W @ X)
    np.testing.assert_allclose(r.x, cov @ X.T @ W @ y, rtol=1e-9)
    np.testing.assert_allclose(r.cov, cov, rtol=1e-9)
    r_rel = solve(p, method="lm")
    np.testing.assert_allclose(r_rel.cov, cov * r_rel.residual_variance, rtol=1e-9)
    np.testing.assert_allclose(r.normalized_residuals, (X @ r.x - y) / sig, rtol=1e-9)


def test_bounds_are_respected():
    t = np.linspace(0, 1, 20)
    p = Problem(lambda q: q["k"] * t - 3.0 * t)
    p.add_block("k", 0.5, lower=0.0, upper=2.0)
    r = solve(p, method="trf")
    assert r.params["k"] == pytest.approx(2.0)
    r = solve(p, method="dogbox")
    assert r.params["k"] == pytest.approx(2.0)


def test_x_scale_from_block_scale_keeps_answer(exponential):
    p, _ = exponential
    ref = solve(p, method="trf")
    p2 = Problem(p._terms[0].fun, jacobian=p._terms[0].jacobian)
    p2.add_block("a", 1.0, scale=10.0).add_block("b", 0.5, scale=0.1).add_block("c", 0.0)
    r = solve(p2, method="trf")
    np.testing.assert_allclose(r.x, ref.x, rtol=1e-6)


def test_check_jacobian_finds_a_wrong_derivative(exponential, circle):
    for p, _ in (exponential, circle):
        ok = p.check_jacobian()
        assert ok.max_rel_error < 1e-6
    p, _ = exponential
    fun, jac = p._terms[0].fun, p._terms[0].jacobian

    def wrong(q):
        d = jac(q)
        d["b"] = 1.01 * d["b"]  # a 1 % error in one column
        return d

    bad = Problem(fun, jacobian=wrong).add_block("a", 1.0).add_block("b", 0.5).add_block("c", 0.0)
    chk = bad.check_jacobian()
    assert chk.worst_label == "b" and 0.005 < chk.max_rel_error < 0.02


def test_progress_bar_and_verbose_run(exponential, capsys, monkeypatch):
    import sys

    p, _ = exponential
    r = solve(p, method="trf", progress=True, verbose=1)
    assert r.success
    # off a terminal the bar stays off: a log or a one-line error is not mixed with bar frames
    assert "least squares" not in capsys.readouterr().err
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    solve(p, method="trf", progress=True)
    assert "least squares" in capsys.readouterr().err


@settings(max_examples=25, deadline=None)
@given(m=st.integers(4, 30), n=st.integers(1, 4), seed=st.integers(0, 10_000),
       method=st.sampled_from(["lm", "trf", "dogbox"]))
def test_property_random_linear_problems_match_textbook(m, n, seed, method):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(m, n)) * rng.uniform(0.1, 10.0, n)
    y = rng.normal(size=m)
    if m <= n or np.linalg.cond(X) > 1e6:
        return
    p = Problem(lambda q: X @ q["w"] - y, jacobian=lambda q: {"w": X}).add_block("w", np.zeros(n))
    r = solve(p, method=method, ftol=1e-12, xtol=1e-12, gtol=1e-12)
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    res = y - X @ beta
    cov = res @ res / (m - n) * np.linalg.inv(X.T @ X)
    np.testing.assert_allclose(r.x, beta, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(r.cov, cov, rtol=1e-5, atol=1e-12)


@pytest.mark.parametrize("loss", ["linear", "soft_l1", "huber", "cauchy", "arctan"])
def test_loss_derivatives_match_finite_differences_of_the_loss(loss):
    from robocal.estimation import loss_derivatives
    from robocal.estimation._solve import _rho

    z = np.array([0.01, 0.5, 0.9, 1.5, 4.0, 30.0])
    h = 1e-6
    r1, r2 = loss_derivatives(z, loss)
    d1 = lambda zz: _rho(zz, loss)[1]  # noqa: E731
    np.testing.assert_allclose(r1, (_rho(z + h, loss)[0] - _rho(z - h, loss)[0]) / (2 * h), rtol=1e-6)
    np.testing.assert_allclose(r2, (d1(z + h) - d1(z - h)) / (2 * h), rtol=1e-5, atol=1e-9)
