"""Camera calibration files of other tools (OpenCV FileStorage YAML/XML, ROS, JSON) as a raw mapping,
and image files checked before they are decoded.

The readers are shared by every rig that takes ``camera: {file: ...}`` or
images; :func:`robocal.camera.load_camera` turns a camera file into a
:class:`~robocal.camera.CameraModel` (the layouts inside the mapping are read
and checked by :func:`robocal.camera.camera_from_document`).
"""

from __future__ import annotations

import re
import struct
import zlib
from pathlib import Path

import numpy as np

from robocal.errors import FileFormatError

__all__ = ["read_camera_file", "read_image"]

# cv2.FileStorage writes "%YAML:1.0" (OpenCV 4) or "%YAML 1.2" + "---" (OpenCV 5) as
# its first line; PyYAML refuses the first form, and neither carries information.
_YAML_DIRECTIVE = re.compile(r"^%YAML[: ]1\.[0-9]+[ \t]*$", re.M)
# "!!opencv-matrix" is an unknown tag to a safe YAML loader; without it the
# matrix is a plain {rows, cols, dt, data} mapping, which camera_from_document reads.
_OPENCV_TAG = re.compile(r"!!opencv-(?:nd-)?matrix")
# cv2.FileStorage spells NaN ".Nan", which YAML 1.1 does not know (.nan, .NaN, .NAN): a string to PyYAML,
# refused as "a string" instead of as the NaN it is.
_OPENCV_NAN = re.compile(r"(?<![\w.])\.Nan(?![\w.])")


def _mapping_from_filestorage(path: Path) -> dict:
    """Top-level scalars and matrices of an OpenCV FileStorage XML file as plain Python."""
    import cv2

    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:  # the Python bindings wrap cv2.error in a SystemError
        err = exc.__cause__ or exc
        m = re.search(r"error: \(-?\d+:[^)]*\) (.*)", str(err))
        detail = m.group(1).strip() if m else type(err).__name__
        raise FileFormatError(f"cv2.FileStorage cannot parse this XML file ({detail})", source=str(path)) from None
    try:
        if not fs.isOpened():
            raise FileFormatError("cv2.FileStorage cannot read this file", source=str(path))
        out = {}
        for key in fs.root().keys():
            node = fs.getNode(key)
            if node.isInt():
                out[key] = int(node.real())
            elif node.isReal():
                out[key] = float(node.real())
            elif node.isString():
                out[key] = node.string()
            else:
                m = node.mat()
                if m is not None:
                    out[key] = np.asarray(m, dtype=float).tolist()
                elif node.isSeq():
                    out[key] = [node.at(i).real() for i in range(node.size())]
        return out
    finally:
        fs.release()


