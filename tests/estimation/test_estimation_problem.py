"""Problem construction and bad input: every mistake is a clear RobocalError."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from robocal.errors import InputError, NonFiniteError, NotEnoughDataError, RobocalError, ShapeError
from robocal.estimation import Problem, solve

T = np.linspace(0, 1, 12)


def _line(fun=None, **kw):
    p = Problem(fun or (lambda q: q["ab"][0] * T + q["ab"][1] - (2 * T + 1)), **kw)
    return p.add_block("ab", [0.0, 0.0])


def test_labels_and_shapes():
    p = Problem(lambda q: np.concatenate([q["M"].ravel(), [q["s"]]]))
    p.add_block("M", np.zeros((2, 2))).add_block("s", 1.0, unit="rad").add_block("v", [1.0, 2.0], labels=["x", "y"])
    assert p.labels == ["M[0,0]", "M[0,1]", "M[1,0]", "M[1,1]", "s", "x", "y"]
    params = p.initial_params()
    assert params["M"].shape == (2, 2) and params["s"].shape == () and params["v"].shape == (2,)
    assert p.blocks["s"].units == ("rad",)
    x = np.arange(7.0)
    np.testing.assert_array_equal(p.free_from_params(p.params_from_free(x)), x)


def test_tie_to_fixed_element_and_chains():
    p = Problem(lambda q: np.r_[q["a"] - 1.0, q["b"] - 2.0, q["c"] - 3.0, q["d"]])
    p.add_block("a", 0.5).add_block("b", 0.0).add_block("c", 0.0).add_block("d", 4.0, fixed=True)
    p.tie("c", "b", factor=2.0).tie("b", "a")
    assert p.free_labels == ["a"]
    r = solve(p, method="lm")
    # c = 2 b = 2 a; least squares of (a-1, a-2, 2a-3) -> a = (1 + 2 + 6) / 6
    assert r.params["a"] == pytest.approx(1.5)
    assert r.params["c"] == pytest.approx(3.0)
    assert r.tied["c"] == ("a", 2.0)
    q = Problem(lambda q: q["a"] + q["b"])
    q.add_block("a", 3.0, fixed=True).add_block("b", 0.0).add_block("z", 0.0)
    q.tie("b", "a", factor=-1.0)
    assert q.initial_params()["b"] == -3.0


@pytest.mark.parametrize(
    "call, exc",
    [
        (lambda p: p.add_block("ab", [1.0]), InputError),
        (lambda p: p.add_block("n", [np.nan]), NonFiniteError),
        (lambda p: p.add_block("n", [1.0, np.inf]), NonFiniteError),
        (lambda p: p.add_block("n", np.zeros(0)), ShapeError),
        (lambda p: p.add_block("n", [1.0, 2.0], fixed=[1, 0]), InputError),
        (lambda p: p.add_block("n", [1.0, 2.0], fixed=np.array([True])), ShapeError),
        (lambda p: p.add_block("n", [1.0, 2.0], labels=["u"]), ShapeError),
        (lambda p: p.add_block("n", [1.0, 2.0], labels=["u", "u"]), InputError),
        (lambda p: p.add_block("n", [1.0], labels=["ab[0]"]), InputError),
        (lambda p: p.add_block("n", 1.0, lower=2.0), InputError),
        (lambda p: p.add_block("n", 1.0, scale=-1.0), InputError),
        (lambda p: p.add_block("n", [1.0, 2.0], lower=[0.0, 0.0, 0.0]), ShapeError),
        (lambda p: p.add_block("", 1.0), InputError),
        (lambda p: p.tie("ab[0]", "nope"), InputError),
        (lambda p: p.tie("ab[0]", "ab[0]"), InputError),
        (lambda p: p.tie("ab[0]", "ab[1]").tie("ab[1]", "ab[0]"), InputError),
        (lambda p: p.set_x0("ab", [1.0, np.nan]), NonFiniteError),
        (lambda p: p.set_x0("ab", [1.0]), ShapeError),
        (lambda p: p.set_fixed("zz", True), InputError),
        (lambda p: p.add_residuals("not callable"), InputError),
        (lambda p: p.add_residuals(lambda q: q, sigma=[1.0, -1.0]), InputError),
        (lambda p: p.add_residuals(lambda q: q, residual_dim=0), InputError),
        (lambda p: p.add_residuals(lambda q: q, blocks=[]), InputError),
        (lambda p: p.tie("ab[0]", "ab[1]").tie("ab[0]", "ab[1]"), InputError),
        (lambda p: p.tie("ab[0]", "ab[1]").set_fixed("ab", np.array([True, False])).free_labels, InputError),
    ],
)
def test_bad_problem_construction(call, exc):
    with pytest.raises(exc):
        call(_line())


@pytest.mark.parametrize(
    "fun, exc, match",
    [
        (lambda q: np.full(12, np.nan), NonFiniteError, "observation 0"),
        (lambda q: np.where(q["ab"][0] > 1.0, np.nan, q["ab"][0] * T - 2 * T), NonFiniteError, "during the solve"),
        (lambda q: np.zeros((2, 2, 3)), ShapeError, "shape"),
        (lambda q: np.zeros(0), ShapeError, "no residuals"),
        (lambda q: "abc", InputError, "non-numeric"),
        (lambda q: np.zeros(12 if q["ab"][0] == 0 else 11) + q["ab"][0] - 1, ShapeError, "must not change"),
    ],
)
def test_bad_residual_functions(fun, exc, match):
    with pytest.raises(exc, match=match):
        solve(_line(fun), method="trf")


def test_residual_dim_mismatch_and_sigma_shapes():
    with pytest.raises(ShapeError, match="multiple"):
        solve(_line(residual_dim=5))
    with pytest.raises(ShapeError, match=r"\(n_obs, 3\)"):
        solve(_line(lambda q: np.zeros((6, 2)) + q["ab"], residual_dim=3))
    with pytest.raises(ShapeError, match="sigma"):
        solve(_line(sigma=np.ones(5)))
    r = solve(_line(lambda q: (np.zeros((6, 2)) + q["ab"] - [1, 2]), sigma=[0.1, 0.2]))
    np.testing.assert_allclose(r.x, [1, 2], atol=1e-8)


def test_bad_jacobians():
    good = lambda q: q["ab"][0] * T + q["ab"][1] - (2 * T + 1)  # noqa: E731
    cases = [
        (lambda q: {"ab": np.ones((12, 3))}, ShapeError),
        (lambda q: {"ab": np.ones((2, 12))}, ShapeError),
        (lambda q: {"zz": np.ones((12, 2))}, InputError),
        (lambda q: np.full((12, 2), np.nan), NonFiniteError),
        (lambda q: np.ones((12, 5)), ShapeError),
    ]
    for jac, exc in cases:
        with pytest.raises(exc):
            solve(_line(good, jacobian=jac))
    with pytest.raises(InputError, match="no jacobian"):
        solve(_line(good), jac="analytic")


def test_bad_solver_options():
    p = _line()
    for kw in (dict(method="newton"), dict(loss="l1"), dict(f_scale=0.0), dict(jac="5-point"),
               dict(outlier_sigma=-1.0), dict(absolute_sigma=True)):
        with pytest.raises(InputError):
            solve(p, **kw)
    with pytest.raises(InputError, match="loss='linear'"):
        solve(p, method="lm", loss="huber")
    with pytest.raises(InputError, match="bounds"):
        solve(Problem(lambda q: q["a"] - 1.0).add_block("a", 0.0, upper=5.0), method="lm")
    with pytest.raises(NotEnoughDataError):
        solve(Problem(lambda q: q["a"][:1]).add_block("a", [0.0, 0.0]), method="lm")
    with pytest.raises(InputError, match="no free parameters"):
        solve(_line().set_fixed("ab", True))
    with pytest.raises(InputError, match="no parameter blocks"):
        solve(Problem(lambda q: np.zeros(3)))
    with pytest.raises(InputError, match="no residuals"):
        solve(Problem().add_block("a", 1.0))
    with pytest.raises(InputError):
        solve("not a problem")


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 6), k=st.integers(0, 5), bad=st.sampled_from([np.nan, np.inf, -np.inf]))
def test_non_finite_x0_always_rejected(n, k, bad):
    x0 = np.zeros(n)
    x0[k % n] = bad
    with pytest.raises(NonFiniteError) as info:
        Problem(lambda q: q["v"]).add_block("v", x0)
    assert "x0 of block 'v'" in str(info.value)
    assert isinstance(info.value, RobocalError)


@settings(max_examples=30, deadline=None)
@given(stage=st.integers(0, 6))
def test_nan_anywhere_in_solve_is_reported_never_returned(stage):
    # the residual turns NaN after `stage` evaluations: an error, not a NaN result
    calls = {"n": 0}

    def fun(q):
        calls["n"] += 1
        r = q["ab"][0] * T + q["ab"][1] - (2 * T + 1)
        return r if calls["n"] <= stage else r * np.nan

    try:
        r = solve(_line(fun), method="trf", jac="2-point")
    except NonFiniteError:
        return
    assert np.all(np.isfinite(r.x)) and np.all(np.isfinite(r.residuals))
