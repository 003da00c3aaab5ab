"""CLI: simulate -> calibrate -> report, the example inputs, the ArUco image path, the demo, file errors."""

import json
from pathlib import Path

import numpy as np
import pytest

from robocal.cli import DemoContext
from robocal.cli.main import main
from robocal.rigs.mirror.cli import RIG
from robocal.rigs.mirror.files import load_input

EXAMPLES = Path(__file__).resolve().parents[3] / "examples" / "mirror"


def test_rig_is_registered():
    from robocal.cli import discover_rigs

    assert "mirror" in [r.name for r in discover_rigs()]


def test_simulate_calibrate_report(tmp_path, capsys):
    sim, cal = tmp_path / "sim", tmp_path / "cal"
    assert main(["mirror", "simulate", "--placements", "2", "--seed", "3", "--out", str(sim)]) == 0
    assert main(["mirror", "calibrate", str(sim / "mirror_input.yaml"), "--out", str(cal)]) == 0
    res = json.loads((cal / "result.json").read_text())
    assert res["rig"] == "mirror" and res["schema"] == "robocal.result/1"
    T = np.array(res["estimate"]["T_r_c"])
    truth = np.array(res["diagnostics"]["truth_T_r_c"])
    std = np.array(res["std"]["t_r_c"])
    assert np.all(np.abs(T[:3, 3] - truth[:3, 3]) < 4 * std)
    assert res["units"]["t_r_c"] == "m" and res["residual_unit"] == "px"
    assert len(res["diagnostics"]["single_image"]) == 2
    html = (cal / "report.html").read_text()
    assert "planar" in html and "data:image/png;base64" in html
    assert main(["mirror", "report", str(cal / "result.json"), "--out", str(tmp_path / "rep")]) == 0
    assert (tmp_path / "rep" / "report.html").stat().st_size > 10_000


@pytest.mark.parametrize("name", ["published_single.yaml", "four_placements.yaml", "aruco_images.yaml"])
def test_examples_run(tmp_path, name):
    assert main(["mirror", "calibrate", str(EXAMPLES / name), "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "result.json").read_text())
    T = np.array(res["estimate"]["T_r_c"])
    truth = np.array(res["diagnostics"]["truth_T_r_c"])
    assert np.linalg.norm(T[:3, 3] - truth[:3, 3]) < 4 * np.linalg.norm(res["std"]["t_r_c"])


def test_no_refine(tmp_path):
    assert main(["mirror", "calibrate", str(EXAMPLES / "four_placements.yaml"), "--no-refine",
                 "--out", str(tmp_path)]) == 0
    assert "joint" not in json.loads((tmp_path / "result.json").read_text())["method"]


def test_aruco_example_detects_tags():
    inp = load_input(EXAMPLES / "aruco_images.yaml")
    assert inp.tags is not None and len(inp.observations) == 2
    for o in inp.observations:
        assert len(o.body_ids) >= 12 and len(o.body_ids) % 4 == 0


def _write(tmp_path, text):
    p = tmp_path / "in.yaml"
    p.write_text(text)
    return p


def test_bad_files_give_one_line_errors(tmp_path, capsys):
    base = (EXAMPLES / "published_single.yaml").read_text()
    cases = {
        "missing": ("mirror_rectangle: {width: 366.0, height: 256.0}\n", "", "mirror_rectangle"),
        "unitless": ("units: {length: mm, pixel: px}\n", "units: {pixel: px}\n", "unit"),
        "three markers": ("marker_uv:\n", "marker_uv_ignored:\n", "marker_uv"),
    }
    for label, (old, new, expect) in cases.items():
        assert old in base, label
        p = _write(tmp_path, base.replace(old, new, 1))
        assert main(["mirror", "calibrate", str(p), "--out", str(tmp_path / "o")]) == 2, label
        err = capsys.readouterr().err.strip()
        assert err.startswith("robocal: error:") and "\n" not in err and expect in err, (label, err)
    img = _write(tmp_path, base.replace("- name: placement 0\n", "- name: placement 0\n  image: nowhere.png\n"))
    assert main(["mirror", "calibrate", str(img), "--out", str(tmp_path / "o")]) == 2
    assert "body_tags" in capsys.readouterr().err


def test_demo_runs_and_passes(tmp_path):
    out = RIG.demo(DemoContext(out_dir=tmp_path, rng=np.random.default_rng(2026), progress=False))
    assert out.passed, out.summary
    assert {"1 image error", "4 placements error", "ArUco image error"} <= set(out.summary)
    assert out.result is not None and (tmp_path / "report.html").exists()
