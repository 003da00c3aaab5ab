"""D-H chains: seed 000's Table 1 and eq. (5), both conventions, Jacobians vs finite differences."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import array_shapes

from robocal.errors import InputError, NonFiniteError, ShapeError
from robocal.geometry import matrix_from_angle, matrix_from_rotvec, transform_from
from robocal.kinematics import DHChain, DHLink

SETTINGS = settings(max_examples=40, deadline=None)


def seed000_chain(d1, d2, convention="modified"):
    """Seed 000, Table 1: link 1, link 2 (revolute) and the fixed end-effector row E."""
    rows = [[np.pi, 0.0, -np.pi / 2, d1], [-np.pi / 2, 0.0, 0.0, 0.0], [np.pi / 2, 0.0, 0.0, d2]]
    return DHChain.from_table(rows, convention=convention, joint_types="RRF")


def seed000_eq5(theta1, theta2, d1, d2):
    """Seed 000, eq. (5), written out entry by entry: ^0T_E(theta1, theta2)."""
    s1, c1, s2, c2 = np.sin(theta1), np.cos(theta1), np.sin(theta2), np.cos(theta2)
    zero, one = np.zeros_like(s1), np.ones_like(s1)
    rows = [
        [s1 * c2, c1, s1 * s2, d2 * s1 * s2],
        [c1 * c2, -s1, c1 * s2, d2 * c1 * s2],
        [s2, zero, -c2, -d2 * c2 - d1],
        [zero, zero, zero, one],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def test_seed000_table1_modified_reproduces_eq5():
    rng = np.random.default_rng(0)
    d1, d2 = rng.uniform(0.05, 0.5, size=2)
    theta = rng.uniform(-np.pi, np.pi, size=(500, 2))
    T = seed000_chain(d1, d2).fk(theta)
    expected = seed000_eq5(theta[:, 0], theta[:, 1], d1, d2)
    assert T.shape == (500, 4, 4)
    assert np.abs(T - expected).max() < 1e-14
    # one configuration at a time gives the same
    assert np.abs(seed000_chain(d1, d2).fk(theta[7]) - expected[7]).max() < 1e-14


def test_seed000_table1_standard_convention_does_not_reproduce_eq5():
    rng = np.random.default_rng(1)
    d1, d2 = 0.3, 0.1
    theta = rng.uniform(-np.pi, np.pi, size=(500, 2))
    err = np.abs(seed000_chain(d1, d2, "standard").fk(theta) - seed000_eq5(theta[:, 0], theta[:, 1], d1, d2))
    worst_per_config = err.max(axis=(-2, -1))
    # not a rounding difference: every configuration is off by a sizeable amount
    assert worst_per_config.min() > 0.1, worst_per_config.min()


def _elementary_product(lk, convention, q=0.0):
    """A_i from explicit elementary factors (independent of the closed form in _dh)."""
    theta = lk.theta + (q if lk.joint == "revolute" else 0.0)
    d = lk.d + (q if lk.joint == "prismatic" else 0.0)
    Rx = transform_from(matrix_from_angle("x", lk.alpha), np.zeros(3))
    Rz = transform_from(matrix_from_angle("z", theta), np.zeros(3))
    Tx = transform_from(np.eye(3), [lk.a, 0, 0])
    Tz = transform_from(np.eye(3), [0, 0, d])
    return Rx @ Tx @ Rz @ Tz if convention == "modified" else Rz @ Tz @ Tx @ Rx


def random_transform(rng):
    return transform_from(matrix_from_rotvec(rng.normal(size=3)), rng.normal(scale=0.3, size=3))


def random_chain(rng, convention, types="RPRFRRP", **kw):
    rows = np.column_stack([
        rng.uniform(-np.pi, np.pi, len(types)),
        rng.uniform(-0.3, 0.3, len(types)),
        rng.uniform(-np.pi, np.pi, len(types)),
        rng.uniform(-0.3, 0.3, len(types)),
    ])
    return DHChain.from_table(rows, convention=convention, joint_types=types,
                              T_base=random_transform(rng), T_tool=random_transform(rng), **kw)


@pytest.mark.parametrize("convention", ["modified", "standard"])
def test_link_transforms_match_elementary_products(convention):
    rng = np.random.default_rng(2)
    chain = random_chain(rng, convention)
    q = rng.uniform(-1, 1, chain.dof)
    frames = chain.fk_all(q)
    assert frames.shape == (chain.n_links + 1, 4, 4)
    assert np.abs(frames[0] - chain.T_base).max() == 0.0
    j = 0
    for i, lk in enumerate(chain.links):
        qi = 0.0
        if lk.joint != "fixed":
            qi, j = q[j], j + 1
        A = _elementary_product(lk, convention, qi)
        assert np.abs(frames[i + 1] - frames[i] @ A).max() < 1e-14
        assert np.abs(chain.link_transform(i, qi) - A).max() < 1e-14
    assert np.abs(chain.fk(q) - frames[-1] @ chain.T_tool).max() < 1e-14


def test_prismatic_joint_translates_along_its_axis():
    # A P1R2P3 arm like seed 004's welding arm.
    chain = DHChain.from_table(
        [[0, 0, 0, 0.4], [0, 0.2, 0.3, 0.1], [np.pi / 2, 0.05, 0.0, 0.15]],
        convention="modified", joint_types=["prismatic", "revolute", "prismatic"],
    )
    q = np.array([0.05, 0.7, 0.02])
    for j, link in ((0, 1), (2, 3)):
        dq = np.zeros(3)
        dq[j] = 0.013
        T0, T1 = chain.fk(q), chain.fk(q + dq)
        z_axis = chain.fk_all(q)[link, :3, 2]  # modified convention: joint i moves along z_i
        assert np.abs(T1[:3, 3] - T0[:3, 3] - 0.013 * z_axis).max() < 1e-15
        assert np.abs(T1[:3, :3] - T0[:3, :3]).max() < 1e-15
    # the table's d of a prismatic joint is its zero offset
    moved = DHChain.from_table(chain.table - np.array([0, 0, 0, 0.4]) * [[1], [0], [0]],
                               joint_types="PRP")
    assert np.abs(moved.fk(q + [0.4, 0, 0]) - chain.fk(q)).max() < 1e-15
    assert chain.joint_offset_names == ("d_1", "theta_2", "d_3")
    assert np.allclose(chain.joint_offsets, [0.4, 0.3, 0.15])


@pytest.mark.parametrize("convention", ["modified", "standard"])
def test_geometric_jacobian_matches_finite_differences(convention, fd):
    rng = np.random.default_rng(3)
    chain = random_chain(rng, convention)
    for _ in range(5):
        q = rng.uniform(-2, 2, chain.dof)
        J = chain.jacobian(q)
        assert J.shape == (6, chain.dof)
        num = fd(chain.fk, q)
        assert np.abs(J - num).max() < 1e-8, np.abs(J - num).max()


@pytest.mark.parametrize("convention", ["modified", "standard"])
def test_param_jacobian_matches_finite_differences(convention, fd):
    rng = np.random.default_rng(4)
    chain = random_chain(rng, convention, base_params=True, tool_params=True)
    assert chain.n_params == 4 * chain.n_links + 12
    p0 = chain.params
    for _ in range(4):
        q = rng.uniform(-2, 2, chain.dof)
        J = chain.param_jacobian(q)
        assert J.shape == (6, chain.n_params)
        num = fd(lambda p: chain.with_params(p).fk(q), p0)
        assert np.abs(J - num).max() < 1e-8, np.abs(J - num).max()


def test_joint_columns_equal_offset_columns():
    rng = np.random.default_rng(5)
    chain = random_chain(rng, "modified")
    q = rng.uniform(-1, 1, (3, chain.dof))
    idx = [chain.param_names.index(n) for n in chain.joint_offset_names]
    assert np.abs(chain.jacobian(q) - chain.param_jacobian(q)[..., idx]).max() < 1e-15


def test_params_round_trip_and_names():
    rng = np.random.default_rng(6)
    chain = random_chain(rng, "standard", types="RRP", base_params=True)
    assert chain.param_names[:5] == ("alpha_1", "a_1", "theta_1", "d_1", "alpha_2")
    assert chain.param_names[-6:] == ("base_x", "base_y", "base_z", "base_roll", "base_pitch", "base_yaw")
    same = chain.with_params(chain.params)
    q = rng.uniform(-1, 1, (10, 3))
    assert np.abs(same.fk(q) - chain.fk(q)).max() < 1e-14
    p = chain.params.copy()
    p[chain.param_names.index("theta_2")] += 0.1
    moved = chain.with_params(p)
    assert np.abs(moved.fk(q) - chain.fk(q + [0, 0.1, 0])).max() < 1e-14
    with pytest.raises(ShapeError):
        chain.with_params(p[:-1])


@SETTINGS
@given(batch=array_shapes(min_dims=0, max_dims=3, min_side=1, max_side=4), seed=st.integers(0, 2**31))
def test_vectorised_over_batch_shapes(batch, seed):
    rng = np.random.default_rng(seed)
    chain = random_chain(rng, "modified" if seed % 2 else "standard", types="RPR", tool_params=True)
    q = rng.uniform(-2, 2, batch + (chain.dof,))
    T, F, J, P = chain.fk(q), chain.fk_all(q), chain.jacobian(q), chain.param_jacobian(q)
    assert T.shape == batch + (4, 4)
    assert F.shape == batch + (chain.n_links + 1, 4, 4)
    assert J.shape == batch + (6, chain.dof)
    assert P.shape == batch + (6, chain.n_params)
    for idx in np.ndindex(*batch):
        assert np.abs(T[idx] - chain.fk(q[idx])).max() < 1e-14
        assert np.abs(J[idx] - chain.jacobian(q[idx])).max() < 1e-14
        assert np.abs(P[idx] - chain.param_jacobian(q[idx])).max() < 1e-14


@SETTINGS
@given(shape=array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=5))
def test_wrong_q_length_raises_shape_error(shape):
    chain = seed000_chain(0.3, 0.1)
    q = np.zeros(shape)
    if shape[-1] == 2:
        assert chain.fk(q).shape == shape[:-1] + (4, 4)
    else:
        with pytest.raises(ShapeError, match=r"q must have shape \(\.\.\., 2\) \(one value per joint: joint1, joint2\)"):
            chain.fk(q)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_q_raises(bad):
    chain = seed000_chain(0.3, 0.1)
    q = np.zeros((4, 2))
    q[2, 1] = bad
    for method in (chain.fk, chain.fk_all, chain.jacobian, chain.param_jacobian, chain.within_limits):
        with pytest.raises(NonFiniteError, match=r"q contains NaN or infinity \(first at index \(2, 1\)\)"):
            method(q)


def test_bad_construction_raises_named_errors():
    with pytest.raises(ShapeError, match="q must have shape"):
        seed000_chain(0.3, 0.1).fk(0.5)
    with pytest.raises(InputError, match="convention"):
        DHChain.from_table([[0, 0, 0, 0]], convention="craig")
    with pytest.raises(InputError, match="DHLink.joint"):
        DHLink(0, 0, 0, 0, joint="helical")
    with pytest.raises(NonFiniteError, match="DHLink.alpha"):
        DHLink(np.nan, 0, 0, 0)
    with pytest.raises(InputError, match="lower <= upper"):
        DHLink(0, 0, 0, 0, limits=(1.0, -1.0))
    with pytest.raises(ShapeError, match=r"rows must have shape"):
        DHChain.from_table([[0, 0, 0]])
    with pytest.raises(ShapeError, match="joint_types must have 2 entries"):
        DHChain.from_table([[0, 0, 0, 0], [0, 0, 0, 0]], joint_types="R")
    with pytest.raises(InputError, match="T_base"):
        DHChain.from_table([[0, 0, 0, 0]], T_base=2 * np.eye(4))
    with pytest.raises(InputError, match="unique"):
        DHChain([DHLink(0, 0, 0, 0, name="j"), DHLink(0, 0, 0, 0, name="j")])
    with pytest.raises(InputError, match="at least one link"):
        DHChain([])


def test_convention_and_frames_are_keyword_only():
    """STYLE: convention flags are keyword-only, so 'standard' can never land in T_base's slot by position."""
    links = [DHLink(0.3, 0.1, 0.2, 0.05), DHLink(-0.4, 0.2, 0.0, 0.1, joint="prismatic")]
    with pytest.raises(TypeError):
        DHChain(links, "standard")
    with pytest.raises(TypeError):
        DHChain(links, "modified", np.eye(4))
    std = DHChain(links, convention="standard", T_base=transform_from(matrix_from_angle("z", 0.3), [1.0, 0.0, 0.0]))
    mod = DHChain(links, convention="modified")
    assert "standard" in repr(std) and "modified" in repr(DHChain(links))
    q = np.array([0.4, 0.02])
    assert not np.allclose(std.fk(q), mod.fk(q))
    # with_params keeps the convention and the base (it re-calls the constructor by keyword)
    np.testing.assert_allclose(std.with_params(std.params).fk(q), std.fk(q), atol=1e-14)
    with pytest.raises(InputError, match="convention must be 'modified' or 'standard', got 'craig'"):
        DHChain(links, convention="craig")


