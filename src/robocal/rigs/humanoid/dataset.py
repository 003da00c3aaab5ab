"""The humanoid data-set file: camera, boards, and one joint record per image.

Format (YAML or JSON; units explicit, see ``docs/rigs/humanoid.md``)::

    format: robocal.humanoid-data/1
    model: default                  # or a URDF path, relative to this file
    tie_hip_yaw_pitch: false
    camera: {fx: 562.5, fy: 562.5, cx: 324, cy: 189, width: 640, height: 480}   # or {file: cam.yaml}: OpenCV,
                                    # ROS camera_info or robocal JSON (robocal.camera.load_camera)
    board: {rows: 4, cols: 6, square: {value: 25, unit: mm},
            centre: {value: [170, 0, 0], unit: mm}}
    joint_resolution: {value: 0.1, unit: deg}
    images: [images/view000.png, ...]          # one per view, relative to this file
    feet: [left, left, right, ...]             # whose board each image shows
    joints:
      unit: deg
      names: [HeadYaw, HeadPitch, LHipYawPitch, ...]
      records: [[0.0, 25.8, -12.3, ...], ...]  # one row per image, in `names` order

Loading checks everything a user can get wrong and names the field: counts of
images, feet and joint records that disagree, missing image files, unknown or
missing joints, angles outside the joint limits.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from robocal.camera import CameraModel, Checkerboard, camera_from_section
from robocal.errors import FileFormatError, InconsistentDataError, InputError
from robocal.io import atomic_write_text, load_document
from robocal.rigs.humanoid.model import FEET, HumanoidModel
from robocal.rigs.humanoid.simulate import JOINT_RESOLUTION, HumanoidDataset

__all__ = ["FORMAT", "load_dataset", "write_dataset"]

FORMAT = "robocal.humanoid-data/1"


def load_dataset(path, *, detect: bool = True, progress: bool = False) -> tuple[HumanoidModel, HumanoidDataset, dict]:
    """Read a data-set file; returns ``(model, data, info)``.

    With ``detect`` the corners are found on every image
    (:func:`robocal.rigs.humanoid.detect.detect_views`: a board not fully found
    leaves that view's corners NaN, a badly detected corner its own; each with a
    message in ``data.messages``).
    ``info`` holds the joint resolution [rad], the input files (for the
    result's hashes) and ``declared``: the units the board square, board centre
    and joint records were written in (so :func:`robocal.rigs.humanoid.slips.check_data`
    names a slip in the file's units).

    Joint records outside the joint limits that all lie within them read in the
    other angle unit are an :class:`~robocal.errors.ImplausibleInputError`
    naming ``joints.unit``.
    """
    path = Path(path)
    doc = load_document(path)
    fmt = doc.str("format", default=FORMAT)
    if fmt != FORMAT:
        raise doc.error("format", f"must be {FORMAT!r}, got {fmt!r}")
    inputs = [path]
    model_key = doc.raw("model", "default")
    tie = doc.bool("tie_hip_yaw_pitch", default=False)
    camera = camera_from_section(doc.sub("camera"))  # inline, or {file: ...} in any format load_camera reads
    if isinstance(doc.raw("camera"), dict) and isinstance(doc.raw("camera").get("file"), str):
        inputs.append(_image_path(path, doc.raw("camera")["file"]))  # hashed with the result's inputs
    b = doc.sub("board", {})
    board = Checkerboard(b.int("rows", default=4, minimum=3), b.int("cols", default=6, minimum=3),
                         b.float("square", kind="length", positive=True) if "square" in b else 0.025)
    centre = b.array("centre", kind="length", shape=(3,)) if "centre" in b else (0.17, 0.0, 0.0)
    urdf = None
    if model_key != "default":
        urdf = doc.path("model")
        inputs.append(urdf)
    model = HumanoidModel.from_urdf(urdf, camera=camera, board=board, board_centre=centre,
                                    tie_hip_yaw_pitch=tie)
    resolution = doc.float("joint_resolution", kind="angle") if "joint_resolution" in doc else JOINT_RESOLUTION
    if resolution < 0:
        raise doc.error("joint_resolution", f"must be >= 0, got {resolution}")

    images = doc.raw("images")
    if not isinstance(images, list) or not images or not all(isinstance(s, str) for s in images):
        raise doc.error("images", "must be a non-empty list of image paths")
    feet = doc.raw("feet")
    if not isinstance(feet, list):
        raise doc.error("feet", "must be a list of 'left' / 'right', one per image")
    bad = [i for i, f in enumerate(feet) if f not in FEET]
    if bad:
        raise doc.error("feet", f"entry {bad[0]} is {feet[bad[0]]!r}; expected 'left' or 'right'")
    j = doc.sub("joints")
    names = j.raw("names")
    if not isinstance(names, list) or not all(isinstance(s, str) for s in names):
        raise j.error("names", "must be a list of joint names")
    dup = sorted({s for s in names if names.count(s) > 1})
    if dup:
        raise j.error("names", f"joint {dup[0]!r} is listed twice")
    unit = j.str("unit", choices=("deg", "rad"))
    rec_raw = j.raw("records")
    if not isinstance(rec_raw, list):
        raise j.error("records", "must be a list of rows, one per image")
    if len(images) != len(rec_raw) or len(feet) != len(rec_raw):
        raise InconsistentDataError(
            f"{path}: {len(images)} images, {len(feet)} feet and {len(rec_raw)} joint records: "
            f"need one foot and one joint record per image")
    # through the loader, so a quoted "25.8", true or null is refused like anywhere else
    rec = j.array("records", finite=False)
    if rec.ndim != 2 or rec.shape[1] != len(names):
        raise j.error("records", f"each row must hold {len(names)} angles (one per name), got shape {rec.shape}")
    if not np.all(np.isfinite(rec)):
        r, c = np.argwhere(~np.isfinite(rec))[0]
        raise j.error("records", f"row {r}, joint {names[c]!r} is not a finite number")
    if unit == "deg":
        rec = np.radians(rec)
    records = [dict(zip(names, row)) for row in rec]
    where = f"{path}: joints.records"
    theta = model.q_from_records(records, source=where)
    tol = 0.5 * resolution + 1e-12
    try:
        model.check_limits(theta, source=where, tolerance=tol)
    except InputError as exc:
        _joint_unit_slip(model, theta, unit, tol, exc, source=f"{path}: joints.unit")
        raise

    files = [_image_path(path, s) for s in images]
    missing = [str(p) for p in files if not p.is_file()]
    if missing:
        raise FileFormatError(f"{len(missing)} image file(s) not found, first: {missing[0]}", source=str(path))
    inputs += files
    names_v = [p.stem for p in files]
    data = HumanoidDataset(list(feet), theta, images=list(files), names=names_v)
    if detect:
        from robocal.rigs.humanoid.detect import detect_views

        detect_views(model, data, progress=progress)
    declared = {"board.square": _declared(b, "square", "length") or "m",
                "board.centre": _declared(b, "centre", "length") or "m", "joints": unit}
    return model, data, {"joint_resolution": resolution, "inputs": inputs, "declared": declared}


def _declared(doc, key: str, kind: str) -> str | None:
    """The unit ``doc[key]`` was written in: its inline ``unit`` or the document's default for ``kind``."""
    raw = doc.raw(key, None)
    if isinstance(raw, dict) and "unit" in raw:
        return str(raw["unit"])
    return doc.units.get(kind)


def _joint_unit_slip(model: HumanoidModel, theta, unit: str, tol: float, exc: InputError, *, source: str) -> None:
    """Raise :class:`ImplausibleInputError` when records outside the limits all fit them in the other unit.

    The figure is how far [deg] the records lie outside the joint limits; the slip is
    :func:`robocal.rigs.humanoid.slips.joint_unit_slip` (the one the corner check tries too), judged by
    :func:`robocal.plausibility.check_slips`: it explains the records when it brings them within the
    limits (``tol``). When it does not, the caller re-raises the limits error ``exc``."""
    from robocal.plausibility import check_slips, try_slips
    from robocal.rigs.humanoid.slips import joint_unit_slip

    lo, hi = [], []
    for name in model.joint_names:
        lim = model.tree.joint(name).limits
        lo.append(-np.inf if lim is None else lim[0])
        hi.append(np.inf if lim is None else lim[1])
    lo, hi = np.array(lo), np.array(hi)

    def excess(q) -> float:
        return float(np.degrees(np.max(np.maximum(np.maximum(lo - q, q - hi), 0.0))))

    baseline = excess(theta)
    trial = try_slips(joint_unit_slip(unit, lambda k: excess(theta * k)), baseline, unit="deg",
                      threshold=float(np.degrees(tol)))
    if trial.best is not None:
        check_slips(what="largest excess over the joint limits", residual=baseline, unit="deg", plausible=False,
                    reason=exc.message, trial=trial, source=source)


def _image_path(doc_path: Path, s: str) -> Path:
    p = Path(s)
    return p if p.is_absolute() else doc_path.parent / p


def write_dataset(path, model: HumanoidModel, data: HumanoidDataset, image_paths, *,
                  joint_resolution: float = JOINT_RESOLUTION, truth=None) -> Path:
    """Write a data-set file (angles in deg) referencing ``image_paths`` (relative when possible).

    ``truth`` (a full parameter vector) is stored under ``simulation_truth``
    (SI units) for reference; calibration ignores it.
    """
    path = Path(path)
    rel = []
    for p in image_paths:
        p = Path(p)
        try:
            rel.append(str(p.resolve().relative_to(path.parent.resolve())))
        except ValueError:
            rel.append(str(p))
    names = list(model.joint_names)
    d = {
        "format": FORMAT,
        "model": "default" if not model.source or Path(model.source).name == "nao_h25_legs_head.urdf"
        else str(model.source),
        "tie_hip_yaw_pitch": bool(model.tied),
        "camera": model.camera.to_dict(),
        "board": {"rows": model.board.rows, "cols": model.board.cols,
                  "square": {"value": model.board.square * 1e3, "unit": "mm"},
                  "centre": {"value": [round(float(v) * 1e3, 6) for v in model.mounts["left"].centre],
                             "unit": "mm"}},
        "joint_resolution": {"value": float(np.degrees(joint_resolution)), "unit": "deg"},
        "images": rel,
        "feet": list(data.feet),
        "joints": {"unit": "deg", "names": names,
                   "records": [[round(float(np.degrees(v)), 4) for v in row] for row in data.theta]},
    }
    if truth is not None:
        d["simulation_truth"] = {"units": "rad for angles, m for lengths",
                                 "values": {k: float(v) for k, v in zip(model.parameter_labels(), truth)}}
    return atomic_write_text(path, yaml.safe_dump(d, sort_keys=False, width=200))
