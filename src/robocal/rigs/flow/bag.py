"""The flow rig's input from a robot recording (issue 15): ``robocal flow calibrate --bag FILE --map topics.yaml``.

Which message: ``mavros_msgs/OpticalFlowRad``, one topic per sensor. It is what a
PX4FLOW-class sensor publishes on a ROS robot (``px4flow`` / mavros'
``px_flow`` plugin: ``/px4flow/raw/optical_flow_rad``), the ROS image of MAVLink
OPTICAL_FLOW_RAD, and it carries everything the rig's flow log holds for one
sensor in one message: the integrated flow [rad], the integrated gyro [rad]
(the sensor's own gyro, in its camera frame), the ground distance [m], the
integration time [us] and the quality. No separate gyro or height topic is
needed, and the records are converted by the same code as
``robocal flow convert-mavlink`` (:func:`robocal.rigs.flow.mavlink_convert.flow_records`:
``flow_u = -f integrated_y``, ``flow_v = f integrated_x``, gyro = integrated / dt,
each record's interval redistributed exactly onto the first mapped sensor's
record ends). The reference, when the map names one, is a ``nav_msgs/Odometry``
topic (x, y and the yaw of the pose; a motion-capture or ground-truth odometry).

The map (``--map topics.yaml``) is a run description without files: the
array (``units``, ``camera``, ``sensors``, as in ``run.yaml``) and the topics::

    units: {length: mm, angle: deg}
    camera: {focal_px: 166.67, window: 64, sigma_px: 0.16}
    sensors:
      - {name: s60,  R: 350, psi: 60,  phi: 0}
      - ...
    topics:
      flow: {s60: /flow/s60/optical_flow_rad, s120: ..., s270: ...}
      reference: /ground_truth/odom        # optional

The loader builds the same in-memory records (:class:`~robocal.rigs.flow.log.FlowRecords`)
and reference trajectory the file path reads from ``flow.csv`` / ``truth.csv``,
so every check and the calibration run unchanged.

Clocks: records are placed at their **header stamps** (the sensors' clock).
Each stream's receive - header time is compared with the first flow topic's;
more than :data:`CLOCK_MISMATCH` apart, the streams are on two clocks: every
stream is then placed at its receive (recorder) times, one clock for all, and a
``clock_mismatch`` warning names the streams and the offset.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robocal.bags._tf import CLOCK_MISMATCH
from robocal.diagnostics import Diagnostic
from robocal.errors import FileFormatError, InputError
from robocal.rigs.flow.log import FlowRecords, RunSpec

__all__ = ["OPTICAL_FLOW_RAD", "OPTICAL_FLOW_RAD_MSG", "REFERENCE_TYPES", "CLOCK_MISMATCH", "BagRunSpec",
           "register_types", "load_bag_run"]

OPTICAL_FLOW_RAD = "mavros_msgs/msg/OpticalFlowRad"
#: mavros_msgs/OpticalFlowRad.msg (mavros 1.x and 2.x), registered when the recording's own typestore lacks it
#: (a ROS 2 .db3 without stored definitions).
OPTICAL_FLOW_RAD_MSG = """std_msgs/Header header
uint32 integration_time_us
float32 integrated_x
float32 integrated_y
float32 integrated_xgyro
float32 integrated_ygyro
float32 integrated_zgyro
int16 temperature
uint8 quality
uint32 time_delta_distance_us
float32 distance
"""
REFERENCE_TYPES = ("nav_msgs/msg/Odometry",)


def register_types(typestore) -> None:
    """Add ``mavros_msgs/msg/OpticalFlowRad`` to a rosbags typestore (a no-op when it has it)."""
    from rosbags.typesys import get_types_from_msg

    if OPTICAL_FLOW_RAD not in typestore.types:
        typestore.register(get_types_from_msg(OPTICAL_FLOW_RAD_MSG, OPTICAL_FLOW_RAD))


@dataclass
class BagRunSpec(RunSpec):
    """A :class:`~robocal.rigs.flow.log.RunSpec` whose flow records and reference come from a recording.

    ``flow_log`` and ``reference`` name the recording (messages name it); ``records`` and
    ``reference_data`` ``(t [s], poses (N, 3) [m, m, rad])`` are what ``flow.csv`` / the reference file
    would give, on the same time base (t = 0 at the first interval's start).
    """

    records: FlowRecords | None = None
    reference_data: tuple | None = None
    files: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    def inputs(self) -> list:
        return [self.path, *self.files]


class _Table:
    """The slice of :class:`robocal.rigs.flow.mavlink.MavlinkLog` that ``flow_records`` reads."""

    def __init__(self, tab: dict, summary: str):
        self._tab, self.stats = tab, type("S", (), {"summary": staticmethod(lambda: summary)})()

    def table(self, name: str) -> dict:
        return self._tab


def _bag_files(bag: Path) -> list[Path]:
    if bag.is_dir():
        return sorted(p for p in bag.iterdir() if p.is_file())
    return [bag]


def _read_map(path):
    """The map file: the array + camera (as run.yaml) and ``topics: {flow: {sensor: topic}, reference: topic}``."""
    from robocal.io import load_document
    from robocal.rigs.flow.log import array_and_camera

    doc = load_document(path)
    src = str(path)
    array, focal, window, rate, sigma_px = array_and_camera(doc)
    topics = doc.raw("topics") if "topics" in doc else None
    if not isinstance(topics, dict) or not isinstance(topics.get("flow"), dict) or not topics["flow"]:
        raise FileFormatError("needs 'topics: {flow: {SENSOR: TOPIC, ...}}' (each sensor's mavros_msgs/OpticalFlowRad "
                              f"topic), got {topics!r}", source=src)
    flow = {str(k): str(v) for k, v in topics["flow"].items()}
    unknown = [k for k in flow if k not in array.names]
    if unknown:
        from robocal.bags import closest_names

        raise FileFormatError(f"topics.flow: '{unknown[0]}' is not a sensor of the array"
                              f"{closest_names(unknown[0], array.names)}", source=src)
    missing = [k for k in array.names if k not in flow]
    if missing:
        raise FileFormatError(f"topics.flow: no topic for sensor(s) {', '.join(missing)} (every sensor of the "
                              "array needs its OpticalFlowRad topic)", source=src)
    ref = topics.get("reference")
    if ref is not None and not isinstance(ref, str):
        raise FileFormatError(f"topics.reference: expected a nav_msgs/Odometry topic name, got {ref!r}", source=src)
    return array, focal, window, rate, sigma_px, flow, ref


def load_bag_run(bag, map_file, *, show_progress: bool = False) -> BagRunSpec:
    """A :class:`BagRunSpec` from a recording and its topic map (module docstring).

    Raises
    ------
    FileFormatError
        A bad map file (named, with the field).
    MissingTopicError
        A mapped topic not in the recording (closest names offered).
    InputError
        A topic of another message type; sensors whose records never overlap.
    """
    from scipy.spatial.transform import Rotation

    from robocal.bags import open_recording, read_arrays
    from robocal.bags._reader import _default_typestore, stamp_ns
    from robocal.rigs.flow.mavlink_convert import flow_records

    # ROS 2 bags before Iron carry no message definitions: the reader's store decodes them, and Humble's lacks mavros
    register_types(_default_typestore())

    if map_file is None:
        raise InputError("--bag needs --map topics.yaml (the array and each sensor's OpticalFlowRad topic; see "
                         "docs/rigs/flow.md, 'From a recording')")
    bag, map_file = Path(bag), Path(map_file)
    array, focal, window, rate, sigma_px, flow_topics, ref_topic = _read_map(map_file)
    keys = ("integration_time_us", "integrated_x", "integrated_y", "integrated_xgyro", "integrated_ygyro",
            "integrated_zgyro", "quality", "distance")
    cols = {k: [] for k in (*keys, "sensor_id", "stamp_ns", "recv_ns")}
    offsets = {}
    with open_recording(bag) as rec:
        source = str(rec.path)
        for i, name in enumerate(array.names):
            topic = rec.topic(flow_topics[name], (OPTICAL_FLOW_RAD,)).name
            n0 = len(cols["sensor_id"])
            for _, r, data in rec.raw(topic, show_progress=show_progress):
                m = rec.deserialize(topic, data)
                for k in keys:
                    cols[k].append(getattr(m, k))
                cols["stamp_ns"].append(stamp_ns(m.header.stamp))
                cols["recv_ns"].append(r)
                cols["sensor_id"].append(i)
            if len(cols["sensor_id"]) == n0:
                raise InputError(f"{source}: topic {topic} holds no message")
            offsets[topic] = float(np.median(np.subtract(cols["recv_ns"][n0:], cols["stamp_ns"][n0:]))) / 1e9
        if ref_topic is not None:
            ref_topic = rec.topic(ref_topic, REFERENCE_TYPES).name
    ref = read_arrays(bag, ref_topic, show_progress=show_progress) if ref_topic is not None else None
    if ref is not None:
        if not len(ref.stamps_ns):
            raise InputError(f"{source}: topic {ref_topic} holds no message")
        offsets[ref_topic] = ref.clock_offset
    tab = {k: np.asarray(v) for k, v in cols.items()}
    # clocks: receive - header per stream; a transport adds ms, another clock much more
    first = next(iter(offsets))
    apart = {t: d - offsets[first] for t, d in offsets.items() if abs(d - offsets[first]) > CLOCK_MISMATCH}
    warnings = []
    clock = "stamp_ns"
    if apart:
        clock = "recv_ns"
        warnings.append(Diagnostic("clock_mismatch", "the header stamps of " + ", ".join(
            f"{t} ({d:+.3f} s)" for t, d in apart.items()) + f" look like another clock than {first}'s (receive minus "
            f"header differs by more than {CLOCK_MISMATCH:g} s; a few ms is transport): every stream is placed at its "
            "receive times instead (one clock, the recorder's)"))
    origin_ns = int(tab[clock].min())
    rel_us = (tab[clock] - origin_ns) // 1000  # whole microseconds, as the MAVLink converter takes them
    tab["log_time_us"] = tab["time_usec"] = rel_us
    tab["sysid"] = np.zeros(len(rel_us), int)
    conv = flow_records(_Table(tab, f"{len(rel_us)} OpticalFlowRad messages"), dict(enumerate(range(array.n))),
                        array.n, focal, clock="message", source=source)
    records = FlowRecords(conv.t, conv.flow, conv.gyro, conv.height, conv.quality, conv.present)
    t0_ns = origin_ns + conv.t0_us * 1000
    reference_data = None
    if ref is not None:
        st = ref.receive_ns if clock == "recv_ns" else ref.stamps_ns
        yaw = Rotation.from_quat(ref["quaternion"]).as_euler("ZYX")[:, 0]
        order = np.argsort(st, kind="stable")
        t_ref = (st[order] - t0_ns) / 1e9
        poses = np.column_stack([ref["position"][order, :2], np.unwrap(yaw[order])])
        reference_data = (t_ref, poses)
    notes = [f"recording {source}: {array.n} OpticalFlowRad topics, {records.t.size - 1} intervals "
             f"({'receive' if clock == 'recv_ns' else 'header'} times)"
             + (f"; reference {ref_topic} ({len(ref.stamps_ns)} poses)" if ref is not None else ""), *conv.notes]
    return BagRunSpec(map_file, array, focal, window, bag, None, bag if ref is not None else None, None, rate,
                      sigma_px, records=records, reference_data=reference_data, files=_bag_files(bag),
                      warnings=warnings, notes=notes)
