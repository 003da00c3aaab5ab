"""CLI: every example input runs; bad input is one line with exit status 2; the demo passes."""

import json
from pathlib import Path

import numpy as np
import pytest

from robocal.workflow import DemoContext
from robocal.cli.main import main
from robocal.io import load_result
from robocal.rigs.projector.cli import RIG

EXAMPLES = Path(__file__).resolve().parents[3] / "examples" / "projector"


def run(argv, capsys):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_help_lists_commands_with_examples(capsys):
    with pytest.raises(SystemExit):
        main(["projector", "calibrate", "--help"])
    out = capsys.readouterr().out
    assert "seed_projector_A.yaml" in out and "examples:" in out
    for cmd in ("simulate", "calibrate", "evaluate", "path"):
        with pytest.raises(SystemExit):
            main(["projector", cmd, "--help"])
        assert "examples:" in capsys.readouterr().out


def test_seed_example_reproduces_published_R(tmp_path, capsys):
    code, out, err = run(["projector", "calibrate", EXAMPLES / "seed_projector_A.yaml", "--out", tmp_path], capsys)
    assert code == 0 and "inconsistent_data" in err
    res = load_result(tmp_path / "result.json")
    assert res.rig == "projector" and res.method == "nonlinear"
    seed = res.diagnostics["methods"]["seed"]
    R = np.array(seed["T_0_W.rotation"])
    assert np.array_equal(np.trunc(R[:2, :2] * 1e4) / 1e4, [[0.9991, -0.0419], [0.0419, 0.9991]])
    assert np.allclose(seed["T_0_W.translation"], [2.40, -0.90, -2.90], atol=1e-12)
    assert [w.code for w in res.warnings][0] == "inconsistent_data" and res.warnings[0].indices == (2,)
    assert len(seed["cost_history"]) == seed["iterations"] + 1
    html = (tmp_path / "report.html").read_text()
    assert "Cost curves" in html and "Error map: predicted spot error" in html and html.count("<img") >= 2
    assert res.diagnostics["std_basis"].startswith("residual-scaled")  # the seed's data state no noise
    # strict mode turns the inconsistency into a one-line error
    code, _, err = run(["projector", "calibrate", EXAMPLES / "seed_projector_A.yaml", "--strict", "--out",
                        tmp_path / "s"], capsys)
    assert code == 2 and "suspect point(s) [2]" in err and err.count("\n") == 1


@pytest.mark.parametrize("name", ["room_A.yaml", "room_A_csv.yaml"])
def test_room_examples_calibrate(tmp_path, capsys, name):
    code, out, _ = run(["projector", "calibrate", EXAMPLES / name, "--out", tmp_path], capsys)
    assert code == 0
    res = load_result(tmp_path / "result.json")
    assert res.estimate["h"] == pytest.approx(2.78, abs=4 * res.std["h"])
    # the pose in the shared vocabulary: rotation std = the yaw's about z (roll, pitch held by the level floor)
    assert list(res.poses) == ["T_0_W"] and not any(k.startswith(("R_0_W", "q_0_W", "t_0_W")) for k in res.estimate)
    pose = res.pose("T_0_W")
    assert pose.std_rotation.tolist() == [0.0, 0.0, res.std["yaw"]] and pose.std_translation[2] == 0.0
    assert pose.T[2, 3] == -res.estimate["H"] and np.isclose(res.estimate["T_0_W.rotvec"][2], res.estimate["yaw"],
                                                              rtol=0, atol=1e-15)
    assert res.residual_unit == "m" and res.residual_rms < 0.02
    assert set(res.inputs)  # input hashes recorded
    assert res.diagnostics["std_basis"].startswith("absolute")  # the file states noise: 5 mm
    html = (tmp_path / "report.html").read_text()
    assert "Error map: predicted spot error" in html
    assert ("the actual error against the simulated truth" in html) == (name == "room_A.yaml")  # has 'truth'
    assert html.count("<img") >= 2


