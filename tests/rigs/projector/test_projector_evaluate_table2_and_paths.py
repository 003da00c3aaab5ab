"""Table 2 protocol, error map, published Table 2, and spot paths over several projectors."""

import math

import numpy as np
import pytest

from robocal.errors import InputError, NotEnoughDataError, ShapeError
from robocal.geometry import matrix_from_angle
from robocal.rigs.projector.evaluate import error_map, evaluate_points, published_table2_errors, table2_grid
from robocal.rigs.projector.model import ProjectorModel
from robocal.rigs.projector.path import joint_trajectory, plan_multi, sample_polyline, segments_blocked
from robocal.rigs.projector.simulate import default_truth, seed_room_projectors


def test_table2_protocol_zero_error_for_perfect_calibration_and_known_error_for_yaw_bias():
    truth = default_truth()
    grid = table2_grid()
    assert grid.shape == (9, 2) and np.allclose(grid[0], [-2.0, -2.0])
    ev = evaluate_points(truth, truth, grid)
    assert ev.reached.all() and ev.max < 1e-9
    # a yaw error delta with t unchanged turns the commanded floor about the world origin:
    # each spot moves by delta * its distance from the origin of {W}
    delta = 1e-3
    wrong = truth.with_(R_0_W=matrix_from_angle("z", delta) @ truth.R_0_W)
    ev = evaluate_points(truth, wrong, grid)
    dist = np.linalg.norm(grid, axis=1)
    assert np.allclose(ev.norm, delta * dist, rtol=2e-3, atol=1e-12)
    rows = ev.rows()
    assert ev.norm[4] < 1e-12 and len(rows) == 9 and rows[0]["error [mm]"] == pytest.approx(1000 * delta * dist[0], rel=2e-3)


def test_error_map_is_nan_outside_reach_and_finite_inside():
    truth = default_truth()
    xs, ys, err = error_map(truth, truth.with_(d1=truth.d1 + 0.01), (-20, 20), (-20, 20), n=21)
    assert err.shape == (21, 21) and np.isnan(err).any() and np.isfinite(err).any()
    assert np.nanmax(err) > 0.01  # 1 cm of h at ~10 m radius


def test_published_table2_statistics():
    pub = published_table2_errors()
    # worst published spots: A at (200, 0) -> (204.3, 0.9) cm; B at (-200, 0) -> (-198.4, -4.9) cm
    assert pub["A"]["max"] == pytest.approx(math.hypot(4.3, 0.9) / 100, rel=1e-9)
    assert pub["B"]["max"] == pytest.approx(math.hypot(1.6, 4.9) / 100, rel=1e-9)
    assert pub["A"]["rms"] == pytest.approx(0.02573, abs=1e-5)
    assert pub["B"]["rms"] == pytest.approx(0.03341, abs=1e-5)
    # A's errors have a +1.6 cm mean in x: a systematic error, not noise
    assert pub["A"]["mean"][0] == pytest.approx(0.01567, abs=1e-4)


def test_sample_polyline_constant_speed_and_bad_input():
    t, p, v = sample_polyline([[0, 0], [1, 0], [1, 1]], 0.5, 0.1)
    assert t[-1] == pytest.approx(4.0) and np.allclose(p[-1], [1, 1])
    assert np.allclose(np.linalg.norm(v, axis=1), 0.5)
    assert np.allclose(np.linalg.norm(np.diff(p, axis=0), axis=1)[:9], 0.05)
    with pytest.raises(NotEnoughDataError):
        sample_polyline([[0, 0]], 1.0, 0.1)
    with pytest.raises(InputError, match="coincide"):
        sample_polyline([[0, 0], [0, 0], [1, 1]], 1.0, 0.1)
    with pytest.raises(InputError, match="> 0"):
        sample_polyline([[0, 0], [1, 1]], -1.0, 0.1)


