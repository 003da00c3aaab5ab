"""solve(method='lm') calls MINPACK directly (SciPy's lmder, or scipy.optimize.leastsq where that private
entry is unusable), not through least_squares' wrappers (issue 16): the same answer, uncertainty, history
and diagnostics as the least_squares path, by either direct route."""

import warnings

import numpy as np
import pytest

import robocal.estimation._solve as S
from robocal.errors import InputError
from robocal.estimation import Problem, solve

from .conftest import make_circle, make_exponential, make_linear

XTOL = 1e-10


def _rank_deficient():
    """y = (a + b) t + c: only a + b is determined (a, b unidentifiable, c free)."""
    rng = np.random.default_rng(5)
    t = np.linspace(0, 1, 30)
    y = 0.7 * t + 0.1 + rng.normal(0, 0.01, t.size)
    p = Problem(lambda q: (q["p"][0] + q["p"][1]) * t + q["p"][2] - y,
                jacobian=lambda q: np.column_stack([t, t, np.ones_like(t)]))
    return p.add_block("p", [0.0, 0.0, 0.0], labels=["a", "b", "c"])


def _tied_scaled_outlier():
    """Two terms (2-D observations with one gross outlier, 1-D), a fixed and a tied element, block scales."""
    rng = np.random.default_rng(7)
    t = np.linspace(0, 2, 40)
    truth = np.array([1.5, -0.4, 0.8])

    def f1(q):
        a, b, c = q["k"]
        r = np.column_stack([a * np.sin(b * t) - truth[0] * np.sin(truth[1] * t), c * t - truth[2] * t])
        return r + noise1

    def f2(q):
        return q["k"][0] * t[:10] + q["off"][0] + q["off"][1] - (truth[0] * t[:10] + 0.3) + noise2

    noise1 = rng.normal(0, 0.01, (40, 2))
    noise1[17] += 0.5                                             # an outlier: named in the warnings
    noise2 = rng.normal(0, 0.01, 10)
    p = Problem()
    p.add_block("k", [1.0, -0.5, 1.0], scale=[1.0, 0.1, 1.0]).add_block("off", [0.1, 0.1], fixed=[False, False])
    p.add_residuals(f1, name="curve", residual_dim=2, sigma=[0.01, 0.02])
    p.add_residuals(f2, name="line", sigma=0.01)
    p.tie("off[1]", "off[0]")
    return p


PROBLEMS = {
    "linear": lambda: make_linear()[0],
    "exponential": lambda: make_exponential()[0],
    "circle": lambda: make_circle()[0],
    "rank_deficient": _rank_deficient,
    "tied_scaled_outlier": _tied_scaled_outlier,
}


def _general(monkeypatch, p, **kw):
    with monkeypatch.context() as m:
        m.setattr(S, "_minpack_diag", lambda *a, **k: False)     # as before: through least_squares
        m.setattr(S, "leastsq", None)                             # and never MINPACK directly
        m.setattr(S, "_lmder", None)
        return solve(p, method="lm", **kw)


def _spy(monkeypatch, via):
    """Route 'lm' through ``via`` ('lmder': SciPy's private lmder; 'leastsq': the public wrapper, the
    fallback) and count the calls."""
    calls = []
    if via == "lmder":
        if S._lmder is None:
            pytest.skip("SciPy's _minpack._lmder is not usable here (solve falls back to leastsq)")
        real = S._lmder
        monkeypatch.setattr(S, "_lmder", lambda *a: calls.append(1) or real(*a))
    else:
        real = S.leastsq
        monkeypatch.setattr(S, "_lmder", None)
        monkeypatch.setattr(S, "leastsq", lambda *a, **k: calls.append(1) or real(*a, **k))
    return calls


def test_lmder_probe_finds_the_private_entry():
    # SciPy >= 1.12 (the lowest pin) has _minpack._lmder with leastsq's call: the fast route is the one taken
    assert S._lmder is not None and S._probe_lmder() is S._lmder


@pytest.mark.parametrize("via", ["lmder", "leastsq"])
@pytest.mark.parametrize("name", sorted(PROBLEMS))
@pytest.mark.parametrize("opts", [{}, {"x_scale": 1.0}, {"jac": "2-point"}],
                         ids=["scale-default", "scale-1", "finite-differences"])
