"""Paths through the nadir on the (theta1 + pi, -theta2) IK branch; range-aware pre-aiming; file-safe names."""

import math
from pathlib import Path

import numpy as np
import pytest

from robocal.cli.main import main
from robocal.errors import InputError
from robocal.rigs.projector.model import ProjectorModel
from robocal.rigs.projector.path import (NADIR_SNAP, JointTrajectory, MultiPlan, joint_trajectory, plan_multi,
                                         sample_polyline)

EXAMPLES = Path(__file__).resolve().parents[3] / "examples" / "projector"
RATE = math.radians(60)


def _model(tilt_min_deg=0.0, **kw):
    return ProjectorModel(H=3.0, d1=0.1, rate_limits=(RATE, RATE), tilt_min=math.radians(tilt_min_deg), **kw)


def _line(offset=0.0, phase=0.0, dt=0.1):
    """A straight line along x at 0.3 m/s, ``offset`` (m) from the nadir; ``phase`` shifts the samples."""
    return sample_polyline([[-2.0 - phase, offset], [2.0, offset]], 0.3, dt)


@pytest.mark.parametrize("phase", [0.0, 0.01, 0.015])
def test_line_through_the_nadir_is_followed_on_the_negative_tilt_branch(phase):
    m = _model(-75.0)
    t, p, v = _line(phase=phase)
    tr = joint_trajectory(m, t, p, v)
    assert tr.ok, tr.segments
    # constant pan, the tilt goes through zero to negative values (no pi flip of the pan)
    assert np.ptp(tr.theta[:, 0]) < 1e-9
    assert tr.theta[0, 1] > 0.5 and tr.theta[-1, 1] < -0.5 and np.all(np.diff(tr.theta[:, 1]) < 0)
    # same spot as the path (seed eq. 6 is invariant under the branch), rates finite and within limits
    assert np.abs(m.spot_world(tr.theta)[:, :2] - p).max() < 1e-12
    assert np.all(np.isfinite(tr.theta_dot)) and np.abs(tr.theta_dot).max() <= RATE
    # eq. (9)^-1 agrees with the commanded series' finite differences away from the nadir
    fd = np.gradient(tr.theta, t, axis=0)
    far = np.flatnonzero(np.abs(p[:, 0]) > 0.3)[1:-1]
    assert np.abs(fd[far] - tr.theta_dot[far]).max() < 1e-3


def test_a_line_within_nadir_snap_goes_through_the_nadir_and_a_farther_one_does_not():
    m = _model(-75.0)
    for phase in (0.0, 0.01):  # one sampling puts a sample 0.9 mm from the nadir, the other straddles it
        t, p, v = _line(offset=0.9 * NADIR_SNAP, phase=phase)
        tr = joint_trajectory(m, t, p, v)
        assert tr.ok and np.abs(m.spot_world(tr.theta)[:, :2] - p).max() <= NADIR_SNAP
    # 3 mm off: the pan really has to swing by 180 deg at v / d = 100 rad/s
    t, p, v = _line(offset=3e-3, phase=0.01)
    assert not joint_trajectory(m, t, p, v).ok


def test_line_through_the_nadir_without_negative_tilt_is_infeasible_with_the_reason():
    t, p, v = _line()
    tr = joint_trajectory(_model(0.0), t, p, v)
    assert not tr.ok and len(tr.segments) == 1
    assert "nadir crossing needs negative tilt" in tr.segments[0]["reason"]
    assert any("tilt_min = 0 deg" in r for r in tr.reason)
    # tilt reaching only -5 deg: the line continues to -34.6 deg on that branch, which the reason says
    tr5 = joint_trajectory(_model(-5.0), t, p, v)
    assert not tr5.ok and any("needs tilt down to -34.6 deg, tilt_min = -5 deg" in r for r in tr5.reason), tr5.reason
    # a coarse sampling that steps over the nadir used to pass: eq. (9) at the samples saw no pan motion
    tc, pc, vc = sample_polyline([[-2.25, 0.0], [2.0, 0.0]], 0.3, 1.0)  # samples at -0.15, 0.15 m
    trc = joint_trajectory(_model(0.0), tc, pc, vc)
    assert not trc.ok and "nadir crossing needs negative tilt" in trc.segments[0]["reason"]
    assert joint_trajectory(_model(-75.0), tc, pc, vc).ok
    # coarse sampling 2 cm from the nadir: the pan turns ~180 deg between two samples, said so; at 0.3 m/s
    # finer sampling cannot help (v/d = 859 deg/s), at 0.01 m/s it does (v/d = 29 deg/s < 60 deg/s)
    tc, pc, vc = sample_polyline([[-2.15, 0.02], [2.0, 0.02]], 0.3, 1.0)
    trc = joint_trajectory(_model(-75.0), tc, pc, vc)
    assert not trc.ok and "sample it more finely" not in " ".join(trc.reason)
    assert "v/d = 859 deg/s" in trc.segments[0]["reason"] and trc.segments[0]["nadir_pass"]["snap"] is not None
    tc, pc, vc = sample_polyline([[-2.15, 0.02], [2.0, 0.02]], 0.01, 30.0)
    trc = joint_trajectory(_model(-75.0), tc, pc, vc)
    assert not trc.ok and "sample it more finely" in " ".join(trc.reason)