def test_within_limits():
    chain = DHChain.from_table([[0, 0, 0, 0], [0, 0.1, 0, 0]], limits=[(-1, 1), None])
    q = np.array([[0.5, 9.0], [1.5, 0.0], [-1.0, -9.0]])
    assert chain.within_limits(q).tolist() == [True, False, True]


@pytest.mark.parametrize("convention", ["modified", "standard"])
def test_to_tree_has_the_same_kinematics(convention):
    rng = np.random.default_rng(7)
    chain = random_chain(rng, convention)
    tree = chain.to_tree()
    assert tree.joint_names == chain.joint_names
    assert np.allclose(tree.offsets, chain.joint_offsets)
    q = rng.uniform(-2, 2, (20, chain.dof))
    poses = tree.fk(q)
    assert np.abs(poses["tool"] - chain.fk(q)).max() < 1e-13
    frames = chain.fk_all(q)
    for i in range(chain.n_links + 1):
        assert np.abs(poses[f"link{i}"] - frames[:, i]).max() < 1e-13
    assert np.abs(tree.jacobian(q, "base", "tool") - chain.jacobian(q)).max() < 1e-13


def test_link_transform_is_vectorised_and_checks_its_index():
    chain = seed000_chain(0.3, 0.1)
    q = np.linspace(-1.0, 1.0, 6).reshape(2, 3)
    A = chain.link_transform(1, q)
    assert A.shape == (2, 3, 4, 4)
    assert np.abs(A[1, 2] - chain.link_transform(1, q[1, 2])).max() == 0.0
    for bad in (3, 1.0, "0"):
        with pytest.raises(InputError, match="link index"):
            chain.link_transform(bad, 0.0)
    with pytest.raises(NonFiniteError):
        chain.link_transform(0, np.nan)
