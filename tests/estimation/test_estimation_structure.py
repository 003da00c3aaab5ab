"""Several residual terms, block sparsity and the sparse solver path."""

import numpy as np
import pytest
import scipy.sparse as sp

from robocal.estimation import Problem, solve


def _bundle(K=30, n_per=8, seed=0, analytic=True, sparse_jac=False):
    """K groups; group k: y = s * t + o_k[0] + o_k[1] t^2, one shared slope s."""
    rng = np.random.default_rng(seed)
    p = Problem()
    p.add_block("slope", 0.0, unit="m")
    truth = {"slope": 1.7}
    for k in range(K):
        t = rng.uniform(-1, 1, n_per)
        o = rng.normal(size=2)
        truth[f"o{k}"] = o
        y = 1.7 * t + o[0] + o[1] * t**2 + rng.normal(0, 0.01, n_per)
        p.add_block(f"o{k}", [0.0, 0.0])

        def res(q, t=t, y=y, k=k):
            return q["slope"] * t + q[f"o{k}"][0] + q[f"o{k}"][1] * t**2 - y

        def jac(q, t=t, k=k):
            blk = np.column_stack([np.ones_like(t), t**2])
            return {"slope": t[:, None], f"o{k}": sp.csr_array(blk) if sparse_jac else blk}

        p.add_residuals(res, name=f"group{k}", blocks=["slope", f"o{k}"], jacobian=jac if analytic else None)
    return p, truth


def test_sparse_and_dense_paths_agree():
    p, truth = _bundle()
    dense = solve(p, method="trf", sparse=False)
    auto = solve(p, method="trf")  # 61 parameters, < 20 % dense -> sparse
    assert sp.issparse(auto.jac) and not sp.issparse(dense.jac)
    # LSMR (the sparse trust-region solver) is iterative: agreement to a
    # small fraction of the statistical uncertainty is what matters
    assert np.all(np.abs(auto.x - dense.x) < 1e-3 * dense.std_array)
    np.testing.assert_allclose(auto.std_array, dense.std_array, rtol=1e-5)
    lm = solve(p, method="lm")
    np.testing.assert_allclose(lm.x, dense.x, atol=1e-9)
    assert abs(dense.params["slope"] - truth["slope"]) < 4 * dense.std["slope"]


def test_sparse_blocks_from_user_jacobian_and_finite_differences():
    p, _ = _bundle(K=20, analytic=True, sparse_jac=True)
    ref = solve(p, method="lm")
    fd, _ = _bundle(K=20, analytic=False)
    r = solve(fd, method="trf", sparse=True)
    np.testing.assert_allclose(r.x, ref.x, atol=1e-6)
    # the block structure lets finite differences group columns: far fewer
    # evaluations than one per parameter per Jacobian
    assert r.nfev < r.njev * (fd.n_free + 1) / 4


def test_terms_have_own_observation_numbers_and_rms():
    p, _ = _bundle(K=3, n_per=5)
    r = solve(p, method="lm")
    assert [t.name for t in r.terms] == ["group0", "group1", "group2"]
    assert [t.obs_start for t in r.terms] == [0, 5, 10]
    assert r.locate_observation(7) == ("group1", 2)
    assert set(r.rms_per_term) == {"group0", "group1", "group2"}
    assert r.obs_residuals("group2").shape == (5, 1)
    with pytest.raises(Exception, match="several residual terms"):
        r.obs_residuals()


def test_outliers_in_multi_term_problem_get_global_indices():
    rng = np.random.default_rng(3)
    a = rng.normal(0, 0.01, (40, 2))
    b = rng.normal(0, 0.01, 30)
    b[12] += 0.5
    a[3] += [0.3, 0.3]
    p = Problem()
    p.add_block("m2", [0.0, 0.0]).add_block("m1", 0.0)
    p.add_residuals(lambda q: a - q["m2"], name="points", blocks=["m2"])
    p.add_residuals(lambda q: b - q["m1"], name="scalars", blocks=["m1"])
    r = solve(p, method="trf", loss="soft_l1", f_scale=0.03)
    assert list(r.outliers) == [3, 40 + 12]
    msg = [w.message for w in r.warnings if w.code == "outliers"][0]
    assert "term 'points' observations [3]" in msg and "term 'scalars' observations [12]" in msg
    assert r.worst_observations(2)[0][1:3] in (("points", 3), ("scalars", 12))


def test_element_level_sparsity_is_used():
    t = np.linspace(0, 1, 6)
    # residual i depends only on v[i]
    p = Problem(lambda q: q["v"] - t, jac_sparsity=np.eye(6))
    p.add_block("v", np.zeros(6))
    ev = p.evaluator(jac="2-point")
    assert ev.structure.nnz == 6
    r = solve(p, method="trf")
    np.testing.assert_allclose(r.x, t, atol=1e-8)
    # one Jacobian costs one extra residual evaluation, not six
    assert r.nfev <= 2 * r.njev + 3


def test_ties_across_blocks_on_the_sparse_path():
    p, _ = _bundle(K=30)
    p.tie("o1[0]", "o0[0]")
    a = solve(p, method="trf", sparse=True)
    b = solve(p, method="lm")
    assert a.params["o1"][0] == a.params["o0"][0]
    assert "o1[0]" not in a.free_labels and a.std["o1[0]"] == pytest.approx(a.std["o0[0]"])
    assert np.all(np.abs(a.x - b.x) < 1e-3 * b.std_array)