def test_plan_and_cli_follow_a_line_through_the_nadir_only_with_negative_tilt(tmp_path, capsys):
    t, p, v = _line()
    assert plan_multi([_model(-75.0)], t, p, v).ok and not plan_multi([_model(0.0)], t, p, v).ok
    ex = EXAMPLES / "path_nadir.yaml"
    assert main(["projector", "path", str(ex), "--out", str(tmp_path / "a")]) == 0
    text = "\n".join(line for line in ex.read_text().splitlines() if "tilt_min" not in line)
    (tmp_path / "no_neg.yaml").write_text(text)
    assert main(["projector", "path", str(tmp_path / "no_neg.yaml"), "--out", str(tmp_path / "b")]) == 1
    assert "nadir crossing needs negative tilt" in capsys.readouterr().out


def test_branch_is_chosen_to_keep_the_pan_inside_its_range():
    # behind the head (eq. 8 pan ~180 deg) with cable stops at +-100 deg: only the negative-tilt branch fits
    t, p, v = sample_polyline([[-0.5, -2.0], [0.5, -2.0]], 0.3, 0.1)
    rng = (-math.radians(100), math.radians(100))
    tr0 = joint_trajectory(_model(0.0, pan_range=rng), t, p, v)
    assert not tr0.ok and "pan beyond its range" in tr0.segments[0]["reason"]
    m = _model(-75.0, pan_range=rng)
    tr = joint_trajectory(m, t, p, v)
    assert tr.ok and np.all(tr.theta[:, 1] < 0) and np.abs(tr.theta[:, 0]).max() < math.radians(15)
    assert np.abs(m.spot_world(tr.theta)[:, :2] - p).max() < 1e-12


def test_tilt_min_is_validated():
    with pytest.raises(InputError, match="tilt_min must be in"):
        _model(5.0)
    with pytest.raises(InputError, match="tilt_min must be in"):
        _model(-80.0)


# ------------------------------------------------------- pre-aiming respects pan_range
def test_pre_aim_slew_stays_inside_the_pan_range():
    t = np.arange(7.0)
    pans = np.radians([160, 170, 0, 0, 0, -170, -160])
    th = np.column_stack([pans, np.full(7, 0.5)])
    z = np.zeros(7)
    B = JointTrajectory("B", t, np.zeros((7, 2)), th, np.zeros((7, 2)), np.ones(7, bool), [""] * 7, z + 0.5)
    A = JointTrajectory("A", t, np.zeros((7, 2)), th * 0, np.zeros((7, 2)), np.ones(7, bool), [""] * 7, z + 0.5)
    assign = np.array([1, 1, 0, 0, 0, 1, 1])
    rng = (-math.pi, math.pi)  # cable stops at +-180 deg: the short way from 170 to -170 deg (+20) passes them
    lim = (math.radians(200), math.radians(200))
    plan = MultiPlan(["A", "B"], t, np.zeros((7, 2)), assign, [A, B], np.ones((2, 7), bool), np.zeros((2, 7), bool),
                     [], [], [], [lim, lim], [rng, rng])
    streams, preaim = plan.projector_commands()
    b = streams[1]["theta"][:, 0]
    assert np.all(b >= rng[0] - 1e-9) and np.all(b <= rng[1] + 1e-9), np.degrees(b)
    assert np.allclose(b[5:], pans[5:])  # served on the trajectory's own turn, reached the long way (340 deg)
    assert preaim[0]["t_ready"] == pytest.approx(1.0 + 340 / 200) and preaim[0]["ok"]
    # endless pan: still the short way round (20 deg), continuing on the next turn
    plan.pan_ranges = [None, None]
    b = plan.projector_commands()[0][1]["theta"][:, 0]
    assert np.degrees(b[5]) == pytest.approx(190.0)


# ------------------------------------------------------- file-safe projector names
def test_projector_names_that_collide_as_file_names_are_an_input_error(tmp_path, capsys):
    f = tmp_path / "two.yaml"
    f.write_text("units: {length: m, angle: deg, speed: m/s}\n"
                 "projectors:\n"
                 "  - {name: A/1, H: 2.9, yaw: 0, t_0_W: [0, 0, -2.9]}\n"
                 "  - {name: A 1, H: 2.9, yaw: 0, t_0_W: [3, 0, -2.9]}\n"
                 "path: {waypoints: [[1, 0], [2, 0]], speed: 0.3}\n")
    code = main(["projector", "path", str(f), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "commands_A_1.csv" in err and "'A/1'" in err, err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


# ------------------------------------------------------- path input: a projector's extrinsics from a result file
def test_path_projector_extrinsics_from_a_result_file(tmp_path):
    """``result: r.json`` used to be unreachable (the load sat under the 'not both' raise): t_0_W was then required."""
    from robocal.io import CalibrationResult, write_result
    from robocal.rigs.projector.files import load_path_input

    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    est = dict(R_0_W=R.tolist(), t_0_W=[1.0, 2.0, -2.9], h=2.8, offsets=[0.0, 0.01])
    write_result(tmp_path / "r.json", CalibrationResult(rig="projector", method="nonlinear", estimate=est))
    f = tmp_path / "p.yaml"
    f.write_text("units: {length: m, angle: deg, speed: m/s}\nprojectors: [{name: A, H: 2.9, result: r.json}]\n"
                 "path: {waypoints: [[1, 0], [2, 0]], speed: 0.3}\n")
    m = load_path_input(f).projectors[0]
    assert np.allclose(m.R_0_W, R) and np.allclose(m.t_0_W, [1.0, 2.0, -2.9])
    assert m.h == pytest.approx(2.8) and m.offsets == (0.0, 0.01)
    write_result(tmp_path / "r.json", CalibrationResult(rig="camera", method="x", estimate=est))
    with pytest.raises(InputError, match="expected 'projector'"):
        load_path_input(f)
