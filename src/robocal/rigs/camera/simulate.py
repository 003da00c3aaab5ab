"""Rendered calibration images of a known camera: the camera rig's simulator (tests, demo, shipped examples).

:func:`simulate_session` renders views of a target (chessboard, ChArUco or
ArUco/AprilTag grid) with :func:`robocal.camera.render_target_view` (exact
under the camera's distortion), with blur, grey-level noise and vignetting as
a real camera has them, and writes what ``robocal camera calibrate`` takes:
``images/view_NNN.png``, ``target.yaml``, ``camera_truth.yaml`` (the true
camera, OpenCV FileStorage) and the session file ``camera_input.yaml``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal.errors import InputError

__all__ = ["TARGET_KINDS", "LENSES", "default_camera", "default_fisheye", "default_target", "sample_poses", "simulate_session", "SimulatedSession",
           "target_mapping", "INPUT_NAME"]

#: The session file ``simulate`` writes (``Workflow.simulated_inputs``).
INPUT_NAME = "camera_input.yaml"
TARGET_KINDS = ("chessboard", "charuco", "aruco_grid")
LENSES = ("pinhole", "fisheye")


def default_camera(width: int = 640, height: int = 480):
    """A 640 x 480 camera of ~65 deg horizontal field of view with a webcam's barrel distortion (5 terms)."""
    from robocal.camera import CameraModel

    s = width / 640.0
    return CameraModel(520.0 * s, 518.0 * s, 322.5 * s, 243.5 * height / 480.0,
                       dist=[-0.28, 0.095, 8e-4, -5e-4, -0.015], width=width, height=height)


def default_fisheye(width: int = 640, height: int = 480):
    """A 640 x 480 equidistant fisheye (cv2.fisheye model) of ~150 deg diagonal field of view."""
    from robocal.camera import FisheyeCamera

    s = width / 640.0
    return FisheyeCamera(260.0 * s, 259.0 * s, 320.5 * s, 240.5 * height / 480.0, [0.05, -0.01, 0.003, -0.001],
                         width, height)


def default_target(kind: str = "chessboard"):
    """The target of each kind simulate renders: a 9 x 6 inner-corner chessboard of 25 mm squares,
    a 7 x 5-square ChArUco board (40 / 30 mm, DICT_5X5_100), a 4 x 6 AprilTag 36h11 grid (40 / 10 mm)."""
    from robocal.camera import ArucoGridTarget, CharucoTarget, ChessboardTarget

    if kind == "chessboard":
        return ChessboardTarget(6, 9, 0.025)
    if kind == "charuco":
        return CharucoTarget(5, 7, 0.04, 0.03, "DICT_5X5_100")
    if kind == "aruco_grid":
        return ArucoGridTarget(4, 6, 0.04, 0.01, "DICT_APRILTAG_36h11")
    raise InputError(f"target must be one of {', '.join(TARGET_KINDS)}, got {kind!r}")


def target_mapping(target) -> dict:
    """The target as the mapping of a target file (lengths in mm), which :func:`robocal.camera.load_target` reads."""
    def mm(x):
        return {"value": round(float(x) * 1e3, 9), "unit": "mm"}

    out = {"type": target.kind, "rows": int(target.rows), "cols": int(target.cols)}
    if target.kind == "chessboard":
        out["square"] = mm(target.square)
    elif target.kind == "charuco":
        out.update(square=mm(target.square), marker=mm(target.marker), dictionary=target.dictionary,
                   legacy=bool(target.legacy), min_points=int(target.min_points))
    else:
        out.update(marker=mm(target.marker), separation=mm(target.separation), dictionary=target.dictionary,
                   first_id=int(target.first_id), min_points=int(target.min_points))
    return out


def sample_poses(camera, target, n_views: int, rng: np.random.Generator, *, whole: bool = True,
                 distance=(0.3, 0.75), tilt_rad: float = 0.6) -> list:
    """``n_views`` poses ``T_cam_board`` (4, 4) [m] of the target seen by ``camera``, drawn from ``rng``.

    The poses of :func:`robocal.camera.simulate_target_views` (centre on the
    ray of a random pixel, random distance and tilt); with ``whole`` every
    point of the target is inside the image (a chessboard is only found
    whole), otherwise at least half of them (a partial ChArUco/grid view).
    """
    from robocal.camera import simulate_target_views

    pts = target.object_points()
    poses = []
    for _ in range(200 * max(n_views, 1)):
        if len(poses) == n_views:
            break
        views, Ts = simulate_target_views(camera, pts, 1, rng, distance=distance, tilt_rad=tilt_rad, margin_px=8.0)
        if whole and len(views[0]) < len(pts):
            continue
        poses.append(Ts[0])
    if len(poses) < n_views:
        raise InputError(f"could not place {n_views} views of the {target.describe()} in the "
                         f"{camera.width} x {camera.height} image at {distance[0]}-{distance[1]} m")
    return poses


