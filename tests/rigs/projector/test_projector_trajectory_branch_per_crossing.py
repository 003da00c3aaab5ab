"""IK branch chosen per stretch between nadir crossings; nadir_snap as a CLI option; near-nadir pass messages."""

import math
from pathlib import Path

import numpy as np
import pytest

from robocal.cli.main import main
from robocal.errors import InputError
from robocal.rigs.projector.model import ProjectorModel
from robocal.rigs.projector.path import (MAX_NADIR_SNAP, check_nadir_snap, joint_trajectory, plan_multi,
                                         sample_polyline)

RATE = math.radians(60)
# from 0.8 m beside the nadir through it, out to (-2, 0), (-2, -2), then back through it to (2, 2): two crossings
TWO_CROSSINGS = [[0.8, 0.0], [-2.0, 0.0], [-2.0, -2.0], [2.0, 2.0]]


def _model(tilt_min_deg, **kw):
    return ProjectorModel(H=3.0, d1=0.1, rate_limits=(RATE, RATE), tilt_min=math.radians(tilt_min_deg), **kw)


def _branches(tr):
    return [b["branch"] for b in tr.branches]


def test_two_crossings_each_decided_on_its_own():
    """tilt_min = -20 deg reaches 1.06 m from the nadir on the negative branch: the first stretch (0.8 m) fits
    on it, so the first crossing is followed; the stretches after both crossings go 2.8 m out and must be on
    eq. (8), so the second crossing cannot be followed. All-or-nothing switching lost both crossings."""
    t, p, v = sample_polyline(TWO_CROSSINGS, 0.3, 0.1)
    m = _model(-20.0)
    tr = joint_trajectory(m, t, p, v)
    assert _branches(tr) == [1, 0, 0]
    assert len(tr.segments) == 1 and tr.segments[0]["stop"] - tr.segments[0]["start"] == 1  # only crossing 2's step
    assert "nadir crossing needs negative tilt" in tr.segments[0]["reason"]
    c1, c2 = tr.branches[1]["start"], tr.branches[2]["start"]
    assert abs(tr.theta[c1, 0] - tr.theta[c1 - 1, 0]) < 1e-6  # followed: pan held, tilt through zero
    assert tr.theta[c1 - 1, 1] < 0 <= tr.theta[c1 + 1, 1]
    assert "followed: pan held" in tr.branches[1]["why"]
    assert "so that the nadir crossing at t = " in tr.branches[0]["why"]
    assert "not followed" in tr.branches[2]["why"] and "tilt below tilt_min" in tr.branches[2]["why"]
    assert c2 > c1 and not tr.feasible[c2] and not tr.feasible[c2 - 1]
    ok = tr.feasible
    assert np.abs(m.spot_world(tr.theta[ok])[:, :2] - p[ok]).max() < 1e-9
    assert np.abs(tr.theta_dot[ok]).max() <= RATE * (1 + 1e-9)


def test_two_crossings_followed_both_ways_or_neither():
    t, p, v = sample_polyline(TWO_CROSSINGS, 0.3, 0.1)
    tr = joint_trajectory(_model(-75.0), t, p, v)
    assert tr.ok and _branches(tr) == [0, 1, 0]
    assert all("followed: pan held" in b["why"] for b in tr.branches[1:])
    tr0 = joint_trajectory(_model(0.0), t, p, v)
    assert _branches(tr0) == [0, 0, 0] and len(tr0.segments) == 2
    assert all("no negative-tilt branch" in b["why"] for b in tr0.branches[1:])
    plan = plan_multi([_model(-20.0)], t, p, v)
    assert len(plan.infeasible) == 1 and [b["branch"] for b in plan.to_dict()["branches"]["projector"]] == [1, 0, 0]


