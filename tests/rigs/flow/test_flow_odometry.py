"""Multi-sensor odometry: the seed's A u = b (eqs. 6-12), robust fusion, covariance."""

import numpy as np
import pytest

from robocal.errors import DegenerateGeometryError, InputError, NotEnoughDataError
from robocal.rigs.flow.model import SensorArray, integrate_twists, relative_twists, rot2, se2_exp, se2_log, seed_array
from robocal.rigs.flow.odometry import SensorSteps, dead_reckon, fuse_steps


def _drive(K=400, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(K + 1) / 400.0
    v = 0.4 + 0.1 * np.sin(np.arange(K) / 50)
    w = 0.8 * np.sin(np.arange(K) / 80)
    tw = np.stack([v / 400, 0.02 * np.cos(np.arange(K) / 30) / 400, w / 400], 1)
    return t, integrate_twists(tw), rng


def _exact_disp(array: SensorArray, poses):
    """Sensor displacements (sensor frame at the end of each step) of the true motion, divided by scale."""
    out = np.empty((array.n, len(poses) - 1, 2))
    for i in range(array.n):
        r = np.array([array.R[i] * np.cos(array.psi[i]), array.R[i] * np.sin(array.psi[i])])
        p = poses[:, :2] + np.einsum("kab,b->ka", rot2(poses[:, 2]), r)
        end = poses[1:, 2]
        out[i] = np.einsum("kba,kb->ka", rot2(end + array.phi[i]), np.diff(p, axis=0)) / array.scale[i]
    return out


def _steps(t, disp, sigma=1e-5):
    n, K, _ = disp.shape
    return SensorSteps(t, disp, np.ones((n, K), bool), np.full((n, K), sigma), np.full((n, K), 255.0))


def test_se2_exp_log_roundtrip():
    u = np.array([[0.01, -0.003, 0.2], [0.0, 0.0, 0.0], [0.02, 0.01, -1e-12]])
    assert np.allclose(se2_log(se2_exp(u)), u)


def test_seed_world_form_equals_robot_frame_solution():
    # eq. 9 written in the world frame with A(theta) and b = R(theta + phi) dS gives the same
    # increment as solving in the robot frame and rotating by theta
    arr = seed_array().copy(phi=np.radians([5.0, -3.0, 10.0]))
    theta = 0.7
    u_body = np.array([0.001, 0.0002, 0.003])
    A0 = arr.design_matrix(0.0)
    b_body = A0 @ u_body
    dS = np.stack([rot2(-arr.phi[i]) @ b_body[2 * i:2 * i + 2] for i in range(3)])
    A = arr.design_matrix(theta)
    b = np.concatenate([rot2(theta + arr.phi[i]) @ dS[i] for i in range(3)])
    u_world = np.linalg.lstsq(A, b, rcond=None)[0]
    assert np.allclose(u_world[:2], rot2(theta) @ u_body[:2])
    assert np.isclose(u_world[2], u_body[2])


def test_exact_displacements_give_exact_trajectory():
    t, poses, _ = _drive()
    arr = seed_array().copy(phi=np.radians([5.0, -3.0, 10.0]), scale=np.array([1.0, 1.05, 0.97]))
    od = dead_reckon(_steps(t, _exact_disp(arr, poses)), arr)
    assert np.abs(od.poses - poses).max() < 1e-9
    # the seed's first-order eq. 12 drifts a little on curves
    eu = dead_reckon(_steps(t, _exact_disp(arr, poses)), arr, method="euler")
    assert 1e-7 < np.abs(eu.poses - poses).max() < 1e-3


def test_two_sensors_suffice_one_does_not():
    t, poses, _ = _drive()
    two = SensorArray([0.35, 0.35], np.radians([60.0, 270.0]), [0.0, 0.0], [1.0, 1.0], ["a", "b"])
    od = dead_reckon(_steps(t, _exact_disp(two, poses)), two)
    assert np.abs(od.poses - poses).max() < 1e-9
    # 4 equations for 3 unknowns: one redundant equation, chi-square with 1 dof (zero here)
    assert np.all(od.chi2 < 1e-12)
    with pytest.raises(NotEnoughDataError, match="at least 2 sensors"):
        SensorArray([0.35], [0.0], [0.0], [1.0], ["only"])


def test_outlier_sensor_is_rejected_not_averaged():
    t, poses, rng = _drive()
    arr = seed_array()
    disp = _exact_disp(arr, poses)
    sig = 2e-6
    disp += rng.normal(0, sig, disp.shape)
    bad = slice(100, 140)
    disp[1, bad] += 3e-4  # sensor s120 over a patch that fools it
    st = _steps(t, disp, sigma=sig)
    robust = dead_reckon(st, arr)
    naive = dead_reckon(st, arr, robust=False)
    assert robust.rejected[1, bad].mean() > 0.95
    assert robust.rejected[[0, 2]].sum() == 0
    assert robust.rejected[1].sum() <= 40 + 2
    err_r = np.abs(robust.poses - poses)[:, :2].max()
    err_n = np.abs(naive.poses - poses)[:, :2].max()
    assert err_r < err_n / 10
    assert any(w.code == "outliers" and "s120" in w.message for w in robust.warnings)


def test_invalid_steps_and_bridging():
    t, poses, _ = _drive(K=100)
    arr = seed_array()
    disp = _exact_disp(arr, poses)
    st = _steps(t, disp)
    st.valid[0, 40:50] = False   # one sensor missing: still solvable from two
    st.valid[1, 60:62] = False
    st.valid[2, 60:62] = False   # only one valid sensor there: bridged
    od = dead_reckon(st, arr)
    assert np.array_equal(np.flatnonzero(od.bridged), [60, 61])
    assert np.allclose(od.twists[60], od.twists[59])
    assert not od.used[0, 40:50].any()
    assert any(w.code == "low_quality" for w in od.warnings)


def test_velocity_covariance_matches_monte_carlo():
    t, poses, rng = _drive(K=50)
    arr = seed_array()
    exact = _exact_disp(arr, poses)
    sig = 5e-6
    runs = []
    for _ in range(300):
        st = _steps(t, exact + rng.normal(0, sig, exact.shape), sigma=sig)
        u, cov, *_ = fuse_steps(st, arr, robust=False)
        runs.append(u[10])
    emp = np.cov(np.array(runs).T)
    st = _steps(t, exact, sigma=sig)
    _, cov, *_ = fuse_steps(st, arr, robust=False)
    ratio = np.diag(emp) / np.diag(cov[10])
    assert np.all((ratio > 0.75) & (ratio < 1.3)), ratio


def test_bad_inputs():
    t, poses, _ = _drive(K=20)
    arr = seed_array()
    disp = _exact_disp(arr, poses)
    t_bad = t.copy()
    t_bad[5] = t_bad[4]
    with pytest.raises(InputError, match=r"increase strictly: t\[5\]"):
        _steps(t_bad, disp)
    with pytest.raises(InputError, match="2 sensors but the array describes 3"):
        dead_reckon(_steps(t, disp[:2]), arr)
    st = _steps(t, disp)
    st.valid[:] = False
    with pytest.raises(NotEnoughDataError, match="no interval"):
        dead_reckon(st, arr)
    with pytest.raises(InputError, match="scale"):
        SensorArray([0.35, 0.35], [0, 1], [0, 0], [1.0, -1.0], None)


def test_relative_twists_inverts_integration():
    t, poses, _ = _drive(K=60)
    assert np.allclose(integrate_twists(relative_twists(poses)), poses)


from hypothesis import given, settings, strategies as st  # noqa: E402


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-0.01, 0.01), st.floats(-0.01, 0.01), st.floats(-0.5, 0.5)), min_size=1, max_size=20))
def test_property_twists_roundtrip(tw):
    tw = np.array(tw)
    assert np.allclose(se2_log(se2_exp(tw)), tw, atol=1e-12)
    poses = integrate_twists(tw, (0.3, -0.2, 2.9))
    assert np.allclose(relative_twists(poses), tw, atol=1e-10)


