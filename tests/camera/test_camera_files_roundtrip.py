"""Camera files: write in each format -> read by cv2 / the core loader / every camera rig -> same projection."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal.camera import CameraModel, FisheyeCamera, camera_file_text, load_camera, write_camera
from robocal.errors import InputError

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

# Non-round values in every parameter, so a term dropped, swapped or rounded on the way changes the projection.
CAM = CameraModel(612.3456789012345, 608.9876543210987, 321.123456789, 238.987654321,
                  dist=[-0.2345678901, 0.0876543219, 1.234567e-3, -7.654321e-4, -0.0123456789], width=640, height=480)
FORMATS = [("opencv", "cam.yaml"), ("opencv", "cam.xml"), ("ros", "cam.yaml"), ("json", "cam.json")]


def _points(n=50):
    rng = np.random.default_rng(3)
    # in front of the camera, within ~35 deg of the axis: where the 5-term model is monotonic
    return np.column_stack([rng.uniform(-0.6, 0.6, (n, 2)), np.ones(n)]) * rng.uniform(0.5, 3.0, (n, 1))


def _same_projection(cam):
    # Every writer keeps 17 significant digits (or Python's exact repr): the camera comes back bit-identical,
    # so 1e-9 px is a margin of ~1e4 over the rounding of one projection (|uv| ~ 1e3 px, eps 2e-16).
    np.testing.assert_allclose(cam.project(_points()), CAM.project(_points()), rtol=0, atol=1e-9)
    assert cam == CAM


@pytest.mark.parametrize("fmt,name", FORMATS)
def test_core_loader_reads_every_format_back(tmp_path, fmt, name):
    path = write_camera(tmp_path / name, CAM, format=fmt)
    _same_projection(load_camera(path))


@pytest.mark.parametrize("name", ["cam.yaml", "cam.xml"])
def test_opencv_file_is_read_by_cv2_filestorage(tmp_path, name):
    import cv2

    path = write_camera(tmp_path / name, CAM, format="opencv")
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        K, d = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
        size = (int(fs.getNode("image_width").real()), int(fs.getNode("image_height").real()))
    finally:
        fs.release()
    assert size == CAM.size
    np.testing.assert_array_equal(K, CAM.K)
    np.testing.assert_array_equal(d.ravel(), CAM.dist)
    # cv2's own projection with what cv2 read: the same pixels as robocal's model (both evaluate the same
    # polynomial in double; 1e-9 px covers the different order of the operations)
    uv, _ = cv2.projectPoints(_points(), np.zeros(3), np.zeros(3), K, d)
    np.testing.assert_allclose(uv.reshape(-1, 2), CAM.project(_points()), rtol=0, atol=1e-9)


def test_ros_file_has_the_layout_of_camera_calibration_parsers(tmp_path):
    """The keys, shapes and model name camera_calibration_parsers' readCalibrationYml requires."""
    d = yaml.safe_load(write_camera(tmp_path / "cam.yaml", CAM, format="ros", camera_name="head").read_text())
    assert (d["image_width"], d["image_height"], d["camera_name"]) == (640, 480, "head")
    assert d["distortion_model"] == "plumb_bob"
    for key, rows, cols in (("camera_matrix", 3, 3), ("distortion_coefficients", 1, 5),
                            ("rectification_matrix", 3, 3), ("projection_matrix", 3, 4)):
        assert (d[key]["rows"], d[key]["cols"], len(d[key]["data"])) == (rows, cols, rows * cols), key
    np.testing.assert_array_equal(np.reshape(d["camera_matrix"]["data"], (3, 3)), CAM.K)
    np.testing.assert_array_equal(np.reshape(d["projection_matrix"]["data"], (3, 4))[:, :3], CAM.K)
    np.testing.assert_array_equal(d["distortion_coefficients"]["data"], CAM.dist)


def test_ros_message_echo_forms_and_both_yaml_headers(tmp_path):
    K, D = CAM.K.ravel().tolist(), CAM.dist.tolist()
    # ros2 topic echo /camera_info (lower case), and rostopic echo (ROS 1, upper case)
    ros2 = {"header": {"frame_id": "cam"}, "height": 480, "width": 640, "distortion_model": "plumb_bob", "d": D,
            "k": K, "r": np.eye(3).ravel().tolist(), "p": [0.0] * 12, "binning_x": 0, "binning_y": 0}
    ros1 = {"height": 480, "width": 640, "distortion_model": "plumb_bob", "D": D, "K": K}
    for name, data in (("ros2.yaml", ros2), ("ros1.yaml", ros1)):
        (tmp_path / name).write_text(yaml.safe_dump(data))
        _same_projection(load_camera(tmp_path / name))
    text = camera_file_text(CAM, format="opencv")
    for header in ("%YAML:1.0", "%YAML 1.0"):
        p = tmp_path / f"h{len(header)}.yaml"
        p.write_text(header + "\n" + text.split("\n", 1)[1])  # in place of cv2's own first line
        _same_projection(load_camera(p))