def test_nadir_pass_reports_distance_rate_and_the_snap_that_helps():
    t, p, v = sample_polyline([[-2.0, 3e-3], [2.0, 3e-3]], 0.3, 0.1)  # 3 mm from the nadir
    tr = joint_trajectory(_model(-75.0), t, p, v)
    assert not tr.ok
    note = tr.segments[0]["nadir_pass"]
    assert note["distance"] == pytest.approx(3e-3) and note["pan_rate"] == pytest.approx(100.0)
    assert "passes 3 mm from the nadir" in note["text"] and "5730 deg/s (limit 60 deg/s)" in note["text"]
    s = note["snap"]
    assert 3e-3 <= s <= MAX_NADIR_SNAP and f"--nadir-snap {1000 * s:g}" in note["text"]
    assert joint_trajectory(_model(-75.0), t, p, v, nadir_snap=s).ok  # the suggestion holds on the whole path
    # without negative tilt, snapping cannot help: say how far the path must stay instead
    note0 = joint_trajectory(_model(0.0), t, p, v).segments[0]["nadir_pass"]
    assert note0["snap"] is None and "at least v / limit = 0.29 m" in note0["text"] and "tilt_min < 0" in note0["text"]
    # 5 cm off at 0.3 m/s: no snap up to the maximum fixes it
    t, p, v = sample_polyline([[-2.0, 0.05], [2.0, 0.05]], 0.3, 0.1)
    note = joint_trajectory(_model(-75.0), t, p, v).segments[0]["nadir_pass"]
    assert note["snap"] is None and "no nadir_snap up to 100 mm helps" in note["text"]


def test_check_nadir_snap():
    assert check_nadir_snap(0) == 0.0 and check_nadir_snap(0.05) == 0.05
    for bad in (-1e-3, float("nan"), float("inf"), 0.2, "x", None):
        with pytest.raises(InputError, match="nadir_snap must"):
            check_nadir_snap(bad)