@settings(max_examples=30, deadline=None)
@given(st.floats(0.05, 1.0), st.floats(-np.pi, np.pi), st.floats(-0.3, 0.3), st.floats(0.8, 1.2))
def test_property_exact_fusion_for_any_placement(R, psi, phi, scale):
    t, poses, _ = _drive(K=60)
    arr = SensorArray([R, 0.35, 0.2], [psi, 2.0, -2.0], [phi, 0.1, -0.2], [scale, 1.0, 1.1], None)
    od = dead_reckon(_steps(t, _exact_disp(arr, poses)), arr)
    assert np.abs(od.poses - poses).max() < 1e-9


def test_degenerate_array_is_rejected():
    # every sensor at the centre (all R = 0), or all at one point: A of eq. 9 has rank 2
    with pytest.raises(DegenerateGeometryError, match="one point.*rank < 3"):
        SensorArray([0.0, 0.0, 0.0], [0.0, 1.0, 2.0], [0.0] * 3, [1.0] * 3, None)
    with pytest.raises(DegenerateGeometryError, match="rank < 3"):
        SensorArray([0.35, 0.35], [1.0, 1.0], [0.0, 0.3], [1.0, 1.0], None)
    SensorArray([0.0, 0.35], [0.0, 1.0], [0.0, 0.0], [1.0, 1.0], None)  # two distinct points suffice


