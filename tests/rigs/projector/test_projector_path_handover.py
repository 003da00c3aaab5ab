"""Paths over one or several heads: pan range, commands.csv status, pre-aiming before a hand-over."""

import math

import numpy as np
import pytest


def test_pan_range_limits_a_path_that_winds_round_the_nadir():
    from robocal.rigs.projector.path import joint_trajectory, plan_multi
    from robocal.rigs.projector.simulate import seed_room_projectors

    A = seed_room_projectors()[0]
    ang = np.linspace(0, 4 * math.pi, 401)  # two loops of radius 2 m round A's nadir at 0.1 m/s
    pts = A.nadir_world + 2.0 * np.column_stack([np.cos(ang), np.sin(ang)])
    t = ang * 2.0 / 0.1
    free = joint_trajectory(A, t, pts)
    assert free.ok and np.ptp(free.theta[:, 0]) == pytest.approx(4 * math.pi, rel=1e-6)  # endless pan: 720 deg
    lim = A.with_(pan_range=(-math.radians(270), math.radians(270)))
    tr = joint_trajectory(lim, t, pts)
    assert not tr.ok and np.all(np.abs(tr.theta[tr.feasible, 0]) <= math.radians(270) + 1e-12)
    # 720 deg of winding centred in a 540 deg range: 90 deg at each end is out
    assert np.mean(~tr.feasible) == pytest.approx(180 / 720, abs=0.01)
    assert "pan beyond its range" in tr.reason[0] and "pan beyond its range" in tr.segments[0]["reason"]
    plan = plan_multi([lim], t, pts)
    status = plan.commands()["status"]
    assert status[200] == "ok" and status[0].startswith("infeasible: A: pan beyond its range")


def test_commands_csv_has_a_status_column_and_plan_json_the_peak_rate(tmp_path):
    import json

    from robocal.cli.main import main

    ex = __import__("pathlib").Path(__file__).resolve().parents[3] / "examples" / "projector" / "path_timed.yaml"
    assert main(["projector", "path", str(ex), "--out", str(tmp_path)]) == 1
    rows = (tmp_path / "commands.csv").read_text().splitlines()
    assert rows[0].endswith(",status")
    blank = [r for r in rows[1:] if ",,,," in r]
    assert blank and all("infeasible: A: pan rate" in r for r in blank)
    assert all(r.endswith(",ok") for r in rows[1:] if r not in blank)
    bad = json.loads((tmp_path / "plan.json").read_text())["infeasible"][0]
    # the stretch's peak (95 deg/s), not its first sample's 66 deg/s, and the slow-down that fixes it
    assert "up to 95.4 deg/s" in bad["reasons"]["A"] and bad["slowdown"]["A"] == pytest.approx(1.59, abs=0.01)


def test_idle_projector_is_pre_aimed_for_its_next_hand_over_within_rate_limits():
    from robocal.rigs.projector.path import plan_multi, sample_polyline
    from robocal.rigs.projector.simulate import seed_room_projectors

    A, B = seed_room_projectors()
    # a wall between the nadirs: above it only A sees the spot, below it only B: A -> B -> A
    t, p, v = sample_polyline([[0, 0], [0, -3.5], [3, -3.5], [3, 0]], 0.3, 0.1)
    plan = plan_multi([A, B], t, p, v, walls=[[-10, -1.8, 10, -1.8]])
    assert plan.ok and [(h["from"], h["to"]) for h in plan.handovers] == [("A", "B"), ("B", "A")]
    streams, preaim = plan.projector_commands()
    on = np.array([s["laser_on"] for s in streams])
    assert np.all(on.sum(axis=0) == 1)  # exactly one laser on at every sample
    for k, (s, proj) in enumerate(zip(streams, (A, B))):
        served = plan.assignment == k
        # where it serves, the head follows its trajectory (up to whole pan turns)
        d = s["theta"][served] - plan.trajectories[k].theta[served]
        assert np.allclose(d[:, 1], 0) and np.allclose(np.mod(d[:, 0] + 1, 2 * math.pi) - 1, 0, atol=1e-9)
        # the commanded stream is continuous and within the rate limits (it used to jump at the hand-over)
        rate = np.abs(np.diff(s["theta"], axis=0)) / np.diff(t)[:, None]
        assert np.all(rate <= np.array(proj.rate_limits) * (1 + 1e-9)), (s["name"], rate.max(axis=0))
    # A stops at t = 6 s and takes over again at 27.4 s: it slews (laser off) and is ready in time
    assert [(a["projector"], a["ok"]) for a in preaim] == [("A", True)]
    assert "slew" in streams[0]["mode"] and preaim[0]["t_ready"] < preaim[0]["t_handover"]
