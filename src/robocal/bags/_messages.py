"""Messages as arrays: joint states by name, images (decoded lazily), camera info, points/vectors/odometry.

Every stream carries both clocks (module docstring of ``_reader``):
``stamps`` [s] are the header stamps, ``receive_stamps`` [s] the recorder's
receive times. Units are SI (m, rad, m/s, rad/s); quaternions scalar-last.
Images come as OpenCV arrays: mono ``(H, W)`` (uint8 or uint16), colour
``(H, W, 3)`` in BGR order (``rgb8`` is converted), so ``cv2`` and
:mod:`robocal.camera` take them as ``cv2.imread`` would give them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.bags._reader import open_recording, seconds_from_ns, stamp_ns
from robocal.errors import FileFormatError, InputError

__all__ = ["JointStates", "TopicArrays", "read_joint_states", "read_camera_info", "read_arrays", "iter_images",
           "image_from_message", "IMAGE_TYPES", "ARRAY_TYPES", "PointClouds", "read_point_clouds", "points_from_cloud"]

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
JOINT_TYPES = ("sensor_msgs/msg/JointState",)
CAMERA_INFO_TYPES = ("sensor_msgs/msg/CameraInfo",)


class _Stamped:
    """Seconds views of a stream's ``stamps_ns`` (header) and ``receive_ns`` (log) [int ns], and its clock offset."""

    stamps_ns: np.ndarray
    receive_ns: np.ndarray

    @property
    def stamps(self) -> np.ndarray:
        """Header stamps [s] (float64: 0.24 us resolution at today's epoch; ``stamps_ns`` is exact)."""
        return seconds_from_ns(self.stamps_ns)

    @property
    def receive_stamps(self) -> np.ndarray:
        """Receive (log) times [s]."""
        return seconds_from_ns(self.receive_ns)

    @property
    def clock_offset(self) -> float:
        """Median receive time minus header stamp [s]: milliseconds on one clock; see ``inspect_recording``'s flags."""
        return float(np.median(self.receive_ns - self.stamps_ns)) / 1e9 if len(self.stamps_ns) else float("nan")


@dataclass(frozen=True)
class JointStates(_Stamped):
    """Joint states of one topic: ``position`` (N, J) [rad or m], ``velocity``, ``effort`` (N, J) (NaN where absent).

    ``stamps_ns`` / ``receive_ns`` (N,) int64: header stamps and receive times [ns].

    ``names`` (J,) is the union of every message's names, in first-seen
    order; a joint missing from a message is NaN there.
    """

    topic: str
    names: tuple
    stamps_ns: np.ndarray
    receive_ns: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray

    def __getitem__(self, name: str) -> np.ndarray:
        """Positions (N,) of joint ``name``."""
        if name not in self.names:
            from robocal.bags._reader import closest_names

            raise InputError(f"topic {self.topic}: no joint '{name}'{closest_names(name, self.names)}; "
                             f"joints: {', '.join(self.names)}")
        return self.position[:, self.names.index(name)]


@dataclass(frozen=True)
class TopicArrays(_Stamped):
    """One topic's messages as arrays: ``fields`` maps a name (``position``, ``T``, ``vector``, ...) to (N, ...)."""

    topic: str
    msgtype: str
    frame_id: str
    stamps_ns: np.ndarray
    receive_ns: np.ndarray
    fields: dict = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self.fields:
            raise InputError(f"topic {self.topic} ({self.msgtype}): no field '{name}'; fields: {', '.join(self.fields)}")
        return self.fields[name]


def read_joint_states(path, topic: str = "/joint_states", *, show_progress: bool = True) -> JointStates:
    """Every ``sensor_msgs/JointState`` of ``topic``, by joint name.

    Messages may name different joints (several drivers on one topic): the
    columns are the union, NaN where a message does not give a joint; an
    empty ``velocity`` or ``effort`` (allowed by the message) is NaN too.
    """
    stamps, recv, rows = [], [], []
    with open_recording(path) as rec:
        topic = rec.topic(topic, JOINT_TYPES).name
        for _, r, data in rec.raw(topic, show_progress=show_progress):
            m = rec.deserialize(topic, data)
            rows.append((tuple(m.name), m.position, m.velocity, m.effort))
            stamps.append(stamp_ns(m.header.stamp))
            recv.append(r)
    layouts = list(dict.fromkeys(row[0] for row in rows))  # distinct name lists, first seen first
    names = list(dict.fromkeys(n for layout in layouts for n in layout))
    col = {n: j for j, n in enumerate(names)}
    out = np.full((3, len(rows), len(names)), np.nan)
    for layout in layouts:  # one vectorised fill per distinct name list (usually one)
        sel = [i for i, row in enumerate(rows) if row[0] == layout]
        idx = [col[n] for n in layout]
        for k in range(3):
            ok = [i for i in sel if len(rows[i][k + 1]) == len(idx)]
            if ok:
                out[k][np.ix_(ok, idx)] = np.array([rows[i][k + 1] for i in ok], float)
    return JointStates(topic, tuple(names), np.asarray(stamps, np.int64), np.asarray(recv, np.int64), *out)