def test_simulate_then_evaluate_and_evaluate_with_result(tmp_path, capsys):
    code, *_ = run(["projector", "simulate", "--points", "6", "--seed", "2", "--out", tmp_path / "sim"], capsys)
    assert code == 0
    sim = tmp_path / "sim" / "projector.yaml"
    code, out, _ = run(["projector", "evaluate", sim, "--out", tmp_path / "ev"], capsys)
    assert code == 0 and "spot error RMS" in out
    d = json.loads((tmp_path / "ev" / "result.json").read_text())
    assert len(d["diagnostics"]["evaluation"]["desired"]) == 9
    html = (tmp_path / "ev" / "report.html").read_text()
    # calibration figures + predicted/true error map + the Table 2 heat map
    assert "Error map: predicted spot error" in html and "spot error over the reachable floor" in html
    assert html.count("<img") >= 3
    code, out, _ = run(["projector", "evaluate", sim, "--result", tmp_path / "ev" / "result.json", "--spacing", "1",
                        "--out", tmp_path / "ev2"], capsys)
    assert code == 0 and (tmp_path / "ev2" / "evaluation.json").exists()


def test_path_examples(tmp_path, capsys):
    code, out, _ = run(["projector", "path", EXAMPLES / "path_room.yaml", "--out", tmp_path / "a"], capsys)
    assert code == 0 and "hand-over" in out
    lines = (tmp_path / "a" / "commands.csv").read_text().splitlines()
    assert lines[0].startswith("t [s],x [m],y [m],projector") and len(lines) > 100
    code, out, _ = run(["projector", "path", EXAMPLES / "path_timed.yaml", "--out", tmp_path / "b"], capsys)
    assert code == 1 and "infeasible" in out
    plan = json.loads((tmp_path / "b" / "plan.json").read_text())
    assert "pan rate" in plan["infeasible"][0]["reasons"]["A"]


