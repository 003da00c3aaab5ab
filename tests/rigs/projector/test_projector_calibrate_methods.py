"""Extrinsic calibration: the seed's published numbers, the seed's method, Monte Carlo vs Cramér-Rao."""

import math

import numpy as np
import pytest

from robocal.errors import (
    DegenerateGeometryError,
    InconsistentDataError,
    InputError,
    NonFiniteError,
    NotEnoughDataError,
    ShapeError,
    UnitError,
    ImplausibleInputError,
)
from robocal.estimation import fisher_bound, monte_carlo
from robocal.geometry import matrix_from_rotvec, rigid_fit_rotation_crb
from robocal.rigs.projector.calibrate import (
    calibrate,
    closed_form,
    check_correspondences,
    distance_consistency,
    floor_pose_jacobian,
    nonlinear,
    seed_initial_rotation,
    seed_method,
    yaw_of,
)
from robocal.rigs.projector.published import (
    SEED_A_POINTS_0,
    SEED_A_POINTS_W,
    SEED_A_R_INIT,
    SEED_A_R_OPT,
    SEED_A_T,
)
from robocal.rigs.projector.simulate import default_nominal, default_truth, sample_floor_points, simulate_calibration

# The paper lists P1 = world origin first; eq. (12) takes differences to "P3".
REFERENCE_FIRST = [2, 1, 0]


def _truncate4(x):
    return np.trunc(np.asarray(x) * 1e4) / 1e4


# ---------------------------------------------------------------- published
def test_published_points_are_inconsistent_and_point_3_is_named():
    rep = distance_consistency(SEED_A_POINTS_W, SEED_A_POINTS_0)
    rel = {(i, j): r for i, j, _, _, _, r in rep.pairs}
    # |P1P3| is 90 cm in {W} but 79.7 cm in {0}: -11.5 %; |P2P3| -5.9 %; |P1P2| only -0.8 %
    assert rel[(0, 2)] == pytest.approx(-0.1147, abs=5e-4)
    assert rel[(1, 2)] == pytest.approx(-0.0587, abs=5e-4)
    assert rel[(0, 1)] == pytest.approx(-0.0080, abs=5e-4)
    assert not rep.consistent and rep.suspects == [2]
    w = rep.warnings[0]
    assert w.code == "inconsistent_data" and w.indices == (2,) and "11.5 %" in w.message
    with pytest.raises(InconsistentDataError, match=r"suspect point\(s\) \[2\]"):
        calibrate(SEED_A_POINTS_W, points_0=SEED_A_POINTS_0, strict=True)


def test_published_R_reproduced_when_the_world_origin_is_the_reference_point():
    """Why the published R is reproducible, and under which reading of eq. (12).

    The printed R's are our values *truncated* (not rounded) to 4 decimals
    (0.039988 -> 0.0399, 0.041958 -> 0.0419), obtained when eq. (12)'s
    reference point "P3" is the world origin [0 0 0] <-> [240 -90 -290] (the
    point listed first in §3) and "P2" is [60 60 0]. The published t is then
    ^0P - R ^WP at that reference point, exactly [240, -90, -290] cm.
    """
    est = seed_method(SEED_A_POINTS_W, SEED_A_POINTS_0, order=REFERENCE_FIRST)
    R_init = est.extra["R_init"]
    assert np.array_equal(_truncate4(R_init), SEED_A_R_INIT)
    assert np.array_equal(_truncate4(est.R_0_W), SEED_A_R_OPT)
    assert np.abs(est.t_0_W - SEED_A_T).max() < 1e-12
    assert math.degrees(yaw_of(R_init)) == pytest.approx(2.2918, abs=1e-4)
    assert math.degrees(est.yaw) == pytest.approx(2.4047, abs=1e-4)
    # the optimum of cost (14) for two in-plane pairs is the mean of their two angles
    assert est.cost_history[-1] < est.cost_history[0] and np.all(np.diff(est.cost_history) <= 1e-18)


def test_published_R_not_reproducible_in_the_printed_order():
    """Read literally (P3 = [0 90 0] as the reference), eq. (23) gives a 10.2 deg rotation:
    R c = d holds exactly for the inconsistent pair P2-P3, so the published init cannot come out."""
    est = seed_method(SEED_A_POINTS_W, SEED_A_POINTS_0)
    assert math.degrees(yaw_of(est.extra["R_init"])) == pytest.approx(10.24, abs=0.01)
    assert math.degrees(est.yaw) == pytest.approx(6.38, abs=0.01)
    assert np.abs(est.R_0_W - SEED_A_R_OPT).max() > 0.05
    # the optimal closed form over all three points lands elsewhere again (P3 pulls it)
    cf = closed_form(SEED_A_POINTS_W, SEED_A_POINTS_0)
    assert math.degrees(cf.yaw) == pytest.approx(4.19, abs=0.01)
    assert cf.rms > 0.03  # 4.5 cm RMS residual: far above a tape measure's noise


