"""A simulated robot recording with known truth, written as a ROS 1 bag, a ROS 2 bag or MCAP.

Used by the tests (read back and compared with the truth), the benchmark and
the committed example ``examples/bags/``. The scene: a mobile base driving in
``odom`` (``odom -> base_link``, dynamic, on ``/tf``), an arm's flange
(``base_link -> tool0``, dynamic), a camera bolted to the base
(``base_link -> camera_link -> camera_optical``, static, on ``/tf_static``),
the arm's joint states, rendered chessboard images with their CameraInfo
(the board poses in the camera frame are part of the truth, not tied to the
tf tree), and odometry.

Clocks: receive time = header stamp + a fixed transport latency per topic;
``camera_clock_offset`` shifts the camera's header stamps (a driver on
another clock), which :func:`robocal.bags.inspect_recording` must flag.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robocal.errors import InputError

__all__ = ["RecordingTruth", "simulate_recording", "RECORDING_FORMATS"]

#: ``format`` names of :func:`simulate_recording`.
RECORDING_FORMATS = ("rosbag1", "rosbag2", "mcap")

#: Image encodings :func:`simulate_recording` can write, each on its own topic.
IMAGE_TOPICS = {"mono8": "/camera/image_raw", "bgr8": "/camera/image_color", "rgb8": "/camera/image_rgb",
                "mono16": "/camera/image_mono16", "png": "/camera/image_raw/compressed"}

T0_NS = 1_700_000_000 * 1_000_000_000  # an epoch time, so float-second rounding is what a real bag gives
LATENCY_NS = {"tf": 2_000_000, "joints": 1_000_000, "camera": 30_000_000, "odom": 5_000_000}


@dataclass
class RecordingTruth:
    """What :func:`simulate_recording` wrote: stamps [ns], poses ``T_parent_child`` (4x4, m), joints [rad], images."""

    path: Path
    format: str
    tf_stamps_ns: np.ndarray
    T_odom_base: np.ndarray
    tool_stamps_ns: np.ndarray
    T_base_tool: np.ndarray
    T_base_camera_link: np.ndarray
    T_camera_link_optical: np.ndarray
    joint_names: tuple
    joint_stamps_ns: np.ndarray
    joint_positions: np.ndarray
    joint_velocities: np.ndarray
    image_stamps_ns: np.ndarray
    images: list
    camera: object
    T_cam_board: np.ndarray  # (N, 4, 4): the 7x5 chessboard (30 mm squares) in the camera frame, per image
    image_topics: dict = field(default_factory=dict)

    def pose(self, name: str, t_s) -> np.ndarray:
        """The exact trajectory ``odom_base`` or ``base_tool`` at times ``t_s`` [s since T0]."""
        return {"odom_base": _odom_base, "base_tool": _base_tool}[name](np.asarray(t_s, float))


def _rot(rotvec) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(rotvec).as_matrix()


def _pose(R, p) -> np.ndarray:
    T = np.zeros(R.shape[:-2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def _odom_base(t):
    p = np.stack([0.5 * np.sin(0.5 * t), 0.3 * t, np.full_like(t, 0.1)], -1)
    r = np.stack([0.05 * np.sin(t), 0.04 * np.cos(0.7 * t), 0.4 * t], -1)
    return _pose(_rot(r), p)


def _base_tool(t):
    p = np.stack([0.4 + 0.1 * np.cos(t), 0.1 * np.sin(1.3 * t), 0.6 + 0.05 * t], -1)
    r = np.stack([0.3 * np.sin(0.8 * t), 0.2 + 0.1 * t, -0.5 * np.cos(t)], -1)
    return _pose(_rot(r), p)


def _stamps(duration: float, rate: float) -> np.ndarray:
    n = int(np.floor(duration * rate)) + 1
    return T0_NS + np.round(np.arange(n) * 1e9 / rate).astype(np.int64)


def _typestore(fmt: str):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if fmt != "rosbag1":
        return get_typestore(Stores.ROS2_HUMBLE)
    ts = get_typestore(Stores.ROS1_NOETIC)  # has no tf2_msgs: registered from its .msg text
    ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    return ts


class _Writer:
    """One writer API over rosbags' ROS 1 and ROS 2 (sqlite3 / MCAP) writers."""

    def __init__(self, path: Path, fmt: str, compress: bool = False):
        self.fmt, self.ts = fmt, _typestore(fmt)
        if fmt == "rosbag1":
            from rosbags.rosbag1 import Writer

            self.w = Writer(path)
            if compress:  # LZ4 chunks, as `rosbag record --lz4` writes them
                self.w.set_compression(Writer.CompressionFormat.LZ4)
        else:
            from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

            plugin = StoragePlugin.MCAP if fmt == "mcap" else StoragePlugin.SQLITE3
            self.w = Writer(path, version=8, storage_plugin=plugin)
            if compress:  # zstd per message, as `ros2 bag record --compression-mode message` writes it
                self.w.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
        self.conns = {}

    def __enter__(self):
        self.w.open()
        return self

    def __exit__(self, *exc):
        self.w.close()

    def msg(self, msgtype, /, **kw):
        return self.ts.types[msgtype](**kw)

    def header(self, stamp_ns: int, frame: str):
        t = self.msg("builtin_interfaces/msg/Time", sec=int(stamp_ns // 10**9), nanosec=int(stamp_ns % 10**9))
        if self.fmt == "rosbag1":
            return self.msg("std_msgs/msg/Header", seq=0, stamp=t, frame_id=frame)
        return self.msg("std_msgs/msg/Header", stamp=t, frame_id=frame)

    def write(self, topic: str, msgtype: str, t_ns: int, message) -> None:
        if topic not in self.conns:
            self.conns[topic] = self.w.add_connection(topic, msgtype, typestore=self.ts)
        ser = self.ts.serialize_ros1 if self.fmt == "rosbag1" else self.ts.serialize_cdr
        self.w.write(self.conns[topic], int(t_ns), ser(message, msgtype))

    # -- message builders ---------------------------------------------------------
    def vec(self, v):
        return self.msg("geometry_msgs/msg/Vector3", x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def quat(self, R):
        from scipy.spatial.transform import Rotation

        q = Rotation.from_matrix(R).as_quat()  # scalar-last, like ROS
        return self.msg("geometry_msgs/msg/Quaternion", x=q[0], y=q[1], z=q[2], w=q[3])

    def transform(self, stamp_ns, parent, child, T):
        tf = self.msg("geometry_msgs/msg/Transform", translation=self.vec(T[:3, 3]), rotation=self.quat(T[:3, :3]))
        return self.msg("geometry_msgs/msg/TransformStamped", header=self.header(stamp_ns, parent),
                        child_frame_id=child, transform=tf)

    def tf(self, transforms):
        return self.msg("tf2_msgs/msg/TFMessage", transforms=transforms)


def _image_msg(w: _Writer, stamp_ns: int, recv_ns: int, img: np.ndarray, encoding: str):
    """``(msgtype, recv_ns, message)`` of one image written with ``encoding``."""
    if encoding == "png":
        import cv2

        ok, buf = cv2.imencode(".png", img)
        return "sensor_msgs/msg/CompressedImage", recv_ns, w.msg("sensor_msgs/msg/CompressedImage",
                                                        header=w.header(stamp_ns, "camera_optical"), format="png",
                                                        data=np.frombuffer(buf.tobytes(), np.uint8))
    if encoding == "bgr8":
        data = np.stack([img, 255 - img, img // 2], -1)
    elif encoding == "rgb8":
        data = np.stack([img // 2, 255 - img, img], -1)  # the same colours as bgr8, channels reversed
    elif encoding == "mono16":
        data = img.astype("<u2") * 257
    else:
        data = img
    h, wid = img.shape
    raw = np.ascontiguousarray(data).view(np.uint8).reshape(-1)
    return "sensor_msgs/msg/Image", recv_ns, w.msg("sensor_msgs/msg/Image", header=w.header(stamp_ns, "camera_optical"),
                                          height=h, width=wid, encoding=encoding, is_bigendian=0,
                                          step=raw.size // h, data=raw)


def expected_image(img: np.ndarray, encoding: str) -> np.ndarray:
    """The array robocal returns for ``img`` (grey, uint8) written with ``encoding`` (colour as BGR, like cv2)."""
    if encoding in ("bgr8", "rgb8"):
        return np.stack([img, 255 - img, img // 2], -1)
    if encoding == "mono16":
        return img.astype(np.uint16) * 257
    return img


def _camera_info(w: _Writer, stamp_ns: int, camera):
    K = [camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0]
    P = [camera.fx, 0.0, camera.cx, 0.0, 0.0, camera.fy, camera.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    d = np.asarray(camera.dist, float)
    model = "plumb_bob" if d.size <= 5 else "rational_polynomial"
    names = ("D", "K", "R", "P") if w.fmt == "rosbag1" else ("d", "k", "r", "p")
    vals = (d, np.array(K), np.eye(3).ravel(), np.array(P))
    roi = w.msg("sensor_msgs/msg/RegionOfInterest", x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return w.msg("sensor_msgs/msg/CameraInfo", header=w.header(stamp_ns, "camera_optical"), height=camera.height,
                 width=camera.width, distortion_model=model, binning_x=0, binning_y=0, roi=roi, **dict(zip(names, vals)))


def _render_views(camera, n: int, rng) -> list:
    from robocal.camera import ChessboardTarget, render_target_view

    target = ChessboardTarget(rows=5, cols=7, square=0.03)
    poses = board_poses(n)
    return [render_target_view(camera, target, T, rng, noise_sigma=2.0) for T in poses], poses


def board_poses(n: int) -> np.ndarray:
    """(n, 4, 4) ``T_cam_board`` of the simulated views: the 7x5 board (30 mm squares) centred 0.45 m ahead, tilted."""
    k = np.arange(n)
    R = _rot(np.stack([0.25 * np.sin(k), 0.25 * np.cos(1.7 * k), 0.3 * np.sin(0.5 * k)], -1))
    centre = np.array([3 * 0.03, 2 * 0.03, 0.0])
    return _pose(R, np.array([0.0, 0.0, 0.45]) - R @ centre)


def simulate_recording(path, *, format: str = "rosbag1", duration: float = 2.0, tf_rate: float = 50.0,
                       joint_rate: float = 100.0, image_rate: float = 2.0, image_size=(160, 120),
                       encodings=("mono8",), distinct_images: int | None = None, camera_clock_offset: float = 0.0,
                       compress: bool = False, rng: np.random.Generator | None = None) -> RecordingTruth:
    """Write a simulated recording to ``path`` and return its truth.

    Parameters
    ----------
    path : str or Path
        A new ``.bag`` file (``rosbag1``) or a new ROS 2 bag folder
        (``rosbag2``: sqlite3 ``.db3`` inside; ``mcap``: ``.mcap`` inside).
    format : {"rosbag1", "rosbag2", "mcap"}
    duration : float
        Seconds recorded.
    tf_rate, joint_rate, image_rate : float
        Rates [Hz] of ``/tf`` (``odom -> base_link``, ``base_link -> tool0``)
        and ``/odom``, of ``/joint_states`` (6 joints), and of the images + ``/camera/camera_info``.
    image_size : (width, height)
    encodings : sequence of str
        Image topics written: ``mono8``, ``bgr8``, ``rgb8``, ``mono16`` (raw
        ``sensor_msgs/Image``) and ``png`` (``CompressedImage``); see ``IMAGE_TOPICS``.
    distinct_images : int, optional
        Render only this many views and repeat them (fast large bags for the benchmark).
    camera_clock_offset : float
        Seconds added to the camera topics' header stamps (another clock).
    compress : bool
        ROS 1: LZ4 chunks; ROS 2 and MCAP: zstd per message.
    rng : numpy.random.Generator, optional
        Image noise (default: seed 0).
    """
    from robocal.camera import CameraModel

    if format not in RECORDING_FORMATS:
        raise InputError(f"format must be one of {', '.join(RECORDING_FORMATS)}, got {format!r}")
    bad = [e for e in encodings if e not in IMAGE_TOPICS]
    if bad:
        raise InputError(f"encodings: {bad} not among {', '.join(IMAGE_TOPICS)}")
    path = Path(path)
    rng = np.random.default_rng(0) if rng is None else rng
    wid, hei = image_size
    f = 0.9 * wid
    camera = CameraModel(f, f, (wid - 1) / 2 + 1.5, (hei - 1) / 2 - 1.0, np.array([-0.12, 0.05, 1e-3, -5e-4, 0.0]),
                         wid, hei)
    tf_ns, tool_ns = _stamps(duration, tf_rate), _stamps(duration, 2 * tf_rate)
    joint_ns, image_ns = _stamps(duration, joint_rate), _stamps(duration, image_rate)
    T_ob, T_bt = _odom_base((tf_ns - T0_NS) / 1e9), _base_tool((tool_ns - T0_NS) / 1e9)
    T_bc = _pose(_rot([0.0, 0.2, 0.0]), [0.25, 0.0, 0.4])
    # REP 103: camera_link is x forward, z up; the optical frame x right, y down, z forward
    T_co = _pose(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]), [0.0, 0.0, 0.0])
    names = tuple(f"joint_{i}" for i in range(1, 7))
    amp, w_j, ph = np.linspace(0.3, 0.8, 6), np.linspace(0.5, 1.5, 6), np.linspace(0.0, 2.0, 6)
    tj = (joint_ns - T0_NS)[:, None] / 1e9
    q, qd = amp * np.sin(w_j * tj + ph), amp * w_j * np.cos(w_j * tj + ph)
    n_views = len(image_ns) if distinct_images is None else min(distinct_images, len(image_ns))
    views, view_poses = _render_views(camera, n_views, rng)
    images = [views[k % n_views] for k in range(len(image_ns))]
    T_cam_board = view_poses[np.arange(len(image_ns)) % n_views]
    off = int(round(camera_clock_offset * 1e9))

    events = []  # (receive_ns, order, callable) written in receive order, like a recorder
    def at(stamp, kind, fn):
        events.append((int(stamp) + LATENCY_NS[kind], len(events), fn))

    with _Writer(path, format, compress) as w:
        start = int(T0_NS)
        w.write("/tf_static", "tf2_msgs/msg/TFMessage", start, w.tf([
            w.transform(start, "base_link", "camera_link", T_bc),
            w.transform(start, "camera_link", "camera_optical", T_co)]))
        for k, s in enumerate(tf_ns):
            at(s, "tf", lambda s=s, k=k: w.write("/tf", "tf2_msgs/msg/TFMessage", s + LATENCY_NS["tf"],
                                                 w.tf([w.transform(s, "odom", "base_link", T_ob[k])])))
            at(s, "odom", lambda s=s, k=k: _write_odom(w, s, T_ob[k]))
        for k, s in enumerate(tool_ns):
            at(s, "tf", lambda s=s, k=k: w.write("/tf", "tf2_msgs/msg/TFMessage", s + LATENCY_NS["tf"],
                                                 w.tf([w.transform(s, "base_link", "tool0", T_bt[k])])))
        for k, s in enumerate(joint_ns):
            at(s, "joints", lambda s=s, k=k: w.write(
                "/joint_states", "sensor_msgs/msg/JointState", s + LATENCY_NS["joints"],
                w.msg("sensor_msgs/msg/JointState", header=w.header(s, ""), name=list(names),
                      position=q[k].copy(), velocity=qd[k].copy(), effort=np.zeros(6))))
        for k, s in enumerate(image_ns):
            recv = s + LATENCY_NS["camera"]
            for enc in encodings:
                at(s, "camera", lambda s=s, k=k, enc=enc, recv=recv: w.write(
                    IMAGE_TOPICS[enc], *_image_msg(w, s + off, recv, images[k], enc)))
            at(s, "camera", lambda s=s, recv=recv: w.write("/camera/camera_info", "sensor_msgs/msg/CameraInfo", recv,
                                                           _camera_info(w, s + off, camera)))
        for _, _, fn in sorted(events, key=lambda e: (e[0], e[1])):
            fn()
    return RecordingTruth(path, format, tf_ns, T_ob, tool_ns, T_bt, T_bc, T_co, names, joint_ns, q, qd,
                          image_ns + off, images, camera, T_cam_board, {e: IMAGE_TOPICS[e] for e in encodings})


def _write_odom(w: _Writer, s: int, T: np.ndarray) -> None:
    pose = w.msg("geometry_msgs/msg/Pose", position=w.msg("geometry_msgs/msg/Point", x=T[0, 3], y=T[1, 3], z=T[2, 3]),
                 orientation=w.quat(T[:3, :3]))
    twist = w.msg("geometry_msgs/msg/Twist", linear=w.vec([0.1, 0.2, 0.3]), angular=w.vec([0.0, 0.0, 0.4]))
    msg = w.msg("nav_msgs/msg/Odometry", header=w.header(s, "odom"), child_frame_id="base_link",
                pose=w.msg("geometry_msgs/msg/PoseWithCovariance", pose=pose, covariance=np.zeros(36)),
                twist=w.msg("geometry_msgs/msg/TwistWithCovariance", twist=twist, covariance=np.zeros(36)))
    w.write("/odom", "nav_msgs/msg/Odometry", s + LATENCY_NS["odom"], msg)