def test_singular_step_is_bridged_never_nan():
    # two of three sensors at one point: a step with only those two valid cannot see the
    # rotation; it must be bridged (velocity held) rather than give NaN
    t, poses, _ = _drive(K=100)
    arr = SensorArray([0.35, 0.35, 0.35], [1.0, 1.0, -1.5], [0.0, 0.2, 0.0], [1.0, 1.0, 1.0], None)
    st = _steps(t, _exact_disp(arr, poses))
    st.valid[2, 50:53] = False
    with np.errstate(all="raise"):
        od = dead_reckon(st, arr)
    assert np.all(np.isfinite(od.poses))
    assert np.array_equal(np.flatnonzero(od.bridged), [50, 51, 52])
    assert np.abs(od.poses - poses).max() < 1e-3


def test_bridged_interval_holds_velocity_over_its_own_length():
    # a longer interval (a dropped record) is bridged at the previous velocity, not its displacement
    t, poses, _ = _drive(K=100)
    arr = seed_array()
    keep = np.r_[0:50, 60:101]
    t2, p2 = t[keep], poses[keep]
    st = _steps(t2, _exact_disp(arr, p2))
    st.valid[:, 49] = False          # the 10-frame interval t[49] -> t[60]
    od = dead_reckon(st, arr)
    assert od.bridged[49] and np.allclose(od.twists[49], 11 * od.twists[48])


def test_understated_flow_noise_is_flagged():
    # flow errors 4x the stated sigma: the median chi-square ratio says so (about 16 vs 1)
    t, poses, rng = _drive(K=400)
    arr = seed_array()
    d = _exact_disp(arr, poses)
    sig = 1e-5
    ok = dead_reckon(_steps(t, d + rng.normal(0, sig, d.shape), sigma=sig), arr)
    assert 0.5 < ok.chi2_ratio < 2 and not any(w.code == "inconsistent_data" for w in ok.warnings)
    bad = dead_reckon(_steps(t, d + rng.normal(0, 4 * sig, d.shape), sigma=sig), arr)
    assert bad.chi2_ratio > 8 and any(w.code == "inconsistent_data" and "sigma_px" in w.message for w in bad.warnings)


def test_flow_sigma_follows_the_kernel_mode():
    # the fusion weights come from the kernel's own accuracy, not a fixed 0.06 px
    from robocal.rigs.flow.kernel import SIGMA_PX, FlowConfig
    from robocal.rigs.flow.log import FlowRecords, steps_from_records

    assert FlowConfig().sigma_px == 0.06
    assert FlowConfig(subpixel="half").sigma_px == SIGMA_PX["half"] == 0.16
    assert FlowConfig(subpixel="none").sigma_px == 0.32 and FlowConfig(refine="lk").sigma_px == 0.03
    n, K = 3, 5
    rec = FlowRecords(np.arange(K + 1) / 400.0, np.zeros((n, K, 2)), np.zeros((n, K, 3)), np.full((n, K), 0.1),
                      np.full((n, K), 255.0), np.ones((n, K), bool))
    s_eq = steps_from_records(rec, 166.7).sigma
    assert np.allclose(steps_from_records(rec, 166.7, FlowConfig(subpixel="half")).sigma, s_eq * 0.16 / 0.06)
    assert np.allclose(steps_from_records(rec, 166.7, sigma_px=0.2).sigma, s_eq * 0.2 / 0.06)


@pytest.mark.parametrize("method", ["exact", "euler"])
def test_final_pose_covariance_matches_monte_carlo(method):
    # first-order propagation of independent twist errors against 4000 integrated noisy paths of an
    # arc (400 steps, 0.9 rad of turn): a sample variance of 4000 draws scatters by 2.2 % (1 sigma)
    # and a sample correlation by <= 0.016, so 10 % and 0.06 are > 4 sigma; the first-order error
    # at 1 mm / 1 mrad per step is far below both
    from robocal.rigs.flow.model import integrate_twists
    from robocal.rigs.flow.odometry import final_pose_covariance

    rng = np.random.default_rng(5)
    K = 400
    u = np.tile([0.002, 0.0002, 0.00225], (K, 1))
    L = np.array([[1e-3, 0, 0], [2e-4, 5e-4, 0], [0, 0, 1e-3]])
    C = np.broadcast_to(L @ L.T, (K, 3, 3))
    poses = integrate_twists(u, method=method)
    pred = final_pose_covariance(poses, u, C, method=method)
    ends = np.array([integrate_twists(u + rng.standard_normal((K, 3)) @ L.T, method=method)[-1] for _ in range(4000)])
    emp = np.cov(ends.T)
    assert np.allclose(np.diag(emp), np.diag(pred), rtol=0.1), (np.diag(emp), np.diag(pred))
    # the correlations with the heading carry the lever of each step's rotation about its end point
    for a, b in ((0, 1), (0, 2), (1, 2)):
        corr = pred[a, b] / np.sqrt(pred[a, a] * pred[b, b])
        assert abs(emp[a, b] / np.sqrt(emp[a, a] * emp[b, b]) - corr) < 0.06, (a, b)
    # a bridged step has no covariance: the final pose's is not claimed
    C2 = np.array(C)
    C2[10] = np.nan
    assert np.all(np.isnan(final_pose_covariance(poses, u, C2, method=method)))
