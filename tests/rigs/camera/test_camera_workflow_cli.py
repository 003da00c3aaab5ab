"""`robocal camera calibrate`: the ways in (folder, glob, files, session), the outputs, and bad input as one line."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest

from robocal.camera import camera_from_section, load_camera
from robocal.cli.main import main
from robocal.io import Document, load_result
from robocal.rigs.camera.simulate import simulate_session
from robocal.rigs.camera.workflow import camera_from_result


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """6 rendered views of the 9x6 chessboard (480 x 360 px), written once for the module."""
    out = tmp_path_factory.mktemp("camsim")
    return simulate_session(out, np.random.default_rng(7), views=6, width=480, height=360)


def _run(argv, capsys):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def _one_line_error(code, err):
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


def test_folder_glob_files_and_session_give_the_same_camera(session, tmp_path, capsys):
    sim = session.session.parent
    runs = {
        "session": [session.session],
        "folder": [sim / "images", "--target", session.target_file],
        "glob": [str(sim / "images" / "view_*.png"), "--target", session.target_file],
        "files": [*session.images, "--target", session.target_file],
    }
    est = {}
    for name, argv in runs.items():
        code, out, err = _run(["camera", "calibrate", *argv, "--out", tmp_path / name], capsys)
        assert code == 0, err
        res = load_result(tmp_path / name / "result.json")
        est[name], std = res.estimate, res.std
        assert "6 of 6 image(s) used" in out
    # the same corners, the same problem: the solves agree to the solver's stopping tolerance (measured 2e-9
    # relative; not bit for bit: a threaded BLAS may sum in another order and LM stop one step apart), which
    # is 1e-4 of the std or less
    for name, e in est.items():
        for k, v in e.items():
            assert abs(v - est["session"][k]) <= 1e-4 * std[k], (name, k, v, est["session"][k], std[k])


def test_camera_files_are_read_back_by_the_core_loader_and_a_rig_section(session, tmp_path, capsys):
    code, _, err = _run(["camera", "calibrate", session.session, "--out", tmp_path / "cal"], capsys)
    assert code == 0, err
    res = load_result(tmp_path / "cal" / "result.json")
    cam = camera_from_result(res)
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-0.4, 0.4, (40, 2)), np.ones(40)]) * rng.uniform(0.5, 3.0, (40, 1))
    uv = cam.project(pts)
    for name in ("camera.yaml", "camera_info.yaml", "camera.json"):
        path = tmp_path / "cal" / name
        # the writers keep 17 significant digits: the camera comes back bit-identical; 1e-9 px is a margin of
        # ~1e4 over the rounding of one projection (|uv| ~ 1e3 px, eps 2e-16)
        np.testing.assert_allclose(load_camera(path).project(pts), uv, rtol=0, atol=1e-9)
        sec = camera_from_section(Document({"file": name}, str(tmp_path / "cal" / "rig_input.yaml"), "camera"))
        np.testing.assert_allclose(sec.project(pts), uv, rtol=0, atol=1e-9)
    fs = cv2.FileStorage(str(tmp_path / "cal" / "camera.yaml"), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("camera_matrix").mat(), cam.K, rtol=1e-15)


def test_simulated_result_matches_its_truth_within_the_reported_std(session, tmp_path, capsys):
    code, out, err = _run(["camera", "calibrate", session.session, "--out", tmp_path / "cal"], capsys)
    assert code == 0, err
    res = load_result(tmp_path / "cal" / "result.json")
    check = res.diagnostics["truth_check"]
    assert check["passed"], check
    t = session.camera
    for k, v in (("fx", t.fx), ("fy", t.fy), ("cx", t.cx), ("cy", t.cy)):
        # NEES covers all nine jointly; each alone within 4.5 std (Bonferroni over 9 at 1e-4: z = 4.4)
        assert abs(res.estimate[k] - v) < 4.5 * res.std[k], (k, res.estimate[k], v, res.std[k])
    assert res.residual_unit == "px" and 0 < res.residual_rms < 0.2


def test_report_is_rebuilt_when_the_images_are_gone(session, tmp_path, capsys):
    sim = tmp_path / "sim"
    shutil.copytree(session.session.parent, sim)
    code, _, err = _run(["camera", "calibrate", sim / "camera_input.yaml", "--out", tmp_path / "cal"], capsys)
    assert code == 0, err
    shutil.rmtree(sim / "images")
    code, _, err = _run(["report", tmp_path / "cal" / "result.json", "--out", tmp_path / "rep"], capsys)
    assert code == 0, err
    assert "Projection uncertainty" in (tmp_path / "rep" / "report.html").read_text()


def test_fix_holds_a_term_at_zero_and_models_change_the_labels(session, tmp_path, capsys):
    code, _, err = _run(["camera", "calibrate", session.session, "--fix", "k3", "--out", tmp_path / "a"], capsys)
    assert code == 0, err
    res = load_result(tmp_path / "a" / "result.json")
    assert res.estimate["k3"] == 0.0 and res.std["k3"] == 0.0
    code, _, err = _run(["camera", "calibrate", session.session, "--model", "opencv4", "--out", tmp_path / "b"],
                        capsys)
    assert code == 0, err
    assert load_result(tmp_path / "b" / "result.json").diagnostics["model"] == "opencv4"


def test_target_with_rows_and_cols_swapped_is_named_and_harmless(session, tmp_path, capsys):
    swapped = tmp_path / "swapped.yaml"
    swapped.write_text("type: chessboard\nrows: 9\ncols: 6\nsquare: {value: 25, unit: mm}\n")
    code, _, err = _run(["camera", "calibrate", session.session.parent / "images", "--target", swapped,
                         "--out", tmp_path / "cal"], capsys)
    assert code == 0, err
    res = load_result(tmp_path / "cal" / "result.json")
    assert "target_transposed" in [w.code for w in res.warnings]
    assert abs(res.estimate["fx"] - session.camera.fx) < 5 * res.std["fx"]


def test_square_in_the_wrong_unit_is_named_and_can_be_accepted(session, tmp_path, capsys):
    big = tmp_path / "big.yaml"
    big.write_text("type: chessboard\nrows: 6\ncols: 9\nsquare: {value: 25, unit: m}\n")
    images = session.session.parent / "images"
    code, _, err = _run(["camera", "calibrate", images, "--target", big, "--out", tmp_path / "cal"], capsys)
    err = _one_line_error(code, err)
    assert f"{big}: square" in err and "`square` looks like mm, not m" in err and "200 m across" in err
    code, _, err = _run(["camera", "calibrate", images, "--target", big, "--accept-implausible",
                         "--out", tmp_path / "cal2"], capsys)
    assert code == 0, err
    res = load_result(tmp_path / "cal2" / "result.json")
    (w,) = [w for w in res.warnings if w.code == "implausible_input"]
    assert w.params == ("square_mm_as_m",)


def _write(path, img):
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), img)
    return path


@pytest.mark.parametrize("case", ["no_board", "sizes_differ", "corrupt", "two_views", "no_target", "empty_folder",
                                  "glob_nothing", "target_as_session", "session_unknown_key", "missing"])
def test_bad_input_is_one_line_naming_the_file(case, session, tmp_path, capsys):
    sim = session.session.parent
    target = session.target_file
    imgs = tmp_path / "imgs"
    if case == "no_board":
        for k in range(3):
            _write(imgs / f"blank_{k}.png", np.full((360, 480), 128, np.uint8))
        argv, says = [imgs, "--target", target], ("no 6x9 chessboard", "found in any of the 3 images")
    elif case == "sizes_differ":
        imgs.mkdir()
        for p in session.images[:3]:
            shutil.copy(p, imgs / p.name)
        _write(imgs / "view_zzz.png", np.full((240, 320), 128, np.uint8))
        argv, says = [imgs, "--target", target], (f"{imgs / 'view_zzz.png'}: image size 320x240 differs",)
    elif case == "corrupt":
        imgs.mkdir()
        for p in session.images[:3]:
            shutil.copy(p, imgs / p.name)
        data = (imgs / session.images[1].name).read_bytes()
        (imgs / session.images[1].name).write_bytes(data[: len(data) // 2])
        argv, says = [imgs, "--target", target], (str(imgs / session.images[1].name),)
    elif case == "two_views":
        argv, says = [*session.images[:2], "--target", target], ("2 usable views", "at least 3")
    elif case == "no_target":
        argv, says = [sim / "images"], ("--target: give the target file",)
    elif case == "empty_folder":
        imgs.mkdir()
        (imgs / "notes.txt").write_text("x")
        argv, says = [imgs, "--target", target], (f"folder {imgs} holds no image files",)
    elif case == "glob_nothing":
        argv, says = [str(sim / "images" / "*.jpg"), "--target", target], ("no file matches",)
    elif case == "target_as_session":
        argv, says = [target], (f"{target}: this is a target file, not a session",)
    elif case == "session_unknown_key":
        bad = tmp_path / "session.yaml"
        bad.write_text(session.session.read_text().replace("images:", "imagez: x\nimages:")
                       .replace("target: target.yaml", f"target: {target}")
                       .replace("images/*.png", str(sim / "images" / "*.png"))
                       .replace("camera_truth.yaml", str(sim / "camera_truth.yaml")))
        argv, says = [bad], (str(bad), "imagez")
    else:
        argv, says = [tmp_path / "nothing_here"], (f"{tmp_path / 'nothing_here'}: no such file or folder",)
    code, _, err = _run(["camera", "calibrate", *argv, "--out", tmp_path / "cal"], capsys)
    err = _one_line_error(code, err)
    for s in says:
        assert s in err, (s, err)
    assert not (tmp_path / "cal").exists()  # a failed run that wrote nothing leaves no folder


def test_session_schema_is_documented_and_its_truth_optional(session, tmp_path, capsys):
    sim = session.session.parent
    doc = tmp_path / "mine.json"
    doc.write_text(json.dumps({"target": str(session.target_file), "images": [str(p) for p in session.images]}))
    code, _, err = _run(["camera", "calibrate", doc, "--out", tmp_path / "cal"], capsys)
    assert code == 0, err
    res = load_result(tmp_path / "cal" / "result.json")
    assert "truth_check" not in res.diagnostics and len(res.diagnostics["views"]) == len(session.images)
    assert str(sim) not in json.dumps(res.diagnostics["views"])  # image paths relative to the result


def test_charuco_session_with_partial_views_calibrates_to_its_truth(tmp_path, capsys):
    code, _, err = _run(["camera", "simulate", "--target", "charuco", "--views", "5", "--width", "400", "--height",
                         "300", "--seed", "4", "--out", tmp_path / "sim"], capsys)
    assert code == 0, err
    code, out, err = _run(["camera", "calibrate", tmp_path / "sim" / "camera_input.yaml", "--out", tmp_path / "cal"],
                          capsys)
    assert code == 0, err
    res = load_result(tmp_path / "cal" / "result.json")
    assert res.diagnostics["truth_check"]["passed"], res.diagnostics["truth_check"]
    n_corners = [len(v["ids"]) for v in res.diagnostics["views"].values()]
    assert len(n_corners) == 5 and max(n_corners) <= 24  # 7x5 squares: 6x4 inner corners, some views partial


def test_fisheye_lens_calibrates_with_the_fisheye_model_and_is_not_compared_with_another(tmp_path, capsys):
    code, _, err = _run(["camera", "simulate", "--lens", "fisheye", "--views", "6", "--width", "480", "--height",
                         "360", "--seed", "5", "--out", tmp_path / "sim"], capsys)
    assert code == 0, err
    session = tmp_path / "sim" / "camera_input.yaml"
    code, _, err = _run(["camera", "calibrate", session, "--model", "fisheye", "--out", tmp_path / "cal"], capsys)
    assert code == 0, err
    res = load_result(tmp_path / "cal" / "result.json")
    assert res.diagnostics["truth_check"]["passed"], res.diagnostics["truth_check"]
    assert load_camera(tmp_path / "cal" / "camera_info.yaml").__class__.__name__ == "FisheyeCamera"
    code, _, err = _run(["camera", "calibrate", session, "--out", tmp_path / "cal2"], capsys)
    assert code == 0, err
    res = load_result(tmp_path / "cal2" / "result.json")
    assert "truth_check" not in res.diagnostics and "not compared" in res.diagnostics["truth_note"]


def test_apriltag_grid_session_uses_every_view(tmp_path, capsys):
    code, _, err = _run(["camera", "simulate", "--target", "aruco_grid", "--views", "6", "--width", "480",
                         "--height", "360", "--seed", "1", "--out", tmp_path / "sim"], capsys)
    assert code == 0, err
    code, out, err = _run(["camera", "calibrate", tmp_path / "sim" / "camera_input.yaml", "--out", tmp_path / "cal"],
                          capsys)
    assert code == 0, err
    # small tilted markers measure up to 0.43 marker sides in the layout check: none may be refused for it
    assert "6 of 6 image(s) used" in out, out
    # (no truth check: marker corners are ~5x noisier than saddle points and correlated within a marker, so the
    # std is optimistic on grids; docs/rigs/camera.md, "Limits")


@pytest.mark.parametrize("fmt", ["rosbag1", "rosbag2", "mcap"])
def test_calibrates_from_a_recording_of_each_format(fmt, tmp_path, capsys):
    from robocal.bags import simulate_recording

    bag = tmp_path / ("run.bag" if fmt == "rosbag1" else "run")
    truth = simulate_recording(bag, format=fmt, duration=2.0, image_rate=5.0, image_size=(320, 240),
                               encodings=("mono8", "png"), rng=np.random.default_rng(3))
    target = tmp_path / "board.yaml"
    target.write_text("type: chessboard\nrows: 5\ncols: 7\nsquare: {value: 30, unit: mm}\n")
    out = tmp_path / "cal"
    code, stdout, err = _run(["camera", "calibrate", "--bag", bag, "--topic", "/camera/image_raw/compressed",
                              "--target", target, "--out", out], capsys)
    assert code == 0, err
    res = load_result(out / "result.json")
    names = list(res.diagnostics["views"])
    assert names and all(n.startswith("/camera/image_raw/compressed@") for n in names)
    # the simulated camera: within 5 std of the truth (rendered views, 10 frames of a 7x5 board)
    for k in ("fx", "fy", "cx", "cy"):
        assert abs(res.estimate[k] - getattr(truth.camera, k)) < 5 * res.std[k], (k, res.estimate[k], res.std[k])
    if bag.is_file():  # a ROS 1 bag is one file: its hash is recorded (a ROS 2 bag is a folder)
        assert str(bag) in res.inputs
    # --every: half the frames; a typo in the topic: one line with the closest names
    code, stdout, err = _run(["camera", "calibrate", "--bag", bag, "--topic", "/camera/image_raw", "--every", "2",
                              "--target", target, "--out", tmp_path / "cal2"], capsys)
    assert code == 0, err
    assert len(load_result(tmp_path / "cal2" / "result.json").diagnostics["views"]) <= (len(names) + 1) // 2 + 1
    code, _, err = _run(["camera", "calibrate", "--bag", bag, "--topic", "/camera/imag_raw", "--target", target,
                         "--out", tmp_path / "cal3"], capsys)
    err = _one_line_error(code, err)
    assert "/camera/image_raw" in err
