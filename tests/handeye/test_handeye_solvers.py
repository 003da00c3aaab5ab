"""AX = XB / AX = ZB solvers vs ground truth and vs OpenCV on the same data."""

import cv2
import numpy as np
import pytest
from opencv_reference import opencv  # cv2 on OpenCV 4; outputs recorded from 4.x on OpenCV 5

from robocal.errors import (DegenerateGeometryError, ImplausibleInputError, InputError, NonFiniteError,
                            NotEnoughDataError, ShapeError)
from robocal.geometry import invert_transform, matrix_from_angle, matrix_from_rotvec, rotvec_from_matrix, transform_from
from robocal.handeye import (
    AXXB_METHODS,
    calibrate_hand_eye,
    calibrate_robot_world,
    relative_motions,
    solve_ax_xb,
    transform_error,
)

CV = {"tsai": cv2.CALIB_HAND_EYE_TSAI, "park": cv2.CALIB_HAND_EYE_PARK, "horaud": cv2.CALIB_HAND_EYE_HORAUD,
      "andreff": cv2.CALIB_HAND_EYE_ANDREFF, "daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS}


def rand_T(rng, ang=1.0, tr=0.5):
    return transform_from(matrix_from_rotvec(rng.normal(size=3) * ang), rng.normal(size=3) * tr)


def noisy(T, rng, s_r, s_t):
    R = matrix_from_rotvec(rng.normal(size=(len(T), 3)) * s_r) @ T[:, :3, :3]
    return transform_from(R, T[:, :3, 3] + rng.normal(size=(len(T), 3)) * s_t)


def scene(rng, n=12):
    X, Y = rand_T(rng), rand_T(rng)
    Tg = np.array([rand_T(rng) for _ in range(n)])
    Tc = invert_transform(X) @ invert_transform(Tg) @ Y  # Y = Tg X Tc
    return X, Y, Tg, Tc


def cv_hand_eye(Tg, Tc, method):
    R, t = opencv.calibrateHandEye(Tg[:, :3, :3], Tg[:, :3, 3], Tc[:, :3, :3], Tc[:, :3, 3], method=CV[method])
    return transform_from(R, t.ravel())


@pytest.mark.parametrize("method", AXXB_METHODS)
def test_exact_data_recovers_truth_and_matches_opencv(method):
    X, _, Tg, Tc = scene(np.random.default_rng(1))
    res = calibrate_hand_eye(Tg, Tc, method, refine=False)
    assert transform_error(res.X, X)[0] < 1e-10 and transform_error(res.X, X)[1] < 1e-10
    assert transform_error(res.X, cv_hand_eye(Tg, Tc, method))[0] < 1e-9


@pytest.mark.parametrize("method", AXXB_METHODS)
def test_noisy_data_as_accurate_as_opencv_and_refinement_helps(method):
    rng = np.random.default_rng(7)
    ours, theirs, refined = [], [], []
    for _ in range(6):
        X, _, Tg, Tc = scene(rng)
        Tcn = noisy(Tc, rng, 2e-3, 1e-3)
        ours.append(transform_error(calibrate_hand_eye(Tg, Tcn, method, refine=False).X, X))
        refined.append(transform_error(calibrate_hand_eye(Tg, Tcn, method).X, X))
        theirs.append(transform_error(cv_hand_eye(Tg, Tcn, method), X))
    ours, theirs, refined = map(np.array, (ours, theirs, refined))
    # closed forms no worse than OpenCV's (same algorithm family), refinement no worse than either
    assert np.mean(ours[:, 0]) < 1.5 * np.mean(theirs[:, 0])
    assert np.mean(refined[:, 0]) <= 1.05 * min(np.mean(ours[:, 0]), np.mean(theirs[:, 0]))
    assert np.mean(refined[:, 1]) <= 1.05 * min(np.mean(ours[:, 1]), np.mean(theirs[:, 1]))


def test_refined_std_matches_monte_carlo_spread():
    rng = np.random.default_rng(3)
    X, _, Tg, Tc = scene(rng, n=10)
    errs, stds = [], []
    for _ in range(40):
        res = calibrate_hand_eye(Tg, noisy(Tc, rng, 1e-3, 1e-3), "park")
        e_rot = rotvec_from_matrix(res.X[:3, :3] @ X[:3, :3].T)
        errs.append(np.r_[e_rot, res.X[:3, 3] - X[:3, 3]])
        stds.append([res.std[k] for k in ("rx", "ry", "rz", "tx", "ty", "tz")])
    errs, stds = np.array(errs), np.array(stds)
    ratio = errs.std(axis=0) / stds.mean(axis=0)
    assert np.all((ratio > 0.6) & (ratio < 1.6)), ratio


def test_robot_world_matches_truth_and_opencv():
    rng = np.random.default_rng(5)
    X, Z = rand_T(rng), rand_T(rng)
    TB = invert_transform(np.array([rand_T(rng) for _ in range(10)]))  # T_gripper_base
    TA = Z @ TB @ invert_transform(X)  # A X = Z B
    res = calibrate_robot_world(TA, TB, refine=False)
    assert max(transform_error(res.X, X)) < 1e-9 and max(transform_error(res.Z, Z)) < 1e-9
    Rb, tb, Rg, tg = opencv.calibrateRobotWorldHandEye(TA[:, :3, :3], TA[:, :3, 3], TB[:, :3, :3], TB[:, :3, 3])
    assert transform_error(transform_from(Rb, tb.ravel()), res.X)[1] < 1e-8
    assert transform_error(transform_from(Rg, tg.ravel()), res.Z)[1] < 1e-8
    ref = calibrate_robot_world(noisy(TA, rng, 1e-3, 1e-3), TB)
    assert transform_error(ref.X, X)[0] < 5e-3 and transform_error(ref.Z, Z)[1] < 5e-3
    assert ref.std["Z.tx"] is not None and ref.std["Z.tx"] > 0


def planar_scene(rng, n=8):
    """Every gripper rotation about the base z axis (mobile robot, seed 002)."""
    X, Y = rand_T(rng), rand_T(rng)
    Tg = transform_from(matrix_from_angle("z", rng.uniform(-2, 2, n)), np.c_[rng.normal(size=(n, 2)), np.zeros(n)])
    Tc = invert_transform(X) @ invert_transform(Tg) @ Y
    return Tg, Tc


@pytest.mark.parametrize("method", AXXB_METHODS)
def test_parallel_axes_are_refused_never_identity(method):
    Tg, Tc = planar_scene(np.random.default_rng(2))
    with pytest.raises(DegenerateGeometryError, match="parallel axes.*translation.*undetermined"):
        calibrate_hand_eye(Tg, Tc, method)


def test_too_little_rotation_is_refused():
    rng = np.random.default_rng(4)
    X, Y = rand_T(rng), rand_T(rng)
    Tg = transform_from(matrix_from_rotvec(rng.normal(size=(6, 3)) * 1e-3), rng.normal(size=(6, 3)))
    Tc = invert_transform(X) @ invert_transform(Tg) @ Y
    with pytest.raises(DegenerateGeometryError, match="too little rotation"):
        calibrate_hand_eye(Tg, Tc)


def test_weak_spread_and_mispaired_poses_are_named():
    rng = np.random.default_rng(8)
    X, Y = rand_T(rng), rand_T(rng)
    axes = np.c_[rng.normal(size=(8, 2)) * 0.03, np.ones(8)]  # ~9 deg spread
    Tg = transform_from(matrix_from_rotvec(axes / np.linalg.norm(axes, axis=1)[:, None] * rng.uniform(-2, 2, (8, 1))),
                        rng.normal(size=(8, 3)))
    Tc = invert_transform(X) @ invert_transform(Tg) @ Y
    res = calibrate_hand_eye(Tg, Tc, refine=False)
    assert "weakly_determined" in [w.code for w in res.warnings]
    X2, _, Tg2, Tc2 = scene(rng)
    Tc2[[2, 5]] = Tc2[[5, 2]]
    with pytest.raises(ImplausibleInputError) as e:     # the swap is named (issue 13)
        calibrate_hand_eye(Tg2, Tc2, refine=False)
    assert e.value.slip == "poses_swapped" and "pose 2 and pose 5 look swapped" in str(e.value)
    res = calibrate_hand_eye(Tg2, Tc2, refine=False, accept_implausible=True)
    bad = [w for w in res.warnings if w.code == "inconsistent_data"]
    assert bad and set(bad[0].indices) == {2, 5}
    assert [w.params for w in res.warnings if w.code == "implausible_input"] == [("poses_swapped",)]


def test_bad_input_errors():
    X, _, Tg, Tc = scene(np.random.default_rng(0), n=5)
    with pytest.raises(ShapeError, match="counts must match"):
        calibrate_hand_eye(Tg, Tc[:4])
    with pytest.raises(NotEnoughDataError):
        calibrate_hand_eye(Tg[:2], Tc[:2])
    bad = Tc.copy()
    bad[1, 0, 0] = np.nan
    with pytest.raises(NonFiniteError):
        calibrate_hand_eye(Tg, bad)
    bad = Tc.copy()
    bad[1, :3, :3] *= 1.1
    with pytest.raises(InputError, match="rotation matrix"):
        calibrate_hand_eye(Tg, bad)
    with pytest.raises(InputError, match="method must be"):
        calibrate_hand_eye(Tg, Tc, "magic")
    A, B = relative_motions(Tg, Tc)
    with pytest.raises(ShapeError):
        solve_ax_xb(A, B[:-1])


def test_invert_with_covariance_matches_finite_differences_and_sampling():
    from robocal.handeye import invert_with_covariance

    rng = np.random.default_rng(4)
    T = transform_from(matrix_from_rotvec([0.4, -1.1, 0.7]), [0.05, -0.2, 0.3])
    A = rng.normal(size=(6, 6)) * np.r_[[1e-3] * 3, [1e-3] * 3]
    cov = A @ A.T
    Ti, Ci = invert_with_covariance(T, cov)
    assert np.allclose(Ti @ T, np.eye(4), atol=1e-12)

    def delta(Ta, Tb):  # rotation vector of R_a R_b^T, t_a - t_b (the covariance convention)
        return np.r_[rotvec_from_matrix(Ta[:3, :3] @ Tb[:3, :3].T), Ta[:3, 3] - Tb[:3, 3]]

    h = 1e-7
    G = np.column_stack([delta(np.linalg.inv(transform_from(matrix_from_rotvec(h * e[:3]) @ T[:3, :3],
                                                             T[:3, 3] + h * e[3:])), Ti) / h for e in np.eye(6)])
    assert np.allclose(G @ cov @ G.T, Ci, rtol=1e-5, atol=1e-14)
    # and by sampling (first order holds at these 1 mrad / 1 mm levels)
    d = rng.multivariate_normal(np.zeros(6), cov, size=4000)
    inv = np.linalg.inv(transform_from(matrix_from_rotvec(d[:, :3]) @ T[:3, :3], T[:3, 3] + d[:, 3:]))
    s = np.c_[rotvec_from_matrix(inv[:, :3, :3] @ Ti[:3, :3].T), inv[:, :3, 3] - Ti[:3, 3]]   # delta, batched
    assert np.allclose(np.sqrt(np.diag(np.cov(s.T))), np.sqrt(np.diag(Ci)), rtol=0.08)
