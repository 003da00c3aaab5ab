"""A user's own inputs: camera calibration files, the ArUco path on rendered images, bad inputs, gauge limits."""

import json

import cv2
import numpy as np
import pytest
import yaml

from robocal.errors import DetectionError, InconsistentDataError, InputError
from robocal.rigs.mirror.calibrate import (
    MirrorObservation,
    calibrate,
    calibrate_single,
    camera_warnings,
    check_camera,
    rectangle_warnings,
)
from robocal.rigs.mirror.files import load_input, write_input
from robocal.rigs.mirror.model import MirrorScene, ri_from_r_points
from robocal.rigs.mirror.render import BodyTags, default_body_tags, detect_mirror_image, render_mirror_image
from robocal.rigs.mirror.simulate import default_setup, simulate_observations

K = [[800.0, 0.0, 383.5], [0.0, 800.0, 287.5], [0.0, 0.0, 1.0]]
D = [-0.289, -0.06639, 0.0005, 0.00072, 0.0]


@pytest.fixture(scope="module")
def setup():
    cam, scene = default_setup()
    obs = simulate_observations(cam, scene, np.random.default_rng(0), sigma_px=0.5)
    return cam, scene, obs


@pytest.fixture(scope="module")
def rendered():
    """One rendered image of the published scene (distortion, blur 0.6 px, grey noise 2) and its tags."""
    cam, s0 = default_setup()
    tags = default_body_tags()
    scene = MirrorScene(s0.T_c_r, s0.T_c_m, tags.body_points_r(), s0.rectangle)
    return cam, scene, tags, render_mirror_image(cam, scene, tags, rng=np.random.default_rng(0))


def _input_with_camera(tmp_path, setup, camera_block) -> str:
    cam, scene, obs = setup
    p = write_input(tmp_path / "in.yaml", cam, scene.rectangle, scene.body_points_r, obs, sigma_px=0.5)
    doc = yaml.safe_load(p.read_text())
    doc["camera"] = camera_block
    p.write_text(yaml.safe_dump(doc, default_flow_style=None, sort_keys=False))
    return p


# ------------------------------------------------------------------ intrinsics
def test_camera_from_opencv_filestorage_yaml_xml_and_json(tmp_path, setup):
    cam = setup[0]
    for name in ("cam.yaml", "cam.xml"):
        fs = cv2.FileStorage(str(tmp_path / name), cv2.FILE_STORAGE_WRITE)
        fs.write("image_width", 768)
        fs.write("image_height", 576)
        fs.write("camera_matrix", np.array(K))
        fs.write("distortion_coefficients", np.array([D]))
        fs.release()
    assert (tmp_path / "cam.yaml").read_text().startswith(("%YAML:1.0", "%YAML 1.2"))  # OpenCV 4 / 5 header
    (tmp_path / "cam.json").write_text(json.dumps({"camera_matrix": K, "dist_coeffs": [D], "image_size": [768, 576]}))
    (tmp_path / "nosize.json").write_text(json.dumps({"camera_matrix": K, "dist_coeffs": [D]}))
    flat = [v for row in K for v in row]
    (tmp_path / "ros.yaml").write_text(yaml.safe_dump({  # ROS camera_calibration
        "image_width": 768, "image_height": 576, "camera_name": "front", "distortion_model": "plumb_bob",
        "camera_matrix": {"rows": 3, "cols": 3, "data": flat},
        "distortion_coefficients": {"rows": 1, "cols": 5, "data": D}}))
    (tmp_path / "info.yaml").write_text(yaml.safe_dump({  # a CameraInfo echo
        "height": 576, "width": 768, "distortion_model": "plumb_bob", "D": D, "K": flat}))
    for block in ({"file": "cam.yaml"}, {"file": "cam.xml"}, {"file": "cam.json"}, {"file": "ros.yaml"},
                  {"file": "info.yaml"}, {"file": "nosize.json", "width": 768, "height": 576}):
        assert load_input(_input_with_camera(tmp_path, setup, block)).camera == cam, block
    assert load_input(_input_with_camera(tmp_path, setup, "cam.yaml")).camera == cam  # shorthand
    # a key next to 'file' overrides the file's
    over = load_input(_input_with_camera(tmp_path, setup, {"file": "cam.json", "dist": [0, 0, 0, 0]})).camera
    assert np.all(over.dist == 0) and over.fx == 800.0
    with pytest.raises(InputError, match=r"camera.file': camera file .*missing.yaml does not exist"):
        load_input(_input_with_camera(tmp_path, setup, {"file": "missing.yaml"}))


