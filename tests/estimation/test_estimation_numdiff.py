"""SciPy's private finite-difference engine: present with the keywords we use, or a clear error."""

import inspect

import numpy as np
import pytest

from robocal.estimation import Problem, solve
from robocal.estimation import _evaluate


def _line(analytic: bool) -> Problem:
    """y = a t + b, noise-free: both Jacobian paths must land on (a, b) = (2, -1)."""
    t = np.linspace(0.0, 1.0, 8)
    y = 2.0 * t - 1.0
    p = Problem()
    p.add_block("ab", [0.0, 0.0])
    jac = (lambda q: np.column_stack([t, np.ones_like(t)])) if analytic else None
    p.add_residuals(lambda q: q["ab"][0] * t + q["ab"][1] - y, name="line", jacobian=jac)
    return p


def test_installed_scipy_provides_approx_derivative_with_the_keywords_used():
    # If a SciPy upgrade moves or changes the private function, this fails first and says so.
    assert _evaluate._NUMDIFF_PROBLEM is None, _evaluate._NUMDIFF_PROBLEM
    params = inspect.signature(_evaluate.approx_derivative).parameters
    assert set(_evaluate._NUMDIFF_KEYWORDS) <= set(params)
    assert callable(_evaluate.group_columns)


@pytest.mark.parametrize("jac", ["2-point", "3-point"])
def test_finite_differences_agree_with_the_analytic_jacobian(jac):
    fd = solve(_line(analytic=False), jac=jac)
    an = solve(_line(analytic=True))
    np.testing.assert_allclose(fd.x, [2.0, -1.0], atol=1e-8)
    np.testing.assert_allclose(fd.jac, an.jac, rtol=1e-6, atol=1e-8)


def test_missing_engine_gives_a_clear_error_and_analytic_jacobians_still_work(monkeypatch):
    monkeypatch.setattr(_evaluate, "_NUMDIFF_PROBLEM", "cannot import it (No module named 'scipy.optimize._numdiff')")
    with pytest.raises(ImportError, match=r"jac='2-point' \(finite differences\) uses scipy\.optimize\._numdiff"
                                          r"\.approx_derivative, a private SciPy function.*jac='analytic'"):
        solve(_line(analytic=False))
    np.testing.assert_allclose(solve(_line(analytic=True)).x, [2.0, -1.0], atol=1e-10)
