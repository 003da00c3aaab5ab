"""MCT (seed 004 §3), its block-scan fit and its covariance by source, against the truth."""

from dataclasses import replace

import numpy as np
import pytest

from robocal.errors import DegenerateGeometryError, InputError
from robocal.geometry import matrix_from_rotvec
from robocal.handeye import transform_error
from robocal.rigs.lineprofiler.mct import (
    _block_scan_residuals,
    _x_delta,
    block_frame_from_planes,
    fit_block_scan,
    mct_calibrate,
)
from robocal.rigs.lineprofiler.model import LaserTracker, default_rig
from robocal.rigs.lineprofiler.simulate import perturbed_chain, simulate_mct

RIG = default_rig()


def test_mct_is_exact_on_noise_free_data():
    # the block-scan fit relabels points until the labels settle: a single
    # relabelling left edge points on the wrong face (85 urad, 25 um of bias)
    d, tr = simulate_mct(RIG, np.random.default_rng(3), noise=False)
    r = mct_calibrate(d, RIG.chain)
    rot, t = transform_error(r.X, RIG.X)
    assert rot < 1e-9 and t < 1e-9 and r.scan_rms < 1e-9


def test_mct_recovers_X_within_its_standard_deviations():
    d, tr = simulate_mct(RIG, np.random.default_rng(3))
    r = mct_calibrate(d, RIG.chain)
    rot, t = transform_error(r.X, RIG.X)
    assert rot < 1.5e-3 and t < 3e-4  # 0.09 deg, 0.3 mm: the seed quotes 0.07 deg, 0.25 mm spread
    assert transform_error(r.T_T_L, tr.T_T_L)[1] < 2e-4
    assert not [w for w in r.warnings if w.code == "inconsistent_data"]
    assert np.all(np.abs(_x_delta(r.X, RIG.X)) < 4 * r.X_std)
    assert abs(r.tracker_sigma / RIG.tracker.sigma - 1) < 0.3  # pooled from ~80 residual degrees of freedom


def test_mct_covariance_with_encoder_noise_matches_monte_carlo():
    """All sources on, P3's encoder made the largest (50 um per reading against a 2 um tracker),
    24 trials. Per component RMSE / predicted std ~ sqrt(chi2_24 / 24): standard error
    1 / sqrt(2 * 24) = 0.144, so 3 standard errors is 0.57 .. 1.43; mean NEES / 6 has standard
    error sqrt(2 / (6 * 24)) = 0.118. The covariance is taken once (stated sigmas: it changes with
    the noise only through the fits' geometry) so the trials need no propagation."""
    n = 24
    rig = replace(RIG, tracker=LaserTracker(sigma=2e-6))
    rng = np.random.default_rng(7)
    err = []
    for k in range(n):
        d, _ = simulate_mct(rig, rng, n_scan=15, sigma_q3=50e-6)
        r = mct_calibrate(d, rig.chain, tracker_sigma=2e-6, encoder_sigma=50e-6, covariance=k == 0)
        if k == 0:
            C, terms = r.X_cov, r.cov_terms
        err.append(_x_delta(r.X, rig.X))
    err = np.array(err)
    std = np.sqrt(np.diag(C))
    band = 3 / np.sqrt(2 * n)
    ratio = np.sqrt(np.mean(err**2, 0)) / std
    assert np.all(np.abs(ratio - 1) < band), ratio
    nees = np.mean([e @ np.linalg.solve(C, e) for e in err]) / 6
    assert abs(nees - 1) < 3 * np.sqrt(2 / (6 * n)), nees
    # the test has power: without the encoder term the errors are far beyond the prediction
    without = np.sqrt(np.mean(err**2, 0)) / np.sqrt(std**2 - terms["P3 encoder"] ** 2)
    assert without.max() > 1 + 2 * band, without
    assert set(terms) == {"tracker", "heights", "block scan", "P3 encoder"}