def read_camera_info(path, topic: str):
    """The camera of the first ``sensor_msgs/CameraInfo`` on ``topic``: a :class:`~robocal.camera.CameraModel`
    (``plumb_bob``, ``rational_polynomial``) or :class:`~robocal.camera.FisheyeCamera` (``equidistant``).

    A camera whose intrinsics change along the recording is an error (calibrate per segment).
    """
    from robocal.camera import camera_from_mapping

    first = None
    with open_recording(path) as rec:
        topic = rec.topic(topic, CAMERA_INFO_TYPES).name
        for _, _, data in rec.raw(topic, show_progress=False):
            m = rec.deserialize(topic, data)
            # ROS 2 spells the fields k, d; ROS 1 K, D
            k = np.asarray(m.k if hasattr(m, "k") else m.K, float)
            d = np.asarray(m.d if hasattr(m, "d") else m.D, float)
            if first is None:
                first = (m, k, d)
            elif not (np.array_equal(k, first[1]) and np.array_equal(d, first[2])):
                raise InputError(f"{rec.path}: topic {topic}: the camera matrix or distortion changes along the "
                                 "recording; read the segments separately")
        if first is None:
            raise InputError(f"{rec.path}: topic {topic} has no message")
        m, k, d = first
        model = m.distortion_model or "plumb_bob"
        if d.size == 0:  # an uncalibrated driver publishes no coefficients: no distortion
            d = np.zeros(5)
        mapping = {"width": int(m.width), "height": int(m.height), "distortion_model": model,
                   "k": k.tolist(), "d": d.tolist()}
        return camera_from_mapping(mapping, f"{rec.path}: topic {topic}")


# -- images ------------------------------------------------------------------------------

#: Raw encodings: (numpy dtype, channels, converted to BGR from RGB order).
_ENCODINGS = {"mono8": ("u1", 1, False), "8UC1": ("u1", 1, False), "bgr8": ("u1", 3, False),
              "8UC3": ("u1", 3, False), "rgb8": ("u1", 3, True), "mono16": ("u2", 1, False),
              "16UC1": ("u2", 1, False), "bgra8": ("u1", 4, False), "rgba8": ("u1", 4, True)}


