"""Accuracy: Monte Carlo against the reported uncertainty, and the whole pipeline from pixels."""

import numpy as np

from robocal.rigs.humanoid.calibrate import calibrate
from robocal.rigs.humanoid.montecarlo import calibration_monte_carlo
from robocal.rigs.humanoid.simulate import simulate_dataset


def test_monte_carlo_coverage_and_spread(model):
    # 0.3 px corner noise, joint readings quantised to 0.1 deg, offsets ~0.5 deg, 5 views per foot.
    # 120 trials: the spread ratio has a standard error of 6.5 %, so +-20 % is a 3-sigma band.
    mc = calibration_monte_carlo(model, 120, np.random.default_rng(2026), n_per_foot=5)
    assert mc.n_failed == 0
    cov = mc.coverage
    assert len(mc.labels) == 21
    # every identifiable offset within 3 sigma of its truth in >= 95 % of the trials
    assert np.all(cov.fraction_within >= 0.95), dict(zip(mc.labels, cov.fraction_within))
    # the reported standard deviations match the Monte Carlo spread within 20 %
    assert np.all(np.abs(cov.spread_ratio - 1.0) <= 0.2), dict(zip(mc.labels, cov.spread_ratio.round(3)))
    # and the estimator is unbiased at the level the trials can resolve
    assert np.all(np.abs(mc.bias) < 4 * mc.bias_se)


def test_quantisation_ignored_makes_the_stds_too_small(model):
    # The same data calibrated as if the joint readings were exact: the stds no longer cover the
    # error (this is what the joint-noise term in the weighting is for).
    rng = np.random.default_rng(5)
    z_model, z_naive = [], []
    for _ in range(6):
        data = simulate_dataset(model, rng, n_per_foot=10)
        for res, out in ((np.radians(0.1), z_model), (0.0, z_naive)):
            cal = calibrate(model, data, joint_resolution=res, corner_sigma=0.3)
            out += [r["error/std"] for r in cal.parameter_rows(data.truth.params)]
    assert np.std(z_naive) > 1.5 * np.std(z_model)
    assert 0.7 < np.std(z_model) < 1.3


def test_end_to_end_from_rendered_images(model):
    rng = np.random.default_rng(17)
    data = simulate_dataset(model, rng, n_per_foot=5, render=True)
    assert data.images and all(img.shape == (480, 640) for img in data.images)
    assert np.all(np.isfinite(data.corners)), data.messages
    cal = calibrate(model, data)
    rows = cal.parameter_rows(data.truth.params)
    # the errors against the reported covariance, one chi-square test over all 21 (NEES, p = 0.001)
    check = cal.truth_check(data.truth.params)
    assert check.passed and check.dof == 21, str(check)
    # the detector's sub-pixel corners on blurred, noisy images are far better than 0.3 px
    assert cal.corner_sigma < 0.25
    assert cal.rms_xy.max() < 0.3
    joint = [abs(r["value"] - r["truth"]) for r in rows if not r["parameter"].startswith(("camera", "board"))]
    assert max(joint) < 0.3  # deg, from true offsets of ~0.5 deg


def test_calibrated_board_poses_agree_with_opencv_pnp(model):
    # Independent check: OpenCV's PnP on each view's detected corners vs the board pose the
    # calibrated kinematic chain predicts; also the nominal (uncalibrated) chain, which must be worse.
    from robocal.camera import solve_pnp
    from robocal.rigs.humanoid.model import FEET

    rng = np.random.default_rng(23)
    data = simulate_dataset(model, rng, n_per_foot=4, render=True)
    cal = calibrate(model, data)
    n = len(model.joint_names)

    def angle(Ta, Tb):
        c = (np.trace(Ta[:3, :3].T @ Tb[:3, :3]) - 1) / 2
        return np.degrees(np.arccos(np.clip(c, -1, 1)))

    cal_err, nominal_err = [], []
    for v, foot in enumerate(cal.data.feet):
        T_pnp = solve_pnp(model.camera, model.object_points, cal.data.corners[v]).T_cam_obj
        fi = FEET.index(foot)
        p = cal.params
        T_cal = model.T_opt_board(cal.data.theta[v][None] + p[:n], foot, p[n:n + 5], p[n + 5 + 3 * fi:n + 8 + 3 * fi])[0]
        T_nom = model.T_opt_board(cal.data.theta[v][None], foot)[0]
        cal_err.append(angle(T_pnp, T_cal))
        nominal_err.append(angle(T_pnp, T_nom))
    assert np.median(cal_err) < 0.25, cal_err
    assert np.median(nominal_err) > 2 * np.median(cal_err), (nominal_err, cal_err)
