"""The hand-eye refinements' analytic Jacobians (issue 16): against finite differences, and the same answer as
the finite-difference path they replaced; the NumPy log map against SciPy's."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocal.geometry import invert_transform, matrix_from_rotvec, transform_from
from robocal.handeye import calibrate_hand_eye, calibrate_robot_world, simulate_eye_in_hand
from robocal.handeye._lie import exp_so3, left_jacobian, left_jacobian_inverse, log_so3
from robocal.handeye.axzb import _refine_robot_world, _rw_residual
from robocal.handeye.motions import _rms, _sigmas
from robocal.handeye.refine import _closure, _perturb, _refine_closure

# Central differences (Problem.check_jacobian, step ~eps^(1/3) ~ 6e-6 relative) are exact to ~eps^(2/3) ~ 4e-11
# relative to a column's scale (truncation h^2 and rounding eps/h alike; 3e-11..7e-11 observed). 1e-7 leaves
# three orders for the curvature of the columns; a missing term (e.g. J_l(w) at the 0.1-0.3 rad test point, or
# a sign) is off by 1e-2..1.
JAC_RTOL = 1e-7
# Points away from the start, so that J_l(w_X), J_l(w_Y) and J_l(e)^-1 all differ from I.
FAR = {"X": np.r_[0.1, -0.2, 0.3, 0.01, 0.02, 0.03], "Y": np.r_[-0.3, 0.2, 0.1, 0.5, 0.1, 0.2]}


@pytest.fixture(scope="module")
def eye_in_hand():
    sim = simulate_eye_in_hand(np.random.default_rng(0), 15)
    closed = calibrate_hand_eye(sim.T_base_gripper, sim.T_cam_target, refine=False)
    _, r0 = _closure(sim.T_base_gripper, sim.T_cam_target, closed.X, closed.Y)
    # per-pose weights as pose_sigmas gives them: the Jacobian must carry them
    w = np.random.default_rng(1).uniform(0.5, 2.0, (len(r0), 6))
    return sim, closed, w, _sigmas(*_rms(r0))


@pytest.fixture(scope="module")
def robot_world():
    rng = np.random.default_rng(5)
    X = transform_from(matrix_from_rotvec(rng.normal(size=3)), rng.normal(size=3) * 0.5)
    Z = transform_from(matrix_from_rotvec(rng.normal(size=3)), rng.normal(size=3) * 0.5)
    TB = invert_transform(transform_from(matrix_from_rotvec(rng.normal(size=(15, 3))), rng.normal(size=(15, 3)) * 0.5))
    TA = Z @ TB @ invert_transform(X)
    TA = transform_from(matrix_from_rotvec(rng.normal(size=(15, 3)) * 1e-3) @ TA[:, :3, :3],
                        TA[:, :3, 3] + rng.normal(size=(15, 3)) * 1e-3)
    closed = calibrate_robot_world(TA, TB, refine=False)
    return TA, TB, closed, _sigmas(*_rms(_rw_residual(TA, TB, closed.X, closed.Z)))


def test_log_map_matches_scipy_everywhere_including_half_turns():
    rng = np.random.default_rng(2)
    ang = np.r_[np.linspace(0, np.pi, 300), np.pi - np.logspace(-12, -1, 100), np.logspace(-14, -1, 100)]
    axes = rng.normal(size=(len(ang), 3))
    v = axes / np.linalg.norm(axes, axis=1, keepdims=True) * ang[:, None]
    R = np.concatenate([Rotation.from_rotvec(v).as_matrix(), Rotation.random(500, random_state=3).as_matrix()])
    ours = log_so3(R)
    # SciPy's representative at exactly pi may be the opposite vector: compare the rotations there
    assert np.abs(Rotation.from_rotvec(ours).as_matrix() - R).max() < 1e-14
    off_pi = np.linalg.norm(ours, axis=1) < np.pi - 1e-6
    assert np.abs(ours - Rotation.from_matrix(R).as_rotvec())[off_pi].max() < 1e-14
    assert np.linalg.norm(ours, axis=1).max() <= np.pi + 1e-15
    assert np.abs(exp_so3(v) - Rotation.from_rotvec(v).as_matrix()).max() < 1e-15


def test_left_jacobian_and_its_inverse():
    u = np.random.default_rng(4).normal(size=(50, 3))
    w = u / np.linalg.norm(u, axis=1, keepdims=True) * np.logspace(-8, np.log10(3.0), 50)[:, None]   # 1e-8..3 rad
    J, Ji = left_jacobian(w), left_jacobian_inverse(w)
    assert np.abs(J @ Ji - np.eye(3)).max() < 1e-13
    # exp(w + d) = exp(J_l(w) d) exp(w) to first order: central difference with h = 1e-6 (error ~h^2)
    h = 1e-6
    for k in range(3):
        d = np.zeros(3)
        d[k] = h
        for wi, Ji_ in zip(w[::7], J[::7]):
            fd = log_so3((exp_so3(wi + d) - exp_so3(wi - d)) @ exp_so3(wi).T / 2 + np.eye(3))
            assert np.allclose(fd, Ji_[:, k] * h, atol=1e-16 + 1e-10 * h)


def test_eye_in_hand_jacobian_matches_finite_differences(eye_in_hand):
    sim, closed, w, (sr, st) = eye_in_hand
    prob, _ = _refine_closure(sim.T_base_gripper, sim.T_cam_target, closed.X, closed.Y, w, sr, st)
    for p in (None, FAR):
        chk = prob.check_jacobian(p)
        assert chk.max_rel_error < JAC_RTOL, chk


def test_robot_world_jacobian_matches_finite_differences(robot_world):
    TA, TB, closed, (sr, st) = robot_world
    prob, _ = _refine_robot_world(TA, TB, closed.X, closed.Z, sr, st)
    for p in (None, {"X": FAR["X"], "Z": FAR["Y"]}):
        chk = prob.check_jacobian(p)
        assert chk.max_rel_error < JAC_RTOL, chk


def _same_solution(a, b):
    # Both paths stop at xtol = 1e-8 relative to |x| <= ~1 (rad, m) and share the minimum (a 2-point Jacobian's
    # 1.5e-8 relative error moves the fixed point by ~1e-8 x the residual): 1e-7 absolute is the solver's
    # tolerance with margin, ~1e-3 of the reported std here. The covariance inherits the 2-point Jacobian's
    # relative error (~1e-8) times the conditioning (~1e2): 1e-4 relative.
    assert np.abs(a.x - b.x).max() < 1e-7
    assert np.allclose(a.cov, b.cov, rtol=1e-4, atol=0)
    assert np.isclose(a.cost, b.cost, rtol=1e-8)


def test_eye_in_hand_refinement_unchanged_by_the_analytic_jacobian(eye_in_hand):
    sim, closed, w, (sr, st) = eye_in_hand
    args = (sim.T_base_gripper, sim.T_cam_target, closed.X, closed.Y, w, sr, st)
    _, analytic = _refine_closure(*args)
    _, numeric = _refine_closure(*args, jac="2-point")
    assert analytic.jac_method == "analytic" and numeric.jac_method == "2-point"
    _same_solution(analytic, numeric)
    # the warm start: the closed form is close, so LM converges in a few steps
    assert analytic.iterations <= 4 and analytic.success


def test_robot_world_refinement_unchanged_by_the_analytic_jacobian(robot_world):
    TA, TB, closed, (sr, st) = robot_world
    _, analytic = _refine_robot_world(TA, TB, closed.X, closed.Z, sr, st)
    _, numeric = _refine_robot_world(TA, TB, closed.X, closed.Z, sr, st, jac="2-point")
    _same_solution(analytic, numeric)
    res = calibrate_robot_world(TA, TB)
    assert np.allclose(res.cov, analytic.cov, rtol=1e-12, atol=0)


def test_robot_world_refinement_beats_shah_with_an_honest_covariance():
    """A X = Z B refined on the camera's own pose error (issue 13's peers bench: the earlier form t(AX) - t(ZB)
    carried the camera's rotation error into the translation residual, ended above Shah's closed form and was
    overconfident, NEES / 12 = 1.27 over 200 sets)."""
    from robocal.geometry import rotvec_from_matrix

    def err(T, T_true):
        return np.r_[rotvec_from_matrix(T[:3, :3] @ T_true[:3, :3].T), T[:3, 3] - T_true[:3, 3]]

    t_shah, t_ref, nees = [], [], []
    for s in range(40):
        sim = simulate_eye_in_hand(np.random.default_rng(s), 15)
        TA, TB = sim.T_cam_target, invert_transform(sim.T_base_gripper)
        Xt, Zt = invert_transform(sim.Y), invert_transform(sim.X)       # T_target_base, T_cam_gripper
        shah = calibrate_robot_world(TA, TB, refine=False)
        # calibrate_robot_world's refinement (test_robot_world_refinement_unchanged_...), without a second
        # closed form and plausibility check per set
        _, lsq = _refine_robot_world(TA, TB, shah.X, shah.Z, *_sigmas(*_rms(_rw_residual(TA, TB, shah.X, shah.Z))))
        X, Z = _perturb(shah.X, lsq.params["X"]), _perturb(shah.Z, lsq.params["Z"])
        t_shah.append([np.linalg.norm(err(shah.X, Xt)[3:]), np.linalg.norm(err(shah.Z, Zt)[3:])])
        t_ref.append([np.linalg.norm(err(X, Xt)[3:]), np.linalg.norm(err(Z, Zt)[3:])])
        e = np.r_[err(X, Xt), err(Z, Zt)]
        nees.append(e @ np.linalg.solve(lsq.cov, e))
    # 200 sets: translation errors 0.77 (X) and 0.65 (Z) of Shah's (earlier form 1.04, 1.01); 40 sets keep a
    # wide margin below 1
    assert np.all(np.mean(t_ref, axis=0) < 0.9 * np.mean(t_shah, axis=0)), (np.mean(t_ref, 0), np.mean(t_shah, 0))
    # NEES / 12 averages 40 chi2(12) / 12 draws: std sqrt(2 / 12 / 40) = 0.065; 0.8-1.2 is ~3 std (1.02 over 200
    # sets, the earlier form 1.27)
    assert 0.8 < np.mean(nees) / 12 < 1.2, np.mean(nees) / 12