@dataclass
class SimulatedSession:
    """What :func:`simulate_session` wrote, with the truth: the session file, the images, camera and poses."""

    session: Path
    images: list
    target_file: Path
    truth_file: Path
    camera: object
    target: object
    poses: list
    defects: dict


def simulate_session(out_dir, rng: np.random.Generator, *, views: int = 12, target: str = "chessboard",
                     width: int = 640, height: int = 480, blur: float = 0.7, noise: float = 2.0,
                     vignetting: float = 0.3, defects: bool = False, image_format: str = "png",
                     lens: str = "pinhole", camera=None, progress: bool = False) -> SimulatedSession:
    """Render ``views`` images of a target with the known :func:`default_camera`; write the session.

    Parameters
    ----------
    views : int
        Images of the target (>= 3).
    target : {"chessboard", "charuco", "aruco_grid"}
        The target (:func:`default_target`); ChArUco and grid views may be
        partial (a part of the board outside the image), chessboard views are whole.
    width, height : int
        Image size [px]; the focal length scales with the width.
    blur : float
        Gaussian blur sigma [px] (optics); ``noise``: grey-level noise std
        (0-255); ``vignetting``: brightness loss at the image corners (0-1).
    defects : bool
        Add two views a real session has: one badly defocused (blur 4 px) and
        a second shot of the first pose (a duplicate); calibrate names and
        skips both.
    lens : {"pinhole", "fisheye"}
        :func:`default_camera` (OpenCV 5-term distortion) or
        :func:`default_fisheye` (equidistant; calibrate it with ``model="fisheye"``).
    image_format : {"png", "jpg"}
        Lossless PNG, or JPEG of quality 90 (a quarter of the size; its
        compression adds ~0.005 px to the corner noise; the shipped examples).
    camera : CameraModel or FisheyeCamera, optional
        The camera to render with instead of ``lens``'s default (a robot of a
        simulated fleet, :mod:`robocal.rigs.camera.fleet`); its size wins over
        ``width`` / ``height``.
    """
    import cv2
    import yaml

    from robocal.camera import render_target_view, write_camera
    from robocal.io import atomic_write_bytes, atomic_write_text
    from robocal.progress import progress as _progress
    from robocal.rigs.camera.files import write_session

    if not isinstance(rng, np.random.Generator):
        raise InputError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    if image_format not in ("png", "jpg"):
        raise InputError(f"image_format: must be 'png' or 'jpg', got {image_format!r}")
    if int(views) < 3:
        raise InputError(f"views: a calibration needs >= 3 views, got {views}")
    for name, v in (("blur", blur), ("noise", noise)):
        if not np.isfinite(v) or v < 0:
            raise InputError(f"{name}: must be >= 0, got {v}")
    out_dir = Path(out_dir)
    if lens not in LENSES:
        raise InputError(f"lens: must be one of {', '.join(LENSES)}, got {lens!r}")
    cam = camera if camera is not None else (default_camera if lens == "pinhole" else default_fisheye)(
        int(width), int(height))
    tgt = default_target(target)
    # distances scale with the focal length, so that the target looks the same in pixels at any image size
    scale = cam.fx / default_camera().fx
    poses = sample_poses(cam, tgt, int(views), rng, whole=tgt.kind == "chessboard",
                         distance=(0.3 * scale, 0.75 * scale))
    shots = [(T, blur) for T in poses]
    defect_names = {}
    if defects:
        shots.append((poses[0], 4.0))
        defect_names[f"view_{len(shots) - 1:03d}.{image_format}"] = "defocused (blur 4 px)"
        shots.append((poses[1], blur))
        defect_names[f"view_{len(shots) - 1:03d}.{image_format}"] = f"a second shot of view_001.{image_format}"
    (out_dir / "images").mkdir(parents=True, exist_ok=True)
    images = []
    for k, (T, b) in enumerate(_progress(shots, desc="render", enabled=progress)):
        img = render_target_view(cam, tgt, T, rng, blur_sigma=b, noise_sigma=noise, vignetting=vignetting)
        params = [cv2.IMWRITE_JPEG_QUALITY, 90] if image_format == "jpg" else []
        ok, buf = cv2.imencode(f".{image_format}", img, params)
        path = out_dir / "images" / f"view_{k:03d}.{image_format}"
        atomic_write_bytes(path, buf.tobytes())
        images.append(path)
    target_file = out_dir / "target.yaml"
    atomic_write_text(target_file, "# robocal camera simulate: the rendered target\n"
                      + yaml.safe_dump(target_mapping(tgt), sort_keys=False))
    truth_file = write_camera(out_dir / "camera_truth.yaml", cam)
    session = write_session(out_dir / INPUT_NAME, f"images/*.{image_format}", target_file, truth_file=truth_file,
                            comment=f"robocal camera simulate: {len(shots)} rendered views of the "
                                    f"{tgt.describe()}, blur {blur} px, noise {noise} grey levels")
    return SimulatedSession(session, images, target_file, truth_file, cam, tgt, poses, defect_names)
