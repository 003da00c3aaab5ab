"""Simulator: real-photo ground, camera model, gyro, gaps, speed ceiling, wheel slip."""

import numpy as np
import pytest

from robocal.errors import InputError
from robocal.rigs.flow.kernel import FlowConfig, compute_flow
from robocal.rigs.flow.log import steps_from_frames
from robocal.rigs.flow.model import relative_twists
from robocal.rigs.flow.odometry import dead_reckon
from robocal.rigs.flow.simulate import SensorCamera, SimConfig, load_texture, max_speed, simulate_run
from robocal.rigs.flow.workflow import default_sim


def test_camera_model_px4flow_numbers():
    cam = SensorCamera(lens_focal=16e-3)
    assert cam.focal_px == pytest.approx(666.67, abs=0.01)   # 16 mm / (6 um x 4)
    sim = SimConfig(camera=cam, height=1.0)
    assert max_speed(sim) == pytest.approx(2.7, abs=0.01)
    sim = SimConfig(camera=cam, height=0.1)
    assert max_speed(sim) == pytest.approx(0.27, abs=0.005)


def test_texture_fallback_says_so():
    img, note = load_texture("procedural")
    assert img.shape == (512, 512) and "not a photograph" in note
    assert 20 < img.std() < 60
    with pytest.raises(InputError, match="texture"):
        load_texture("carpet")


def test_rendered_motion_gyro_and_heights():
    sim = default_sim("loop", 0.5, supersample=1, gyro_noise=0.0, gyro_bias=0.0, height_noise=0.0)
    run = simulate_run(sim, np.random.default_rng(0))
    assert run.frames.shape == (3, 201, 64, 64)
    tw = relative_twists(run.poses)
    # yaw about the optical axis (pointing down) is minus the robot's yaw rate
    assert np.allclose(run.gyro[:, :, 2], -tw[None, :, 2] * 400, atol=0.05)
    assert np.allclose(run.height / run.true_height, np.asarray(sim.height_scale)[:, None])
    st, flows = steps_from_frames(run.frames, run.t, run.gyro, run.true_height, sim.camera.focal_px)
    assert all(f.valid.all() for f in flows)
    od = dead_reckon(st, sim.array_true)
    assert np.linalg.norm(od.poses[-1, :2] - run.poses[-1, :2]) < 0.01 * 0.2 + 0.002


def test_texture_gap_is_reported_and_fused_around():
    sim0 = default_sim("straight", 0.6, supersample=1)
    run0 = simulate_run(sim0, np.random.default_rng(1), render=False)
    # a low-texture disc where sensor s270 passes in the middle of the drive
    k = len(run0.t) // 2
    p = run0.poses[k]
    r = sim0.array_true.R[2] * np.array([np.cos(sim0.array_true.psi[2]), np.sin(sim0.array_true.psi[2])])
    c, s = np.cos(p[2]), np.sin(p[2])
    centre = p[:2] + np.array([[c, -s], [s, c]]) @ r
    sim = default_sim("straight", 0.6, supersample=1, gaps=((centre[0], centre[1], 0.04),))
    run = simulate_run(sim, np.random.default_rng(1))
    st, flows = steps_from_frames(run.frames, run.t, run.gyro, run.height, sim.camera.focal_px)
    bad = ~flows[2].valid
    assert bad.sum() > 20 and flows[0].valid.all()
    assert set(r for r in np.array(flows[2].reason)[bad]) <= {"low texture", "ambiguous"}
    od = dead_reckon(st, sim.array_nominal)
    assert not od.bridged.any() and not od.used[2, bad].any()
    assert any(w.code == "low_quality" and "s270" in w.message for w in od.warnings)


def test_speed_ceiling_failure_is_visible():
    # 1.5 m/s at 10 cm, 400 Hz, f = 166.7 px: 3.6 px per frame plus turning -> beyond +/-4 px at times
    sim = default_sim("straight", 0.3, supersample=1, speed=1.3)
    assert sim.speed > 0.85 * max_speed(sim)
    fast = default_sim("straight", 0.3, supersample=1, speed=2.0)
    run = simulate_run(fast, np.random.default_rng(2))
    st, flows = steps_from_frames(run.frames, run.t, run.gyro, run.height, fast.camera.focal_px)
    true_px = 2.0 / 400 / (fast.height / fast.camera.focal_px)
    assert true_px > 4.5
    # the matcher cannot report the true 8 px: frames are rejected or wrong, never right
    f = flows[0].flow_px[flows[0].valid]
    assert np.all(np.abs(np.abs(f[:, 0]) - true_px) > 1.0)


def test_wheel_odometry_slips():
    sim = default_sim("loop", 4.0, supersample=1)
    run = simulate_run(sim, np.random.default_rng(3), render=False)
    err = np.linalg.norm(run.wheel_poses[-1, :2] - run.poses[-1, :2])
    assert err > 0.02


def test_library_does_not_need_scikit_image(monkeypatch):
    import subprocess
    import sys

    code = "import sys, robocal.rigs.flow.cli, robocal.rigs.flow.simulate; assert 'skimage' not in sys.modules"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0
    monkeypatch.setitem(sys.modules, "skimage.data", None)  # as if the test extra were not installed
    img, note = load_texture("gravel")
    assert "scikit-image is not installed" in note and img.shape == (512, 512)


def test_gyro_compensation_removes_chassis_rocking():
    # the chassis rocks 1 deg at 3 Hz about a pivot at lens height: pure camera rotation,
    # which eqs. 3-4 must remove (the uncompensated flow carries f * omega * dt of it)
    sim = default_sim("straight", 0.5, supersample=1, rock_amplitude=np.radians(1.0), gyro_noise=0.0, gyro_bias=0.0)
    run = simulate_run(sim, np.random.default_rng(4))
    f = sim.camera.focal_px
    tw = relative_twists(run.poses)
    errs = {}
    for label, gyro in (("compensated", run.gyro), ("raw", np.zeros_like(run.gyro))):
        st, _ = steps_from_frames(run.frames, run.t, gyro, run.true_height, f)
        od = dead_reckon(st, sim.array_true.copy(scale=np.ones(3)))
        errs[label] = np.sqrt(np.mean((od.twists[:, :2] - tw[:, :2]) ** 2))
    assert errs["compensated"] < 0.5 * errs["raw"], errs