def read_camera_file(path) -> dict:
    """The raw mapping of a camera calibration file (YAML, OpenCV FileStorage YAML/XML, or JSON).

    OpenCV's ``%YAML:1.0`` (OpenCV 4) and ``%YAML 1.2`` (OpenCV 5) headers and
    its ``!!opencv-matrix`` tags, which a plain YAML reader rejects, are
    accepted: the matrices come back as ``{rows, cols, dt, data}`` mappings
    (read by :func:`robocal.camera.camera_from_document`).

    Raises
    ------
    FileFormatError
        One line naming the file: missing, unreadable (a folder, no
        permission), not UTF-8 text (a binary file), not parseable, or not a
        mapping at the top level. The values themselves (a focal length of
        1e300, say) are checked by :func:`camera_from_document`.
    """
    path = Path(path)
    src = str(path)
    if not path.exists():
        raise FileFormatError("camera file not found", source=src)
    suffix = path.suffix.lower()
    if suffix not in (".yaml", ".yml", ".json", ".xml"):
        raise FileFormatError(f"camera file: expected .yaml, .yml, .json or .xml (cv2.FileStorage), got "
                              f"{path.suffix or 'no suffix'!r}", source=src)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise FileFormatError(f"camera file cannot be read ({exc.strerror or exc})", source=src) from None
    if not raw.strip():
        raise FileFormatError("camera file is empty", source=src)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"camera file is not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start}; "
                              "a binary file?): expected YAML, JSON or cv2.FileStorage XML", source=src) from None
    if "\x00" in text:
        raise FileFormatError("camera file holds NUL bytes (a binary file?): expected YAML, JSON or "
                              "cv2.FileStorage XML", source=src)
    if suffix == ".xml":
        return _mapping_from_filestorage(path)
    if suffix != ".json":
        opencv = _YAML_DIRECTIVE.search(text) is not None or _OPENCV_TAG.search(text) is not None
        text = _YAML_DIRECTIVE.sub("", text, count=1)
        text = _OPENCV_TAG.sub("", text)
        if opencv:
            text = _OPENCV_NAN.sub(".nan", text)
    from robocal.io import parse_document

    data = parse_document(text, suffix=suffix, source=src).data
    if not isinstance(data, dict):
        raise FileFormatError(f"camera file must hold a mapping (camera_matrix, dist_coeffs, ... or fx, fy, ...) at "
                              f"the top level, got a {type(data).__name__}", source=src)
    return data


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_problem(data: bytes) -> str | None:
    """What is wrong with a PNG's chunk structure (length, CRC-32, IEND), or None.

    libpng prints its complaints about a damaged file straight to the
    process's stderr before OpenCV returns (a second line beside robocal's one
    error line, which Python cannot catch), so a damaged file is named here,
    from the chunk CRCs every PNG carries (PNG spec, section 5.3), and never
    reaches the decoder.
    """
    pos = len(_PNG_SIGNATURE)
    while pos + 12 <= len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        end = pos + 12 + length
        if end > len(data):
            return f"cut short: chunk {kind.decode('latin-1')!r} at byte {pos} runs past the end of the file"
        crc = struct.unpack(">I", data[end - 4:end])[0]
        if zlib.crc32(data[pos + 4:end - 4]) != crc:
            return f"damaged: chunk {kind.decode('latin-1')!r} at byte {pos} fails its CRC check"
        if kind == b"IEND":
            return None
        pos = end
    return "cut short: no IEND chunk"


def _quiet_imdecode(cv2, data: bytes, flags: int):
    """``cv2.imdecode`` with OpenCV's own log silenced for the call: a file it cannot
    decode is reported by robocal in one line, not by a ``[ERROR:0@0.2] ...`` line too."""
    log = getattr(getattr(cv2, "utils", None), "logging", None)
    try:
        level = log.getLogLevel()
        log.setLogLevel(log.LOG_LEVEL_SILENT)
    except AttributeError:  # a build without cv2.utils.logging: decode with its log as it is
        log = None
    try:
        return cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    finally:
        if log is not None:
            log.setLogLevel(level)


def read_image(path, *, grey: bool = True) -> np.ndarray:
    """Read an image file as uint8 (grey ``(H, W)`` or BGR ``(H, W, 3)``), checked before decoding.

    A missing, empty, truncated or damaged file (PNG chunk CRCs; a JPEG
    without its end-of-image marker) is a one-line :class:`FileFormatError`
    naming the file, and the file never reaches a decoder that would print its
    own warnings to the terminal.
    """
    import cv2

    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise FileFormatError("image file not found", source=str(path)) from None
    except OSError as exc:
        raise FileFormatError(f"cannot read image file ({exc.strerror or exc})", source=str(path)) from None
    if not data:
        raise FileFormatError("image file is empty", source=str(path))
    problem = None
    if data.startswith(_PNG_SIGNATURE):
        problem = _png_problem(data)
    elif data.startswith(b"\xff\xd8"):  # JPEG: a complete file ends with the EOI marker (some writers pad after it)
        if b"\xff\xd9" not in data[-64:]:
            problem = "cut short: no JPEG end-of-image marker"
    if problem is not None:
        raise FileFormatError(f"image file {problem}", source=str(path))
    img = _quiet_imdecode(cv2, data, cv2.IMREAD_GRAYSCALE if grey else cv2.IMREAD_COLOR)
    if img is None:
        raise FileFormatError("not an image OpenCV can decode (PNG, JPEG, TIFF, BMP, ...)", source=str(path))
    return img
