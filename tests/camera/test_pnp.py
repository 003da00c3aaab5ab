import numpy as np
import pytest

from robocal.camera import (
    Checkerboard,
    CameraModel,
    pnp_covariance,
    pnp_jacobian,
    solve_pnp,
    solve_pnp_planar,
)
from robocal.errors import DegenerateGeometryError, InputError, NonFiniteError, NotEnoughDataError, ShapeError
from robocal.geometry import rotation_angle, rotvec_from_matrix, transform_from_rotvec

BOARD = Checkerboard(6, 8, 0.025)
T_TRUE = transform_from_rotvec([0.35, -0.25, 0.1], [-0.06, -0.04, 0.5])


def _pose_errors(T, T_true):
    dR = T[:3, :3] @ T_true[:3, :3].T
    return float(np.degrees(rotation_angle(dR))), float(np.linalg.norm(T[:3, 3] - T_true[:3, 3]))


def test_solve_pnp_exact_general_and_planar(cam):
    rng = np.random.default_rng(10)
    p3 = rng.uniform(-0.1, 0.1, (12, 3))
    for p in (p3, BOARD.object_points()):
        uv = cam.project_points(p, T_TRUE)
        sol = solve_pnp(cam, p, uv)
        assert np.max(np.abs(sol.T_cam_obj - T_TRUE)) < 1e-9
        assert sol.rms_px < 1e-8 and sol.rms == sol.rms_px
        assert sol.residuals.shape == (len(p), 2)
        assert np.allclose(sol.rvec, [0.35, -0.25, 0.1]) and np.allclose(sol.tvec, T_TRUE[:3, 3])


def test_solve_pnp_accepts_strided_views(cam):
    # column slices and reversed views are not C-contiguous; OpenCV rejects them unless copied
    p = np.asfortranarray(BOARD.object_points())
    uv = np.hstack([cam.project_points(p, T_TRUE), np.zeros((len(p), 1))])[:, :2]
    assert not uv.flags.c_contiguous and not p.flags.c_contiguous
    for solver in (solve_pnp, lambda c, a, b: solve_pnp_planar(c, a, b).best):
        sol = solver(cam, p, uv)
        assert np.max(np.abs(sol.T_cam_obj - T_TRUE)) < 1e-9


def test_solve_pnp_with_noise_is_close(cam):
    rng = np.random.default_rng(11)
    p = BOARD.object_points()
    uv = cam.project_points(p, T_TRUE) + rng.normal(0, 0.1, (len(p), 2))
    sol = solve_pnp(cam, p, uv)
    dang, dt = _pose_errors(sol.T_cam_obj, T_TRUE)
    assert dang < 0.2 and dt < 2e-3
    # within 4 predicted standard deviations per component
    std = np.sqrt(np.diag(pnp_covariance(cam, p, T_TRUE, 0.1)))
    err = np.concatenate([sol.rvec - rotvec_from_matrix(T_TRUE[:3, :3]), sol.tvec - T_TRUE[:3, 3]])
    assert np.all(np.abs(err) < 4 * std), err / std
    assert 0.05 < sol.rms_px < 0.2
    unrefined = solve_pnp(cam, p, uv, refine=False)
    assert unrefined.rms_px >= sol.rms_px - 1e-12


def test_planar_returns_both_solutions_sorted(cam):
    p = BOARD.object_points()
    uv = cam.project_points(p, T_TRUE)
    cands = solve_pnp_planar(cam, p, uv)
    assert len(cands) == 2
    assert cands[0].rms_px <= cands[1].rms_px
    assert np.max(np.abs(cands.best.T_cam_obj - T_TRUE)) < 1e-9
    assert cands.ambiguity < 1e-6 and cands.error_ratio > 1e6
    # the second pose is a genuinely different (flipped) pose
    dang, _ = _pose_errors(cands[1].T_cam_obj, T_TRUE)
    assert dang > 1.0


def test_planar_ambiguity_grows_for_small_distant_targets():
    cam = CameraModel(500, 500, 319.5, 239.5, (0, 0, 0, 0), 640, 480)
    small = Checkerboard(2, 2, 0.01)
    rng = np.random.default_rng(12)
    T = transform_from_rotvec([0.05, 0.02, 0.0], [0.0, 0.0, 3.0])
    uv = cam.project_points(small.object_points(), T) + rng.normal(0, 0.3, (4, 2))
    cands = solve_pnp_planar(cam, small.object_points(), uv)
    assert cands.ambiguity > 0.3  # the two flips fit nearly equally well


