"""The predicted spot-error map (evaluate.predicted_error_map) against Monte Carlo, off the reachable floor and for a rank-deficient fit."""

import numpy as np

from robocal.rigs.projector.calibrate import calibrate
from robocal.rigs.projector.evaluate import estimate_covariance, predicted_error_map
from robocal.rigs.projector.simulate import default_nominal, default_truth, sample_floor_points, simulate_calibration

SIGMA = 0.005  # world measurement noise (m)


def _calibrate(sc, estimate=("h", "tilt_offset")):
    return calibrate(sc.points_W, theta=sc.theta, model=sc.nominal, methods=("nonlinear",), estimate=estimate,
                     sigma=SIGMA)



def test_predicted_error_map_matches_monte_carlo_at_floor_points():
    truth = default_truth()
    nominal = default_nominal(truth)
    design = sample_floor_points(truth, 6, np.random.default_rng(3))
    # near the nadir, inside the calibration points, outside them, near the tilt limit (10.4 m)
    W = truth.nadir_world + np.array([[0.5, 0.3], [3.0, -2.0], [-5.0, 4.0], [7.5, 5.0]])
    rng = np.random.default_rng(11)
    pred = None
    errs = []
    for _ in range(120):
        sc = simulate_calibration(rng, truth=truth, nominal=nominal, points_W=design, sigma=SIGMA)
        model, cov, labels, note = estimate_covariance(_calibrate(sc))
        if pred is None:  # the map as the report draws it, read at the four points (1 x 1 grids)
            assert labels == ["yaw", "t_x", "t_y", "h", "tilt_offset"] and note == ""
            pred = np.array([predicted_error_map(model, cov, labels, (w[0], w[0]), (w[1], w[1]), 1)[2][0, 0]
                             for w in W])
        errs.append(truth.spot_world(model.ik_world(W))[:, :2] - W)
    mc = np.sqrt(np.mean(np.sum(np.array(errs) ** 2, axis=-1), axis=0))
    # 120 trials: the RMS of a (nearly 1-D) error has a relative SE of about 1/sqrt(240) = 6.5 %; 3 SE
    assert np.all(np.abs(mc / pred - 1) < 0.2), (mc, pred)
    assert pred[1] < pred[0] < pred[2] < pred[3]  # smallest among the points, largest near the tilt limit


def test_predicted_error_map_is_nan_outside_reach_and_survives_a_rank_deficient_fit():
    sc = simulate_calibration(np.random.default_rng(5), n_points=8, sigma=SIGMA)
    run = _calibrate(sc, estimate=("h", "pan_offset", "tilt_offset"))
    assert not np.all(np.isfinite(run.best.cov))  # the pan offset is not identifiable
    model, cov, labels, note = estimate_covariance(run)
    assert "pseudo-inverse" in note and np.all(np.isfinite(cov))
    r = model.floor_radius
    n0 = model.nadir_world
    xs, ys, err = predicted_error_map(model, cov, labels, (n0[0] - 1.2 * r, n0[0] + 1.2 * r),
                                      (n0[1] - 1.2 * r, n0[1] + 1.2 * r), 25)
    assert np.isnan(err[0, 0]) and np.isfinite(err[12, 12]) and np.nanmin(err) > 0
    # the unobservable pan-offset direction moves no spot: same map as without the pan offset
    ref = estimate_covariance(_calibrate(sc))
    ref_err = predicted_error_map(*ref[:3], (n0[0] - 1.2 * r, n0[0] + 1.2 * r), (n0[1] - 1.2 * r, n0[1] + 1.2 * r), 25)
    both = np.isfinite(err) & np.isfinite(ref_err[2])
    both[12, 12] = False  # the nadir itself: the commanded pan there is arbitrary, and so is the error direction
    assert both.sum() > 300 and np.allclose(err[both], ref_err[2][both], rtol=1e-3)