def test_direct_minpack_matches_least_squares(monkeypatch, name, opts, via):
    kw = dict(xtol=XTOL, ftol=1e-12, **opts)
    ref = _general(monkeypatch, PROBLEMS[name](), **kw)
    calls = _spy(monkeypatch, via)
    r = solve(PROBLEMS[name](), method="lm", **kw)
    assert calls, f"method='lm' did not take the direct MINPACK path ({via})"
    # one MINPACK run with the same inputs: identical iterates in exact arithmetic. The tolerance is the
    # solver's own (xtol, relative to the parameters' size); std and cost follow from x (first order).
    scale = max(np.max(np.abs(ref.x)), 1.0)
    np.testing.assert_allclose(r.x, ref.x, rtol=10 * XTOL, atol=10 * XTOL * scale)
    assert r.cost == pytest.approx(ref.cost, rel=1e-9, abs=1e-15)
    np.testing.assert_allclose(r.cost_history, ref.cost_history, rtol=1e-9)
    np.testing.assert_allclose(r.std_array, ref.std_array, rtol=1e-6)       # NaN where unidentifiable, both
    np.testing.assert_allclose(r.cov, ref.cov, rtol=1e-6, atol=1e-12 * np.nanmax(np.abs(ref.cov)))
    assert (r.status, r.message, r.success) == (ref.status, ref.message, ref.success)
    assert (r.iterations, r.nfev, r.njev, r.rank, r.dof) == (ref.iterations, ref.nfev, ref.njev, ref.rank, ref.dof)
    assert r.unidentifiable == ref.unidentifiable and r.weakly_determined == ref.weakly_determined
    assert [(w.code, w.message) for w in r.warnings] == [(w.code, w.message) for w in ref.warnings]
    np.testing.assert_array_equal(r.outliers, ref.outliers)
    assert r.cost_history[-1] == r.cost and len(r.cost_history) == r.iterations + 1


def test_the_problems_exercise_what_they_claim(monkeypatch):
    # the comparison above must cover a rank-deficient problem and named outliers, not only clean fits
    r = solve(_rank_deficient(), method="lm")
    assert r.unidentifiable == ["a", "b"] and "rank_deficient" in r.warning_codes()
    r = solve(_tied_scaled_outlier(), method="lm")
    assert "outliers" in r.warning_codes() and 17 in r.outliers and r.std["off[1]"] == r.std["off[0]"]


@pytest.mark.parametrize("via", ["lmder", "leastsq"])
def test_stop_budget_and_callback_on_the_direct_path(monkeypatch, via):
    p = make_exponential()[0]
    _spy(monkeypatch, via)
    # the evaluation budget: MINPACK's info 5 is least_squares' status 0, with its message
    r, ref = solve(p, method="lm", max_nfev=2), _general(monkeypatch, p, max_nfev=2)
    assert r.status == ref.status == 0 and r.message == ref.message and "not_converged" in r.warning_codes()
    np.testing.assert_array_equal(r.x, ref.x)
    # the callback sees iterate 0 once (leastsq probes the start point before MINPACK does; the tracker
    # serves the second request from its cache) and can stop
    seen = []
    r = solve(p, method="lm", callback=lambda it: seen.append(it.iteration) or it.iteration >= 2)
    assert seen == [0, 1, 2] and r.status == -2 and r.iterations == 2


@pytest.mark.parametrize("kw", [{"verbose": 1}, {"ftol": 1e-17}, {"x_scale": [1.0, -1.0, 1.0]}])
def test_what_only_least_squares_words_goes_to_it(monkeypatch, kw, capsys):
    # printing, tolerances below epsilon and a bad x_scale keep least_squares' own output and errors (the
    # direct path is disabled here: taking it would fail with a TypeError, not these)
    monkeypatch.setattr(S, "leastsq", None)
    p = make_exponential()[0]
    if "verbose" in kw:
        assert solve(p, method="lm", **kw).success
        assert "termination condition" in capsys.readouterr().out
        return
    with pytest.raises(InputError, match="x_scale" if "x_scale" in kw else "epsilon"), \
            warnings.catch_warnings():
        warnings.simplefilter("ignore")       # SciPy versions that warn about the tolerance before refusing
        solve(p, method="lm", **kw)