def test_block_scan_encoder_sensitivity_matches_refit():
    """``dx_dq3`` (implicit function theorem) against refitting with one P3 reading moved by 0.2 um
    (small: a larger step can move a point across the fit's face/outlier thresholds)."""
    d, _ = simulate_mct(RIG, np.random.default_rng(4), n_scan=9)
    q30 = float(d.q_scan0[-1])
    scan = fit_block_scan(d.scan_profiles, d.scan_q3, q30, d.block_size)
    h = 2e-7
    for i in (0, 4):
        q3 = d.scan_q3.copy()
        q3[i] += h
        moved = fit_block_scan(d.scan_profiles, q3, q30, d.block_size)
        T_pred, u_pred = scan.perturbed(h * scan.dx_dq3[:, i])
        rot, t = transform_error(moved.T_L_B, T_pred)
        rot0, t0 = transform_error(moved.T_L_B, scan.T_L_B)
        assert t0 > 0.1 * h and t < 0.02 * t0 and rot < 0.02 * rot0
        assert np.linalg.norm(moved.u - u_pred) < 0.02 * np.linalg.norm(moved.u - scan.u)


def test_encoder_term_is_reported_by_source_and_defaults_to_5_um():
    d, _ = simulate_mct(RIG, np.random.default_rng(3), n_scan=9)
    r = mct_calibrate(d, RIG.chain)
    assert r.encoder_sigma == 5e-6 and "P3 encoder" in r.cov_terms
    # independent sources: the variances by source add up to the diagonal
    assert np.allclose(sum(v**2 for v in r.cov_terms.values()), np.diag(r.X_cov), rtol=1e-9)
    with pytest.raises(InputError, match="encoder"):
        mct_calibrate(d, RIG.chain, encoder_sigma=-1e-6)


def test_mct_covariance_with_arm_errors_matches_monte_carlo():
    """An arm whose D-H rows are off by 0.3 mm / 0.1 deg (the seed comparison's errors): MCT takes P3's
    row as exact, so X errs by ~0.3 mm, 5x its tracker-only std; stating ``dh_sigma`` makes the
    covariance cover it (mean NEES / 6 = 1; 16 trials: standard error 0.14). Stated sigmas: the
    covariance is taken once."""
    rng = np.random.default_rng(11)
    nees = []
    for k in range(16):
        d, _ = simulate_mct(RIG, rng, n_scan=15, true_chain=perturbed_chain(RIG.chain, rng))
        r = mct_calibrate(d, RIG.chain, tracker_sigma=RIG.tracker.sigma, encoder_sigma=0.0,
                          dh_sigma=(0.3e-3, np.deg2rad(0.1)), covariance=k == 0)
        if k == 0:
            C, terms = r.X_cov, r.cov_terms
        e = _x_delta(r.X, RIG.X)
        nees.append(e @ np.linalg.solve(C, e))
    assert 0.55 < np.mean(nees) / 6 < 1.45
    assert terms["D-H row of P3"][3] > 3 * terms["tracker"][3]  # the arm dominates t_x


def test_block_scan_analytic_jacobian_matches_finite_differences():
    from scipy.optimize._numdiff import approx_derivative

    rng = np.random.default_rng(3)
    mu = rng.normal(size=(40, 3)) * 0.02
    su = rng.uniform(-0.015, 0.015, 40)
    lu = rng.integers(0, 3, 40)
    u0 = np.array([0.0, -1.0, 0.0])
    b1, b2 = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    fun, jac = _block_scan_residuals(mu, su, lu, u0, b1, b2, matrix_from_rotvec([0.4, -0.2, 0.9]))
    x = np.r_[0.02, -0.03, 0.3, -0.5, 0.2, 0.01, -0.02, 0.27]
    assert np.allclose(jac(x), approx_derivative(fun, x, method="3-point"), rtol=1e-6, atol=1e-9)


def test_block_faces_must_be_right_handed():
    d, _ = simulate_mct(RIG, np.random.default_rng(3), noise=False)
    with pytest.raises(InputError, match="left-handed"):
        block_frame_from_planes([d.block_faces_T[1], d.block_faces_T[0], d.block_faces_T[2]])


def test_mct_bad_input():
    d, _ = simulate_mct(RIG, np.random.default_rng(3), noise=False)
    d.q_arc[:, 1] = d.q_arc[0, 1] + np.linspace(0, 1e-3, len(d.q_arc))
    with pytest.raises(DegenerateGeometryError, match="arc spans"):
        mct_calibrate(d, RIG.chain)
    d2, _ = simulate_mct(RIG, np.random.default_rng(3), noise=False)
    d2.arc_T = d2.arc_T[:-1]
    with pytest.raises(InputError, match="counts must match"):
        mct_calibrate(d2, RIG.chain)
