"""One reader and one writer for camera calibration files, shared by every camera rig.

Three families of files are read by :func:`load_camera` (and written by
:func:`write_camera`), whatever tool made them:

* **OpenCV FileStorage** YAML (``%YAML:1.0`` of OpenCV 4, ``%YAML 1.0``/``1.2``)
  or XML: ``camera_matrix`` (``!!opencv-matrix``), ``distortion_coefficients``
  (or ``dist_coeffs``), ``image_width``, ``image_height`` -- what OpenCV's
  ``calibration.cpp`` sample and most ``cv2.calibrateCamera`` scripts write;
* **ROS** ``camera_info`` YAML of ``camera_calibration_parsers`` (``camera_matrix:
  {rows, cols, data}``, ``distortion_model``, ``distortion_coefficients``,
  ``image_width``, ``image_height``), and the message itself as ``rostopic echo``
  (``K``, ``D``, ``width``, ``height``) or ``ros2 topic echo`` (``k``, ``d``) print it;
* **robocal** JSON/YAML, :meth:`CameraModel.to_dict` (``fx, fy, cx, cy, dist, width, height``).

The checks on the values are :func:`robocal.camera.camera_from_document`'s;
this module adds the ones a file from another tool needs first, each a
one-line :class:`~robocal.errors.InputError` naming the file and the field:
an image size missing (naming the keys to add, in the file's own layout), a
3x3 matrix that is not a camera matrix (skew, a focal length <= 0, a bottom
row other than ``[0, 0, 1]``), a distortion model ROS does not know.
"""

from __future__ import annotations

import difflib
import json
import os
from pathlib import Path

import numpy as np

from robocal.camera._files import read_camera_file
from robocal.camera._fisheye import FisheyeCamera
from robocal.camera._model import BROWN_CONRADY_MODELS, CameraModel, camera_from_document
from robocal.errors import FileFormatError, InputError

__all__ = ["CAMERA_FILE_FORMATS", "FISHEYE_MODELS", "load_camera", "camera_from_file", "camera_from_mapping",
           "camera_from_section", "camera_file_text", "write_camera"]

#: Formats :func:`write_camera` writes, with the file suffixes each may have.
CAMERA_FILE_FORMATS = {"opencv": (".yaml", ".yml", ".xml"), "ros": (".yaml", ".yml"), "json": (".json",)}

#: ``distortion_model`` values (ROS, kalibr) and robocal ``model`` names of the equidistant fisheye (Kannala-Brandt).
FISHEYE_MODELS = ("equidistant", "fisheye", "kannala_brandt", "kannala-brandt", "equi", "fisheye-kannala-brandt")

#: Other camera models' names (kalibr's) that are neither Brown-Conrady nor equidistant: known, so
#: :func:`camera_from_document` refuses them as models robocal does not represent, not as unknown names.
_OTHER_KNOWN_MODELS = ("double_sphere", "omni", "fov")


def _layout(data: dict) -> str:
    """Which family a mapping is written in: 'ros2' (k, d), 'opencv' (camera_matrix / K) or 'robocal' (fx, ...)."""
    if "camera_matrix" in data or "K" in data:
        return "opencv"
    if "k" in data and "fx" not in data:  # robocal's FisheyeCamera writes k = (k1..k4) beside fx
        return "ros2"
    return "robocal"


#: The image-size keys to name when a file has none, by layout.
_SIZE_KEYS = {"opencv": ("image_width", "image_height"), "ros2": ("width", "height"), "robocal": ("width", "height")}


def _matrix_values(raw):
    """The numbers of a matrix field written as nested lists, a flat list or ``{rows, cols, data}`` (or None)."""
    if isinstance(raw, dict):
        raw = raw.get("data")
    try:
        a = np.asarray(raw, dtype=float)
    except (TypeError, ValueError):
        return None  # strings, ragged rows: camera_from_document names those
    return a if a.size == 9 else None


