"""CLI smoke tests over the example input, the plan and the demo."""

import json
from pathlib import Path

import numpy as np
import pytest

from robocal.cli import DemoContext
from robocal.cli.main import main
from robocal.kinematics import KinematicTree
from robocal.rigs.humanoid.cli import RIG
from robocal.rigs.humanoid.plan import plan_poses

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "humanoid" / "run.yaml"


def test_calibrate_example_and_report(tmp_path, capsys):
    out = tmp_path / "cal"
    assert main(["humanoid", "calibrate", str(EXAMPLE), "--out", str(out), "--tie"]) == 0
    d = json.loads((out / "result.json").read_text())
    assert d["rig"] == "humanoid" and "RHipYawPitch" in d["diagnostics"]["tied"]
    assert (out / "report.html").stat().st_size > 10_000
    urdf = next(out.glob("*_calibrated.urdf"))
    assert KinematicTree.from_urdf(urdf).n_joints == 14
    assert "joint_offsets" in (out / "offsets.yaml").read_text()
    assert main(["humanoid", "report", str(out / "result.json"), "--out", str(tmp_path / "rep")]) == 0
    assert (tmp_path / "rep" / "report.html").is_file()
    assert "LM iterations" in capsys.readouterr().out


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text(EXAMPLE.read_text().replace("images/view000.png", "images/nothere.png"))
    assert main(["humanoid", "calibrate", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nothere.png" in err[0]


def test_plan_beats_random_order(model):
    plan = plan_poses(model, 10, np.random.default_rng(3), n_candidates=30)
    rows = plan.table()
    assert len(plan.feet) == 10 and set(plan.feet) == {"left", "right"}
    planned = rows[-1]["worst joint std [deg]"]
    rnd = rows[-1]["random order: worst joint std [deg]"]
    assert planned is not None and (rnd is None or planned < rnd)
    # the uncertainty shrinks (never grows) as poses are added once everything is determined
    w = [r["worst joint std [deg]"] for r in rows if r["worst joint std [deg]"] is not None]
    assert np.all(np.diff(w) <= 1e-12)


def test_plan_command(tmp_path):
    assert main(["humanoid", "plan", "--poses", "6", "--candidates", "20", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "plan.yaml").is_file() and (tmp_path / "report.html").is_file()


def test_demo_passes(tmp_path):
    outcome = RIG.demo(DemoContext(out_dir=tmp_path, rng=np.random.default_rng(2026), progress=False))
    assert outcome.passed, outcome.summary
    assert "RMS x/y" in outcome.summary and (tmp_path / "result.json").is_file()


def test_help_lists_examples(capsys):
    with pytest.raises(SystemExit):
        main(["humanoid", "calibrate", "--help"])
    assert "examples/humanoid/run.yaml" in capsys.readouterr().out
