"""The camera rig's input: images (files, folders, globs) and a target, or a session file naming both.

Two ways in, one :class:`CameraInput`::

    robocal camera calibrate shots/ --target board.yaml          # a folder of images
    robocal camera calibrate 'shots/*.png' --target board.yaml    # a glob (quoted: robocal expands it)
    robocal camera calibrate camera_input.yaml                    # a session file
    robocal camera calibrate --bag run.bag --topic /cam/image_raw --target board.yaml   # a recording

Session file (YAML/JSON, schema ``robocal.camera_input/1``; paths relative to
the file)::

    schema: robocal.camera_input/1
    target: target.yaml            # a target file (docs/camera.md) or the target inline
    images: images/*.png           # a glob, a folder, or a list of files
    truth: {file: camera_truth.yaml}   # optional: the true camera (simulations), checked in the report

The images are read one at a time and the target detected in each
(:func:`robocal.camera.detect_targets`); the views that cannot serve (target
missing, too few points, blurred, duplicate) are named with their reason.
"""

from __future__ import annotations

import glob as _glob
from dataclasses import dataclass, field
from pathlib import Path

from robocal.errors import InputError, RobocalError

__all__ = ["CameraInput", "IMAGE_SUFFIXES", "INPUT_SCHEMA", "load_input", "expand_images", "write_session"]

#: The schema string of a session file.
INPUT_SCHEMA = "robocal.camera_input/1"
#: Image file suffixes a folder is searched for (what ``cv2.imread`` decodes everywhere).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")
_SESSION_SUFFIXES = (".yaml", ".yml", ".json")
_SESSION_KEYS = ("schema", "target", "images", "truth", "units", "comment")


@dataclass
class CameraInput:
    """What :func:`load_input` read: the images, the target, the detections, and the truth when known.

    Attributes
    ----------
    images : list of Path
        Every image given, in order (sorted within a folder or glob).
    target : ChessboardTarget, CharucoTarget or ArucoGridTarget
    target_source : str
        Where the target came from (a file, or ``"<session>: target"``).
    detections : DetectionSet
        The target found in the images (usable and rejected views, notes).
    source : Path or None
        The session file or the recording (``--bag``), when one was given.
    target_file : Path or None
        The target file, when the target came from one.
    truth : CameraModel or None
        The true camera of a simulated session (``truth: {file: ...}``).
    truth_file : Path or None
    """

    images: list
    target: object
    target_source: str
    detections: object
    source: Path | None = None
    target_file: Path | None = None
    truth: object = None
    truth_file: Path | None = None
    notes: list = field(default_factory=list)

    @property
    def image_size(self) -> tuple[int, int]:
        return self.detections.image_size


def _is_pattern(text: str) -> bool:
    return any(c in text for c in "*?[")


def expand_images(items, *, base_dir: Path | None = None, source: str | None = None) -> list[Path]:
    """Image paths from files, folders (their image files, sorted) and glob patterns (sorted), in the order given.

    A path that is neither an image file, a folder nor a pattern matching
    something is a one-line :class:`InputError` naming it; so is an empty
    result (a folder without images names the suffixes searched). The same
    image given twice is kept once (a glob overlapping a file list).
    """
    out: list[Path] = []
    for raw in items:
        text = str(raw)
        p = Path(text).expanduser()
        if base_dir is not None and not p.is_absolute():
            p = Path(base_dir) / p
        where = source or text
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.is_file() and q.suffix.lower() in IMAGE_SUFFIXES)
            if not found:
                raise InputError(f"folder {p} holds no image files ({', '.join(IMAGE_SUFFIXES)})", source=where)
        elif _is_pattern(text) and not p.exists():
            found = sorted(Path(q) for q in _glob.glob(str(p)) if Path(q).is_file())
            if not found:
                raise InputError(f"no file matches {text!r}", source=where)
        elif p.is_file():
            if p.suffix.lower() in _SESSION_SUFFIXES:
                raise InputError(f"{p.name} is a {p.suffix} file among images: give a session file alone "
                                 "(robocal camera calibrate camera_input.yaml), a target file with --target",
                                 source=str(p))
            found = [p]
        else:
            raise InputError("no such file or folder", source=text)
        for q in found:
            if q not in out:
                out.append(q)
    if not out:
        raise InputError("no images given", source=source)
    return out


def _session(path: Path):
    """``(images, target, target_file, target_source, truth, truth_file)`` of a session file."""
    from robocal.camera import camera_from_section, load_target, target_from_document
    from robocal.io import load_document

    doc = load_document(path)
    if "type" in doc and "images" not in doc:
        raise InputError("this is a target file, not a session: give the images and --target "
                         f"{path.name} (robocal camera calibrate IMAGES... --target {path.name})", source=str(path))
    doc.require_known_keys(_SESSION_KEYS)
    if "schema" in doc:
        doc.str("schema", choices=(INPUT_SCHEMA,))
    raw_images = doc.raw("images")
    items = raw_images if isinstance(raw_images, list) else [raw_images]
    if not items or not all(isinstance(i, str) for i in items):
        raise doc.error("images", "must be a glob, a folder or a list of image files (strings)")
    images = expand_images(items, base_dir=path.parent, source=f"{path}: images")
    raw_target = doc.raw("target")
    if isinstance(raw_target, str):
        target_file = doc.path("target")
        target, target_source = load_target(target_file), str(target_file)
    elif isinstance(raw_target, dict):
        target_file, target_source = None, f"{path}: target"
        target = target_from_document(doc.sub("target"))
    else:
        raise doc.error("target", f"must be a target file or a mapping, got {type(raw_target).__name__}")
    truth = truth_file = None
    if "truth" in doc:
        sec = doc.sub("truth")
        truth = camera_from_section(sec, fisheye=True)
        if "file" in sec:
            truth_file = doc.sub("truth").path("file")
    return images, target, target_file, target_source, truth, truth_file