BAD = {
    "nan.yaml": ("units: {length: cm}\nprojector: {H: 290}\npoints: {world: [[0, 0], [1, .nan], [0, 2]], "
                 "projector: [[0, 0, -290], [1, 0, -290], [0, 2, -290]]}\n", "NaN"),
    "two.yaml": ("units: {length: cm}\nprojector: {H: 290}\npoints: {world: [[0, 0], [1, 0]], "
                 "projector: [[0, 0, -290], [1, 0, -290]]}\n", "at least 3"),
    "collinear.yaml": ("units: {length: cm}\nprojector: {H: 290}\npoints: {world: [[0, 0], [1, 1], [2, 2]], "
                       "projector: [[0, 0, -290], [1, 1, -290], [2, 2, -290]]}\n", "one line"),
    "dup.yaml": ("units: {length: cm}\nprojector: {H: 290}\npoints: {world: [[0, 0], [50, 0], [50, 0], [0, 50]], "
                 "projector: [[0, 0, -290], [50, 0, -290], [50, 0, -290], [0, 50, -290]]}\n", "coincide"),
    "nounit.yaml": ("projector: {H: 290}\npoints: {world: [[0, 0], [1, 0], [0, 1]], "
                    "projector: [[0, 0, -290], [1, 0, -290], [0, 1, -290]]}\n", "has no unit"),
    "badunit.yaml": ("units: {length: furlong}\nprojector: {H: 290}\npoints: {world: [[0, 0], [1, 0], [0, 1]], "
                     "projector: [[0, 0, -290], [1, 0, -290], [0, 1, -290]]}\n", "unknown unit"),
    "mixed.yaml": ("projector: {H: {value: 2.9, unit: m}}\npoints:\n  world: {value: [[0, 0], [60, 60], [0, 90]], "
                   "unit: mm}\n  projector: {value: [[0, 0, -290], [60, 60, -290], [0, 90, -290]], unit: cm}\n",
                   "`points.world` looks like cm declared as mm (10x too small): with x10 the median residual drops"),
    "floor.yaml": ("projector: {H: {value: 2.9, unit: m}}\npoints:\n  world: {value: [[0, 0], [60, 60], [0, 90]], "
                   "unit: cm}\n  projector: {value: [[0, 0, -290], [60, 60, -290], [0, 90, -290]], unit: mm}\n",
                   "z must equal"),
    "shape.yaml": ("units: {length: cm}\nprojector: {H: 290}\npoints: {world: [[0, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0]],"
                   " projector: [[0, 0, -290], [1, 0, -290], [0, 1, -290]]}\n", "shape"),
    "count.yaml": ("units: {length: cm}\nprojector: {H: 290}\npoints: {world: [[0, 0], [1, 0], [0, 1], [1, 1]], "
                   "projector: [[0, 0, -290], [1, 0, -290], [0, 1, -290]]}\n", "has 4 points"),
    "missing.yaml": ("units: {length: cm}\nprojector: {H: 290}\n", "points"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_input_is_one_line_exit_2(tmp_path, capsys, name):
    text, needle = BAD[name]
    f = tmp_path / name
    f.write_text(text)
    code, out, err = run(["projector", "calibrate", f, "--out", tmp_path / "o"], capsys)
    assert code == 2, (out, err)
    assert err.startswith("robocal: error:") and err.count("\n") == 1 and needle in err, err


def test_path_input_with_wrong_unit_kind_is_exit_2(tmp_path, capsys):
    f = tmp_path / "unit.yaml"
    f.write_text("units: {length: m, angle: deg}\nprojectors: [{name: A, H: 2.9, t_0_W: [0, 0, -2.9]}]\n"
                 "path: {waypoints: [[1, 0], [2, 0]], speed: {value: 0.3, unit: deg/s}}\n")
    code, _, err = run(["projector", "path", f, "--out", tmp_path / "o"], capsys)
    assert code == 2 and "speed" in err and err.count("\n") == 1


def test_unreachable_waypoints_are_reported(tmp_path, capsys):
    f = tmp_path / "far.yaml"
    f.write_text("units: {length: m, angle: deg, speed: m/s, time: s}\nprojectors: [{name: A, H: 2.9, t_0_W: [0, 0, -2.9]}]\n"
                 "path: {waypoints: [[1, 0], [30, 0]], speed: 1.0, dt: 0.5}\n")
    code, out, err = run(["projector", "path", f, "--out", tmp_path / "o"], capsys)
    # a point no projector can ever reach is wrong input (exit 2, one line), not a failed plan (exit 1)
    assert code == 2 and err.count("\n") == 1 and "outside every projector's reachable floor" in err, err
    assert "far.yaml" in err and not (tmp_path / "o" / "plan.json").exists()


def test_demo_passes(tmp_path):
    out = RIG.step("demo")(DemoContext(out_dir=tmp_path, rng=np.random.default_rng(2026), progress=False))
    assert out.passed, out.summary
    check = out.result.diagnostics["truth_check"]  # NEES of the primary estimate against the simulated truth
    assert check["passed"] and check["dof"] == 5 and set(check["z"]) == {"yaw", "t_x", "t_y", "h", "tilt_offset"}
    assert out.summary["published R"] == "reproduced" and out.result is not None
    assert any("Table 2" in s.title for s in out.sections)


BEYOND = ("units: {length: m, angle: deg}\nprojector: {H: 2.9, d1: 0.12}\npoints:\n"
          "  world: [[2.738, 15.527], [19.480, -3.435], [-9.046, -24.855], [-1.39, 0.8025]]\n"
          "  joint_angles: [[10, 80], [100, 82], [200, 84], [300, 30]]\n")


def test_calibrate_points_beyond_the_tilt_limit_warn_and_strict_is_exit_2(tmp_path, capsys):
    f = tmp_path / "beyond.yaml"
    f.write_text(BEYOND)
    code, _, err = run(["projector", "calibrate", f, "--out", tmp_path / "o"], capsys)
    assert code == 0 and "[near_singularity] joint_angles: point(s) [0, 1, 2] lie beyond the tilt limit" in err, err
    res = load_result(tmp_path / "o" / "result.json")
    assert [w.indices for w in res.warnings if w.code == "near_singularity"] == [(0, 1, 2)]
    code, _, err = run(["projector", "calibrate", f, "--strict", "--out", tmp_path / "s"], capsys)
    assert code == 2 and err.count("\n") == 1 and "tilt limit of 75 deg" in err, err


def test_joint_angles_in_the_wrong_unit_get_a_unit_hint(tmp_path, capsys):
    f = tmp_path / "rad.yaml"
    f.write_text((EXAMPLES / "room_A.yaml").read_text().replace("angle: deg}", "angle: rad}", 1))
    code, _, err = run(["projector", "calibrate", f, "--out", tmp_path / "o"], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert "'points.joint_angles': row 2" in err and "degrees declared as rad?" in err


def test_evaluate_with_no_reachable_grid_point_is_exit_2_and_partial_grid_warns(tmp_path, capsys):
    room = EXAMPLES / "room_A.yaml"
    code, out, err = run(["projector", "evaluate", room, "--center", "100", "100", "--out", tmp_path / "a"], capsys)
    assert code == 2 and err.count("\n") == 1 and "no Table 2 grid point is on the reachable floor" in err, err
    assert "nan" not in out + err
    code, out, err = run(["projector", "evaluate", room, "--center", "8", "0", "--out", tmp_path / "b"], capsys)
    assert code == 0 and "3/9 reached" in out and "grid point(s) [4, 5, 6, 7, 8, 9]" in err, (out, err)


PATH_BAD = {
    "tz.yaml": ("units: {length: m, angle: deg, speed: m/s}\nprojectors: [{name: A, H: 2.9, t_0_W: [0, 0, -2.5]}]\n"
                "path: {waypoints: [[1, 0], [2, 0]], speed: 0.3}\n", "must equal -H"),
    "both.yaml": ("units: {length: m, angle: deg, speed: m/s}\nprojectors: [{name: A, H: 2.9, t_0_W: [0, 0, -2.9], "
                  "result: r.json}]\npath: {waypoints: [[1, 0], [2, 0]], speed: 0.3}\n", "not both"),
}


@pytest.mark.parametrize("name", sorted(PATH_BAD))
def test_path_projector_extrinsics_are_checked(tmp_path, capsys, name):
    text, needle = PATH_BAD[name]
    f = tmp_path / name
    f.write_text(text)
    code, _, err = run(["projector", "path", f, "--out", tmp_path / "o"], capsys)
    assert code == 2 and err.count("\n") == 1 and needle in err and "projectors[0]" in err, err


def test_simulate_caps_the_number_of_points(tmp_path, capsys):
    code, _, err = run(["projector", "simulate", "--points", "100000000", "--out", tmp_path], capsys)
    assert code == 2 and "--points must be in [3, 10000]" in err and err.count("\n") == 1


def test_path_room_writes_one_stream_per_projector(tmp_path, capsys):
    code, out, _ = run(["projector", "path", EXAMPLES / "path_room.yaml", "--out", tmp_path], capsys)
    assert code == 0 and "commands_A.csv" in out and "commands_B.csv" in out
    a = (tmp_path / "commands_A.csv").read_text().splitlines()
    b = (tmp_path / "commands_B.csv").read_text().splitlines()
    assert a[0].endswith("laser_on,mode") and len(a) == len(b) > 100
    on = [int(ra.split(",")[5]) + int(rb.split(",")[5]) for ra, rb in zip(a[1:], b[1:])]
    assert set(on) == {1}  # one laser on at a time
    # B is aimed at its hand-over pose before it takes over (it used to jump there at t = 28.5 s)
    first_on = next(i for i, r in enumerate(b[1:]) if r.split(",")[5] == "1")
    assert b[1].split(",")[1:3] == b[1 + first_on].split(",")[1:3]


def test_path_retime_slows_the_fast_stretch_down_instead_of_blank_rows(tmp_path, capsys):
    code, out, _ = run(["projector", "path", EXAMPLES / "path_timed.yaml", "--retime", "--out", tmp_path], capsys)
    assert code == 0 and "all feasible" in out and "retimed: 20.000 s -> 20.389 s" in out, out
    rows = [r.split(",") for r in (tmp_path / "commands.csv").read_text().splitlines()[1:]]
    assert all(r[-1] == "ok" for r in rows)
    rates = np.array([[float(r[6]), float(r[7])] for r in rows])
    assert np.degrees(np.abs(rates).max()) <= 60.0 + 1e-6  # the example's 60 deg/s limit, peak 95 deg/s before


def test_cli_nadir_snap_constants_equal_the_path_planner_ones():
    """cli repeats them so that building the parser does not import path (and scipy)."""
    from robocal.rigs.projector import cli, path

    assert cli.NADIR_SNAP == path.NADIR_SNAP
    assert cli.MAX_NADIR_SNAP == path.MAX_NADIR_SNAP


def test_a_result_is_read_back_as_its_pose_by_evaluate_and_path_and_a_v1_file_too(tmp_path, capsys):
    from robocal.rigs.projector.commands import model_from_result
    from robocal.rigs.projector.files import load_calibration_input

    code, *_ = run(["projector", "calibrate", EXAMPLES / "room_A.yaml", "--out", tmp_path / "cal"], capsys)
    assert code == 0
    res = load_result(tmp_path / "cal" / "result.json")
    nominal = load_calibration_input(EXAMPLES / "room_A.yaml").model
    m = model_from_result(tmp_path / "cal" / "result.json", nominal)
    T = res.pose("T_0_W").T
    assert np.array_equal(m.R_0_W, T[:3, :3]) and np.array_equal(m.t_0_W, T[:3, 3])
    assert m.h == pytest.approx(res.estimate["h"], abs=1e-15) and m.offsets == tuple(res.estimate["offsets"])
    # the same estimate as a robocal.result/1 file wrote it (R_0_W, t_0_W as separate keys)
    v1 = {"schema": "robocal.result/1", "rig": "projector", "method": "nonlinear",
          "estimate": {"R_0_W": T[:3, :3].tolist(), "t_0_W": T[:3, 3].tolist(), "h": res.estimate["h"],
                       "offsets": res.estimate["offsets"]}}
    (tmp_path / "v1.json").write_text(json.dumps(v1))
    m1 = model_from_result(tmp_path / "v1.json", nominal)
    assert np.array_equal(m1.R_0_W, m.R_0_W) and np.array_equal(m1.t_0_W, m.t_0_W) and m1.d1 == m.d1
    # a path input naming the result file gets the calibrated head
    f = tmp_path / "path.yaml"
    f.write_text(f"units: {{length: m, angle: deg, speed: m/s, time: s}}\nprojectors: [{{name: A, H: 2.9, "
                 f"result: {tmp_path / 'cal' / 'result.json'}}}]\npath: {{waypoints: [[1.5, -1.5], [3.0, -0.5]], "
                 f"speed: 0.3, dt: 0.2}}\n")
    code, out, err = run(["projector", "path", f, "--out", tmp_path / "path"], capsys)
    assert code == 0 and "all feasible" in out, err
    # a result of another rig is named as such
    other = dict(v1, rig="mirror")
    (tmp_path / "other.json").write_text(json.dumps(other))
    f.write_text(f.read_text().replace(str(tmp_path / "cal" / "result.json"), str(tmp_path / "other.json")))
    code, _, err = run(["projector", "path", f, "--out", tmp_path / "p2"], capsys)
    assert code == 2 and "result of rig 'mirror', expected 'projector'" in err and err.count("\n") == 1, err


def test_report_of_a_result_missing_what_it_draws_is_one_line_exit_2(tmp_path, capsys):
    code, *_ = run(["projector", "calibrate", EXAMPLES / "room_A_csv.yaml", "--out", tmp_path / "cal"], capsys)
    assert code == 0
    d = json.loads((tmp_path / "cal" / "result.json").read_text())
    del d["diagnostics"]["residuals"]
    (tmp_path / "edited").mkdir()
    (tmp_path / "edited" / "result.json").write_text(json.dumps(d))
    code, out, err = run(["report", tmp_path / "edited" / "result.json", "--out", tmp_path / "rep"], capsys)
    assert code == 2 and err.count("\n") == 1 and "'residuals' missing" in err and "Traceback" not in err, err
