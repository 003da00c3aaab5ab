"""The seed's error measures (eqs. 13-15) and the FPDP vs MCT comparison re-run."""

import numpy as np

from robocal.geometry import matrix_from_rotvec, transform_from
from robocal.rigs.lineprofiler.compare import axis_angle_translation, repeatability_errors, run_comparison
from robocal.rigs.lineprofiler.model import default_rig

RIG = default_rig()


def test_error_measures_eqs_13_15():
    X = transform_from(matrix_from_rotvec([0, 0, 0.5]), [1.0, 2.0, 3.0])
    v, th, p = axis_angle_translation(X)
    assert np.allclose(v, [0, 0, 1]) and np.isclose(th, 0.5) and np.allclose(p, [1, 2, 3])
    Xs = [X, transform_from(matrix_from_rotvec([0, 0, 0.52]), [1.0, 2.0, 3.004])]
    e_v, e_t, e_p = repeatability_errors(Xs)
    assert np.allclose(e_v, 0) and np.allclose(e_t, 0.01) and np.allclose(e_p, 0.002)


def test_seed_comparison_contrast():
    """3 x 16 poses: MCT meets the seed's figures, FPDP is far worse (seed §4.3, Fig. 5)."""
    c = run_comparison(RIG, np.random.default_rng(0))
    assert c.undetermined == ("X.ty", "Q.z")
    assert np.all(c.e_v["MCT"] < 1e-3) and np.all(np.rad2deg(c.e_theta["MCT"]) <= 0.07)
    assert np.all(c.e_p["MCT"] <= 0.25e-3)
    assert c.e_p["FPDP"].max() > 5 * c.e_p["MCT"].max()
    assert c.err_true_t["FPDP"].mean() > 3 * c.err_true_t["MCT"].mean()
    # the refinement (with the stated joint noise) is more repeatable than linear FPDP and closer to the
    # truth; taking the joints as exact it was not (e_theta RMS 0.153 vs FPDP's 0.188 deg on this seed)
    rms = {k: np.sqrt(np.mean(v**2)) for k, v in c.e_theta.items()}
    assert rms["FPDP+refine"] < 0.5 * rms["FPDP"], rms
    assert np.sqrt(np.mean(c.e_p["FPDP+refine"] ** 2)) < 0.5 * np.sqrt(np.mean(c.e_p["FPDP"] ** 2))
    assert c.err_true_rot["FPDP+refine"].mean() < c.err_true_rot["FPDP"].mean()
    assert set(c.X) == {"FPDP", "refine, q exact", "FPDP+refine", "MCT"}
    assert c.extra["std"]["FPDP+refine"].shape == (3, 6)


def test_comparison_takes_one_joint_sigma_for_every_joint():
    # a scalar sigma_q is broadcast to every joint (it raised IndexError for the MCT run's P3 reading)
    c = run_comparison(RIG, np.random.default_rng(0), n_runs=2, n_poses=8, sigma_q=0.0)
    assert set(c.X) == {"FPDP", "refine, q exact", "FPDP+refine", "MCT"}
