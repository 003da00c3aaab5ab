"""A simulated hand-eye recording with known truth: an arm moving between stations, a camera imaging a board.

What a ROS user records for hand-eye calibration, written as a ROS 1 bag, a ROS 2 bag or MCAP
(:data:`robocal.bags.RECORDING_FORMATS`):

* ``/tf_static``: ``world -> base_link`` and the tool offset ``flange -> tool0``;
* ``/tf`` at ``tf_rate`` (robot_state_publisher style, both edges in one message):
  ``base_link -> shoulder_link -> flange``, so ``base_link -> tool0`` is a chain of two dynamic and
  one static edge;
* ``/camera/image_raw`` (``sensor_msgs/Image`` mono8, or ``CompressedImage`` PNG on
  ``/camera/image_raw/compressed``) at ``image_rate``, streamed while the arm moves and while it dwells,
  each image rendered at the exact pose of its header stamp (no motion blur), and ``/camera/camera_info``.

Set-ups (``docs/handeye.md``): ``eye-in-hand``: the camera on ``tool0`` (``X = T_gripper_cam``) looks
at a fixed 7 x 5 chessboard (``Y = T_base_target``); ``eye-to-hand``: the camera fixed in ``base_link``
(``X = T_base_cam``), the board on ``tool0`` (``Y = T_gripper_target``). Neither X nor the board is in
the tf tree: they are what the calibration finds. The stations are the views of
:func:`robocal.handeye.simulate_eye_in_hand` (0.30-0.45 m, tilted up to 35 deg); between two
stations the board's pose in the camera moves along the geodesic (SLERP + linear) with a smoothstep in
time (zero speed at the stations), and the robot pose follows from the closure
``T_base_gripper X T_cam_target = Y`` (eye-to-hand: ``T_base_gripper^-1 X T_cam_target = Y``).

Clocks: receive time = header stamp + a transport latency (tf 2 ms, camera 30 ms, as
:func:`simulate_recording`); ``camera_clock_offset`` shifts the camera's header stamps (a camera on
another clock).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal.bags._simulate import LATENCY_NS, RECORDING_FORMATS, T0_NS, _camera_info, _image_msg, _pose, _rot, \
    _Writer
from robocal.errors import InputError

__all__ = ["HandEyeRecordingTruth", "simulate_handeye_recording", "HANDEYE_BOARD_YAML"]

#: The board of the simulated recordings: 7 x 5 inner corners, 30 mm squares (``target.yaml`` of the example).
HANDEYE_BOARD_YAML = "type: chessboard\nrows: 5\ncols: 7\nsquare: {value: 30, unit: mm}\n"


@dataclass
class HandEyeRecordingTruth:
    """What :func:`simulate_handeye_recording` wrote.

    ``X`` / ``Y``: the set-up's unknowns (``T_gripper_cam`` / ``T_base_target`` eye-in-hand,
    ``T_base_cam`` / ``T_gripper_target`` eye-to-hand; 4x4, m; Y in the renderer's board frame, which the
    chessboard detector may number from the opposite corner). Per image: ``image_stamps_ns`` (header
    stamps, camera clock), ``T_base_gripper`` (exact, ``base_link -> tool0``) and ``T_cam_board``.
    ``tf_stamps_ns``: the ``/tf`` stamps.
    """

    path: Path
    format: str
    setup: str
    X: np.ndarray
    Y: np.ndarray
    image_stamps_ns: np.ndarray
    T_base_gripper: np.ndarray
    T_cam_board: np.ndarray
    tf_stamps_ns: np.ndarray
    camera: object
    image_topic: str
    camera_info_topic: str = "/camera/camera_info"
    base: str = "base_link"
    gripper: str = "tool0"
    target_yaml: str = HANDEYE_BOARD_YAML


def _quats(T: np.ndarray) -> np.ndarray:
    """(N, 4) scalar-last quaternions (ROS order) of (N, 4, 4) poses."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(T[:, :3, :3]).as_quat()


def _transform(w: _Writer, stamp_ns: int, parent: str, child: str, p, q):
    """A ``TransformStamped`` from a translation and a scalar-last quaternion."""
    rot = w.msg("geometry_msgs/msg/Quaternion", x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))
    tf = w.msg("geometry_msgs/msg/Transform", translation=w.vec(p), rotation=rot)
    return w.msg("geometry_msgs/msg/TransformStamped", header=w.header(stamp_ns, parent), child_frame_id=child,
                 transform=tf)


def _pose_stamped(w: _Writer, stamp_ns: int, T: np.ndarray):
    """``geometry_msgs/PoseStamped`` of the board in ``camera_optical``."""
    p = w.msg("geometry_msgs/msg/Point", x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3]))
    pose = w.msg("geometry_msgs/msg/Pose", position=p, orientation=w.quat(T[:3, :3]))
    return w.msg("geometry_msgs/msg/PoseStamped", header=w.header(stamp_ns, "camera_optical"), pose=pose)