@pytest.mark.parametrize("dist, ok, match", [
    (D[:4], True, None),
    (D + [0.0] * 9, True, None),                          # 14 values, extra terms zero
    (D[:3], False, r"4, 5, 8, 12 or 14 values .* got 3"),
    (D + [0.01, 0.0, 0.0], True, None),                   # the rational model: CameraModel projects it
    (D + [0.0] * 6 + [0.001], True, None),                # thin prism too
    (D + [0.0] * 8 + [0.01], False, r"14 coefficients .*TILTED"),
])
def test_distortion_length_is_checked_by_opencv_model(tmp_path, setup, dist, ok, match):
    block = {"camera_matrix": K, "dist_coeffs": dist, "image_width": 768, "image_height": 576}
    p = _input_with_camera(tmp_path, setup, block)
    if ok:
        assert np.allclose(load_input(p).camera.dist[:4], D[:4])
    else:
        with pytest.raises(InputError, match=match):
            load_input(p)


def test_fisheye_and_mismatched_image_sizes_are_refused_or_warned(tmp_path, setup):
    cam = setup[0]
    fish = {"camera_matrix": K, "D": [0.1, 0.01, 0, 0], "distortion_model": "equidistant",
            "image_width": 768, "image_height": 576}
    with pytest.raises(InputError, match=r"an equidistant \(fisheye\) camera; this rig takes OpenCV's pinhole"):
        load_input(_input_with_camera(tmp_path, setup, fish))
    # principal point outside the declared image: an image size of another resolution
    small = {"camera_matrix": [[1600.0, 0, 959.5], [0, 1600.0, 719.5], [0, 0, 1]], "dist_coeffs": D,
             "image_size": [768, 576]}
    with pytest.raises(InputError, match=r"principal point .* outside the 768 x 576 px image"):
        load_input(_input_with_camera(tmp_path, setup, small))
    # (height, width) instead of cv2's (width, height): inside, but warned with the reason
    swapped = load_input(_input_with_camera(tmp_path, setup, {"camera_matrix": K, "dist_coeffs": D,
                                                                "image_size": [576, 768]})).camera
    assert "width and height swapped" in camera_warnings(swapped)[0].message
    assert camera_warnings(cam) == []
    check_camera(cam)


def test_image_points_of_another_image_size_are_refused(setup):
    cam, scene, obs = setup
    o = obs[0]
    b = o.body_uv.copy()
    b[0] = [cam.width + 30.0, 100.0]  # a point of a larger photo (the old 50 % margin let 1152 px through)
    with pytest.raises(InconsistentDataError, match=r"row 0 = \(798, 100\) px lies outside the 768 x 576"):
        calibrate_single(cam, scene.rectangle, scene.body_points_r, MirrorObservation(o.marker_uv, b))


def test_image_file_of_another_size_names_the_fix(tmp_path, rendered):
    cam, scene, tags, img = rendered
    half = cv2.resize(img, (384, 288))
    with pytest.raises(InputError, match=r"image is 384 x 288 px but the camera .* 768 x 576 px; the image is 0.5 x "
                                         r"the calibration resolution: .* scale fx, fy, cx, cy by 0.5"):
        detect_mirror_image(half, cam, tags, name="shot")
    with pytest.raises(InputError, match=r"width and height look swapped"):
        detect_mirror_image(np.ascontiguousarray(img.T), cam, tags)


