"""LSQResult: JSON round trip, summary table, queries."""

import json

import numpy as np
import pytest

from robocal.errors import InputError
from robocal.estimation import LSQResult, Problem, outlier_sigma, solve


def _rich_result():
    rng = np.random.default_rng(22)  # a draw whose clean noise stays inside 3 sigma
    P = rng.uniform(-1, 1, (30, 2))
    obs = P * 1.1 + [0.2, -0.1] + rng.normal(0, 0.01, (30, 2))
    obs[5] += 1.0
    p = Problem(lambda q: P * q["k"] + q["t"] + 0.0 * q["unused"] - obs, name="reprojection")
    p.add_block("k", 1.0).add_block("t", [0.0, 0.0], unit="px").add_block("unused", 3.0)
    p.add_block("fixed", [1.0, 2.0], fixed=True).add_block("mirror", 0.0)
    p.tie("mirror", "k", factor=-1.0)
    return solve(p, method="trf", loss="huber", f_scale=0.02)


def test_to_dict_is_json_and_round_trips():
    r = _rich_result()
    assert set(r.warning_codes()) == {"rank_deficient", "outliers"}
    d = r.to_dict()
    text = json.dumps(d, allow_nan=False)
    back = LSQResult.from_dict(json.loads(text))
    for name in ("x", "residuals", "normalized_residuals", "cost_history", "singular_values", "observation_scores"):
        np.testing.assert_array_equal(getattr(back, name), getattr(r, name))
    np.testing.assert_array_equal(back.cov, r.cov)  # NaN rows survive as NaN
    assert back.std == r.std and back.std["unused"] is None
    assert back.warnings == r.warnings and back.terms == r.terms
    assert back.tied == r.tied and back.unidentifiable == ["unused"]
    for k in r.params:
        np.testing.assert_array_equal(back.params[k], r.params[k])
    np.testing.assert_array_equal(back.outliers, r.outliers)
    assert back.summary() == r.summary()
    assert back.to_dict() == d
    with_jac = r.to_dict(include_jacobian=True)
    assert np.asarray(with_jac["jac"]).shape == (60, len(r.free_labels))
    with pytest.raises(InputError):
        LSQResult.from_dict({"x": [1.0]})


def test_summary_table_lists_every_label_with_status():
    r = _rich_result()
    text = r.summary()
    for lab in r.labels:
        assert any(line.strip().startswith(lab) for line in text.splitlines()), lab
    assert "px" in text and "fixed" in text and "= -1 * k" in text
    assert "not identifiable" in text and "rank_deficient" in text
    assert "term 'reprojection': 30 observations x 2" in text
    assert "do not include model error" in text


def test_queries():
    r = _rich_result()
    assert r.value("mirror") == pytest.approx(-r.params["k"].item())
    assert r.value("unused") is None
    np.testing.assert_array_equal(r.block_std("fixed"), [0.0, 0.0])
    assert np.isnan(r.block_std("unused"))
    assert r.block_std("t").shape == (2,)
    assert r.worst_observations(1)[0][:3] == (5, "reprojection", 5)
    assert list(r.outliers) == [5]
    assert r.obs_residuals(kind="normalized").shape == (30, 2)
    # the default threshold is Bonferroni-corrected for the 30 observations: 3.59 sigma
    assert r.outlier_sigma == pytest.approx(outlier_sigma(30))
    assert r.outlier_threshold(1) == pytest.approx(outlier_sigma(30) ** 2)
    with pytest.raises(InputError):
        r.value("nope")
    with pytest.raises(InputError):
        r.obs_residuals(kind="odd")


def test_outlier_sigma_keeps_the_family_false_alarm_rate():
    # Bonferroni: each of n observations tested at 1 % / n (two-sided Gaussian tail)
    assert outlier_sigma(216) == pytest.approx(4.07, abs=0.005)
    assert outlier_sigma(1000) == pytest.approx(4.42, abs=0.005)
    assert outlier_sigma(1) == 3.0 and outlier_sigma(10) > 3.0  # never below 3 sigma
    from scipy import stats
    for n in (50, 216, 5000):
        assert 2 * stats.norm.sf(outlier_sigma(n)) * n == pytest.approx(0.01, rel=1e-9)
    with pytest.raises(ValueError):
        outlier_sigma(10, family_p=1.5)
