"""The markerless form through the CLI (issue 14): the example, simulate --markerless, the report, bad input."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal.cli.main import main
from robocal.io import load_result
from robocal.rigs.mirror.files import MarkerlessInput, load_input, write_markerless_input
from robocal.rigs.mirror.markerless import simulate_markerless
from robocal.rigs.mirror.workflow import markerless_setup

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "mirror" / "markerless.yaml"


def test_the_example_runs_and_reports(tmp_path, capsys):
    cal = tmp_path / "cal"
    assert main(["mirror", "calibrate", str(EXAMPLE), "--out", str(cal)]) == 0
    out = capsys.readouterr().out
    assert "conditioning: rotation about" in out and " deg " in out
    res = load_result(cal / "result.json")
    d = res.diagnostics
    assert d["markerless"] and len(d["mirror_planes"]) == 3 and len(d["reference_points_r"]) == 3
    assert res.method.startswith("markerless")
    pose = res.pose("T_r_c")  # the shared vocabulary: robot -> camera, left rotation std
    assert res.poses["T_r_c"] == {"rotation_std": "left", "parent": "robot", "child": "camera"}
    assert d["truth_check"]["passed"] and d["truth_check"]["dof"] == 6
    assert np.all(pose.std_translation > 0)
    html = (cal / "report.html").read_text()
    assert "Conditioning:" in html and "Mirror planes" in html and "closed form" in html
    # robocal report rebuilds it from result.json alone
    assert main(["report", str(cal / "result.json"), "--out", str(tmp_path / "rep")]) == 0
    assert "Mirror planes" in (tmp_path / "rep" / "report.html").read_text()


def test_simulate_markerless_then_calibrate(tmp_path):
    sim, cal = tmp_path / "sim", tmp_path / "cal"
    assert main(["mirror", "simulate", "--markerless", "--mirrors", "4", "--points", "6", "--seed", "5",
                 "--out", str(sim)]) == 0
    inp = load_input(sim / "mirror_input.yaml")
    assert isinstance(inp, MarkerlessInput) and len(inp.observations) == 4 and len(inp.points_r) == 6
    assert inp.truth is not None
    assert main(["mirror", "calibrate", str(sim / "mirror_input.yaml"), "--out", str(cal)]) == 0
    res = json.loads((cal / "result.json").read_text())
    assert res["diagnostics"]["truth_check"]["passed"]
    assert len(res["diagnostics"]["closed_form_error"]) == 6


def _write(tmp_path, mutate=None, *, mirrors=3, points=3, seed=2, parallel=False):
    rng = np.random.default_rng(seed)
    cam, scene, P = markerless_setup(mirrors, rng, points=points)
    n, d = scene.planes()
    if parallel:  # one mirror orientation, only shifted between poses
        n, d = np.repeat(n[:1], mirrors, axis=0), d[0] + 0.05 * np.arange(mirrors)
    obs = simulate_markerless(cam, scene.T_c_r, P, n, d, rng, sigma_px=0.3)
    path = write_markerless_input(tmp_path / "in.yaml", cam, P, obs, sigma_px=0.3)
    if mutate is not None:
        doc = yaml.safe_load(path.read_text())
        mutate(doc)
        path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _two_poses(doc):
    doc["mirror_poses"] = doc["mirror_poses"][:2]


def _two_points(doc):
    doc["reference_points"] = doc["reference_points"][:2]
    for p in doc["mirror_poses"]:
        p["uv"] = p["uv"][:2]


def _mm_declared_m(doc):
    doc["units"]["length"] = "m"


def _bad_ids(doc):
    doc["mirror_poses"][1]["ids"] = [0, 1, 7]


@pytest.mark.parametrize("mutate, kw, expected", [
    (_two_poses, {}, r"need >= 3 mirror poses that see >= 3 reference points each, got 2"),
    (_two_points, {}, r"reference_points.*need >= 3 points \(P3P per mirror pose\), got 2"),
    # 3 points: the right P3P combination has parallel normals, a wrong one fits with the camera off the robot
    (None, {"parallel": True},
     r"camera .* m from the nearest reference point .* makes all mirror normals parallel \([01]\.\d\d deg apart\)"),
    (None, {"parallel": True, "points": 6},
     r"all mirror normals are parallel \(largest angle between two poses' normals [01]\.\d\d deg, need >= 2 deg"),
    (_mm_declared_m, {}, r"`reference_points` looks like mm, not m: with /1000"),
    (_bad_ids, {}, r"mirror_poses\[1\]\.ids.*must be rows of reference_points \(0\.\.2\), got 7"),
], ids=["two_poses", "two_points", "parallel_normals_3_points", "parallel_normals_6_points", "mm_declared_m",
        "ids_out_of_range"])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, mutate, kw, expected):
    import re

    path = _write(tmp_path, mutate, **kw)
    assert main(["mirror", "calibrate", str(path), "--out", str(tmp_path / "cal")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and str(path) in err, err
    assert re.search(expected, err), err
    assert not (tmp_path / "cal" / "result.json").exists()


def test_a_point_missing_in_a_pose_is_counted(tmp_path):
    def drop(doc):
        pose = doc["mirror_poses"][2]
        pose["ids"] = [0, 1, 3]
        del pose["uv"][2]

    path = _write(tmp_path, drop, points=4, seed=3)
    assert main(["mirror", "calibrate", str(path), "--out", str(tmp_path / "cal")]) == 0
    res = load_result(tmp_path / "cal" / "result.json")
    msg = [w.message for w in res.warnings if w.code == "dropped"]
    assert any("1 reflection(s) not seen" in m and "11 of 12 used" in m for m in msg), msg
    assert [p["n_points"] for p in res.diagnostics["mirror_planes"]] == [4, 4, 3]


def test_mixed_file_with_and_without_markers(tmp_path):
    from robocal.rigs.mirror.files import write_input
    from robocal.rigs.mirror.model import MirrorScene
    from robocal.rigs.mirror.simulate import simulate_observations

    rng = np.random.default_rng(3)
    cam, scene, P = markerless_setup(4, rng, points=8)
    n, d = scene.planes()
    with_markers = simulate_observations(cam, MirrorScene(scene.T_c_r, scene.T_c_m[:2], P, scene.rectangle), rng)
    without = simulate_markerless(cam, scene.T_c_r, P, n[2:], d[2:], rng, sigma_px=0.5)
    path = write_input(tmp_path / "mixed.yaml", cam, scene.rectangle, P, with_markers, sigma_px=0.5)
    doc = yaml.safe_load(path.read_text())
    doc["mirror_poses"] = [{"name": o.name, "uv": o.uv.tolist(), "ids": o.ids.tolist()} for o in without]
    doc["truth"] = {"R_r_c": scene.T_r_c[:3, :3].tolist(), "t_r_c": (scene.T_r_c[:3, 3] * 1e3).tolist()}
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    assert main(["mirror", "calibrate", str(path), "--out", str(tmp_path / "cal")]) == 0
    res = load_result(tmp_path / "cal" / "result.json")
    assert res.method.startswith("mixed: 2 mirror pose(s) with markers") and res.diagnostics["mixed"]
    assert res.diagnostics["truth_check"]["passed"]
    assert len(res.diagnostics["marker_poses"]) == 2 and len(res.diagnostics["mirror_planes"]) == 2
    assert "mirror poses with markers" in (tmp_path / "cal" / "report.html").read_text()


def test_chessboard_through_the_mirror_image_set(tmp_path):
    sim, cal = tmp_path / "sim", tmp_path / "cal"
    assert main(["mirror", "simulate", "--markerless", "--images", "--mirrors", "3", "--seed", "1",
                 "--out", str(sim)]) == 0
    assert len(list(sim.glob("mirror_pose_*.png"))) == 3
    assert main(["mirror", "calibrate", str(sim / "mirror_input.yaml"), "--out", str(cal)]) == 0
    res = load_result(cal / "result.json")
    assert res.diagnostics["truth_check"]["passed"]
    assert [p["n_points"] for p in res.diagnostics["mirror_planes"]] == [35, 35, 35]  # 5 x 7 corners each
    assert sum(k.endswith(".png") for k in res.inputs) == 3  # the images are hashed as inputs


def _unflipped_uv_file(tmp_path, sim):
    """The simulated file with pose 0's points as the plain (unflipped) detector labels them."""
    from robocal.camera import ChessboardTarget, detect_target, read_image

    doc = yaml.safe_load((sim / "mirror_input.yaml").read_text())
    det = detect_target(read_image(sim / "mirror_pose_0.png"), ChessboardTarget(5, 7, 0.04))
    assert det is not None  # the trap: found, labelled as a direct view
    doc["mirror_poses"][0] = {"name": "mirror pose 0", "uv": det.image_points.tolist(),
                              "ids": [int(i) for i in det.ids]}
    path = sim / "unflipped.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def test_a_target_in_unmirrored_order_is_refused_with_the_fix(tmp_path, capsys):
    sim = tmp_path / "sim"
    assert main(["mirror", "simulate", "--markerless", "--images", "--mirrors", "3", "--seed", "1",
                 "--out", str(sim)]) == 0
    path = _unflipped_uv_file(tmp_path, sim)
    capsys.readouterr()
    assert main(["mirror", "calibrate", str(path), "--out", str(tmp_path / "cal")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and str(path) in err and "mirror_poses[0].uv" in err, err
    assert "unmirrored order" in err and "Fix: detect on the flipped image" in err and "i*7+j -> i*7+(6-j)" in err
    # a target frame of the other handedness is refused too
    doc = yaml.safe_load((sim / "mirror_input.yaml").read_text())
    doc["reference_target"]["R_r_t"][0] = [-v for v in doc["reference_target"]["R_r_t"][0]]
    bad = sim / "left_handed.yaml"
    bad.write_text(yaml.safe_dump(doc, sort_keys=False))
    assert main(["mirror", "calibrate", str(bad), "--out", str(tmp_path / "cal2")]) == 2
    assert "must be a rotation" in capsys.readouterr().err
