"""The jackknife std of X beside the first-order one (issue 13): the two agree on simulated data, where the
noise model holds, within the jackknife's own sampling error; the result and the report carry it."""

import numpy as np

from robocal.handeye import calibrate_hand_eye, simulate_eye_in_hand
from robocal.handeye.jackknife import jackknife_hand_eye


def _ratios(rng, n):
    s = simulate_eye_in_hand(rng, n)
    res = calibrate_hand_eye(s.T_base_gripper, s.T_cam_target)
    jk = jackknife_hand_eye(s.T_base_gripper, s.T_cam_target, res.X, res.Y)
    return jk, jk.std / np.sqrt(np.diag(res.cov))


def test_delete_one_agrees_with_the_first_order_std():
    rng = np.random.default_rng(0)
    r = []
    for _ in range(8):
        jk, ratio = _ratios(rng, 30)
        r.append(ratio)
    assert jk.kind == "delete-one" and jk.replicates == 30 and jk.group_size == 1
    r = np.array(r)
    # one component's ratio scatters by 0.1-0.2 from set to set (20 sets of 30 poses: sd 0.11-0.21, mean
    # 1.00-1.06); the mean of 6 x 8 by sd(per-set mean) / sqrt(8) = 0.06 / 2.8 = 0.02: within 1 +/- 0.1 is
    # 5 of its sigma, and each component's mean over 8 sets within 1 +/- 0.35 (4.5 sigma of 0.075)
    assert abs(r.mean() - 1) < 0.1, r.mean(axis=0)
    assert np.all(np.abs(r.mean(axis=0) - 1) < 0.35), r.mean(axis=0)


def test_delete_a_group_beyond_100_poses():
    jk, ratio = _ratios(np.random.default_rng(1), 300)
    assert jk.kind == "delete-a-group" and jk.replicates == 50 and jk.group_size == 6
    # 50 groups: the std's relative sampling error is ~1 / sqrt(2 x 49) = 10 % per component, the mean of 6
    # components' ratios scatters by 0.017 (3 sets: mean 0.96): within 1 +/- 0.15
    assert abs(ratio.mean() - 1) < 0.15 and np.all((ratio > 0.6) & (ratio < 1.5)), ratio


def test_two_gauss_newton_steps_match_a_full_re_solve():
    # each delete-one replicate solved to convergence (scipy LM, 1e-14 tolerances) with the jackknife's own
    # residuals and weights: the std agrees to 0.1 % (measured 0.9994-1.0008); 1 % leaves room for the
    # finite-difference Jacobian's rounding, far below the jackknife's sampling error
    from scipy.optimize import least_squares

    from robocal.handeye import jackknife as J

    s = simulate_eye_in_hand(np.random.default_rng(0), 20)
    G, Tc = s.T_base_gripper, s.T_cam_target
    res = calibrate_hand_eye(G, Tc)
    jk = J.jackknife_hand_eye(G, Tc, res.X, res.Y)
    r = J._residuals(G, Tc, res.X, res.Y, np.zeros((1, 12)), np.broadcast_to(np.eye(6), (1, 20, 6, 6)))[0]
    sig = np.r_[[np.sqrt(np.mean(r[:, :3] ** 2))] * 3, [np.sqrt(np.mean(r[:, 3:] ** 2))] * 3]
    W = np.broadcast_to(np.diag(1 / sig), (20, 6, 6))
    th = []
    for k in range(20):
        m = np.arange(20) != k
        th.append(least_squares(lambda d: J._residuals(G[m], Tc[m], res.X, res.Y, d[None], W[m][None])[0].ravel(),
                                np.zeros(12), method="lm", xtol=1e-14, ftol=1e-14).x[:6])
    th = np.array(th)
    exact = np.sqrt(19 / 20 * np.sum((th - th.mean(axis=0)) ** 2, axis=0))
    assert np.allclose(jk.std, exact, rtol=0.01), jk.std / exact