def test_writer_refuses_a_suffix_its_format_cannot_have(tmp_path):
    with pytest.raises(InputError, match=r"a ros camera file is \.yaml or \.yml, got '\.json'"):
        write_camera(tmp_path / "cam.json", CAM, format="ros")
    with pytest.raises(InputError, match="format must be one of opencv, ros, json, got 'matlab'"):
        write_camera(tmp_path / "cam.yaml", CAM, format="matlab")
    assert not list(tmp_path.iterdir())


def _humanoid_camera(tmp_path, camera_section):
    from robocal.rigs.humanoid.dataset import load_dataset

    shutil.copytree(EXAMPLES / "humanoid", tmp_path / "hum")
    run = tmp_path / "hum" / "run.yaml"
    d = yaml.safe_load(run.read_text())
    d["camera"] = camera_section
    run.write_text(yaml.safe_dump(d, sort_keys=False))
    model, _, info = load_dataset(run, detect=False)
    return model.camera, info


def _mirror_camera(tmp_path, camera_section):
    from robocal.rigs.mirror.files import load_input

    d = yaml.safe_load((EXAMPLES / "mirror" / "published_single.yaml").read_text())
    d["camera"] = camera_section
    (tmp_path / "mirror.yaml").write_text(yaml.safe_dump(d, sort_keys=False))
    return load_input(tmp_path / "mirror.yaml").camera


@pytest.mark.parametrize("fmt,name", FORMATS)
def test_every_camera_rig_reads_every_format_through_the_core_loader(tmp_path, fmt, name):
    path = write_camera(tmp_path / name, CAM, format=fmt)
    cam, info = _humanoid_camera(tmp_path, {"file": str(path)})
    _same_projection(cam)
    assert path in [Path(p) for p in info["inputs"]]  # the camera file is hashed with the run's inputs
    _same_projection(_mirror_camera(tmp_path, {"file": str(path)}))
    # (the lineprofiler and hand-eye rigs take no camera intrinsics: nothing to read there)


def test_humanoid_reads_the_opencv_file_the_mirror_rig_ships(tmp_path):
    """Issue 12: the humanoid rig refused this file (`camera.width is missing`)."""
    ref = load_camera(EXAMPLES / "mirror" / "opencv_camera.yaml")
    shutil.copy(EXAMPLES / "mirror" / "opencv_camera.yaml", tmp_path / "ocv.yaml")
    cam, _ = _humanoid_camera(tmp_path, {"file": "../ocv.yaml"})  # relative to the data-set file
    assert cam == ref == _mirror_camera(tmp_path, {"file": "ocv.yaml"})


def test_keys_beside_file_override_the_file(tmp_path):
    path = write_camera(tmp_path / "cam.json", CAM, format="json")
    cam, _ = _humanoid_camera(tmp_path, {"file": str(path), "fx": 700.0})
    assert cam.fx == 700.0 and cam.fy == CAM.fy
    assert json.loads(path.read_text())["fx"] == CAM.fx


RATIONAL = [*CAM.dist, 0.0123, -0.00456, 0.000789]
PRISM = [*RATIONAL, 1.1e-3, -2.3e-4, 3.4e-4, -4.5e-5]