def _check_camera_matrix(doc, key: str) -> None:
    """Refuse, naming the entry, a 3x3 matrix that is not ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``."""
    K = _matrix_values(doc.raw(key))
    if K is None or not np.all(np.isfinite(K)):
        return  # shape and finiteness: Document.array's messages, via camera_from_document
    K = K.reshape(3, 3)
    form = "not a camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]"
    for (i, j), name in (((0, 0), "fx"), ((1, 1), "fy")):
        if not K[i, j] > 0:
            raise doc.error(key, f"{form}: {name} = {key}[{i}][{j}] = {K[i, j]:.6g} px, expected > 0 (a focal "
                            "length; a matrix of another quantity, or an empty calibration?)", InputError)
    # cv2.calibrateCamera never estimates skew (it writes an exact 0); a 1e-12 relative slack admits
    # a value that went through a float32 or a text round trip of another tool.
    if abs(K[0, 1]) > 1e-12 * abs(K[0, 0]) or K[1, 0] != 0.0:
        raise doc.error(key, f"{form}: skew {key}[0][1] = {K[0, 1]:.6g}, {key}[1][0] = {K[1, 0]:.6g}, expected 0 "
                        "(robocal's camera has square-axis pixels, as OpenCV's calibration; a rotation or a "
                        "transposed matrix?)", InputError)
    if np.any(K[2] != [0.0, 0.0, 1.0]):
        hint = " (transposed? cx, cy are in the last column)" if K[2, 2] == 1.0 and np.any(K[2, :2] != 0) else ""
        raise doc.error(key, f"{form}: last row {K[2].tolist()}, expected [0, 0, 1]{hint}", InputError)


def _check_size(doc, layout: str) -> None:
    """Name the keys to add when a file has no image size (every file from OpenCV's sample has them)."""
    if "image_size" in doc or "resolution" in doc:
        return
    w, h = _SIZE_KEYS[layout]
    have_w = any(k in doc for k in ("width", "image_width"))
    have_h = any(k in doc for k in ("height", "image_height"))
    if have_w and have_h:
        return
    missing = [k for k, have in ((w, have_w), (h, have_h)) if not have]
    raise doc.error(missing[0], f"is missing: add {' and '.join(f'{k}: <px>' for k in missing)} (the size of the "
                    "images this camera was calibrated on; the camera matrix alone does not give it)")


def _check_intrinsics_present(doc) -> None:
    """A file with none of the intrinsics' spellings: name the field of the file's own layout, not ``fx``."""
    if any(k in doc for k in ("camera_matrix", "K", "k", "fx", "fy", "cx", "cy")):
        return  # present, or partly present: camera_from_document names the missing one
    raise doc.error("camera_matrix", "is missing: expected camera_matrix (OpenCV, ROS camera_info), K / k "
                    "(a CameraInfo message) or fx, fy, cx, cy (robocal); keys found: "
                    f"{', '.join(map(str, list(doc.keys())[:8])) or 'none'}")


#: Every spelling of the distortion vector the loaders read (camera_from_document's, and ROS 2's ``d``).
_DIST_SPELLINGS = ("dist", "dist_coeffs", "distortion_coefficients", "D", "d")


def _check_distortion_key(doc) -> None:
    """A misspelt distortion key would leave the camera without distortion, silently: name it.

    (``distortion_coefficents``, one letter short, is in files copied from a ROS tutorial.)
    """
    if any(k in doc for k in _DIST_SPELLINGS):
        return
    for key in doc.keys():
        name = str(key)
        lower = name.lower()
        close = difflib.get_close_matches(lower, _DIST_SPELLINGS[:3], n=1, cutoff=0.75)
        if name != "distortion_model" and (close or lower.startswith(("dist_", "distortion"))):
            hint = close[0] if close else "distortion_coefficients"
            raise doc.error(name, f"unknown key (did you mean {hint!r}?): the distortion would be read as none; "
                            f"the distortion vector is {', '.join(_DIST_SPELLINGS[:-1])} or d (ROS 2)")


