"""Markerless calibration through K >= 3 mirror poses (issue 14): closed form, refinement, conditioning, bad input."""

import numpy as np
import pytest

from robocal.errors import DegenerateGeometryError, NotEnoughDataError
from robocal.estimation import truth_check
from robocal.rigs.mirror.markerless import (
    MarkerlessObservation,
    _problem,
    calibrate_markerless,
    closed_form,
    simulate_markerless,
    virtual_pose_candidates,
)
from robocal.rigs.mirror.model import virtual_transform
from robocal.rigs.mirror.result import TRUTH_NAMES, pose_error
from robocal.rigs.mirror.simulate import default_setup

THREE = [0, 3, 17]  # three well-spread body points of the published scene (front face corners, a cube)


def _scene(seed, K=3, tilt=30.0):
    rng = np.random.default_rng(seed)
    cam, scene = default_setup(K, rng, tilt_deg=tilt)
    return cam, scene, rng


def test_closed_form_is_exact_on_noise_free_data_with_20_and_3_points():
    cam, scene, rng = _scene(1)
    n, d = scene.planes()
    # the virtual poses themselves: exact up to rounding
    T_r_c, n_hat, d_hat, _ = closed_form(virtual_transform(scene.T_c_r[None], n, d))
    e = pose_error(T_r_c, scene.T_r_c)
    assert np.abs(e).max() < 1e-9
    assert np.abs(n_hat - n).max() < 1e-9 and np.abs(d_hat - d).max() < 1e-9
    for ids in (None, THREE):
        P = scene.body_points_r if ids is None else scene.body_points_r[ids]
        obs = simulate_markerless(cam, scene.T_c_r, P, n, d, rng, sigma_px=0.0)
        cal = calibrate_markerless(cam, P, obs)
        # closed form from SQPnP + LM (~1e-9) or cv2.solveP3P of noise-free points: its roots are polished
        # to ~1e-5 relative only (measured 5e-5 rad / m here), hence 1e-3; the refinement then reaches rounding
        assert np.abs(pose_error(cal.T_r_c_closed_form, scene.T_r_c)).max() < 1e-3
        assert np.abs(pose_error(cal.T_r_c, scene.T_r_c)).max() < 1e-9
        assert np.abs(cal.distances - d).max() < 1e-9


def test_three_points_enumerate_the_p3p_solutions_and_report_the_minima():
    cam, scene, rng = _scene(2)
    P = scene.body_points_r[THREE]
    n, d = scene.planes()
    obs = simulate_markerless(cam, scene.T_c_r, P, n, d, rng, sigma_px=0.3)
    assert max(len(virtual_pose_candidates(cam, P, o)) for o in obs) > 1  # P3P is ambiguous here
    cal = calibrate_markerless(cam, P, obs, sigma_px=0.3)
    assert cal.n_combinations > 1
    assert cal.minima[0]["rotation_from_best_deg"] == 0.0
    assert sum(m["starts"] for m in cal.minima) <= 4
    # the best minimum is the truth's: consistent with its covariance
    chk = truth_check(pose_error(cal.T_r_c, scene.T_r_c), cal.cov, names=TRUTH_NAMES)
    assert chk.passed, chk


def test_refinement_jacobian_matches_finite_differences():
    cam, scene, rng = _scene(3)
    n, d = scene.planes()
    obs = simulate_markerless(cam, scene.T_c_r, scene.body_points_r, n, d, rng, sigma_px=0.5)
    prob, _, _ = _problem(cam, scene.body_points_r, obs, scene.T_r_c, n, d + 0.01, 0.5)
    p = prob.initial_params()
    p["rot_rc"] = np.array([0.01, -0.02, 0.005])
    p["plane_a"] = np.full((3, 2), 0.02)
    chk = prob.check_jacobian(p)
    assert chk.max_rel_error < 1e-5, chk  # central differences: ~1e-8 relative; above 1e-5 is a bug


def test_conditioning_is_told_in_words():
    cam, scene, rng = _scene(4)
    n, d = scene.planes()
    obs = simulate_markerless(cam, scene.T_c_r, scene.body_points_r, n, d, rng, sigma_px=0.5)
    cal = calibrate_markerless(cam, scene.body_points_r, obs, sigma_px=0.5)
    text = cal.conditioning["text"]
    assert "rotation about" in text and " deg " in text and "mm" in text and "condition number" in text
    # the worded figure is the covariance's largest rotation std
    worst = np.degrees(np.sqrt(np.linalg.eigvalsh(cal.cov[:3, :3]).max()))
    assert f"{worst:.2g} deg" in text
    assert cal.conditioning["condition_number"] > 1


