"""DHChain.fk_all, jacobian and param_jacobian on column arrays (issue 16) against the previous implementation:
(N, 4, 4) stacks of link matrices chained with batched ``@`` and twist columns from ``screw_column``."""

import numpy as np

from robocal.kinematics import DHChain
from robocal.kinematics._common import origin_screws, screw_column, xyz_rpy_from_transform
from dh_reference import stacked_frames
from tests.kinematics.test_dh_fk_fast import random_chain

_EX, _EZ = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])


def stack_fk_all(chain, q):
    """The previous fk_all: T_base @ A_1 @ ... @ A_i as (..., 4, 4) stacks."""
    return np.stack(stacked_frames(chain, q), axis=-3)


def stack_param_jacobian(chain, q, joints_only=False):
    """The previous jacobian / param_jacobian: screw_column on the stacked frames."""
    frames = stack_fk_all(chain, q)
    p = (frames[..., -1, :, :] @ chain.T_tool)[..., :3, 3]
    cols = []
    for i, lk in enumerate(chain.links):
        before, after = frames[..., i, :, :], frames[..., i + 1, :, :]
        fx, fz = (before, after) if chain.convention == "modified" else (after, before)
        screws = [(fx, _EX, True), (fx, _EX, False), (fz, _EZ, True), (fz, _EZ, False)]
        if joints_only:
            screws = [] if lk.joint == "fixed" else [screws[2] if lk.joint == "revolute" else screws[3]]
        cols += [screw_column(G, ax, rev, p) for G, ax, rev in screws]
    if not joints_only:
        if chain._base_params:
            G0 = np.broadcast_to(np.eye(4), frames.shape[:-3] + (4, 4))
            cols += [screw_column(G, a, r, p) for G, a, r in origin_screws(G0, xyz_rpy_from_transform(chain.T_base))]
        if chain._tool_params:
            Gn = frames[..., -1, :, :]
            cols += [screw_column(G, a, r, p) for G, a, r in origin_screws(Gn, xyz_rpy_from_transform(chain.T_tool))]
    return np.stack(cols, axis=-1) if cols else np.zeros(p.shape[:-1] + (6, 0))


def test_frames_and_jacobians_equal_the_stacked_products_on_random_chains():
    rng = np.random.default_rng(161)
    for k in range(60):
        c = random_chain(rng, k)
        chain = DHChain(c.links, convention=c.convention, T_base=c.T_base, T_tool=c.T_tool,
                        base_params=k % 2 == 0, tool_params=k % 3 == 0)
        shape = [(), (5,), (2, 3)][k % 3]
        q = rng.uniform(-3, 3, shape + (chain.dof,))
        F = chain.fk_all(q)
        assert F.shape == shape + (chain.n_links + 1, 4, 4)
        # <= 7 links of unit rotations and translations <= ~2 m (random_chain): a few ulps per product;
        # 1e-13 is ~500 ulps of 1, and the twists (lever arms <= ~10 m) get 1e-12
        assert np.abs(F - stack_fk_all(chain, q)).max() < 1e-13, k
        assert np.array_equal(F[..., 3, :], np.broadcast_to([0.0, 0.0, 0.0, 1.0], F.shape[:-1]))
        assert np.abs(F[..., -1, :, :] @ chain.T_tool - chain.fk(q)).max() < 1e-13
        J, P = chain.jacobian(q), chain.param_jacobian(q)
        assert J.shape == shape + (6, chain.dof) and P.shape == shape + (6, chain.n_params)
        assert np.abs(J - stack_param_jacobian(chain, q, joints_only=True)).max(initial=0.0) < 1e-12, k
        assert np.abs(P - stack_param_jacobian(chain, q)).max() < 1e-12, k
