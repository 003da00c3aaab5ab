"""Monte Carlo: reported uncertainty against actual spread, and against the Cramér–Rao bound."""

import json
import math

import numpy as np
import pytest

from robocal.errors import ConvergenceError, DegenerateGeometryError, InputError, ShapeError
from robocal.estimation import Problem, check_coverage, fisher_bound, monte_carlo, solve

T = np.linspace(-1.0, 2.0, 40)
X = np.column_stack([np.ones_like(T), T, T**2])
BETA = np.array([0.5, -1.0, 0.3])
SIGMA = 0.05


def _simulate_linear(rng):
    return BETA @ X.T + rng.normal(0, SIGMA, T.size), BETA


def _estimate_linear(y, absolute=True):
    p = Problem(lambda q: X @ q["b"] - y, jacobian=lambda q: {"b": X}, sigma=SIGMA)
    p.add_block("b", np.zeros(3))
    return solve(p, method="lm", absolute_sigma=absolute)


def test_fisher_bound_is_textbook():
    crb = fisher_bound(X, SIGMA)
    np.testing.assert_allclose(crb, SIGMA**2 * np.linalg.inv(X.T @ X), rtol=1e-10)
    s = np.linspace(0.01, 0.1, T.size)
    np.testing.assert_allclose(fisher_bound(X, s), np.linalg.inv(X.T @ np.diag(s**-2) @ X), rtol=1e-10)
    with pytest.raises(DegenerateGeometryError, match="b"):
        fisher_bound(X[:, [0, 1, 1]], SIGMA, labels=["a", "b", "b2"])
    with pytest.raises(ShapeError):
        fisher_bound(X, np.ones(3))
    with pytest.raises(InputError):
        fisher_bound(X, 0.0)


def test_least_squares_attains_the_cramer_rao_bound():
    n = 300
    mc = monte_carlo(_simulate_linear, _estimate_linear, n, np.random.default_rng(10),
                     bound=fisher_bound(X, SIGMA), labels=["b0", "b1", "b2"])
    # rmse of n Gaussian errors: relative standard error ~ 1 / sqrt(2 n)
    tol = 3.0 / math.sqrt(2 * n)
    assert np.all(np.abs(mc.ratio_to_bound - 1.0) < tol), mc.ratio_to_bound
    assert abs(mc.ratio_total - 1.0) < tol
    assert np.all(np.abs(mc.bias) < 4 * mc.bias_se)
    # reported std (absolute sigma) against the Monte Carlo spread
    c = mc.coverage
    assert c is not None and c.n == n
    assert np.all(np.abs(c.spread_ratio - 1.0) < 3 * c.spread_ratio_se), c.spread_ratio
    assert c.consistent(0.2)
    assert abs(c.fraction_within_all - c.expected_fraction) < 0.01
    assert "rmse/CRB" in mc.summary()


def test_reported_std_of_nonlinear_fit_matches_spread():
    # exponential decay, noise level estimated from the residuals (not given)
    t = np.linspace(0.0, 4.0, 60)
    truth = np.array([2.0, 1.3, 0.5])

    def simulate(rng):
        return truth[0] * np.exp(-truth[1] * t) + truth[2] + rng.normal(0, 0.02, t.size), truth

    def estimate(y):
        def jac(q):
            e = np.exp(-q["p"][1] * t)
            return {"p": np.column_stack([e, -q["p"][0] * t * e, np.ones_like(t)])}

        p = Problem(lambda q: q["p"][0] * np.exp(-q["p"][1] * t) + q["p"][2] - y, jacobian=jac)
        p.add_block("p", [1.0, 0.5, 0.0])
        return solve(p, method="lm")

    n = 250
    mc = monte_carlo(simulate, estimate, n, np.random.default_rng(11))
    c = mc.coverage
    # sampling tolerance plus a small margin for the estimated noise variance
    assert np.all(np.abs(c.spread_ratio - 1.0) < 3 * c.spread_ratio_se + 0.03), c.spread_ratio
    assert c.consistent(0.2)
    assert np.all(np.abs(mc.bias) < 4 * mc.bias_se)


def test_check_coverage_detects_wrong_uncertainty():
    rng = np.random.default_rng(12)
    e = rng.normal(0, 1.0, (400, 2))
    good = check_coverage(e, [1.0, 1.0])
    assert good.consistent(0.2)
    bad = check_coverage(e, [0.5, 1.0])  # first std reported too small by half
    assert not bad.consistent(0.2)
    assert bad.spread_ratio[0] == pytest.approx(2.0, rel=0.15)
    assert bad.fraction_within[0] < 0.9
    per_trial = check_coverage(e, np.ones((400, 2)))
    np.testing.assert_allclose(per_trial.spread_ratio, good.spread_ratio)
    nan_std = check_coverage(e, np.array([np.nan, 1.0]))
    assert np.isnan(nan_std.spread_ratio[0]) and nan_std.spread_ratio[1] == pytest.approx(good.spread_ratio[1])
    json.dumps(nan_std.to_dict(), allow_nan=False)
    with pytest.raises(ShapeError):
        check_coverage(e, [1.0, 1.0, 1.0])
    with pytest.raises(InputError):
        check_coverage(e, [0.0, 1.0])


def test_bias_of_a_biased_estimator_is_measured():
    mc = monte_carlo(_simulate_linear, lambda y: _estimate_linear(y).x + [0.01, 0.0, 0.0], 100,
                     np.random.default_rng(13))
    assert abs(mc.bias[0] - 0.01) < 4 * mc.bias_se[0]
    assert mc.bias[0] > 4 * mc.bias_se[0]


def test_failures_are_recorded_and_trials_reproducible():
    def estimate(y):
        if y[0] > BETA @ X[0]:
            raise ConvergenceError("pretend failure")
        return _estimate_linear(y).x

    mc = monte_carlo(_simulate_linear, estimate, 40, np.random.default_rng(14))
    assert 5 < mc.n_failed < 35 and mc.errors.shape == (40 - mc.n_failed, 3)
    assert mc.failures[0][1] == "pretend failure"
    d = mc.to_dict(include_errors=True)
    json.dumps(d, allow_nan=False)
    assert d["n_failed"] == mc.n_failed
    mc2 = monte_carlo(_simulate_linear, estimate, 40, np.random.default_rng(14))
    np.testing.assert_array_equal(mc.errors, mc2.errors)
    with pytest.raises(ConvergenceError, match="all 3"):
        monte_carlo(_simulate_linear, lambda y: estimate(y + 10), 3, np.random.default_rng(0))


def test_custom_error_and_bad_arguments():
    mc = monte_carlo(_simulate_linear, lambda y: _estimate_linear(y).x, 20, np.random.default_rng(15),
                     error=lambda est, truth: [np.linalg.norm(est - truth)])
    assert mc.errors.shape == (20, 1) and np.all(mc.errors >= 0)
    with pytest.raises(InputError, match="Generator"):
        monte_carlo(_simulate_linear, _estimate_linear, 5, 42)
    with pytest.raises(InputError):
        monte_carlo(_simulate_linear, _estimate_linear, 1, np.random.default_rng(0))
    with pytest.raises(ShapeError):
        monte_carlo(_simulate_linear, _estimate_linear, 5, np.random.default_rng(0), bound=np.eye(2))
    with pytest.raises(ShapeError):
        monte_carlo(_simulate_linear, _estimate_linear, 5, np.random.default_rng(0), labels=["a"])