def _check_distortion_model(doc) -> None:
    model = doc.raw("distortion_model", default=None)
    if model is None:
        return
    if not isinstance(model, str):
        raise doc.error("distortion_model", f"must be a name such as plumb_bob, got a {type(model).__name__}")
    name = model.lower()
    if name in BROWN_CONRADY_MODELS or name in FISHEYE_MODELS or name in _OTHER_KNOWN_MODELS:
        return  # Brown-Conrady, fisheye, or a model camera_from_document refuses by name
    raise doc.error("distortion_model", f"unknown distortion model {model!r}: expected one of ROS's "
                    f"{', '.join(BROWN_CONRADY_MODELS[:2])} (OpenCV's pinhole model) or equidistant", InputError)


def _is_fisheye(doc) -> bool:
    names = (doc.raw("distortion_model", default=None), doc.raw("model", default=None))
    return any(isinstance(n, str) and n.lower() in FISHEYE_MODELS for n in names)


def _fisheye_from(doc, layout: str) -> FisheyeCamera:
    """An equidistant camera: the camera matrix and size as any camera's, ``(k1, k2, k3, k4)`` as its distortion."""
    from robocal.io import Document

    dist_keys = ("k",) if layout == "robocal" else ("d",) if layout == "ros2" else _DIST_SPELLINGS
    key = next((k for k in dist_keys if k in doc), None)
    if key is None:
        raise doc.error(dist_keys[-1] if layout != "opencv" else "distortion_coefficients",
                        "is missing: an equidistant (fisheye) camera needs its 4 coefficients k1, k2, k3, k4")
    raw = doc.raw(key)
    k = Document({key: raw.get("data") if isinstance(raw, dict) else raw}, doc.source, doc.prefix, doc.units
                 ).array(key).reshape(-1)
    if k.size != 4:
        raise doc.error(key, f"an equidistant (fisheye) camera has 4 coefficients k1, k2, k3, k4 "
                        f"(cv2.fisheye), got {k.size}", InputError)
    # the matrix, size and principal point are checked as a pinhole camera's, without the fisheye's terms
    rest = {n: v for n, v in doc.data.items() if n not in (key, "distortion_model", "model")}
    pin = camera_from_mapping(rest, doc.source, prefix=doc.prefix, units=doc.units, units_error=doc.units_error)
    return FisheyeCamera(pin.fx, pin.fy, pin.cx, pin.cy, k, pin.width, pin.height)


def camera_from_mapping(data: dict, source: str = "<camera>", *, prefix: str = "", units=None,
                        units_error=None) -> CameraModel:
    """A :class:`CameraModel` from the raw mapping of any layout :func:`load_camera` reads.

    ``source``/``prefix`` name the file and the section in error messages;
    ``units``/``units_error``: default units of the enclosing document (pixel
    quantities must be px) and the error of its malformed ``units`` entry, if any.
    """
    from robocal.io import Document

    if not isinstance(data, dict):
        raise FileFormatError(f"field '{prefix or 'camera'}': must be a mapping (camera_matrix, dist_coeffs, "
                              f"image_width, ... or fx, fy, cx, cy, width, height), got {type(data).__name__}",
                              source=source)
    layout = _layout(data)
    doc = Document(dict(data), source, prefix, {**(units or {}), "pixel": "px"}, units_error)
    _check_intrinsics_present(doc)
    _check_distortion_key(doc)
    _check_distortion_model(doc)
    _check_size(doc, layout)
    if _is_fisheye(doc):
        return _fisheye_from(doc, layout)
    if layout == "ros2":
        _check_camera_matrix(doc, "k")
        # ros2 topic echo spells CameraInfo's K and D in lower case; the core reads the upper-case ones
        data = {("K" if k == "k" else "D" if k == "d" and "D" not in data else k): v for k, v in data.items()}
        doc = Document(data, source, prefix, doc.units, doc.units_error)
    else:
        for key in ("camera_matrix", "K"):
            if key in doc:
                _check_camera_matrix(doc, key)
                break
    return camera_from_document(doc)


