"""PnP answers that do not depend on the OpenCV version: converged refinement, robocal's own tie order."""

import numpy as np

from robocal.camera import CameraModel, MarkerRectangle, PnPSolution, pnp_jacobian, solve_pnp, solve_pnp_planar
from robocal.camera._pnp import _order_candidates
from robocal.geometry import transform_from_rotvec


def _relative_gradient(cam, p, uv, T):
    """|J^T r| / (|J| |r|): the cosine between the residual and the pose directions; 0 at a minimum."""
    pred, J = pnp_jacobian(cam, p, T)
    J = J.reshape(-1, 6)
    r = (uv - pred).ravel()
    return np.max(np.abs(J.T @ r)) / (np.linalg.norm(J) * np.linalg.norm(r))


def test_each_planar_candidate_is_a_minimum_or_the_same_pose():
    # A 120 x 84 mm rectangle 1.6 m away (the mirror rig's ambiguous scene, seed 102): OpenCV 4's LM
    # left the second IPPE pose at 0.42 px RMS with |J^T r| = 6 px^2/rad; 5's went on to the first
    # pose's minimum. robocal finishes both refinements, so the candidates are minima on either.
    cam = CameraModel(800.0, 800.0, 383.5, 287.5, (-0.289, -0.06639, 5e-4, 7.2e-4, 0.0), 768, 576)
    rect = MarkerRectangle(0.12, 0.084)
    T = transform_from_rotvec([0.05, -0.12, 0.01], [-0.19, -0.19, 1.63])
    rng = np.random.default_rng(102)
    for _ in range(20):
        uv = cam.project_points(rect.object_points(), T) + rng.normal(0, 0.5, (4, 2))
        for c in solve_pnp_planar(cam, rect.object_points(), uv):
            # 1e-6: MINPACK's gtol is 1e-15 of the same cosine; a stopped-short pose is ~1e-2
            assert _relative_gradient(cam, rect.object_points(), uv, c.T_cam_obj) < 1e-6


def test_noise_free_pose_is_exact_to_rounding():
    # OpenCV 5's LM alone stops 3e-9 rad short here (4's reaches 1e-16); robocal's answer must not care
    cam = CameraModel(600.0, 605.0, 321.3, 238.7, (-0.28, 0.11, 8e-4, -6e-4, -0.02), 640, 480)
    T = transform_from_rotvec([0.35, -0.25, 0.1], [-0.06, -0.04, 0.5])
    p = np.random.default_rng(10).uniform(-0.1, 0.1, (12, 3))
    sol = solve_pnp(cam, p, cam.project_points(p, T))
    # the pose is ~cond(J) * 1e-16 from the truth: J^T J here has condition ~1e4
    assert np.max(np.abs(sol.T_cam_obj - T)) < 1e-11 and sol.rms_px < 1e-9


def _sol(rvec, t, rms):
    return PnPSolution(transform_from_rotvec(rvec, t), rms, np.zeros((4, 2)))


def test_a_near_tie_is_ordered_by_robocal_whatever_order_opencv_returns():
    a = _sol([0.0, 0.1, 0.0], [0, 0, 1.0], 0.3)
    b = _sol([0.0, -0.3, 0.0], [0, 0, 1.0], 0.3 * (1 + 1e-9))  # a tie: the less rotated pose first
    assert _order_candidates([a, b])[0] is a and _order_candidates([b, a])[0] is a
    c = _sol([0.0, -0.3, 0.0], [0, 0, 1.0], 0.29)  # 3 % better: no tie, the better fit first
    assert _order_candidates([a, c])[0] is c and _order_candidates([c, a])[0] is c
