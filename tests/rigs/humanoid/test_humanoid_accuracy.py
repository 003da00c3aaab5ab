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
    assert all(abs(r["error/std"]) < 3.5 for r in rows), rows
    # the detector's sub-pixel corners on blurred, noisy images are far better than 0.3 px
    assert cal.corner_sigma < 0.25
    assert cal.rms_xy.max() < 0.3
    joint = [abs(r["value"] - r["truth"]) for r in rows if not r["parameter"].startswith(("camera", "board"))]
    assert max(joint) < 0.3  # deg, from true offsets of ~0.5 deg
