"""Rank deficiency, weak determination and correlations, named by parameter."""

import numpy as np
import pytest

from robocal.estimation import Problem, analyze_jacobian, solve


def _sum_model(seed=0):
    rng = np.random.default_rng(seed)
    x = np.linspace(0, 1, 30)
    y = 3.0 * x + 0.5 + rng.normal(0, 0.01, 30)
    p = Problem(lambda q: (q["a"] + q["b"]) * x + q["c"] - y,
                jacobian=lambda q: {"a": x[:, None], "b": x[:, None], "c": np.ones((30, 1))})
    p.add_block("a", 1.0, unit="m").add_block("b", 0.0, unit="m").add_block("c", 0.0)
    return p, x, y


@pytest.mark.parametrize("method", ["lm", "trf", "dogbox"])
@pytest.mark.parametrize("jac", ["analytic", "2-point", "3-point"])
def test_sum_of_parameters_is_rank_deficient_with_names(method, jac):
    p, x, y = _sum_model()
    r = solve(p, method=method, jac=jac)
    assert r.rank == 2
    assert r.unidentifiable == ["a", "b"]
    assert r.std["a"] is None and r.std["b"] is None
    assert r.value("a") is None and r.value("c") is not None
    w = [d for d in r.warnings if d.code == "rank_deficient"]
    assert len(w) == 1 and w[0].params == ("a", "b")
    assert np.isnan(r.cov[0, 0]) and np.isnan(r.corr[0, 2])
    # c is orthogonal to the null space: its std is the textbook one of y = s x + c
    X = np.column_stack([x, np.ones_like(x)])
    beta, rss, *_ = np.linalg.lstsq(X, y, rcond=None)
    cov = rss[0] / (30 - 2) * np.linalg.inv(X.T @ X)
    assert r.std["c"] == pytest.approx(np.sqrt(cov[1, 1]), rel=1e-5)
    assert r.params["a"] + r.params["b"] == pytest.approx(beta[0], rel=1e-6)
    assert r.dof == 28


def test_summary_prints_no_value_for_unidentifiable():
    p, *_ = _sum_model()
    r = solve(p)
    text = r.summary()
    line_a = [ln for ln in text.splitlines() if ln.strip().startswith("a ")][0]
    assert "not identifiable" in line_a
    assert f"{r.params['a']:.4g}"[:5] not in line_a
    rows = {row["label"]: row for row in r.parameter_table()}
    assert rows["a"]["value"] is None and rows["a"]["status"] == "unidentifiable"
    assert rows["c"]["value"] == pytest.approx(r.params["c"])


def test_parameter_the_residuals_ignore_is_unidentifiable():
    p = Problem(lambda q: q["v"][0] - np.array([1.0, 1.1, 0.9]))
    p.add_block("v", [0.0, 5.0], labels=["used", "ignored"])
    r = solve(p)
    assert r.unidentifiable == ["ignored"] and r.std["used"] is not None


def test_weakly_determined_parameters_named():
    rng = np.random.default_rng(4)
    x1 = rng.normal(size=50)
    x2 = x1 + 1e-3 * rng.normal(size=50)  # nearly collinear columns
    x3 = rng.normal(size=50)
    y = x1 + x2 + x3 + rng.normal(0, 0.01, 50)
    X = np.column_stack([x1, x2, x3])
    p = Problem(lambda q: X @ q["w"] - y, jacobian=lambda q: {"w": X})
    p.add_block("w", np.zeros(3))
    r = solve(p, method="lm")
    assert r.rank == 3 and not r.unidentifiable
    assert r.weakly_determined == ["w[0]", "w[1]"]
    assert "weakly_determined" in r.warning_codes()
    assert r.correlations[0][:2] == ("w[0]", "w[1]") and r.correlations[0][2] < -0.999
    # its std is still the textbook one: weak, not missing
    cov = r.residual_variance * np.linalg.inv(X.T @ X)
    np.testing.assert_allclose(r.std_array, np.sqrt(np.diag(cov)), rtol=1e-6)


def test_column_scaling_makes_units_irrelevant():
    # the same well-posed problem with one parameter in micro-units: no rank loss
    rng = np.random.default_rng(2)
    X = rng.normal(size=(40, 3)) * [1.0, 1e6, 1e-6]
    ident = analyze_jacobian(X, ["a", "b", "c"])
    assert ident.rank == 3 and ident.condition_number < 10
    ident2 = analyze_jacobian(X[:, [0, 0, 1, 2]] * [1, 2, 1, 1], ["a", "a2", "b", "c"])
    assert ident2.rank == 3 and ident2.unidentifiable == ("a", "a2")
    assert "+0.71 a" in ident2.null_directions()[0].replace("-", "+")


def test_null_direction_sign_does_not_flip_on_a_tie():
    """Two columns that cancel exactly: the direction is +-(a - b)/sqrt(2), written with a first."""
    rng = np.random.default_rng(5)
    base = rng.normal(size=(30, 2))
    for flip in (1.0, -1.0):  # the null vector's sign as the SVD returns it is arbitrary
        J = np.column_stack([base[:, 0], -base[:, 0], base[:, 1]])
        ident = analyze_jacobian(J, ["a", "b", "c"])
        ident.null_space[:] *= flip
        assert ident.null_directions() == ["+0.71 a +0.71 b"]


def test_analyze_jacobian_wide_and_sparse():
    import scipy.sparse as sp

    J = np.array([[1.0, 0.0, 2.0]])
    ident = analyze_jacobian(J)
    assert ident.rank == 1 and ident.unidentifiable == ("p[0]", "p[1]", "p[2]")
    assert np.all(np.isnan(ident.std))
    ident_s = analyze_jacobian(sp.csr_array(np.eye(3)[:, [0, 1, 1]]))
    assert ident_s.unidentifiable == ("p[1]", "p[2]")


def test_tall_jacobian_path_matches_the_textbook_formulas():
    # many rows, few parameters: the QR shortcut must give (J^T J)^-1 and find a null direction
    rng = np.random.default_rng(4)
    J = rng.normal(size=(5000, 6)) * [1.0, 10.0, 0.1, 1.0, 1.0, 1.0]
    ident = analyze_jacobian(J, residual_variance=2.5)
    np.testing.assert_allclose(ident.cov, 2.5 * np.linalg.inv(J.T @ J), rtol=1e-9)
    assert ident.rank == 6 and not ident.unidentifiable
    J[:, 5] = J[:, 3] - 2.0 * J[:, 4]
    ident = analyze_jacobian(J)
    assert ident.rank == 5 and set(ident.unidentifiable) == {"p[3]", "p[4]", "p[5]"}
