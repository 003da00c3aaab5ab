"""``read_camera_file``: both FileStorage headers, and one-line errors for broken files."""

import json

import cv2
import numpy as np
import pytest

from robocal.camera import CameraModel, camera_from_document, read_camera_file, read_image
from robocal.errors import FileFormatError, InputError, RobocalError
from robocal.io import Document

K = [[800.0, 0.0, 383.5], [0.0, 801.0, 287.5], [0.0, 0.0, 1.0]]
D = [-0.289, -0.06639, 0.0005, 0.00072, 0.0]

# What cv2.FileStorage writes, verbatim, so that both majors are read whichever one is installed.
_BODY = """image_width: 768
image_height: 576
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 800., 0., 383.5, 0., 801., 287.5, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ -0.289, -0.06639, 5.0000000000000001e-04, 7.2000000000000005e-04, 0. ]
"""
OPENCV4_YAML = "%YAML:1.0\n---\n" + _BODY
OPENCV5_YAML = "%YAML 1.2\n---\n" + _BODY


def _camera(path):
    return camera_from_document(Document(read_camera_file(path), str(path)))


@pytest.mark.parametrize("text", [OPENCV4_YAML, OPENCV5_YAML], ids=["opencv4", "opencv5"])
def test_both_filestorage_headers_read_to_the_same_camera(tmp_path, text):
    p = tmp_path / "cam.yaml"
    p.write_text(text)
    cam = _camera(p)
    assert cam == CameraModel.from_matrix(K, D, 768, 576)


@pytest.mark.parametrize("suffix", [".yaml", ".xml"])
def test_what_the_installed_opencv_writes_is_read_back(tmp_path, suffix):
    p = tmp_path / f"cam{suffix}"
    fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 768)
    fs.write("image_height", 576)
    fs.write("camera_matrix", np.array(K))
    fs.write("distortion_coefficients", np.array([D]))
    fs.release()
    # FileStorage prints doubles with 17 significant digits: the round trip is exact
    assert _camera(p) == CameraModel.from_matrix(K, D, 768, 576)


@pytest.mark.parametrize("name, content, match", [
    ("bin.yaml", bytes(range(256)) * 4, r"bin\.yaml: camera file is not UTF-8 text \(byte 0x80 at offset 128"),
    ("nul.json", b'{"fx": 800}\x00\x00', r"nul\.json: camera file holds NUL bytes"),
    ("empty.yaml", b"  \n", r"empty\.yaml: camera file is empty"),
    ("list.yaml", b"- 1\n- 2\n", r"list\.yaml: .*mapping"),
    ("bad.xml", b"<opencv_storage><a>1</a", r"bad\.xml: cv2\.FileStorage cannot parse this XML file"),
    ("bad.yaml", b"fx: [1, 2\n", r"bad\.yaml"),
    ("cam.txt", b"fx: 1\n", r"cam\.txt: camera file: expected \.yaml"),
])
def test_a_broken_file_is_one_line_naming_the_file(tmp_path, name, content, match):
    p = tmp_path / name
    p.write_bytes(content)
    with pytest.raises(FileFormatError, match=match) as info:
        read_camera_file(p)
    assert "\n" not in str(info.value)


def test_a_folder_or_a_missing_file_is_named(tmp_path):
    (tmp_path / "d.yaml").mkdir()
    with pytest.raises(FileFormatError, match=r"d\.yaml: camera file cannot be read"):
        read_camera_file(tmp_path / "d.yaml")
    with pytest.raises(FileFormatError, match=r"nope\.yaml: camera file not found"):
        read_camera_file(tmp_path / "nope.yaml")


@pytest.mark.parametrize("fx", ["1e300", "1.0e6", ".inf", ".nan", "-800", "0"])
def test_an_absurd_focal_length_is_one_line_naming_file_and_field(tmp_path, fx):
    p = tmp_path / "cam.yaml"
    p.write_text(f"fx: {fx}\nfy: 800\ncx: 383.5\ncy: 287.5\nwidth: 768\nheight: 576\n")
    with pytest.raises(RobocalError, match=r"cam\.yaml.*fx") as info:
        _camera(p)
    assert "\n" not in str(info.value)
    # the same through the OpenCV layout: the error names the matrix
    k = [[float(fx.replace(".inf", "inf").replace(".nan", "nan")), 0, 383.5], [0, 800, 287.5], [0, 0, 1]]
    p = tmp_path / "cam.json"
    p.write_text(json.dumps({"camera_matrix": k, "image_size": [768, 576]}))
    with pytest.raises(RobocalError, match=r"cam\.json.*(camera_matrix|fx)"):
        _camera(p)


def test_the_focal_length_limit_lets_long_lenses_through():
    assert CameraModel(9.9e5, 9.9e5, 320, 240).fx == 9.9e5
    with pytest.raises(InputError, match=r"CameraModel\.fy must be < 1e\+06 px"):
        CameraModel(800, 2e6, 320, 240)


def _png(tmp_path, name="img.png"):
    img = (np.arange(40 * 30) % 251).astype(np.uint8).reshape(30, 40)
    p = tmp_path / name
    assert cv2.imwrite(str(p), img)
    return p, img


def test_read_image_reads_png_and_jpeg(tmp_path):
    p, img = _png(tmp_path)
    np.testing.assert_array_equal(read_image(p), img)  # PNG is lossless: exact
    j = tmp_path / "img.jpg"
    assert cv2.imwrite(str(j), img)
    assert read_image(j).shape == img.shape
    assert read_image(p, grey=False).shape == (30, 40, 3)


@pytest.mark.parametrize("damage, message", [
    (lambda b: b[: len(b) // 2], "cut short"),
    (lambda b: b[:60] + bytes([b[60] ^ 0xFF]) + b[61:], "fails its CRC check"),
    (lambda b: b"", "empty"),
    (lambda b: b"GIF89a not really", "not an image OpenCV can decode"),
])
def test_read_image_names_a_damaged_file_before_decoding(tmp_path, capfd, damage, message):
    p, _ = _png(tmp_path)
    p.write_bytes(damage(p.read_bytes()))
    with pytest.raises(FileFormatError, match=message) as info:
        read_image(p)
    assert str(info.value).startswith(str(p))
    assert capfd.readouterr().err == ""  # libpng never got the file, so printed nothing


def test_read_image_names_a_truncated_jpeg(tmp_path):
    p = tmp_path / "img.jpg"
    assert cv2.imwrite(str(p), np.full((30, 40), 128, np.uint8))
    p.write_bytes(p.read_bytes()[:-100])
    with pytest.raises(FileFormatError, match="no JPEG end-of-image marker"):
        read_image(p)
    with pytest.raises(FileFormatError, match="not found"):
        read_image(tmp_path / "missing.png")
