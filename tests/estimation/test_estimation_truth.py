"""truth_check: NEES against the chi-square bound, the one truth test of every rig's demo."""

import numpy as np
import pytest

from robocal.errors import InputError
from robocal.estimation import truth_check


def _cov(rng, n):
    A = rng.normal(size=(n, n))
    return A @ A.T + 0.1 * np.eye(n)


def test_honest_errors_fail_at_the_stated_rate():
    rng = np.random.default_rng(7)
    C = _cov(rng, 6)
    L = np.linalg.cholesky(C)
    n = 2000
    fails = sum(not truth_check(L @ rng.normal(size=6), C, alpha=0.05).passed for _ in range(n))
    # binomial(2000, 0.05): std 0.0049; 4 std either side
    assert abs(fails / n - 0.05) < 4 * np.sqrt(0.05 * 0.95 / n)


def test_a_bias_of_five_std_fails_and_names_the_parameter():
    C = np.diag([1.0, 4.0, 9.0])
    chk = truth_check([0.1, 10.0, 0.2], C, names=["a", "b", "c"])
    assert not chk.passed and chk.worst[0] == "b" and chk.worst[1] == pytest.approx(5.0)
    assert "NOT consistent" in str(chk)


def test_correlations_count():
    # strongly correlated pair: an error along the narrow direction is 10 sigma although each |z| < 1.1
    C = np.array([[1.0, 0.99], [0.99, 1.0]])
    e = np.array([1.0, -1.0])
    chk = truth_check(e, C)
    assert max(abs(v) for v in chk.z.values()) < 1.1
    assert chk.nees == pytest.approx(e @ np.linalg.solve(C, e)) and not chk.passed


def test_unidentified_parameters_are_left_out():
    chk = truth_check([0.5, 100.0], np.array([1.0, np.nan]))
    assert chk.dof == 1 and chk.passed and np.isnan(chk.z["1"])
    d = chk.to_dict()
    assert d["z"]["1"] is None and d["dof"] == 1


def test_bad_arguments():
    with pytest.raises(InputError, match="expected shape"):
        truth_check([1.0, 2.0], np.eye(3))
    with pytest.raises(InputError, match="alpha"):
        truth_check([1.0], [1.0], alpha=2.0)
