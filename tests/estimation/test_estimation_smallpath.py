"""The small-problem paths of issue 16 give the numbers of the general path: one dense term's Jacobian taken
as the term returns it (no zero-filled assembly, no column fold), the free vector used as the full one when
nothing is fixed or tied. Solved with both on the same problems, rank-deficient and fixed-element ones
included."""

import numpy as np
import pytest

from robocal.estimation import Problem, solve
from robocal.estimation import _evaluate as E
from robocal.estimation import _layout as L

from .conftest import make_circle, make_exponential, make_linear
from .test_estimation_fastpath import _rank_deficient


def _one_term_with_fixed():
    """One term over two blocks with a fixed element: the fast Jacobian path with a column selection."""
    rng = np.random.default_rng(3)
    t = np.linspace(0, 3, 50)
    y = 1.2 * np.exp(-0.7 * t) + 0.2 * t + rng.normal(0, 0.01, t.size)

    def jac(q):
        a, b = q["ab"]
        e = np.exp(-b * t)
        return np.column_stack([e, -a * t * e, t, np.ones_like(t)])

    p = Problem(lambda q: q["ab"][0] * np.exp(-q["ab"][1] * t) + q["lin"][0] * t + q["lin"][1] - y, jacobian=jac)
    return p.add_block("ab", [1.0, 0.5]).add_block("lin", [0.1, 0.0], fixed=[False, True])


def _dense_full_matrix():
    """The linear fit with its Jacobian as one full matrix (not a dict): the term shape the fast path takes."""
    p, X, y, _ = make_linear()
    q = Problem(lambda v: X @ v["beta"] - y, jacobian=lambda v: X, sigma=0.05)
    return q.add_block("beta", np.zeros(3), labels=["b0", "b1", "b2"])


PROBLEMS = {
    "linear_dict": lambda: make_linear()[0],
    "linear_matrix": _dense_full_matrix,
    "exponential": lambda: make_exponential()[0],
    "circle": lambda: make_circle()[0],
    "rank_deficient": _rank_deficient,
    "fixed_element": _one_term_with_fixed,
}


def _general_path(monkeypatch):
    """Every evaluation through the general assembly and layout map (the code before issue 16's paths)."""
    init_e, init_l = E.Evaluator.__init__, L._Layout.__init__

    def ev_init(self, *a, **k):
        init_e(self, *a, **k)
        self._single = False

    def lay_init(self, *a, **k):
        init_l(self, *a, **k)
        self._all_free = False

    monkeypatch.setattr(E.Evaluator, "__init__", ev_init)
    monkeypatch.setattr(L._Layout, "__init__", lay_init)


@pytest.mark.parametrize("method", ["lm", "trf"])
@pytest.mark.parametrize("name", sorted(PROBLEMS))
def test_small_paths_give_the_general_numbers(monkeypatch, name, method):
    fast = solve(PROBLEMS[name](), method=method)
    with monkeypatch.context() as m:
        _general_path(m)
        ref = solve(PROBLEMS[name](), method=method)
    # the same floating-point operations in the same order (a division by sigma of the same entries, the
    # same columns picked): equal to the last bit, so the solver takes the same steps
    np.testing.assert_array_equal(fast.x, ref.x)
    np.testing.assert_array_equal(fast.cov, ref.cov)            # NaN rows of unidentifiable ones in both
    np.testing.assert_array_equal(fast.cost_history, ref.cost_history)
    np.testing.assert_array_equal(fast.jac, ref.jac)
    assert (fast.nfev, fast.njev, fast.rank, fast.status) == (ref.nfev, ref.njev, ref.rank, ref.status)
    assert [(w.code, w.message) for w in fast.warnings] == [(w.code, w.message) for w in ref.warnings]


def test_the_paths_are_taken(monkeypatch):
    # the comparison above means something only if the fast paths run for these problems
    taken = []
    real = E.Evaluator._analytic_general
    monkeypatch.setattr(E.Evaluator, "_analytic_general", lambda self, *a: taken.append(1) or real(self, *a))
    for name in ("linear_matrix", "fixed_element", "rank_deficient"):
        ev = PROBLEMS[name]().evaluator()
        assert ev._single, name
        ev.jacobian(ev.layout.x0_full[ev.layout.free_full])
    assert not taken
    assert PROBLEMS["linear_matrix"]().evaluator().layout._all_free
    assert not PROBLEMS["fixed_element"]().evaluator().layout._all_free
    r = solve(_rank_deficient(), method="lm")
    assert r.unidentifiable == ["a", "b"]


def test_a_non_finite_jacobian_is_still_named(monkeypatch):
    # the fast path hands a NaN to the general assembly, which names term, residual and parameter
    t = np.linspace(0, 1, 10)

    def jac(q):
        J = np.column_stack([t, np.ones_like(t)])
        J[4, 1] = np.nan
        return J

    p = Problem(lambda q: q["p"][0] * t + q["p"][1] - t, jacobian=jac).add_block("p", [0.5, 0.0], labels=["a", "b"])
    with pytest.raises(Exception, match="residual 4, parameter 'b'"):
        solve(p, method="lm")
