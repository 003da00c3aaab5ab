"""Issue 16's shortcuts in the hand-eye call give what the generic code gives: the pose check's vectorised
path (same acceptance, the generic check's words on failure), the refinement started from the caller's
closure (the same solve), the Park rotation as the nearest rotation to sum alpha beta^T."""

import numpy as np
import pytest

from robocal.errors import InputError, NonFiniteError, ShapeError
from robocal.geometry import project_to_rotation
from robocal.handeye import calibrate_hand_eye, simulate_eye_in_hand
from robocal.handeye.axxb import _rot_park
from robocal.handeye.motions import _check_poses
from robocal.handeye.refine import _closure, _refine_closure
from robocal.validation import check_transform


@pytest.fixture(scope="module")
def sim():
    return simulate_eye_in_hand(np.random.default_rng(0), 15)


def _bad_lists(T):
    out = {}
    a = T.copy(); a[3, 0, 0] = np.nan; out["nan_rotation"] = a                      # noqa: E702
    a = T.copy(); a[2, 1, 3] = np.inf; out["inf_translation"] = a                   # noqa: E702
    a = T.copy(); a[5, :3, :3] *= 1.001; out["not_orthonormal"] = a                 # noqa: E702
    a = T.copy(); a[1, :3, 0] *= -1; out["reflection"] = a                          # noqa: E702
    a = T.copy(); a[7, 3, 2] = 0.5; out["last_row"] = a                              # noqa: E702
    a = T.copy(); a[0, 3, 3] = np.nan; out["nan_last_row"] = a                       # noqa: E702
    out["one_pose"] = T[0]
    return out


def test_pose_check_fast_path_accepts_and_refuses_as_the_generic_one(sim):
    T = sim.T_base_gripper
    assert _check_poses(T, "T_base_gripper") is T                   # valid float64 (N, 4, 4): as given
    # within tolerance (1e-5) passes on both paths; just beyond, both refuse
    a = T.copy(); a[:, :3, :3] *= 1 + 4e-6                              # noqa: E702
    assert _check_poses(a, "x") is a
    for name, bad in _bad_lists(T).items():
        with pytest.raises((InputError, NonFiniteError, ShapeError)) as fast:
            _check_poses(bad, "T_base_gripper")
        try:
            check_transform(bad, "T_base_gripper", atol=1e-5)
            generic = None
        except (InputError, NonFiniteError, ShapeError) as exc:
            generic = exc
        if generic is not None:                                      # the same words as the generic check
            assert type(fast.value) is type(generic) and str(fast.value) == str(generic), name
    # lists and integer arrays take the generic path
    assert _check_poses(T.tolist(), "x").dtype == np.float64
    ints = np.broadcast_to(np.eye(4, dtype=int), (3, 4, 4))
    assert np.array_equal(_check_poses(ints, "x"), np.tile(np.eye(4), (3, 1, 1)))


def test_refinement_from_the_callers_closure_is_the_same_solve(sim):
    Tg, Tc = sim.T_base_gripper, sim.T_cam_target
    closed = calibrate_hand_eye(Tg, Tc, refine=False)
    _, r0 = _closure(Tg, Tc, closed.X, closed.Y)
    w = np.ones((len(Tg), 6))
    sr, st = closed.rot_rms, closed.trans_rms                       # the scales calibrate_hand_eye uses
    _, seeded = _refine_closure(Tg, Tc, closed.X, closed.Y, w, sr, st, r0=r0)
    _, fresh = _refine_closure(Tg, Tc, closed.X, closed.Y, w, sr, st)
    # r0 is the closure the Problem's first evaluation computes, bit for bit: the same iterates
    np.testing.assert_array_equal(seeded.x, fresh.x)
    np.testing.assert_array_equal(seeded.cov, fresh.cov)
    assert seeded.nfev == fresh.nfev and seeded.njev == fresh.njev
    full = calibrate_hand_eye(Tg, Tc)
    np.testing.assert_array_equal(full.lsq.x, seeded.x)
    # the RMS reported from the solver's residuals: the closure at the refined X, Y (to rounding)
    _, r = _closure(Tg, Tc, full.X, full.Y)
    assert full.rot_rms == pytest.approx(np.sqrt(np.mean(r[:, :3] ** 2)), rel=1e-12)
    assert full.trans_rms == pytest.approx(np.sqrt(np.mean(r[:, 3:] ** 2)), rel=1e-12)


def _park_polar(alpha, beta):
    """Park-Martin as written in the paper: (M^T M)^-1/2 M^T with M = sum beta alpha^T (then projected)."""
    M = beta.T @ alpha
    w, V = np.linalg.eigh(M.T @ M)
    return project_to_rotation(V @ np.diag(1 / np.sqrt(w)) @ V.T @ M.T)


def test_park_is_the_papers_formula_where_that_is_a_rotation():
    rng = np.random.default_rng(4)
    for _ in range(20):
        alpha = rng.normal(size=(10, 3))
        R = project_to_rotation(rng.normal(size=(3, 3)))
        beta = alpha @ R + rng.normal(0, 0.01, (10, 3))              # alpha_i ~ R_X beta_i with R_X = R
        # det M > 0 (consistent motions): the polar factor is a rotation and both agree to rounding
        np.testing.assert_allclose(_rot_park(alpha, beta), _park_polar(alpha, beta), atol=1e-12)
        np.testing.assert_allclose(_rot_park(alpha, beta), R, atol=0.05)
    # rank 2 (two motions): still a rotation, where the polar form divides by a zero eigenvalue
    R2 = _rot_park(alpha[:2], beta[:2])
    np.testing.assert_allclose(R2 @ R2.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R2) == pytest.approx(1.0)
