"""The workflow through the CLI: simulate -> calibrate -> report, the example inputs, the ArUco image path,
the demo, the result's vocabulary, file errors."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal.cli.main import main
from robocal.io import load_result
from robocal.rigs.mirror.cli import RIG
from robocal.rigs.mirror.files import load_input
from robocal.workflow import DemoContext

EXAMPLES = Path(__file__).resolve().parents[3] / "examples" / "mirror"


def test_rig_is_registered():
    from robocal.cli import discover_rigs

    assert "mirror" in [r.name for r in discover_rigs()]


def test_simulate_calibrate_report(tmp_path, capsys):
    sim, cal = tmp_path / "sim", tmp_path / "cal"
    assert main(["mirror", "simulate", "--placements", "2", "--seed", "3", "--out", str(sim)]) == 0
    assert main(["mirror", "calibrate", str(sim / "mirror_input.yaml"), "--out", str(cal)]) == 0
    res = json.loads((cal / "result.json").read_text())
    assert res["rig"] == "mirror" and res["schema"] == "robocal.result/2"
    t = np.array(res["estimate"]["T_r_c.translation"])
    truth = np.array(res["diagnostics"]["truth_T_r_c"])
    std = np.array(res["std"]["T_r_c.translation"])
    assert np.all(np.abs(t - truth[:3, 3]) < 4 * std)
    assert res["units"]["T_r_c.translation"] == "m" and res["residual_unit"] == "px"
    assert res["poses"]["T_r_c"] == {"rotation_std": "left", "parent": "robot", "child": "camera"}
    assert len(res["diagnostics"]["single_image"]) == 2
    html = (cal / "report.html").read_text()
    assert "planar" in html and "data:image/png;base64" in html
    assert main(["mirror", "report", str(cal / "result.json"), "--out", str(tmp_path / "rep")]) == 0
    assert (tmp_path / "rep" / "report.html").stat().st_size > 10_000


@pytest.mark.parametrize("name", ["published_single.yaml", "four_placements.yaml", "aruco_images.yaml",
                                  "own_camera.yaml"])
def test_examples_run(tmp_path, name):
    assert main(["mirror", "calibrate", str(EXAMPLES / name), "--out", str(tmp_path)]) == 0
    res = load_result(tmp_path / "result.json")
    pose = res.pose("T_r_c")
    truth = np.array(res.diagnostics["truth_T_r_c"])
    assert np.linalg.norm(pose.T[:3, 3] - truth[:3, 3]) < 4 * np.linalg.norm(pose.std_translation)
    # the simulated truth is checked by NEES against the reported covariance (alpha = 1e-3)
    assert res.diagnostics["truth_check"]["passed"] and res.diagnostics["truth_check"]["dof"] == 6


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
    out = RIG.step("demo")(DemoContext(out_dir=tmp_path, rng=np.random.default_rng(2026), progress=False))
    assert out.passed, out.summary
    assert {"1 image error", "4 placements error", "ArUco image error", "4 placements NEES",
            "ArUco image NEES"} <= set(out.summary)
    assert out.result is not None and (tmp_path / "report.html").exists()
    html = (tmp_path / "report.html").read_text()
    assert "NEES" in html and "points drawn on grey" not in html  # the rendered image is drawn under its overlay


def test_report_of_another_rig_or_incomplete_result_is_a_one_line_error(tmp_path, capsys):
    assert main(["mirror", "calibrate", str(EXAMPLES / "published_single.yaml"), "--out", str(tmp_path / "c")]) == 0
    capsys.readouterr()
    good = json.loads((tmp_path / "c" / "result.json").read_text())
    other = dict(good, rig="projector")
    missing = json.loads(json.dumps(good))
    del missing["diagnostics"]["observations"]
    for label, doc, expect in (("other rig", other, "'projector', not 'mirror'"),
                               ("missing key", missing, "diagnostics.observations")):
        p = tmp_path / f"{label.replace(' ', '_')}.json"
        p.write_text(json.dumps(doc))
        assert main(["mirror", "report", str(p), "--out", str(tmp_path / "r")]) == 2, label
        err = capsys.readouterr().err.strip()
        assert err.startswith("robocal: error:") and "\n" not in err and expect in err and p.name in err, err


@pytest.mark.parametrize("argv, expect", [(["--sigma", "-1"], "--sigma"), (["--sigma", "nan"], "--sigma"),
                                         (["--placements", "0"], "--placements")])
def test_simulate_rejects_bad_arguments(tmp_path, capsys, argv, expect):
    with pytest.raises(SystemExit) as exc:  # argparse usage errors exit 2 from the parser
        main(["mirror", "simulate", *argv, "--out", str(tmp_path)])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and expect in err


def test_noise_free_simulation_round_trips(tmp_path):
    # --sigma 0: the file must not carry sigma_px: 0 (calibrate requires sigma_px > 0)
    assert main(["mirror", "simulate", "--sigma", "0", "--out", str(tmp_path / "s")]) == 0
    assert load_input(tmp_path / "s" / "mirror_input.yaml").sigma_px is None
    assert main(["mirror", "calibrate", str(tmp_path / "s" / "mirror_input.yaml"), "--out", str(tmp_path / "c")]) == 0


def test_calibration_errors_name_the_input_file(tmp_path):
    # errors raised during calibration (not parsing) must still name the file
    from robocal.cli._workflow import calibrate_files
    from robocal.errors import NotEnoughDataError

    doc = yaml.safe_load((EXAMPLES / "published_single.yaml").read_text())
    doc["images"][0]["body_uv"] = doc["images"][0]["body_uv"][:3]
    doc["images"][0]["body_ids"] = [0, 1, 2]
    p = tmp_path / "three_body_points.yaml"
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(NotEnoughDataError) as exc:
        calibrate_files(RIG, [p], out_dir=tmp_path / "o")
    assert str(exc.value).startswith(str(p)) and "at least 4" in str(exc.value)


def test_planar_choice_is_reported_on_stdout_in_result_and_report(tmp_path, capsys):
    from robocal.camera import MarkerRectangle
    from robocal.rigs.mirror.files import write_input
    from robocal.rigs.mirror.model import MirrorScene
    from robocal.rigs.mirror.simulate import default_setup, simulate_observations

    cam, s0 = default_setup()
    scene = MirrorScene(s0.T_c_r, s0.T_c_m, s0.body_points_r, MarkerRectangle(0.12, 0.084))  # ambiguous
    obs = simulate_observations(cam, scene, np.random.default_rng(0), sigma_px=0.5)
    p = write_input(tmp_path / "amb.yaml", cam, scene.rectangle, scene.body_points_r, obs, sigma_px=0.5)
    assert main(["mirror", "calibrate", str(p), "--out", str(tmp_path / "c")]) == 0
    out = capsys.readouterr().out
    assert "planar choice: 1 of 1 image(s) had two marker poses" in out
    pc = json.loads((tmp_path / "c" / "result.json").read_text())["diagnostics"]["single_image"][0]["planar_choice"]
    assert pc["ambiguous"] and len(pc["candidate_T_r_c"]) == 2 and "marker_rms_px_per_point" in pc
    assert "marker_rms_px" not in pc  # one name per definition (single_image[k].marker_rms_px is per coordinate)
    html = (tmp_path / "c" / "report.html").read_text()
    assert "decisive" in html and ("other pose&#x27;s t_r_c" in html or "other pose's t_r_c" in html)
    # the published scene has no ambiguity: no line
    assert main(["mirror", "calibrate", str(EXAMPLES / "published_single.yaml"), "--out", str(tmp_path / "d")]) == 0
    assert "planar choice" not in capsys.readouterr().out


def test_image_paths_are_relative_to_the_result_and_missing_images_are_said(tmp_path):
    import shutil

    work = tmp_path / "a"
    shutil.copytree(EXAMPLES, work / "inputs")
    assert main(["mirror", "calibrate", str(work / "inputs" / "aruco_images.yaml"), "--out", str(work / "cal")]) == 0
    images = json.loads((work / "cal" / "result.json").read_text())["diagnostics"]["images"]
    assert images and all(not Path(p).is_absolute() and p.startswith("..") for p in images.values())
    assert "points drawn on grey" not in (work / "cal" / "report.html").read_text()
    # the run moves as a whole: the report still finds the images; one that is gone is said,
    # not silently replaced by grey
    moved = tmp_path / "b"
    shutil.move(str(work), str(moved))
    (moved / "inputs" / "placement_1.png").unlink()
    assert main(["mirror", "report", str(moved / "cal" / "result.json"), "--out", str(tmp_path / "r")]) == 0
    html = (tmp_path / "r" / "report.html").read_text()
    assert "placement_1.png (points drawn on grey)" in html and "placement_0.png (points drawn" not in html


def test_report_says_when_overlays_are_capped(tmp_path):
    assert main(["mirror", "simulate", "--placements", "5", "--seed", "1", "--out", str(tmp_path / "s")]) == 0
    assert main(["mirror", "calibrate", str(tmp_path / "s" / "mirror_input.yaml"), "--out", str(tmp_path / "c")]) == 0
    assert "Overlays for the first 4 of 5 images" in (tmp_path / "c" / "report.html").read_text()


def test_aruco_path_with_rotated_tags_and_configured_mirror_tags(tmp_path):
    # body tags need not be upright on +x_r faces; the mirror tags' ids and dictionary are input
    import cv2

    from robocal.errors import InputError
    from robocal.geometry import transform_from
    from robocal.rigs.mirror.files import write_input
    from robocal.rigs.mirror.model import MirrorScene
    from robocal.rigs.mirror.render import BodyTags, MirrorTags, default_body_tags, render_mirror_image, tag_rotation
    from robocal.rigs.mirror.simulate import default_setup

    cam, s0 = default_setup()
    d = default_body_tags()
    turned = tag_rotation([1.0, 0.0, 0.0], x_axis=[0.0, 0.0, 1.0])  # front face, tag turned 90 deg
    T = np.stack([transform_from(turned, t[:3, 3]) if k >= 4 else t for k, t in enumerate(d.T_r_tag)])
    tags = BodyTags(d.ids, T, d.size, "DICT_5X5_100")
    mt = MirrorTags((10, 11, 12, 13), "DICT_5X5_100")
    scene = MirrorScene(s0.T_c_r, s0.T_c_m, tags.body_points_r(), s0.rectangle)
    img = render_mirror_image(cam, scene, tags, rng=np.random.default_rng(0), mirror_tags=mt)
    cv2.imwrite(str(tmp_path / "shot.png"), img)

    class _Obs:
        name = "shot"

    p = write_input(tmp_path / "in.yaml", cam, s0.rectangle, None, [_Obs()], tags=tags, image_files={0: "shot.png"},
                    mirror_tags=mt)
    inp = load_input(p)
    assert inp.tags.dictionary == "DICT_5X5_100" and inp.mirror_tags == mt
    assert np.allclose(inp.body_points_r, tags.body_points_r(), atol=1e-9)
    o = inp.observations[0]
    assert {4, 5} <= set(int(i) // 4 for i in o.body_ids)  # the turned tags are found
    from robocal.rigs.mirror.calibrate import calibrate

    cal = calibrate(inp.camera, inp.rectangle, inp.body_points_r, inp.observations)
    assert np.linalg.norm(cal.T_r_c[:3, 3] - s0.T_r_c[:3, 3]) < 4 * np.linalg.norm(cal.std_translation)
    # default tags and mirror tags round-trip too (no mirror_tags block, no dictionary key)
    d_scene = MirrorScene(s0.T_c_r, s0.T_c_m, d.body_points_r(), s0.rectangle)
    cv2.imwrite(str(tmp_path / "plain.png"), render_mirror_image(cam, d_scene, d, rng=np.random.default_rng(0)))
    p2 = write_input(tmp_path / "plain.yaml", cam, s0.rectangle, None, [_Obs()], tags=d, image_files={0: "plain.png"})
    assert "mirror_tags" not in p2.read_text() and "dictionary" not in p2.read_text()
    plain = load_input(p2)
    assert plain.mirror_tags is None and np.allclose(plain.body_points_r, d.body_points_r(), atol=1e-9)
    # a body tag with a mirror tag's id (same dictionary) is refused, naming the field
    text = p.read_text().replace("- id: 0\n", "- id: 12\n", 1)
    assert text != p.read_text()
    (tmp_path / "clash.yaml").write_text(text)
    with pytest.raises(InputError, match=r"body_tags.tags: ids \[12\] are also mirror tag ids"):
        load_input(tmp_path / "clash.yaml")
