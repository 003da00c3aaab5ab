"""A simulated flow-rig recording (issue 15): a simulated run's per-sensor flow records as a ROS bag.

:func:`simulate_flow_recording` takes a run written by ``robocal flow simulate`` (``run.yaml``,
``flow.csv``, ``truth.csv``: the simulator's known truth) and writes what the robot would have
recorded: per sensor a ``mavros_msgs/OpticalFlowRad`` topic (one message per flow record: the
inverse of :mod:`robocal.rigs.flow.mavlink_convert`'s conversion), the true poses as a
``nav_msgs/Odometry`` topic, and the topic map (``topics.yaml``) that
:func:`robocal.rigs.flow.bag.load_bag_run` reads. Raw frames are not written (small bags).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from robocal.errors import InputError

__all__ = ["REFERENCE_TOPIC", "flow_topic", "FlowRecordingTruth", "simulate_flow_recording"]

REFERENCE_TOPIC = "/ground_truth/odom"


def flow_topic(name: str) -> str:
    """The OpticalFlowRad topic of sensor ``name`` (mavros' px4flow plugin's layout, one namespace per sensor)."""
    return f"/px4flow/{name}/raw/optical_flow_rad"


@dataclass
class FlowRecordingTruth:
    """What :func:`simulate_flow_recording` wrote: the recording, its map, and the run folder it came from."""

    path: Path
    map: Path
    format: str
    run: Path


def simulate_flow_recording(path, run_yaml, *, format: str = "rosbag1", map_path=None,
                            clock_offset: dict | None = None, rename: dict | None = None) -> FlowRecordingTruth:
    """Write the run of ``run_yaml`` (a flow log run) as a recording at ``path``; return where.

    Parameters
    ----------
    path : path
        A new ``.bag`` (``rosbag1``) or a new ROS 2 bag folder (``rosbag2``, ``mcap``).
    run_yaml : path
        A run with ``flow_log`` and ``reference`` (``robocal flow simulate --no-frames``).
    map_path : path, optional
        Where to write the topic map (default ``<path>.topics.yaml``).
    clock_offset : dict, optional
        Sensor name (or ``"reference"``) -> seconds added to that stream's header stamps
        (a stream stamped on another clock; receive times unchanged).
    rename : dict, optional
        Sensor name -> the topic the map gives for it (a typo in the map).
    """
    from robocal.bags._simulate import LATENCY_NS, RECORDING_FORMATS, T0_NS, _Writer
    from robocal.rigs.flow.bag import OPTICAL_FLOW_RAD, register_types
    from robocal.rigs.flow.log import load_run, read_flow_csv, read_poses_csv

    if format not in RECORDING_FORMATS:
        raise InputError(f"format must be one of {', '.join(RECORDING_FORMATS)}, got {format!r}")
    spec = load_run(run_yaml)
    if spec.flow_log is None or spec.reference is None:
        raise InputError(f"{run_yaml}: needs a 'flow_log' and a 'reference' to write as a recording")
    rec = read_flow_csv(spec.flow_log, spec.array.n)
    t_ref, poses = read_poses_csv(spec.reference)
    f = spec.focal_px
    dt = np.diff(rec.t)
    off = {k: int(round(v * 1e9)) for k, v in (clock_offset or {}).items()}
    path = Path(path)
    events = []

    def us(t):  # header stamps on whole microseconds, as PX4FLOW's time_usec
        return T0_NS + int(round(float(t) * 1e6)) * 1000

    with _Writer(path, format) as w:
        register_types(w.ts)
        for i, name in enumerate(spec.array.names):
            topic = flow_topic(name)
            for k in range(dt.size):
                s = us(rec.t[k + 1])
                g = rec.gyro[i, k] * dt[k]
                # the inverse of mavlink_convert: flow_u = -f integrated_y, flow_v = f integrated_x
                msg = w.msg(OPTICAL_FLOW_RAD, header=w.header(s + off.get(name, 0), f"{name}_optical"),
                            integration_time_us=int(round(dt[k] * 1e6)),
                            integrated_x=np.float32(rec.flow[i, k, 1] / f),
                            integrated_y=np.float32(-rec.flow[i, k, 0] / f),
                            integrated_xgyro=np.float32(g[0]), integrated_ygyro=np.float32(g[1]),
                            integrated_zgyro=np.float32(g[2]), temperature=np.int16(2500),
                            quality=np.uint8(rec.quality[i, k]), time_delta_distance_us=np.uint32(0),
                            distance=np.float32(rec.height[i, k]))
                events.append((s + LATENCY_NS["joints"], len(events), topic, OPTICAL_FLOW_RAD, msg))
        from scipy.spatial.transform import Rotation

        for t, p in zip(t_ref, poses):
            s = us(t)
            R = Rotation.from_euler("z", p[2]).as_matrix()
            pose = w.msg("geometry_msgs/msg/Pose", position=w.msg("geometry_msgs/msg/Point", x=float(p[0]),
                                                                 y=float(p[1]), z=0.0), orientation=w.quat(R))
            zero = w.vec((0.0, 0.0, 0.0))
            msg = w.msg("nav_msgs/msg/Odometry", header=w.header(s + off.get("reference", 0), "odom"),
                        child_frame_id="base_link",
                        pose=w.msg("geometry_msgs/msg/PoseWithCovariance", pose=pose, covariance=np.zeros(36)),
                        twist=w.msg("geometry_msgs/msg/TwistWithCovariance",
                                    twist=w.msg("geometry_msgs/msg/Twist", linear=zero, angular=zero),
                                    covariance=np.zeros(36)))
            events.append((s + LATENCY_NS["odom"], len(events), REFERENCE_TOPIC, "nav_msgs/msg/Odometry", msg))
        for r, _, topic, msgtype, msg in sorted(events, key=lambda e: (e[0], e[1])):
            w.write(topic, msgtype, r, msg)

    a = spec.array
    names = dict(rename or {})
    doc = {"units": {"length": "mm", "angle": "deg"},
           "camera": {"focal_px": float(f), "window": spec.window,
                      **({"sigma_px": float(spec.sigma_px)} if spec.sigma_px is not None else {})},
           "sensors": [{"name": nm, "R": float(1e3 * a.R[i]), "psi": float(np.degrees(a.psi[i])),
                        "phi": float(np.degrees(a.phi[i])), "scale": float(a.scale[i])}
                       for i, nm in enumerate(a.names)],
           "topics": {"flow": {nm: names.get(nm, flow_topic(nm)) for nm in a.names}, "reference": REFERENCE_TOPIC}}
    map_path = Path(map_path) if map_path is not None else path.with_name(path.name + ".topics.yaml")
    map_path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return FlowRecordingTruth(path, map_path, format, Path(run_yaml))