@pytest.mark.parametrize("fmt,name", FORMATS)
@pytest.mark.parametrize("dist", [RATIONAL, PRISM], ids=["rational8", "prism12"])
def test_rational_and_thin_prism_models_round_trip_through_every_rig(tmp_path, fmt, name, dist):
    """OpenCV's 8-term rational model (ROS rational_polynomial) and the 12-term thin-prism one (what
    calibrate_intrinsics(model="opencv8"/"opencv12") gives) keep all their terms through every format and rig."""
    cam = CameraModel(CAM.fx, CAM.fy, CAM.cx, CAM.cy, dist=dist, width=640, height=480)
    if fmt == "ros" and len(dist) == 12:
        # camera_info's models hold 5 or 8 terms: refused in one line naming the formats that can
        with pytest.raises(InputError, match="ROS's distortion models hold 5 .* or 8 .* coefficients, this camera "
                                             "has 12: write it as format='opencv' or 'json'"):
            write_camera(tmp_path / name, cam, format=fmt)
        return
    path = write_camera(tmp_path / name, cam, format=fmt)
    if fmt == "ros":
        assert yaml.safe_load(path.read_text())["distortion_model"] == "rational_polynomial"
    # bit-identical parameters (17 significant digits): 1e-9 px is rounding margin as in _same_projection
    for back in (load_camera(path), _humanoid_camera(tmp_path, {"file": str(path)})[0],
                 _mirror_camera(tmp_path, {"file": str(path)})):
        assert back == cam and back.dist.size == len(dist)
        np.testing.assert_allclose(back.project(_points()), cam.project(_points()), rtol=0, atol=1e-9)


@pytest.mark.slow  # ~10 s: a rendered session calibrated through the CLI, report included
def test_files_the_camera_rig_writes_are_read_by_every_camera_rig(tmp_path, capsys):
    """The issue's round trip end to end: `robocal camera calibrate` writes its camera in the three formats;
    the humanoid and mirror rigs read each (camera: {file: ...}) and project as the calibrated camera does."""
    from robocal.cli.main import main
    from robocal.io import load_result
    from robocal.rigs.camera.simulate import simulate_session
    from robocal.rigs.camera.workflow import CAMERA_FILES, camera_from_result

    sim = simulate_session(tmp_path / "sim", np.random.default_rng(4), views=6, width=320, height=240)
    code = main(["camera", "calibrate", str(sim.session), "--out", str(tmp_path / "cal")])
    assert code == 0, capsys.readouterr().err
    cam = camera_from_result(load_result(tmp_path / "cal" / "result.json"))
    assert set(CAMERA_FILES) == {"camera.yaml", "camera_info.yaml", "camera.json"}  # OpenCV, ROS, JSON
    uv = cam.project(_points())
    for name in CAMERA_FILES:
        path = tmp_path / "cal" / name
        (tmp_path / name).mkdir()  # each rig's data set in a folder of its own
        for back in (load_camera(path), _humanoid_camera(tmp_path / name, {"file": str(path)})[0],
                     _mirror_camera(tmp_path / name, {"file": str(path)})):
            assert back == cam, name
            np.testing.assert_allclose(back.project(_points()), uv, rtol=0, atol=1e-9, err_msg=name)


FISH = FisheyeCamera(400.123456789, 401.5, 639.25, 479.75, k=[0.05, -0.01, 0.002, -3e-4], width=1280, height=960)


@pytest.mark.parametrize("fmt,name", FORMATS)
def test_fisheye_round_trip(tmp_path, fmt, name):
    """An equidistant camera comes back as one (OpenCV files carry distortion_model: equidistant, as ROS's)."""
    import cv2

    path = write_camera(tmp_path / name, FISH, format=fmt)
    back = load_camera(path)
    assert isinstance(back, FisheyeCamera) and back == FISH
    # up to ~60 deg off axis; bit-identical parameters, so 1e-9 px is rounding margin as above
    p = np.column_stack([np.random.default_rng(0).uniform(-1.5, 1.5, (20, 2)), np.ones(20)])
    np.testing.assert_allclose(back.project(p), FISH.project(p), rtol=0, atol=1e-9)
    if fmt == "opencv":  # and cv2.fisheye projects what cv2.FileStorage read to the same pixels
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        K, D = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
        fs.release()
        uv, _ = cv2.fisheye.projectPoints(p.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, D.reshape(4, 1))
        np.testing.assert_allclose(uv.reshape(-1, 2), FISH.project(p), rtol=0, atol=1e-9)


@pytest.mark.parametrize("fmt,name", [("ros", "cam.yaml"), ("json", "cam.json")])
def test_rigs_refuse_a_fisheye_camera_in_one_line(tmp_path, fmt, name):
    """The humanoid and mirror rigs project with the pinhole model: a fisheye file is named, not misread."""
    path = write_camera(tmp_path / name, FISH, format=fmt)
    with pytest.raises(InputError, match=r"camera.file of .*: field '(distortion_model|model)': an equidistant "
                                         r"\(fisheye\) camera; this rig takes OpenCV's pinhole camera"):
        _humanoid_camera(tmp_path, {"file": str(path)})
    with pytest.raises(InputError, match="an equidistant .fisheye. camera; this rig takes"):
        _mirror_camera(tmp_path, {"file": str(path)})
