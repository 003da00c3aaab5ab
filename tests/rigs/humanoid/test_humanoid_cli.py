"""CLI smoke tests over the example input, the plan and the demo."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal.workflow import DemoContext
from robocal.cli.main import main
from robocal.kinematics import KinematicTree
from robocal.rigs.humanoid.cli import RIG
from robocal.rigs.humanoid.plan import plan_poses

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "humanoid" / "run.yaml"


def test_calibrate_example_and_report(tmp_path, capsys):
    # the example is simulated with two independent HipYawPitch offsets: calibrated untied, every
    # parameter is within 3 sigma of the truth (with --tie LHipPitch was off by 4.6 sigma)
    out = tmp_path / "cal"
    assert main(["humanoid", "calibrate", str(EXAMPLE), "--out", str(out)]) == 0
    d = json.loads((out / "result.json").read_text())
    assert d["rig"] == "humanoid" and not d["diagnostics"]["tied"] and not d["warnings"]
    truth = yaml.safe_load(EXAMPLE.with_name("truth.yaml").read_text())["truth"]
    z = [(v - truth[k]) / d["std"][k] for k, v in d["estimate"].items()]
    assert len(z) == 21 and max(abs(x) for x in z) < 3.0, z
    assert (out / "report.html").stat().st_size > 10_000
    urdf = next(out.glob("*_calibrated.urdf"))
    assert KinematicTree.from_urdf(urdf).n_joints == 14
    import hashlib

    digest = hashlib.sha256(EXAMPLE.read_bytes()).hexdigest()
    assert f"run.yaml sha256 {digest}" in urdf.read_text().split("<robot", 1)[0]  # provenance comment
    assert "joint_offsets" in (out / "offsets.yaml").read_text()
    text = capsys.readouterr().out
    assert "LM iterations: " in text and " from zero + " in text and "warning" not in text
    assert "simulation truth: NEES " in text and "over 21 parameters" in text and ": consistent with" in text
    assert "also written beside the result: offsets.yaml, nao_h25_legs_head_calibrated.urdf" in text
    assert d["diagnostics"]["truth_check"]["passed"] and d["diagnostics"]["truth_check"]["dof"] == 21
    # the rebuilt report has what the first one had: tables, histograms, per-view RMS, overlays
    assert main(["humanoid", "report", str(out / "result.json"), "--out", str(tmp_path / "rep")]) == 0
    first, again = ((p / "report.html").read_text() for p in (out, tmp_path / "rep"))
    for html in (first, again):
        assert html.count("<img") == 7  # histograms, cost of both passes, per-view RMS, 4 overlays
        for title in ("Simulation truth", "Per-joint offsets and camera correction", "Solver", "Residuals",
                      "Reprojection overlays"):
            assert f"<h2>{title}</h2>" in html
    assert "grey canvas" not in again
    # without the image files the overlays are still drawn, on a grey canvas, and the page says so
    (tmp_path / "moved.json").write_text((out / "result.json").read_text().replace(
        str(EXAMPLE.parent.resolve()), str(tmp_path / "nowhere")))
    assert main(["humanoid", "report", str(tmp_path / "moved.json"), "--out", str(tmp_path / "rep2")]) == 0
    moved = (tmp_path / "rep2" / "report.html").read_text()
    assert moved.count("<img") == 7 and moved.count("(image file not available: grey canvas)</figcaption>") == 4


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text(EXAMPLE.read_text().replace("images/view000.png", "images/nothere.png"))
    assert main(["humanoid", "calibrate", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nothere.png" in err[0]


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf"])
def test_corner_sigma_must_be_finite_and_positive(tmp_path, capsys, value):
    # before: 0 -> LinAlgError traceback (exit 1), -1 accepted and written to result.json
    assert main(["humanoid", "calibrate", str(EXAMPLE), "--corner-sigma", value, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "corner_sigma must be a finite number > 0 px" in err[0] and value in err[0]


def test_bad_options_are_refused_before_detection(tmp_path, capsys, monkeypatch):
    import robocal.rigs.humanoid.detect as det

    def boom(*a, **k):
        raise AssertionError("detection ran before the options were checked")

    monkeypatch.setattr(det, "detect_views", boom)
    for opt, msg in ((["--params", "camera.z"], "camera.z' (the camera's z shift is not observable"),
                     (["--consistency-ratio", "0.5"], "--consistency-ratio"),
                     (["--corner-sigma", "0"], "corner_sigma")):
        assert main(["humanoid", "calibrate", str(EXAMPLE), *opt, "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and msg in err[0]


def test_negative_offset_scale_is_refused(tmp_path, capsys):
    assert main(["humanoid", "simulate", "--offset-scale", "-0.5", "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--offset-scale" in err[0]


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
    # no condition number while some parameter is undetermined (was 8.8e15 next to '—' stds)
    assert rows[0]["worst joint std [deg]"] is None and rows[0]["condition number"] is None
    assert all(r["condition number"] is None for r in rows if r["worst joint std [deg]"] is None)


def test_plan_command(tmp_path, capsys):
    assert main(["humanoid", "plan", "--poses", "6", "--candidates", "20", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "plan.yaml").is_file() and (tmp_path / "report.html").is_file()
    # plan for a data file's robot, a tied model and another corner noise (was: default model only)
    worst = {}
    for tag, extra in (("data", ["--data", str(EXAMPLE)]), ("tie", ["--tie"]),
                       ("sharp", ["--data", str(EXAMPLE), "--corner-sigma", "0.1"])):
        out = tmp_path / tag
        assert main(["humanoid", "plan", "--poses", "6", "--candidates", "12", *extra, "--out", str(out)]) == 0
        doc = yaml.safe_load((out / "plan.yaml").read_text())
        worst[tag] = doc["predicted_std_deg_after_each_pose"][-1]
        assert doc["assumed"]["tied"] == (tag == "tie")
    assert doc["assumed"]["corner_sigma_px"] == 0.1 and worst["sharp"] < worst["data"]
    capsys.readouterr()
    assert main(["humanoid", "plan", "--corner-sigma", "0", "--out", str(tmp_path / "x")]) == 2
    assert "--corner-sigma must be a finite number > 0" in capsys.readouterr().err


def test_demo_passes(tmp_path):
    outcome = RIG.step("demo")(DemoContext(out_dir=tmp_path, rng=np.random.default_rng(2026), progress=False))
    assert outcome.passed, outcome.summary
    assert "RMS x/y" in outcome.summary and "NEES" in outcome.summary
    assert outcome.result.diagnostics["truth_check"]["passed"]
    # its images are saved beside its report, so the result's report rebuilds with them
    assert (tmp_path / "offsets.yaml").is_file() and (tmp_path / "report.html").is_file()
    assert all(Path(p).is_file() for p in outcome.result.diagnostics["images"])


def test_help_lists_examples(capsys):
    with pytest.raises(SystemExit):
        main(["humanoid", "calibrate", "--help"])
    assert "examples/humanoid/run.yaml" in capsys.readouterr().out