def test_a_point_missing_in_one_pose_is_allowed_and_counted():
    cam, scene, rng = _scene(5)
    P = scene.body_points_r[[0, 3, 17, 9]]
    n, d = scene.planes()
    obs = simulate_markerless(cam, scene.T_c_r, P, n, d, rng, sigma_px=0.3)
    obs[1] = MarkerlessObservation(obs[1].uv[1:], obs[1].ids[1:], obs[1].name)
    cal = calibrate_markerless(cam, P, obs, sigma_px=0.3)
    msg = [w.message for w in cal.warnings if w.code == "dropped"]
    assert any("1 reflection(s) not seen" in m and "11 of 12 used" in m for m in msg), msg
    assert truth_check(pose_error(cal.T_r_c, scene.T_r_c), cal.cov, names=TRUTH_NAMES).passed


def test_too_few_poses_or_points_are_refused():
    cam, scene, rng = _scene(6)
    n, d = scene.planes()
    obs = simulate_markerless(cam, scene.T_c_r, scene.body_points_r, n, d, rng)
    with pytest.raises(NotEnoughDataError, match=r"need >= 3 mirror poses .* got 2"):
        calibrate_markerless(cam, scene.body_points_r, obs[:2])
    with pytest.raises(NotEnoughDataError, match=r"reference_points: need >= 3 points .* got 2"):
        calibrate_markerless(cam, scene.body_points_r[:2], [MarkerlessObservation(o.uv[:2], [0, 1], o.name)
                                                             for o in obs])


def test_parallel_mirror_normals_are_named():
    cam, scene, rng = _scene(7)
    n, d = scene.planes()
    n_par = np.repeat(n[:1], 3, axis=0)  # one mirror orientation, shifted only
    obs = simulate_markerless(cam, scene.T_c_r, scene.body_points_r, n_par, d[0] + np.array([0.0, 0.1, -0.1]),
                              rng, sigma_px=0.1)
    with pytest.raises(DegenerateGeometryError, match="all mirror normals are parallel"):
        calibrate_markerless(cam, scene.body_points_r, obs)


def test_mixed_poses_with_and_without_markers_in_one_problem():
    from robocal.rigs.mirror.calibrate import calibrate
    from robocal.rigs.mirror.mixed import calibrate_mixed
    from robocal.rigs.mirror.model import MirrorScene
    from robocal.rigs.mirror.simulate import simulate_observations
    from robocal.rigs.mirror.workflow import markerless_setup

    rng = np.random.default_rng(3)
    cam, scene, P = markerless_setup(4, rng, points=8)
    n, d = scene.planes()
    with_markers = simulate_observations(cam, MirrorScene(scene.T_c_r, scene.T_c_m[:2], P, scene.rectangle), rng)
    without = simulate_markerless(cam, scene.T_c_r, P, n[2:], d[2:], rng, sigma_px=0.5)
    mix = calibrate_mixed(cam, scene.rectangle, P, with_markers, without, sigma_px=0.5)
    assert truth_check(pose_error(mix.T_r_c, scene.T_r_c), mix.cov, names=TRUTH_NAMES).passed
    assert mix.T_c_m.shape == (2, 4, 4) and mix.normals.shape == (2, 3)
    # the two markerless poses add information: every translation std below the markers-only one (measured
    # 22/55/14 mm against 65/71/46 mm: a first-order property of the same geometry, not a noise draw)
    only = calibrate(cam, scene.rectangle, P, with_markers, sigma_px=0.5)
    assert np.all(mix.std_translation < only.std_translation)
    assert "rotation about" in mix.conditioning["text"]


def test_many_poses_enumerate_only_the_first_three_poses_combinations(monkeypatch):
    import robocal.rigs.mirror.markerless as ml

    monkeypatch.setattr(ml, "MAX_COMBINATIONS", 1)  # force the first-three path (else taken beyond 256)
    cam, scene, rng = _scene(8, K=5)
    P = scene.body_points_r[THREE]
    n, d = scene.planes()
    obs = simulate_markerless(cam, scene.T_c_r, P, n, d, rng, sigma_px=0.0)
    cal = calibrate_markerless(cam, P, obs)
    assert cal.n_combinations > 1
    # noise-free: the rest of the poses' P3P solutions chosen by the reflection test, refined to rounding
    assert np.abs(pose_error(cal.T_r_c, scene.T_r_c)).max() < 1e-9