# ---------------------------------------------------------- the seed method
def test_seed_initial_rotation_is_exact_for_consistent_pairs():
    rng = np.random.default_rng(3)
    for _ in range(50):
        R = matrix_from_rotvec(rng.normal(size=3) * 0.8)
        a, c = (v / np.linalg.norm(v) for v in rng.normal(size=(2, 3)))
        assert np.abs(seed_initial_rotation(a, R @ a, c, R @ c) - R).max() < 1e-9


def test_seed_method_recovers_exact_3d_rotation_and_decreases_cost():
    rng = np.random.default_rng(4)
    R = matrix_from_rotvec([0.2, -0.3, 0.5])
    pw = rng.normal(size=(5, 3))
    p0 = pw @ R.T + [1.0, 2.0, -3.0]
    est = seed_method(pw, p0)
    assert np.abs(est.R_0_W - R).max() < 1e-9 and np.abs(est.t_0_W - [1.0, 2.0, -3.0]).max() < 1e-9
    noisy = p0 + rng.normal(0, 0.01, p0.shape)
    est = seed_method(pw, noisy)
    assert est.extra["converged"] and len(est.cost_history) == est.iterations + 1
    assert np.all(np.diff(est.cost_history) <= 1e-15)  # L' < 0 (eq. 27) with the pseudo-inverse step


# ------------------------------------------------------ Monte Carlo vs CRB
@pytest.fixture(scope="module")
def design():
    truth = default_truth().with_(offsets=(0.0, 0.0))
    pts = sample_floor_points(truth, 6, np.random.default_rng(1))
    nominal = truth.with_(R_0_W=np.eye(3), t_0_W=None)
    sigma = 0.005
    p0 = truth.spot(truth.ik_world(pts))
    J = floor_pose_jacobian(p0, float(yaw_of(truth.R_0_W)), truth.t_0_W)
    crb = fisher_bound(J, sigma)
    return truth, nominal, pts, sigma, crb


def _mc(design, estimator, n=300, seed=5):
    truth, nominal, pts, sigma, crb = design

    def sim(rng):
        return simulate_calibration(rng, truth=truth, nominal=nominal, sigma=sigma, points_W=pts), truth

    return monte_carlo(sim, estimator, n, np.random.default_rng(seed),
                       error=lambda e, t: np.atleast_1d(e)[:1] - yaw_of(t.R_0_W), bound=np.sqrt(crb[:1, 0]))


def test_crb_of_the_floor_pose_equals_the_rigid_fit_bound(design):
    truth, _, pts, sigma, crb = design
    p0 = truth.spot(truth.ik_world(pts))
    assert crb[0, 0] == pytest.approx(rigid_fit_rotation_crb(p0, sigma)[2, 2], rel=1e-9)


def test_monte_carlo_closed_form_and_nonlinear_reach_the_crb_seed_method_does_not(design):
    truth, nominal, *_ = design
    cf = _mc(design, lambda sc: np.array([closed_form(sc.points_W, nominal.spot(sc.theta)).yaw]))
    nl = _mc(design, lambda sc: (lambda e: (np.array([e.yaw]), np.array([e.std["yaw"]])))(
        nonlinear(sc.points_W, theta=sc.theta, model=nominal)))
    seed = _mc(design, lambda sc: np.array([seed_method(sc.points_W, nominal.spot(sc.theta)).yaw]))
    assert 0.9 < cf.ratio_to_bound[0] < 1.1, cf.summary()
    assert 0.9 < nl.ratio_to_bound[0] < 1.1, nl.summary()
    # the seed's unit-vector cost weights short baselines like long ones and reuses the
    # reference point's noise in every pair: about 1.5x the bound on this 6-point design
    assert 1.3 < seed.ratio_to_bound[0] < 1.8, seed.summary()
    assert abs(cf.bias[0]) < 4 * cf.bias_se[0]
    # the reported std (residual-scaled covariance) matches the Monte Carlo spread
    assert nl.coverage is not None and nl.coverage.consistent(0.2), nl.summary()


def test_monte_carlo_nonlinear_with_h_and_tilt_offset(design):
    truth = default_truth()
    nominal = default_nominal(truth)
    pts = sample_floor_points(truth, 8, np.random.default_rng(1))
    sigma = 0.005
    th = truth.ik_world(pts)
    ref = nonlinear(pts, theta=th, model=nominal, estimate=("h", "tilt_offset"), sigma=sigma, absolute_sigma=True)
    assert ref.labels == ["yaw", "t_x", "t_y", "h", "tilt_offset"]
    bound = ref.cov[np.ix_([0, 3, 4], [0, 3, 4])]  # the Fisher bound at the truth

    def sim(rng):
        return simulate_calibration(rng, truth=truth, nominal=nominal, sigma=sigma, points_W=pts), truth

    def est(sc):
        e = nonlinear(sc.points_W, theta=sc.theta, model=sc.nominal, estimate=("h", "tilt_offset"))
        return np.array([e.yaw, e.extra["h"], e.extra["offsets"][1]])

    mc = monte_carlo(sim, est, 200, np.random.default_rng(6), bound=bound,
                     error=lambda e, t: e - [yaw_of(t.R_0_W), t.h, t.offsets[1]])
    assert np.all((mc.ratio_to_bound > 0.88) & (mc.ratio_to_bound < 1.12)), mc.summary()
    assert abs(ref.extra["h"] - truth.h) < 1e-9  # noise-free data: exact