def image_from_message(msg, msgtype: str, *, source: str = "<image>") -> np.ndarray:
    """Pixels of a ``sensor_msgs/Image`` (raw encodings of ``_ENCODINGS``) or ``CompressedImage`` (any cv2 codec)."""
    import cv2

    data = np.asarray(msg.data, np.uint8)
    if msgtype.endswith("CompressedImage"):
        try:
            img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        except cv2.error:
            img = None
        if img is None:
            raise FileFormatError(f"{source}: a compressed image ('{msg.format}') that OpenCV cannot decode")
        return img
    enc = msg.encoding
    if enc not in _ENCODINGS:
        raise InputError(f"{source}: image encoding '{enc}' is not supported; supported: {', '.join(_ENCODINGS)}")
    dtype, ch, rgb = _ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    itemsize = np.dtype(dtype).itemsize
    if step < w * ch * itemsize or data.size < h * step:
        raise FileFormatError(f"{source}: a {w}x{h} {enc} image needs {h} rows of >= {w * ch * itemsize} bytes, "
                              f"got step {step} and {data.size} bytes")
    # rows may be padded to `step` bytes: view the rows, then drop the padding
    rows = data[:h * step].reshape(h, step)[:, :w * ch * itemsize]
    img = rows.copy().view(np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<")).reshape(h, w, ch)
    img = img.astype(np.dtype(dtype).newbyteorder("="), copy=False)
    if rgb:
        img = img[..., [2, 1, 0, 3][:ch]]
    return np.ascontiguousarray(img[..., 0] if ch == 1 else img)


def iter_images(path, topic: str, stamps=None, *, tolerance: float = 1e-6, show_progress: bool = True):
    """Yield ``(stamp_ns, image)`` of ``topic``, decoding only the frames asked for.

    ``stamps``: header stamps to pick (int ns or float s); each must match a
    frame within ``tolerance`` [s], else a one-line error names the nearest.
    ``None``: every frame. Frames are chosen from their raw header stamp, so
    the pixels of the frames left out are never copied or decoded.
    """
    with open_recording(path) as rec:
        topic = rec.topic(topic, IMAGE_TYPES).name
        msgtype = rec.topics[topic].msgtype
        wanted = None
        if stamps is not None:
            st = np.atleast_1d(np.asarray(stamps))
            wanted = st.astype(np.int64) if np.issubdtype(st.dtype, np.integer) else np.round(st * 1e9).astype(np.int64)
            wanted = np.sort(wanted)
            found = np.zeros(len(wanted), bool)
        seen = []
        for _, _, data in rec.raw(topic, show_progress=show_progress):
            s = rec.header_stamp_ns(data)
            if wanted is not None:
                seen.append(s)
                i = int(np.argmin(np.abs(wanted - s)))
                if abs(wanted[i] - s) > tolerance * 1e9:
                    continue
                found[i] = True
            yield s, image_from_message(rec.deserialize(topic, data), msgtype, source=f"{rec.path}: topic {topic}")
        if wanted is not None and not found.all():
            miss = wanted[~found][0]
            near = min(seen, key=lambda x: abs(x - miss)) if seen else None
            hint = f"; nearest frame {near / 1e9:.6f} s" if near is not None else "; the topic has no frame"
            raise InputError(f"{rec.path}: topic {topic}: {int((~found).sum())} stamp(s) have no frame within "
                             f"{tolerance:g} s, first {miss / 1e9:.6f} s{hint}")


# -- points, vectors, poses, odometry -----------------------------------------------------------

def _xyz(v) -> list:
    return [v.x, v.y, v.z]


def _pose_fields(p) -> dict:
    return {"position": _xyz(p.position), "quaternion": [p.orientation.x, p.orientation.y, p.orientation.z,
                                                          p.orientation.w]}


#: Per message type: the arrays extracted from one message (names -> values).
ARRAY_TYPES = {
    "geometry_msgs/msg/PointStamped": lambda m: {"point": _xyz(m.point)},
    "geometry_msgs/msg/Vector3Stamped": lambda m: {"vector": _xyz(m.vector)},
    "geometry_msgs/msg/PoseStamped": lambda m: _pose_fields(m.pose),
    "geometry_msgs/msg/PoseWithCovarianceStamped": lambda m: {**_pose_fields(m.pose.pose),
                                                              "covariance": list(m.pose.covariance)},
    "geometry_msgs/msg/TransformStamped": lambda m: {"position": _xyz(m.transform.translation),
                                                     "quaternion": _xyz(m.transform.rotation) + [m.transform.rotation.w]},
    "geometry_msgs/msg/TwistStamped": lambda m: {"linear": _xyz(m.twist.linear), "angular": _xyz(m.twist.angular)},
    "nav_msgs/msg/Odometry": lambda m: {**_pose_fields(m.pose.pose), "linear": _xyz(m.twist.twist.linear),
                                        "angular": _xyz(m.twist.twist.angular),
                                        "pose_covariance": list(m.pose.covariance)},
    "sensor_msgs/msg/Imu": lambda m: {"quaternion": _xyz(m.orientation) + [m.orientation.w],
                                      "angular_velocity": _xyz(m.angular_velocity),
                                      "linear_acceleration": _xyz(m.linear_acceleration)},
    "sensor_msgs/msg/Range": lambda m: {"range": m.range},
}


def read_arrays(path, topic: str, *, show_progress: bool = True) -> TopicArrays:
    """A topic of points, vectors, poses, twists, odometry, IMU or ranges as arrays (the types of ``ARRAY_TYPES``).

    Poses give ``position`` (N, 3) [m], ``quaternion`` (N, 4) scalar-last and
    ``T`` (N, 4, 4) (``T_frame_id_child``: the pose of the message's child /
    body in ``header.frame_id``); twists ``linear`` [m/s] and ``angular``
    [rad/s] (N, 3) in the child frame (ROS's ``nav_msgs/Odometry``).
    """
    with open_recording(path) as rec:
        topic = rec.topic(topic, tuple(ARRAY_TYPES)).name
        msgtype = rec.topics[topic].msgtype
        get = ARRAY_TYPES[msgtype]
        rows, stamps, recv, frame = [], [], [], ""
        for _, r, data in rec.raw(topic, show_progress=show_progress):
            m = rec.deserialize(topic, data)
            rows.append(get(m))
            stamps.append(stamp_ns(m.header.stamp))
            recv.append(r)
            frame = frame or m.header.frame_id
        source = rec.path
    fields = {k: np.asarray([row[k] for row in rows], float) for k in (rows[0] if rows else {})}
    if "quaternion" in fields and "position" in fields:
        from scipy.spatial.transform import Rotation

        n = np.linalg.norm(fields["quaternion"], axis=1)
        bad = ~(np.abs(n - 1.0) < 1e-2)  # tf2's tolerance for a unit quaternion; also catches NaN
        if np.any(bad):
            raise InputError(f"{source}: topic {topic}: {int(bad.sum())} orientation(s) not a unit quaternion, "
                             f"first at message {int(np.argmax(bad))} (|q| = {n[np.argmax(bad)]:.6g})")
        T = np.zeros((len(rows), 4, 4))
        T[:, :3, :3] = Rotation.from_quat(fields["quaternion"]).as_matrix()
        T[:, :3, 3], T[:, 3, 3] = fields["position"], 1.0
        fields["T"] = T
    return TopicArrays(topic, msgtype, frame.lstrip("/"), np.asarray(stamps, np.int64), np.asarray(recv, np.int64), fields)


# -- point clouds (sensor_msgs/PointCloud2: depth cameras, lidars, line-laser profilers) ---------------------

POINT_CLOUD_TYPES = ("sensor_msgs/msg/PointCloud2",)
#: PointField datatypes (sensor_msgs/PointField's constants) -> NumPy kinds.
_POINT_FIELD_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


@dataclass(frozen=True)
class PointClouds(_Stamped):
    """One ``PointCloud2`` topic: ``points`` a list of (M_i, len(fields)) float64 arrays, one per message.

    Points come in the message's order (row by row); invalid points (NaN, as drivers mark dropouts in
    an organised cloud) are kept: the caller chooses. ``frame_id``: the clouds' frame (the first
    message's; a leading ``/`` dropped).
    """

    topic: str
    frame_id: str
    fields: tuple
    stamps_ns: np.ndarray
    receive_ns: np.ndarray
    points: list = field(default_factory=list)


def points_from_cloud(msg, fields=("x", "y", "z"), *, source: str = "<cloud>") -> np.ndarray:
    """(height * width, len(fields)) float64 of one ``sensor_msgs/PointCloud2`` (any field layout and byte order)."""
    have = {f.name: f for f in msg.fields}
    missing = [n for n in fields if n not in have]
    if missing:
        raise InputError(f"{source}: a PointCloud2 without field(s) {', '.join(missing)}; fields: "
                         f"{', '.join(have) or 'none'}")
    bad = [n for n in fields if have[n].datatype not in _POINT_FIELD_TYPES]
    if bad:
        raise FileFormatError(f"{source}: PointCloud2 field '{bad[0]}' has unknown datatype {have[bad[0]].datatype}")
    order = ">" if msg.is_bigendian else "<"
    step, w, h, row = int(msg.point_step), int(msg.width), int(msg.height), int(msg.row_step)
    dtype = np.dtype({"names": list(fields), "formats": [order + _POINT_FIELD_TYPES[have[n].datatype] for n in fields],
                      "offsets": [int(have[n].offset) for n in fields], "itemsize": step})
    data = np.asarray(msg.data, np.uint8)
    if step <= 0 or row < w * step or data.size < h * row or any(
            int(have[n].offset) + dtype[n].itemsize > step for n in fields):
        raise FileFormatError(f"{source}: a {w}x{h} PointCloud2 of {step}-byte points needs {h} rows of >= "
                              f"{w * step} bytes, got row_step {row} and {data.size} bytes")
    # rows may be padded to row_step bytes: view the rows, drop the padding, read the fields in place
    rows = np.ascontiguousarray(data[:h * row].reshape(h, row)[:, :w * step]).reshape(-1)
    pts = rows.view(dtype)
    return np.column_stack([pts[n].astype(np.float64) for n in fields]) if len(pts) else np.zeros((0, len(fields)))


def read_point_clouds(path, topic: str, fields=("x", "y", "z"), *, show_progress: bool = True) -> PointClouds:
    """Every ``sensor_msgs/PointCloud2`` of ``topic`` as arrays of ``fields`` (:class:`PointClouds`) [m]."""
    stamps, recv, clouds, frame = [], [], [], ""
    with open_recording(path) as rec:
        topic = rec.topic(topic, POINT_CLOUD_TYPES).name
        where = f"{rec.path}: topic {topic}"
        for _, r, data in rec.raw(topic, show_progress=show_progress):
            m = rec.deserialize(topic, data)
            clouds.append(points_from_cloud(m, tuple(fields), source=where))
            stamps.append(stamp_ns(m.header.stamp))
            recv.append(r)
            frame = frame or m.header.frame_id
    return PointClouds(topic, frame.lstrip("/"), tuple(fields), np.asarray(stamps, np.int64),
                       np.asarray(recv, np.int64), clouds)
