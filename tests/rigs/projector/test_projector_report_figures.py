"""The projector's figures: one cost axis per method; every report figure fits a ~1000 px column."""

import numpy as np

from robocal.rigs.projector.calibrate import calibrate
from robocal.rigs.projector.simulate import simulate_calibration

SIGMA = 0.005  # world measurement noise (m)


def _calibrate(sc, estimate=("h", "tilt_offset")):
    return calibrate(sc.points_W, theta=sc.theta, model=sc.nominal, methods=("nonlinear",), estimate=estimate,
                     sigma=SIGMA)



def test_cost_curves_get_one_axis_per_method_so_the_seed_curve_is_visible():
    from robocal.report import new_figure
    from robocal.rigs.projector.plots import iterative_methods, plot_cost_curves

    sc = simulate_calibration(np.random.default_rng(7), n_points=8, sigma=SIGMA)
    run = calibrate(sc.points_W, theta=sc.theta, model=sc.nominal, estimate=("h", "tilt_offset"), sigma=SIGMA)
    assert iterative_methods(run.estimates) == ["seed", "nonlinear"]
    fig, ax = new_figure(1, 2)
    plot_cost_curves(run.estimates, ax)
    for a, name in zip(ax, ("seed", "nonlinear")):
        h = run.estimates[name].cost_history
        assert len(a.get_lines()) == 1
        lo, hi = a.get_ylim()  # each axis spans its own curve, not 1e-6 .. 1e3 for both
        assert lo >= 0.5 * h.min() and hi <= 2 * h.max()
    assert run.estimates["seed"].cost_history.max() < 1e-3 < run.estimates["nonlinear"].cost_history.max()