def test_pan_offset_is_not_identifiable_and_is_named():
    truth = default_truth()
    pts = sample_floor_points(truth, 8, np.random.default_rng(2))
    e = nonlinear(pts, theta=truth.ik_world(pts), model=default_nominal(truth),
                  estimate=("h", "tilt_offset", "pan_offset"))
    codes = {w.code: w for w in e.warnings}
    assert "rank_deficient" in codes and "pan_offset" in codes["rank_deficient"].params
    assert e.std["pan_offset"] is None and e.std["h"] is not None


# ------------------------------------------------------------- bad inputs
def test_bad_inputs_raise_named_errors():
    pw = np.array([[0, 0], [1, 0], [0, 1], [1, 1.0]])
    p0 = np.column_stack([pw + [2.0, -1.0], np.full(4, -2.9)])
    with pytest.raises(NotEnoughDataError, match="at least 3"):
        calibrate(pw[:2], points_0=p0[:2])
    with pytest.raises(DegenerateGeometryError, match="one line"):
        calibrate([[0, 0], [1, 1], [2, 2.0]], points_0=[[0, 0, -2.9], [1, 1, -2.9], [2, 2, -2.9]])
    dup = pw.copy()
    dup[3] = dup[1]
    with pytest.raises(DegenerateGeometryError, match="points 1 and 3 coincide"):
        calibrate(dup, points_0=p0)
    bad = pw.copy()
    bad[2, 0] = np.nan
    with pytest.raises(NonFiniteError, match="points_W"):
        calibrate(bad, points_0=p0)
    with pytest.raises(ShapeError, match="points_W"):
        calibrate(pw[:, :1], points_0=p0)
    with pytest.raises(ShapeError, match="same number"):
        calibrate(pw[:3], points_0=p0)
    with pytest.raises(ImplausibleInputError, match="looks like cm declared as m") as info:
        calibrate(pw * 100, points_0=np.column_stack([p0[:, :2], p0[:, 2]]))  # cm vs m
    assert info.value.slip == "world_cm_as_m"
    with pytest.raises(UnitError, match="same length unit"):  # the bare check still names the unit mix-up
        check_correspondences(pw * 100, p0)
    with pytest.raises(InputError, match="z must equal"):
        calibrate(pw, points_0=p0 * [1, 1, 0] + [0, 0, -2.9] + np.array([[0, 0, 0.1], [0, 0, 0], [0, 0, 0], [0, 0, 0]]))
    with pytest.raises(InputError, match="methods"):
        calibrate(pw, points_0=p0, methods=("magic",))
    with pytest.raises(InputError, match="needs joint angles"):
        nonlinear(pw, points_0=p0, estimate=("h",))


def test_calibrate_driver_runs_every_method():
    sc = simulate_calibration(np.random.default_rng(7), n_points=8, sigma=0.003)
    run = calibrate(sc.points_W, theta=sc.theta, model=sc.nominal, estimate=("h", "tilt_offset"), sigma=0.003)
    assert set(run.estimates) == {"seed", "closed_form", "nonlinear"} and run.primary == "nonlinear"
    assert run.consistency.consistent
    best = run.best
    err = abs(best.yaw - yaw_of(sc.truth.R_0_W))
    assert err < 4 * best.std["yaw"]
    m = run.calibrated_model()
    assert abs(m.h - sc.truth.h) < 4 * best.std["h"]


def test_truth_check_passes_an_honest_estimate_and_names_the_parameter_of_a_biased_truth():
    """The demo's acceptance check: NEES over the free parameters with the reported covariance (p = 0.001)."""
    from robocal.rigs.projector.workflow import truth_check_of

    sc = simulate_calibration(np.random.default_rng(3), n_points=8, sigma=0.005)
    run = calibrate(sc.points_W, theta=sc.theta, model=sc.nominal, estimate=("h", "tilt_offset"), sigma=sc.sigma)
    ok = truth_check_of(run.best, sc.truth)
    assert ok.passed and ok.dof == 5 and set(ok.z) == {"yaw", "t_x", "t_y", "h", "tilt_offset"}
    # the truth moved by 8 std along x: the check fails (chi-square(5) limit 20.5 < 64) and names t_x
    moved = sc.truth.with_(t_0_W=sc.truth.t_0_W + np.array([8 * run.best.std["t_x"], 0.0, 0.0]))
    bad = truth_check_of(run.best, moved)
    assert not bad.passed and bad.worst[0] == "t_x"