def test_cli_nadir_snap_option(tmp_path, capsys):
    f = tmp_path / "near.yaml"
    f.write_text("units: {length: m, angle: deg, speed: m/s, time: s}\n"
                 "projectors: [{name: A, H: 3.0, d1: 0.1, yaw: 0, t_0_W: [0, 0, -3.0], tilt_min: -75,"
                 " rate_limits: {value: [60, 60], unit: deg/s}}]\n"
                 "path: {waypoints: [[-2, 0.003], [2, 0.003]], speed: 0.3, dt: 0.1}\n")
    assert main(["projector", "path", str(f), "--out", str(tmp_path / "a")]) == 1
    out = capsys.readouterr().out
    assert "passes 3 mm from the nadir" in out and "--nadir-snap " in out, out
    snap = out.split("--nadir-snap ")[1].split(")")[0]
    assert main(["projector", "path", str(f), "--nadir-snap", snap, "--out", str(tmp_path / "b")]) == 0
    out = capsys.readouterr().out
    assert "all feasible" in out and "followed: pan held" in out
    for bad in ("-1", "nan", "1000"):
        assert main(["projector", "path", str(f), "--nadir-snap", bad, "--out", str(tmp_path / "c")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--nadir-snap must be in [0, 100] mm" in err, err


ROOT = Path(__file__).resolve().parents[3]


def _documented_path_commands():
    """``robocal projector path ...`` lines of docs/rigs/projector.md and of the example files' headers, with the
    exit status they state ('exit 1', else 0)."""
    texts = [(ROOT / "docs" / "rigs" / "projector.md").read_text()]
    texts += [f.read_text() for f in sorted((ROOT / "examples" / "projector").glob("path_*.yaml"))]
    cmds = {}
    for text in texts:
        for line in text.splitlines():
            line = line.lstrip("# ").strip()
            if line.startswith("robocal projector path "):
                cmd, _, comment = line.partition("#")
                argv, code = cmd.split()[3:], 1 if "exit 1" in comment else 0
                key = " ".join(argv)
                if cmds.get(key, (argv, code))[1] != code:
                    code = None  # the docs and an example header state different exit statuses
                cmds[key] = (argv, code)
    return [cmds[k] for k in sorted(cmds)]


@pytest.mark.parametrize("argv,code", _documented_path_commands())
def test_documented_path_commands_run_with_the_stated_exit_status(argv, code, tmp_path, capsys):
    argv = [str(ROOT / a) if a.startswith("examples/") else a for a in argv]
    i = argv.index("--out")
    argv[i + 1] = str(tmp_path / "out")
    assert main(["projector", "path", *argv]) == code, capsys.readouterr()


@pytest.mark.parametrize("argv,msg", [
    (["simulate", "--noise", "nan"], "--noise must be a finite sigma > 0 [mm], got nan"),
    (["simulate", "--theta-noise", "inf"], "--theta-noise must be a finite sigma >= 0 [deg], got inf"),
    (["evaluate", "examples/projector/room_A.yaml", "--spacing", "inf"], "--spacing must be a finite distance > 0"),
    (["evaluate", "examples/projector/room_A.yaml", "--center", "nan", "0"], "--center must be two finite"),
    (["path", "examples/projector/path_room.yaml", "--nadir-margin", "-1"], "--nadir-margin must be in [0, 45] deg"),
    (["path", "examples/projector/path_room.yaml", "--limit-margin", "80"], "--limit-margin must be in [0, 45] deg"),
])
def test_bad_numeric_options_are_one_line_exit_2(argv, msg, tmp_path, capsys):
    argv = [str(ROOT / a) if a.startswith("examples/") else a for a in argv]
    assert main(["projector", *argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and msg in err, err


def test_misspelt_keys_in_a_path_input_are_named(tmp_path, capsys):
    text = (ROOT / "examples" / "projector" / "path_nadir.yaml").read_text()
    for wrong, right in (("tilt_min:", "tilt_mim:"), ("  dt: 0.1", "  dtt: 0.1"), ("walls", "walls")):
        f = tmp_path / "p.yaml"
        f.write_text(text.replace(wrong, right) if wrong != "walls" else text + "wall: []\n")
        assert main(["projector", "path", str(f), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        key = {"tilt_min:": "tilt_mim", "  dt: 0.1": "dtt", "walls": "wall"}[wrong]
        assert err.count("\n") == 1 and f".{key}': unknown key" in err or f"'{key}': unknown key" in err, err
        assert "did you mean" in err
    with pytest.raises(InputError, match=r"\[0, 90\] deg/s"):
        ProjectorModel(H=3.0, rate_limits=(0.0, math.radians(90)))


def test_commands_csv_quotes_names_and_reasons_with_commas(tmp_path):
    """The CSV writer formats column by column now (4x faster on 200 000 samples); csv.reader must still read it."""
    import csv

    f = tmp_path / "two.yaml"
    f.write_text("units: {length: m, angle: deg, speed: m/s, time: s}\n"
                 "projectors:\n  - {name: 'A,1', H: 2.9, yaw: 0, t_0_W: [0, 0, -2.9]}\n"
                 "  - {name: 'B \"2\"', H: 2.9, yaw: 0, t_0_W: [-3, 0, -2.9]}\n"
                 "walls: [[1.5, -1, 1.5, 1]]\n"
                 "path: {waypoints: [[-1, 0.6], [4, 0.6]], speed: 0.3, dt: 0.5}\n")
    assert main(["projector", "path", str(f), "--out", str(tmp_path / "o")]) == 0
    rows = list(csv.reader((tmp_path / "o" / "commands.csv").open()))
    assert rows[0][3] == "projector" and {r[3] for r in rows[1:]} == {"A,1", 'B "2"'}
    assert all(len(r) == 9 and r[8] == "ok" for r in rows[1:])
    a = np.array([[float(x) for x in r[:3] + r[4:8]] for r in rows[1:]])
    assert np.all(np.isfinite(a))
    stream = list(csv.reader((tmp_path / "o" / "commands_A_1.csv").open()))
    assert stream[0][-2:] == ["laser_on", "mode"] and {r[-1] for r in stream[1:]} <= {"serve", "slew", "hold"}