def _bag_frames(bag, topic, every: int, progress: bool) -> list:
    """``(name, image)`` of every ``every``-th frame of ``topic`` in the recording ``bag`` (names ``topic@stamp``)."""
    from robocal.bags import images

    if topic is None:
        raise InputError("give the image topic with --topic (robocal bag inspect FILE lists the recording's "
                         "topics)", source="--topic")
    # frames are decoded one at a time; the ones skipped cost their decoding only (a raw image is a reshape)
    frames = [f for k, f in enumerate(images(bag, topic, show_progress=progress)) if k % every == 0]
    if not frames:
        raise InputError(f"topic {topic} holds no images", source=str(bag))
    return frames


def load_input(*paths, target=None, blur_limit: float | None = None, duplicate_limit: float | None = None,
               bag=None, topic: str | None = None, every: int = 1, progress: bool = True, **_) -> CameraInput:
    """Read the images (or a session file, or a recording's image topic) and detect the target in each.

    Parameters
    ----------
    *paths : path or str
        Image files, folders, glob patterns; or one session file (module docstring).
    target : path, optional
        The target file (required with images and recordings; a session file names its own).
    blur_limit, duplicate_limit : float, optional
        Thresholds of :func:`robocal.camera.detect_targets` [px] (default its own).
    bag, topic, every : optional
        A ROS 1 / ROS 2 / MCAP recording (:mod:`robocal.bags`), its image topic
        (``sensor_msgs/Image`` or ``CompressedImage``) and the frame step (every
        ``every``-th frame: consecutive video frames are near-duplicates). Views
        are named ``topic@stamp``.
    """
    from robocal.camera import load_target

    source = truth = truth_file = None
    if bag is not None:
        if paths:
            raise InputError(f"give images or --bag, not both ({len(paths)} image argument(s) with --bag)",
                             source="--bag")
        if int(every) < 1:
            raise InputError(f"must be >= 1, got {every}", source="--every")
        if target is None:
            raise InputError("give the target file with --target TARGET.yaml (see docs/rigs/camera.md)",
                             source="--target")
        source = Path(bag)
        tgt, target_file = load_target(target), Path(target)
        frames = _bag_frames(source, topic, int(every), progress)
        images = [name for name, _ in frames]
        return _detected(images, frames, tgt, str(target_file), target_file, source, None, None, blur_limit,
                         duplicate_limit, progress)
    if not paths:
        raise InputError("no images given: give image files, folders or globs with --target, a session file, or "
                         "--bag FILE --topic TOPIC --target TARGET.yaml")
    first = Path(paths[0])
    if len(paths) == 1 and first.suffix.lower() in _SESSION_SUFFIXES and first.is_file():
        source = first
        images, tgt, target_file, target_source, truth, truth_file = _session(first)
        if target is not None:
            raise InputError(f"--target given with a session file that names its own target ({target_source}); "
                             "give one of the two", source="--target")
    else:
        images = expand_images(paths)  # a missing path is named before a missing --target
        if target is None:
            raise InputError("give the target file with --target TARGET.yaml (chessboard, charuco or aruco_grid: "
                             "see docs/rigs/camera.md), or a session file naming it", source="--target")
        target_file = Path(target)
        if not target_file.is_file():
            raise InputError(f"target file {target_file} does not exist", source="--target")
        tgt, target_source = load_target(target_file), str(target_file)
    return _detected(images, images, tgt, target_source, target_file, source, truth, truth_file, blur_limit,
                     duplicate_limit, progress)


def _detected(images, frames, tgt, target_source, target_file, source, truth, truth_file, blur_limit,
              duplicate_limit, progress) -> CameraInput:
    """The :class:`CameraInput` of ``frames`` (paths or ``(name, array)`` pairs) with the target detected."""
    from robocal.camera import BLUR_LIMIT_PX, DUPLICATE_LIMIT_PX, detect_targets

    try:
        dets = detect_targets(frames, tgt, progress_desc="detect" if progress else None,
                              blur_limit=BLUR_LIMIT_PX if blur_limit is None else float(blur_limit),
                              duplicate_limit=DUPLICATE_LIMIT_PX if duplicate_limit is None else float(duplicate_limit))
    except RobocalError as exc:
        # detect_targets names the image; a message without a file is about the target: it gets the target's name
        if exc.source is None:
            raise exc.with_source(target_source) from None
        raise
    return CameraInput(list(images), tgt, target_source, dets, source=source, target_file=target_file, truth=truth,
                       truth_file=truth_file)


def write_session(path, images, target_file, *, truth_file=None, comment: str | None = None) -> Path:
    """Write a session file naming ``images`` (a glob, folder or list, relative to ``path``) and ``target_file``."""
    import yaml

    from robocal.io import atomic_write_text

    path = Path(path)
    base = path.parent

    def rel(p):
        p = Path(p)
        try:
            return p.relative_to(base).as_posix()
        except ValueError:
            return str(p)

    doc = {"schema": INPUT_SCHEMA, "target": rel(target_file),
           "images": images if isinstance(images, str) else [rel(p) for p in images]}
    if truth_file is not None:
        doc["truth"] = {"file": rel(truth_file)}
    text = (f"# {comment}\n" if comment else "") + yaml.safe_dump(doc, sort_keys=False)
    atomic_write_text(path, text)
    return path