def load_camera(path) -> CameraModel | FisheyeCamera:
    """Read a camera calibration file: OpenCV FileStorage YAML/XML, ROS ``camera_info`` YAML, or robocal JSON/YAML.

    A :class:`FisheyeCamera` when the file says so (``distortion_model:
    equidistant`` (ROS), ``fisheye``, or robocal's ``model: fisheye-kannala-brandt``),
    else a :class:`CameraModel`.

    The file's suffix must be ``.yaml``, ``.yml``, ``.json`` or ``.xml``; the
    layout is recognised from the keys (module docstring). Every problem is
    one :class:`~robocal.errors.InputError` line naming the file and the field.
    """
    path = Path(path)
    return camera_from_mapping(read_camera_file(path), str(path))


#: Alias of :func:`load_camera`, after :meth:`CameraModel.from_dict` / :func:`camera_from_document`.
camera_from_file = load_camera


def camera_from_section(doc, *, base_dir=None, fisheye: bool = False) -> CameraModel:
    """The ``camera`` section of a rig's input file: inline, or ``{file: PATH}`` plus keys that override the file's.

    ``doc``: the section as a :class:`robocal.io.Document`. A relative
    ``file`` is resolved against ``base_dir`` (default: the folder of the
    input file). Errors in the camera file name it and the input file:
    ``cam.yaml (camera.file of input.yaml): field 'camera_matrix': ...``.
    ``fisheye``: whether the rig takes a :class:`FisheyeCamera`; when not, an
    equidistant camera is one line naming the field (its 4 coefficients would
    otherwise be read as ``k1, k2, p1, p2``).
    """
    data = doc.data
    if not isinstance(data, dict):
        raise FileFormatError(f"field '{doc.prefix or 'camera'}': must be a mapping (fx, fy, ... or "
                              f"{{file: <camera file>}}), got {type(data).__name__}", source=doc.source)
    data = dict(data)
    source, prefix = doc.source, doc.prefix
    if "file" in data:
        raw = data.pop("file")
        if not isinstance(raw, str):
            raise doc.error("file", f"must be the path of a camera calibration file, got {type(raw).__name__}")
        p = Path(raw).expanduser()
        if not p.is_absolute():
            p = (Path(base_dir) if base_dir is not None else Path(source).parent) / p
        if not p.exists():
            raise doc.error("file", f"camera file {p} does not exist")
        data = {**read_camera_file(p), **data}  # keys in the input file complete or override the file's
        source, prefix = f"{os.path.normpath(p)} (camera.file of {doc.source})", ""
    cam = camera_from_mapping(data, source, prefix=prefix, units=doc.units, units_error=doc.units_error)
    if isinstance(cam, FisheyeCamera) and not fisheye:
        key = "model" if "model" in data and not isinstance(data.get("distortion_model"), str) else "distortion_model"
        where = f"{prefix}.{key}" if prefix else key
        raise InputError(f"field '{where}': an equidistant (fisheye) camera; this rig takes OpenCV's pinhole "
                         "camera (plumb_bob, rational_polynomial): calibrate it with that model, or undistort the "
                         "images first", source=source)
    return cam


