"""DHChain.fk (folded constants, motions in closed form; issue 16) against the plain product of link matrices."""

import math

import numpy as np
import pytest

from robocal.errors import NonFiniteError
from robocal.geometry import matrix_from_rotvec, transform_from
from robocal.kinematics import DHChain
from dh_reference import stacked_frames


def product_fk(chain, q):
    """The previous implementation: T_base @ A_1(q) @ ... @ A_n(q) @ T_tool with every A_i a full matrix."""
    return np.broadcast_to(stacked_frames(chain, q)[-1] @ chain.T_tool, q.shape[:-1] + (4, 4))


def random_chain(rng, k):
    n = int(rng.integers(1, 8))
    rows = np.column_stack([rng.uniform(-math.pi, math.pi, n), rng.uniform(-1, 1, n),
                            rng.uniform(-math.pi, math.pi, n), rng.uniform(-1, 1, n)])
    if k % 4 == 1:
        rows[:, :2] = 0.0  # identity constants: skipped, must not change the result
    if k % 4 == 2:
        rows[:, 0] = rng.choice([0.0, math.pi / 2, -math.pi / 2, math.pi], n)  # exact 0 / 1 entries in K
    kw = {}
    if k % 3:
        kw["T_base"] = transform_from(matrix_from_rotvec(rng.normal(size=3)), rng.normal(size=3))
    if k % 5 < 3:
        kw["T_tool"] = transform_from(matrix_from_rotvec(rng.normal(size=3)), rng.normal(size=3))
    return DHChain.from_table(rows, convention=("modified", "standard")[k % 2],
                              joint_types="".join(rng.choice(list("RPF"), n)), **kw)


def test_fk_equals_the_link_matrix_product_on_random_chains():
    rng = np.random.default_rng(16)
    for k in range(120):
        chain = random_chain(rng, k)
        shape = [(), (7,), (3, 4)][k % 3]
        q = rng.uniform(-3, 3, shape + (chain.dof,))
        T = chain.fk(q)
        assert T.shape == shape + (4, 4)
        # <= 7 links of unit rotations and translations <= ~2 m: a few ulps per product, 1e-13 is ~500 ulps of 1
        assert np.abs(T - product_fk(chain, q)).max() < 1e-13, (k, chain)
        assert np.array_equal(T[..., 3, :], np.broadcast_to([0.0, 0.0, 0.0, 1.0], shape + (4,)))
        if chain.dof:  # one configuration at a time: the same numbers
            one = np.stack([chain.fk(x) for x in q.reshape(-1, chain.dof)]).reshape(T.shape)
            assert np.abs(T - one).max() < 1e-15


def test_fk_of_a_list_a_strided_array_and_huge_finite_values():
    chain = DHChain.from_table([[0.0, 0.0, 0.0, 0.3], [-math.pi / 2, 0.1, 0.2, 0.0]])
    q = np.random.default_rng(1).uniform(-3, 3, (5, 4))[:, ::2]  # not contiguous
    assert np.abs(chain.fk(q) - chain.fk(q.tolist())).max() == 0.0
    assert np.abs(chain.fk(q) - product_fk(chain, q)).max() < 1e-14
    big = np.full((2, 2), 1e150)  # huge but finite: accepted (beyond ~1e154 the fast check's dot overflows and
    assert np.all(np.isfinite(chain.fk(big)))  # the exact check decides)
    bad = q.copy()
    bad[3, 0] = np.nan
    with pytest.raises(NonFiniteError, match=r"q contains NaN or infinity \(first at index \(3, 0\)\)"):
        chain.fk(bad)
    bad[3, 0], bad[1, 1] = np.inf, -np.inf  # inf - inf in the sum is NaN: caught too
    with pytest.raises(NonFiniteError, match=r"\(first at index \(1, 1\)\)"):
        chain.fk(bad)