# ------------------------------------------------------------------ ArUco path
def test_aruco_ids_and_corners_on_a_distorted_blurred_noisy_image(rendered):
    cam, scene, tags, img = rendered
    o = detect_mirror_image(img, cam, tags, name="shot")
    found = sorted({int(i) // 4 for i in o.body_ids})
    assert len(found) >= 5  # tag 1 is partly hidden behind the box tag 4 in this view
    # reported corners against the true reflections (with distortion)
    from robocal.rigs.mirror.model import mirror_plane

    n, d = mirror_plane(scene.T_c_m[0])
    pc = scene.body_points_r[o.body_ids] @ scene.T_c_r[:3, :3].T + scene.T_c_r[:3, 3]
    truth = cam.project(pc - 2.0 * (pc @ n - d)[:, None] * n)
    err = np.linalg.norm(o.body_uv - truth, axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.15 and err.max() < 0.4  # edge-fitted corners (0.4-0.9 px RMS before)
    m_truth = cam.project_points(scene.rectangle.object_points(), scene.T_c_m[0])
    assert np.abs(o.marker_uv - m_truth).max() < 0.1
    missing = sorted(set(range(len(tags.ids))) - set(found))
    assert [w.code for w in o.warnings] == ["dropped"] * bool(missing)
    if missing:
        assert f"body tag id(s) {[tags.ids[k] for k in missing]} not found" in o.warnings[0].message
        cal = calibrate(cam, scene.rectangle, scene.body_points_r, [o])
        assert any(w.code == "dropped" for w in cal.warnings)  # carried into the result


def test_aruco_occluded_duplicated_and_unknown_tags(rendered):
    cam, scene, tags, img = rendered
    o = detect_mirror_image(img, cam, tags)
    # mirror tag B hidden by a hand: the error names the letter and what was seen
    b = o.marker_uv[1].round().astype(int)
    hidden = img.copy()
    hidden[b[1] - 6:b[1] + 6, b[0] - 30:b[0] + 30] = 150
    with pytest.raises(DetectionError, match=r"mirror tag\(s\) B \(id 41\) not found .* ids found in the image: "
                                             r"\[40, 42, 43\]"):
        detect_mirror_image(hidden, cam, tags, name="shot")
    # a corner of tag B bitten off by a small occluder: still decoded, centre ~1.8 px off -> named
    from robocal.rigs.mirror.render import _detect

    corner = _detect(img)[41][0][2].round().astype(int)
    bitten = img.copy()
    bitten[corner[1] - 4:corner[1] + 5, corner[0] - 4:corner[0] + 5] = 150
    ob = detect_mirror_image(bitten, cam, tags, name="shot", rectangle=scene.rectangle)
    assert [w.indices for w in ob.warnings if "not a square" in w.message] == [(1,)]
    assert not any("not a square" in w.message
                   for w in detect_mirror_image(img, cam, tags, rectangle=scene.rectangle).warnings)
    # a second copy of mirror tag A in view
    a = o.marker_uv[0].round().astype(int)
    twice = img.copy()
    patch = img[a[1] - 30:a[1] + 30, a[0] - 30:a[0] + 30]
    twice[400:460, 20:80] = patch
    with pytest.raises(DetectionError, match=r"mirror tag id\(s\) \[40\] found \[2\] times"):
        detect_mirror_image(twice, cam, tags)
    # body tags: one id used twice on the body (tags 0 and 5 both print id 0) -> both dropped, named;
    # an id missing from the model -> ignored, named
    dup = BodyTags((0, 1, 2, 3, 4, 0), tags.T_r_tag, tags.size)
    unknown = BodyTags((0, 1, 2, 3, 4), tags.T_r_tag[:5], tags.size)
    img_dup = render_mirror_image(cam, scene, dup, rng=np.random.default_rng(1))
    od = detect_mirror_image(img_dup, cam, BodyTags((0, 1, 2, 3, 4, 7), tags.T_r_tag, tags.size))
    msgs = " | ".join(w.message for w in od.warnings)
    assert "body tag id(s) [0] found more than once" in msgs and 0 not in {int(i) // 4 for i in od.body_ids}
    assert all(w.code == "dropped" for w in od.warnings)
    ou = detect_mirror_image(render_mirror_image(cam, scene, tags, rng=np.random.default_rng(2)), cam, unknown)
    assert any("tag id(s) [5] seen in the mirror" in w.message for w in ou.warnings)
    # id 8 of DICT_4X4_50 reads the same in a mirror: named
    from robocal.rigs.mirror.render import mirror_symmetric_ids

    assert mirror_symmetric_ids("DICT_4X4_50") == {8, 9, 17, 47} and not mirror_symmetric_ids("DICT_5X5_100")
    sym = BodyTags((8, 1, 2, 3, 4, 5), tags.T_r_tag, tags.size)
    osym = detect_mirror_image(render_mirror_image(cam, scene, sym, rng=np.random.default_rng(3)), cam, sym)
    assert any("body tag id(s) [8] read the same in a mirror" in w.message for w in osym.warnings)
    assert 0 in {int(i) // 4 for i in osym.body_ids}  # still used


# ------------------------------------------------------------------ bad inputs and what cannot be seen
def test_a_shifted_body_model_moves_the_answer_by_the_shift_in_every_direction(setup):
    # r is defined by the body model: any rigid shift delta of the model gives t_r_c + delta, the same
    # rotation and the same residuals (nothing in the images can see it); not only along x
    cam, scene, obs = setup
    ref = calibrate_single(cam, scene.rectangle, scene.body_points_r, obs[0], sigma_px=0.5)
    for delta in np.eye(3) * 0.1:
        s = calibrate_single(cam, scene.rectangle, scene.body_points_r + delta, obs[0], sigma_px=0.5)
        # two separate iterative solves (SQPnP + LM) of problems that differ by the shift: they agree to
        # the LM's convergence (~2e-9 rad / 1e-9 m measured), not to the last bit, and that depends on the
        # CPU; 1e-7 (rad, m) is far below any real change (~1e-3 for a model off by 1 mm). A pose that
        # close moves a residual by at most fx * 1e-7 rad + fx * 1e-7 m / z (z ~ 0.6 m) ~ 2e-4 px.
        pose_tol = 1e-7
        assert np.allclose(s.T_r_c[:3, 3] - ref.T_r_c[:3, 3], delta, rtol=0, atol=pose_tol)
        assert np.allclose(s.T_r_c[:3, :3], ref.T_r_c[:3, :3], rtol=0, atol=pose_tol)
        assert np.allclose(s.body_residuals, ref.body_residuals, rtol=0, atol=3 * cam.fx * pose_tol)
        assert [w.message for w in s.warnings] == [w.message for w in ref.warnings]
    # ... and every result says so
    from robocal.rigs.mirror.report import result_from_calibration

    res = result_from_calibration(calibrate(cam, scene.rectangle, scene.body_points_r, obs[:1], sigma_px=0.5))
    assert "any vector (x, y or z alike)" in res.diagnostics["unobservable"]


def test_a_flat_model_with_the_x_sign_wrong_is_a_shift_along_x(setup):
    # body points on one face x = c: the x-flipped model is the true one shifted by -2c along x,
    # so it fits exactly and the answer moves by -2c along x
    cam, scene, obs = setup
    face = scene.body_points_r[:4]  # the front face corners, x = 0.45 m
    other = scene.body_points_r[4:8].copy()
    other[:, 0] = 0.45
    P = np.vstack([face, other])
    o = simulate_observations(cam, MirrorScene(scene.T_c_r, scene.T_c_m, P, scene.rectangle),
                              np.random.default_rng(1), sigma_px=0.0)[0]
    good = calibrate_single(cam, scene.rectangle, P, o)
    bad = calibrate_single(cam, scene.rectangle, ri_from_r_points(P), o)
    assert np.allclose(bad.T_r_c[:3, 3] - good.T_r_c[:3, 3], [-0.9, 0.0, 0.0], atol=1e-6)
    assert not any("mirror image" in w.message for w in bad.warnings)


def test_wrong_handedness_is_flagged_without_sigma(setup):
    cam, scene, obs = setup
    good = calibrate_single(cam, scene.rectangle, scene.body_points_r, obs[0])
    assert not any("mirror image" in w.message for w in good.warnings)
    flipped = calibrate_single(cam, scene.rectangle, ri_from_r_points(scene.body_points_r), obs[0])
    w = [w for w in flipped.warnings if "mirror image of body_points" in w.message]
    assert w and w[0].code == "inconsistent_data" and "u and v swapped" in w[0].message
    vu = MirrorObservation(obs[0].marker_uv, obs[0].body_uv[:, ::-1].copy(), name="vu")
    s = calibrate_single(cam, scene.rectangle, scene.body_points_r, vu)  # u, v swapped in body_uv: a reflection
    assert any("mirror image of body_points" in w.message for w in s.warnings)


def test_unit_errors_and_too_small_sigma_are_named(setup):
    cam, scene, obs = setup
    from robocal.camera import MarkerRectangle

    assert rectangle_warnings(scene.rectangle) == []
    w = rectangle_warnings(MarkerRectangle(3.66, 2.56))  # 366 x 256 read as cm
    assert w and "check its unit" in w[0].message
    with pytest.raises(InconsistentDataError, match=r"limit 5 x sigma_px = 0.25 px; if sigma_px = 0.05 px is below"):
        calibrate_single(cam, scene.rectangle, scene.body_points_r, obs[0], sigma_px=0.05)


def test_rectangle_size_errors_swapped_sides_and_a_misfit_are_named(setup):
    cam, scene, obs = setup
    from robocal.camera import MarkerRectangle

    w, h = scene.rectangle.width, scene.rectangle.height
    # width and height swapped (or the order started at B): the error says which rectangle fits
    with pytest.raises(InconsistentDataError, match=r"they fit a 366 x 256 mm one .* width and height are swapped"):
        calibrate_single(cam, MarkerRectangle(h, w), scene.body_points_r, obs[0], sigma_px=0.5)
    # a 16 mm (6 %) height error passes the hard limit; with sigma_px it is flagged by the marker chi-square
    s = calibrate_single(cam, MarkerRectangle(w, h - 0.016), scene.body_points_r, obs[0], sigma_px=0.5)
    assert any("four markers fit a 366 x 240 mm rectangle worse" in m.message for m in s.warnings)
    ok = calibrate_single(cam, scene.rectangle, scene.body_points_r, obs[0], sigma_px=0.5)
    assert not any("four markers" in m.message for m in ok.warnings)


def test_own_camera_example_hashes_the_camera_file_and_a_camera_file_as_input_is_named(tmp_path):
    from pathlib import Path

    from robocal.errors import FileFormatError
    from robocal.rigs.mirror.workflow import calibrate_input, to_result

    ex = Path(__file__).resolve().parents[3] / "examples" / "mirror"
    inp = load_input(ex / "own_camera.yaml")
    assert inp.camera == load_input(ex / "published_single.yaml").camera
    assert inp.camera_file and inp.camera_file.endswith("opencv_camera.yaml")
    result = to_result(calibrate_input(inp, out_dir=tmp_path), inp)
    assert any(k.endswith("opencv_camera.yaml") for k in result.inputs)
    with pytest.raises(FileFormatError, match=r"looks like a camera calibration file .* 'camera: \{file: "):
        load_input(ex / "opencv_camera.yaml")