def _opencv_text(camera: CameraModel, suffix: str) -> str:
    import cv2

    # cv2 writes the file itself (to memory), so whatever FileStorage version reads it finds its own syntax
    fs = cv2.FileStorage("camera" + suffix, cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    fs.write("image_width", int(camera.width))
    fs.write("image_height", int(camera.height))
    fs.write("camera_matrix", camera.K)
    fs.write("distortion_coefficients", np.asarray(_dist(camera), dtype=float).reshape(1, -1))
    if isinstance(camera, FisheyeCamera):
        # OpenCV has no key for the model; without one the 4 coefficients would read as k1, k2, p1, p2
        fs.write("distortion_model", "equidistant")
    return fs.releaseAndGetString()


def _dist(camera) -> np.ndarray:
    return camera.k if isinstance(camera, FisheyeCamera) else camera.dist


def _ros_matrix(name: str, rows: int, cols: int, values) -> str:
    data = ", ".join(repr(float(v)) for v in np.asarray(values, dtype=float).ravel())
    return f"{name}:\n  rows: {rows}\n  cols: {cols}\n  data: [{data}]\n"


def _ros_text(camera: CameraModel, camera_name: str) -> str:
    dist = np.asarray(_dist(camera), dtype=float).ravel()
    if isinstance(camera, FisheyeCamera):
        model = "equidistant"
    elif dist.size not in (4, 5, 8):  # sensor_msgs/distortion_models.h: plumb_bob 5, rational_polynomial 8
        raise InputError(f"ROS's distortion models hold 5 (plumb_bob) or 8 (rational_polynomial) coefficients, "
                         f"this camera has {dist.size}: write it as format='opencv' or 'json'")
    else:
        model = "plumb_bob" if dist.size <= 5 else "rational_polynomial"
    P = np.hstack([camera.K, np.zeros((3, 1))])
    return (f"image_width: {camera.width}\nimage_height: {camera.height}\ncamera_name: {camera_name}\n"
            + _ros_matrix("camera_matrix", 3, 3, camera.K)
            + f"distortion_model: {model}\n"
            + _ros_matrix("distortion_coefficients", 1, dist.size, dist)
            + _ros_matrix("rectification_matrix", 3, 3, np.eye(3))
            + _ros_matrix("projection_matrix", 3, 4, P))


def camera_file_text(camera: CameraModel, *, format: str = "opencv", suffix: str = ".yaml",
                     camera_name: str = "camera") -> str:
    """The text :func:`write_camera` writes (see there)."""
    if format not in CAMERA_FILE_FORMATS:
        raise InputError(f"camera file format must be one of {', '.join(CAMERA_FILE_FORMATS)}, got {format!r}")
    suffix = suffix.lower()
    if suffix not in CAMERA_FILE_FORMATS[format]:
        raise InputError(f"a {format} camera file is {' or '.join(CAMERA_FILE_FORMATS[format])}, got "
                         f"{suffix or 'no suffix'!r}")
    if not isinstance(camera, (CameraModel, FisheyeCamera)):
        raise InputError(f"camera must be a CameraModel or FisheyeCamera, got {type(camera).__name__}")
    if format == "opencv":
        return _opencv_text(camera, suffix)
    if format == "ros":
        return _ros_text(camera, camera_name)
    return json.dumps(camera.to_dict(), indent=2) + "\n"


def write_camera(path, camera: CameraModel, *, format: str = "opencv", camera_name: str = "camera") -> Path:
    """Write ``camera`` to ``path`` (atomically) in a format other tools read; :func:`load_camera` reads it back.

    ``format``:

    * ``"opencv"``: cv2.FileStorage YAML (``.yaml``/``.yml``) or XML (``.xml``), written by
      ``cv2.FileStorage`` itself: ``image_width``, ``image_height``,
      ``camera_matrix``, ``distortion_coefficients`` (1 x n), as OpenCV's
      ``calibration.cpp`` sample writes them;
    * ``"ros"``: the YAML of ROS's ``camera_calibration_parsers`` (what
      ``camera_info_manager`` loads), ``camera_name`` as given, an identity
      rectification and projection matrix ``[K | 0]`` (a monocular camera);
    * ``"json"``: :meth:`CameraModel.to_dict` / :meth:`FisheyeCamera.to_dict`.

    A :class:`FisheyeCamera` is written with ``distortion_model: equidistant``
    (ROS's name; in the OpenCV file too, where OpenCV has no key for it).

    Numbers are written with 17 significant digits (OpenCV) or Python's
    shortest round-trip repr, so a camera read back is bit-identical.
    """
    from robocal.io import atomic_write_text

    path = Path(path)
    return atomic_write_text(path, camera_file_text(camera, format=format, suffix=path.suffix,
                                                    camera_name=camera_name))