def test_planar_accepts_any_plane(cam):
    # board points moved into an arbitrary object frame: no longer z = 0
    T_obj_board = transform_from_rotvec([0.4, 0.9, -0.3], [0.1, 0.2, 0.05])
    p = BOARD.object_points() @ T_obj_board[:3, :3].T + T_obj_board[:3, 3]
    T_cam_obj = T_TRUE @ np.linalg.inv(T_obj_board)
    uv = cam.project_points(p, T_cam_obj)
    cands = solve_pnp_planar(cam, p, uv)
    assert np.max(np.abs(cands.best.T_cam_obj - T_cam_obj)) < 1e-8


def test_pnp_bad_inputs(cam):
    p = BOARD.object_points()
    uv = cam.project_points(p, T_TRUE)
    with pytest.raises(NotEnoughDataError, match="at least 4 points, got 3"):
        solve_pnp(cam, p[:3], uv[:3])
    with pytest.raises(NotEnoughDataError):
        solve_pnp_planar(cam, p[:3], uv[:3])
    with pytest.raises(InputError, match="same number of points, got 48 and 47"):
        solve_pnp(cam, p, uv[:-1])
    with pytest.raises(ShapeError, match="uv"):
        solve_pnp(cam, p, np.ones((48, 3)))
    bad = uv.copy()
    bad[5, 1] = np.nan
    with pytest.raises(NonFiniteError, match="uv"):
        solve_pnp(cam, p, bad)
    line = np.column_stack([np.linspace(0, 0.1, 6), np.zeros(6), np.zeros(6)])
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        solve_pnp(cam, line, uv[:6])
    rng = np.random.default_rng(0)
    with pytest.raises(DegenerateGeometryError, match="coplanar"):
        solve_pnp_planar(cam, rng.uniform(-0.1, 0.1, (8, 3)), uv[:8])
    with pytest.raises(InputError, match="CameraModel"):
        solve_pnp("camera", p, uv)


@pytest.mark.parametrize("solver", [solve_pnp, solve_pnp_planar])
def test_degenerate_image_points_raise_a_named_error(cam, solver):
    # OpenCV answered these with an assertion (SQPnP), a NaN pose or "behind the camera" (IPPE)
    p = BOARD.object_points()[:8]
    for uv, what in ((np.tile([[300.0, 200.0]], (8, 1)), "coincide"),
                     (np.c_[np.linspace(100, 200, 8), np.full(8, 200.0)], "are collinear")):
        with pytest.raises(DegenerateGeometryError, match=f"uv: the 8 image points {what}"):
            solver(cam, p, uv)


def test_pnp_jacobian_matches_finite_differences(cam):
    p = BOARD.object_points()
    uv, J = pnp_jacobian(cam, p, T_TRUE)
    x0 = np.concatenate([rotvec_from_matrix(T_TRUE[:3, :3]), T_TRUE[:3, 3]])
    h = 1e-7
    for k in range(6):
        dx = np.zeros(6)
        dx[k] = h
        up = cam.project_points(p, transform_from_rotvec((x0 + dx)[:3], (x0 + dx)[3:]))
        dn = cam.project_points(p, transform_from_rotvec((x0 - dx)[:3], (x0 - dx)[3:]))
        assert np.allclose(J[..., k], (up - dn) / (2 * h), rtol=1e-5, atol=1e-4)


def test_pnp_covariance_matches_monte_carlo(cam):
    """Predicted (rvec, t) std vs the spread of 400 noisy re-solves, within 15 %."""
    sigma = 0.3
    p = BOARD.object_points()
    uv0 = cam.project_points(p, T_TRUE)
    cov = pnp_covariance(cam, p, T_TRUE, sigma)
    rng = np.random.default_rng(20240601)
    x0 = np.concatenate([rotvec_from_matrix(T_TRUE[:3, :3]), T_TRUE[:3, 3]])
    xs = []
    for _ in range(400):
        sol = solve_pnp(cam, p, uv0 + rng.normal(0, sigma, uv0.shape))
        xs.append(np.concatenate([sol.rvec, sol.tvec]) - x0)
    xs = np.asarray(xs)
    ratio = xs.std(axis=0) / np.sqrt(np.diag(cov))
    assert np.all(np.abs(ratio - 1) < 0.15), ratio
    # and the correlation structure: whitened samples have ~identity covariance
    L = np.linalg.cholesky(cov)
    w = np.linalg.solve(L, xs.T)
    assert np.allclose(np.cov(w), np.eye(6), atol=0.2)


def test_pnp_covariance_bad_inputs(cam):
    p = BOARD.object_points()
    with pytest.raises(InputError, match="sigma_px must be > 0"):
        pnp_covariance(cam, p, T_TRUE, 0.0)
    line = np.column_stack([np.linspace(0, 0.1, 6), np.zeros(6), np.zeros(6)])
    with pytest.raises(DegenerateGeometryError, match="not determined"):
        pnp_covariance(cam, line, T_TRUE, 0.1)