def _pose_with_covariance(w: _Writer, stamp_ns: int, T: np.ndarray, noise):
    """``geometry_msgs/PoseWithCovarianceStamped``: the pose and its covariance, ROS order (x, y, z, rx, ry, rz)."""
    pose = _pose_stamped(w, stamp_ns, T).pose
    cov = np.diag([noise[1] ** 2] * 3 + [noise[0] ** 2] * 3).ravel()
    return w.msg("geometry_msgs/msg/PoseWithCovarianceStamped", header=w.header(stamp_ns, "camera_optical"),
                 pose=w.msg("geometry_msgs/msg/PoseWithCovariance", pose=pose, covariance=cov))


def _smooth_station(t: np.ndarray, n: int, move: float, dwell: float) -> np.ndarray:
    """The station coordinate u in [0, n-1] at times ``t`` [s]: dwell at station k, then a smoothstep to k+1."""
    period = move + dwell
    k = np.floor(t / period)
    r = np.clip((t - k * period - dwell) / move, 0.0, 1.0)
    return np.clip(k + r * r * (3.0 - 2.0 * r), 0.0, n - 1.0)


def simulate_handeye_recording(path, *, format: str = "rosbag1", setup: str = "eye-in-hand", stations: int = 6,
                               move: float = 1.0, dwell: float = 1.0, tf_rate: float = 100.0,
                               image_rate: float = 1.0, image_size=(320, 240), compressed: bool = False,
                               noise_sigma: float = 1.0, pose_topic: bool = False, pose_noise=(1e-3, 0.2e-3),
                               camera_clock_offset: float = 0.0, tf_hole=None, compress: bool = False,
                               rng: np.random.Generator | None = None) -> HandEyeRecordingTruth:
    """Write a simulated hand-eye recording to ``path`` and return its truth (module docstring).

    Parameters
    ----------
    path : str or Path
        A new ``.bag`` file (``rosbag1``) or a new ROS 2 bag folder (``rosbag2``, ``mcap``).
    format : {"rosbag1", "rosbag2", "mcap"}
    setup : {"eye-in-hand", "eye-to-hand"}
    stations : int
        Robot stations (>= 3); the recording lasts ``stations * (move + dwell) - move`` seconds.
    move, dwell : float
        Seconds moving between two stations and resting at each. With the default 1 s moves of
        ~0.1-0.3 m, linear tf interpolation at 100 Hz is off by < 20 um (acceleration x period^2 / 8).
    tf_rate, image_rate : float
        Rates [Hz] of ``/tf`` and of the images + camera info. Image stamps sit 3.7 ms off the tf
        grid, so every robot pose is interpolated.
    image_size : (width, height)
        The camera: focal length 0.95 x width, a webcam's mild barrel distortion.
    compressed : bool
        PNG ``CompressedImage`` on ``/camera/image_raw/compressed`` (a third of the size) instead of
        mono8 ``Image`` on ``/camera/image_raw``.
    noise_sigma : float
        Grey-level noise of the rendered images.
    pose_topic : bool
        Also write ``/camera/target_pose`` (``geometry_msgs/PoseStamped``, frame ``camera_optical``): the
        board's pose in the camera at each image stamp, as a user's detector publishes it, with
        ``pose_noise`` = (rotation [rad], translation [m]) Gaussian noise per axis; and the same poses
        with that covariance on ``/camera/target_pose_cov`` (``PoseWithCovarianceStamped``).
    camera_clock_offset : float
        Seconds added to the camera topics' header stamps.
    compress : bool
        ROS 1: LZ4 chunks; ROS 2 and MCAP: zstd per message (:func:`simulate_recording`'s).
    tf_hole : (float, float), optional
        ``/tf`` is not written from ``tf_hole[0]`` to ``tf_hole[1]`` [s from the start] (a stalled publisher).
    rng : numpy.random.Generator, optional
        Stations and image noise (default: seed 0).
    """
    from robocal.camera import CameraModel, ChessboardTarget, render_target_view
    from robocal.geometry import invert_transform, transform_from
    from robocal.handeye.simulate import simulate_eye_in_hand, simulate_eye_to_hand
    from robocal.io import interpolate_poses

    if format not in RECORDING_FORMATS:
        raise InputError(f"format must be one of {', '.join(RECORDING_FORMATS)}, got {format!r}")
    if setup not in ("eye-in-hand", "eye-to-hand"):
        raise InputError(f"setup must be eye-in-hand or eye-to-hand, got {setup!r}")
    if stations < 3:
        raise InputError(f"stations must be at least 3 (AX = XB needs 2 motions), got {stations}")
    path, rng = Path(path), (np.random.default_rng(0) if rng is None else rng)
    sim = (simulate_eye_in_hand if setup == "eye-in-hand" else simulate_eye_to_hand)(rng, stations, noise=False)
    board = ChessboardTarget(rows=5, cols=7, square=0.03)
    # the stations look at the target frame's origin: put the board's centre there (as images.py does)
    centre = transform_from(np.eye(3), [-0.5 * 0.03 * (board.cols - 1), -0.5 * 0.03 * (board.rows - 1), 0.0])
    wid, hei = image_size
    f = 0.95 * wid
    camera = CameraModel(f, f, (wid - 1) / 2 + 1.5, (hei - 1) / 2 - 1.0, np.array([-0.05, 0.02, 0.0, 0.0, 0.0]),
                         wid, hei)

    duration = stations * (move + dwell) - move
    tf_ns = T0_NS + np.round(np.arange(int(np.floor(duration * tf_rate)) + 1) * 1e9 / tf_rate).astype(np.int64)
    t_img = np.arange(0.5 / image_rate, duration - 0.01, 1.0 / image_rate) + 0.0037
    img_ns = T0_NS + np.round(t_img * 1e9).astype(np.int64)

    def views(t):  # T_cam_target along the path at times t [s]
        return interpolate_poses(np.arange(stations, dtype=float), sim.T_cam_target,
                                 _smooth_station(t, stations, move, dwell))

    def gripper(Tc):  # the closure solved for the robot pose
        if setup == "eye-in-hand":
            return sim.Y @ invert_transform(Tc) @ invert_transform(sim.X)
        return sim.X @ Tc @ invert_transform(sim.Y)

    T_bt = gripper(views((tf_ns - T0_NS) / 1e9))
    T_cam_target_img = views(t_img)
    T_cam_board = T_cam_target_img @ centre
    images = [render_target_view(camera, board, T, rng, noise_sigma=noise_sigma) for T in T_cam_board]
    T_pose_msg = T_cam_board.copy()
    if pose_topic:
        n = len(T_pose_msg)
        T_pose_msg[:, :3, :3] = _rot(rng.normal(size=(n, 3)) * pose_noise[0]) @ T_pose_msg[:, :3, :3]
        T_pose_msg[:, :3, 3] += rng.normal(size=(n, 3)) * pose_noise[1]

    # the arm's chain: a shoulder turning about z towards the flange, then the rest; a static tool offset
    T_world_base = _pose(_rot([0.0, 0.0, 0.3]), [1.0, 0.5, 0.0])
    T_flange_tool = _pose(_rot([0.0, 0.0, np.pi / 4]), [0.0, 0.0, 0.05])
    T_bf = T_bt @ invert_transform(T_flange_tool)
    yaw = np.arctan2(T_bf[:, 1, 3], T_bf[:, 0, 3])
    T_bs = _pose(_rot(np.stack([np.zeros_like(yaw), np.zeros_like(yaw), yaw], -1)), [0.0, 0.0, 0.15])
    T_sf = invert_transform(T_bs) @ T_bf

    topic = "/camera/image_raw/compressed" if compressed else "/camera/image_raw"
    off = int(round(camera_clock_offset * 1e9))
    events = []  # (receive_ns, order, writer): written in receive order, like a recorder

    with _Writer(path, format, compress) as w:
        w.write("/tf_static", "tf2_msgs/msg/TFMessage", int(T0_NS), w.tf([
            w.transform(int(T0_NS), "world", "base_link", T_world_base),
            w.transform(int(T0_NS), "flange", "tool0", T_flange_tool)]))
        q_bs, q_sf = _quats(T_bs), _quats(T_sf)  # one batch: per-message conversions took seconds
        hole = np.zeros(len(tf_ns), bool) if tf_hole is None else \
            (tf_ns >= T0_NS + tf_hole[0] * 1e9) & (tf_ns <= T0_NS + tf_hole[1] * 1e9)
        for k in np.flatnonzero(~hole):
            s = tf_ns[k]
            events.append((int(s) + LATENCY_NS["tf"], len(events), lambda s=int(s), k=k: w.write(
                "/tf", "tf2_msgs/msg/TFMessage", s + LATENCY_NS["tf"],
                w.tf([_transform(w, s, "base_link", "shoulder_link", T_bs[k, :3, 3], q_bs[k]),
                      _transform(w, s, "shoulder_link", "flange", T_sf[k, :3, 3], q_sf[k])]))))
        for k, s in enumerate(img_ns):
            recv = int(s) + LATENCY_NS["camera"]
            events.append((recv, len(events), lambda s=int(s), k=k, recv=recv: w.write(
                topic, *_image_msg(w, s + off, recv, images[k], "png" if compressed else "mono8"))))
            events.append((recv, len(events), lambda s=int(s), recv=recv: w.write(
                "/camera/camera_info", "sensor_msgs/msg/CameraInfo", recv, _camera_info(w, s + off, camera))))
            if pose_topic:
                events.append((recv + 1, len(events), lambda s=int(s), k=k, recv=recv: w.write(
                    "/camera/target_pose", "geometry_msgs/msg/PoseStamped", recv + 1, _pose_stamped(
                        w, s + off, T_pose_msg[k]))))
                events.append((recv + 1, len(events), lambda s=int(s), k=k, recv=recv: w.write(
                    "/camera/target_pose_cov", "geometry_msgs/msg/PoseWithCovarianceStamped", recv + 1,
                    _pose_with_covariance(w, s + off, T_pose_msg[k], pose_noise))))
        for _, _, fn in sorted(events, key=lambda e: (e[0], e[1])):
            fn()
    X, Y = sim.X, sim.Y @ centre
    return HandEyeRecordingTruth(path, format, setup, X, Y, img_ns + off, gripper(T_cam_target_img), T_cam_board,
                                 tf_ns, camera, topic)