def test_joint_trajectory_follows_path_and_rates_match_finite_differences():
    A, _ = seed_room_projectors()
    t, p, v = sample_polyline([[-1.0, -1.0], [1.0, -0.5], [1.5, 1.5]], 0.2, 0.02)
    tr = joint_trajectory(A, t, p, v)
    assert tr.ok and not tr.segments
    assert np.abs(A.spot_world(tr.theta)[:, :2] - p).max() < 1e-9
    fd = np.gradient(tr.theta, t, axis=0)
    corner = np.flatnonzero(np.abs(np.diff(v, axis=0)).max(axis=1) > 1e-9)
    inner = np.array([i for i in range(2, len(t) - 2) if np.all(np.abs(corner - i) > 2)])
    assert np.abs(fd[inner] - tr.theta_dot[inner]).max() < 2e-3
    assert np.all(np.isfinite(tr.theta_dot))


def test_path_near_nadir_and_too_fast_is_reported_never_nan():
    m = ProjectorModel(H=3.0, d1=0.1, rate_limits=(math.radians(60), math.radians(60)))
    t = np.arange(0, 4.0, 0.05)
    p = np.column_stack([-1.0 + 0.5 * t, np.full_like(t, 0.15)])  # passes 0.15 m from the nadir
    tr = joint_trajectory(m, t, p)
    assert not tr.ok and np.all(np.isfinite(tr.theta_dot)) and np.all(np.isfinite(tr.theta))
    seg = tr.segments[0]
    assert "pan" in seg["reason"] and seg["slowdown"] > 1.0
    # slowing the path down by that factor makes it feasible
    tr2 = joint_trajectory(m, t * seg["slowdown"] * 1.01, p)
    assert tr2.ok
    # through the nadir itself: the singular stretch is named
    p2 = np.column_stack([-1.0 + 0.5 * t, np.zeros_like(t)])
    tr3 = joint_trajectory(m, t, p2)
    assert any("nadir" in s["reason"] for s in tr3.segments)
    # outside the reachable floor
    far = np.column_stack([np.linspace(10, 20, 5), np.zeros(5)])
    tr4 = joint_trajectory(m, np.arange(5.0), far)
    assert "outside the reachable floor" in tr4.segments[0]["reason"]
    with pytest.raises(InputError, match="increase strictly"):
        joint_trajectory(m, [0.0, 0.0], [[0, 1], [0, 2]])
    with pytest.raises(ShapeError):
        joint_trajectory(m, [0.0, 1.0], [[0, 1, 2], [0, 2, 3]])


def test_segments_blocked():
    walls = [[0, -1, 0, 1]]
    assert segments_blocked([[-1, 0], [-1, 0], [1, 2]], [[1, 0], [-0.5, 0], [1, -2]], walls).tolist() == [
        True, False, False]


def test_two_projectors_hand_over_and_walls_force_the_choice():
    A, B = seed_room_projectors()
    walls = [[-0.5, -3.0, -0.5, 0.5]]
    t, p, v = sample_polyline([[-2.0, -1.5], [-2.0, 1.0], [1.5, 1.5], [3.5, -1.0], [1.0, -4.0]], 0.3, 0.1)
    plan = plan_multi([A, B], t, p, v, walls=walls)
    assert plan.ok and len(plan.handovers) >= 1
    # served samples are never behind a wall for the serving projector, and within its reach
    for k in range(2):
        m = plan.assignment == k
        assert not plan.occluded[k, m].any() and plan.trajectories[k].feasible[m].all()
    h = plan.handovers[0]
    assert plan.available[plan.names.index(h["to"]), h["index"]]
    # with only A, the part of the path behind the wall (seen from A) is infeasible
    only_a = plan_multi([A], t, p, v, walls=[[-3.0, -1.0, 5.0, -1.0]])
    assert not only_a.ok and only_a.infeasible
    cmd = plan.commands()
    assert np.all(np.isfinite(cmd["theta"])) and cmd["theta"].shape == (len(t), 2)
    with pytest.raises(InputError, match="unique"):
        plan_multi([A, A], t, p)
