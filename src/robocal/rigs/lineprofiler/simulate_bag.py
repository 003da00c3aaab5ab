"""A simulated FPDP sphere scan written as a robot recording (ROS 1 bag, ROS 2 bag or MCAP), with its truth.

The rig's simulator (:func:`.simulate.simulate_fpdp`: P1R2P3 arm, Gocator-class
profiler, precision sphere) gives the poses and profiles; here the arm moves
between the poses (``move`` seconds, linear in joint space) and holds each one
``hold`` seconds, during which the profiler is triggered once:

* ``/joint_states``: the arm's joints (the chain's names ``P1, R2, P3``, m and rad) at ``joint_rate``;
* ``/tf``: ``base_link -> flange`` (``T_W_E``, the forward kinematics of the readings) at ``joint_rate``;
* ``/profiler/points``: one ``sensor_msgs/PointCloud2`` per pose in frame ``profiler`` (L): float32
  ``x, y, z`` with ``y = 0`` and an ``intensity`` field, as profiler drivers publish them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal.errors import InputError

__all__ = ["LineProfilerRecordingTruth", "simulate_lineprofiler_recording", "PROFILE_TOPIC", "JOINTS_TOPIC"]

PROFILE_TOPIC = "/profiler/points"
JOINTS_TOPIC = "/joint_states"
#: Transport latency of the profiles [ns] (receive time - header stamp).
_PROFILE_LATENCY_NS = 3_000_000


@dataclass
class LineProfilerRecordingTruth:
    """What :func:`simulate_lineprofiler_recording` wrote: the rig (``rig.X`` the true ``T_E_L``), the FPDP
    data (readings ``q``, profiles ``(x, z)`` [m]), the profile stamps [ns] and each pose's hold [ns]."""

    path: Path
    format: str
    rig: object
    data: object
    truth: object
    profile_stamps_ns: np.ndarray
    hold_ns: np.ndarray


def _cloud(w, stamp_ns: int, xz: np.ndarray, frame: str):
    """A PointCloud2 of the profile ``xz`` (M, 2) [m]: float32 x, y = 0, z and a uint16 intensity, 1 x M."""
    rec = np.zeros(len(xz), np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<u2")]))
    rec["x"], rec["z"], rec["intensity"] = xz[:, 0], xz[:, 1], 1000
    fields = [w.msg("sensor_msgs/msg/PointField", name=n, offset=off, datatype=dt, count=1)
              for n, off, dt in (("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 4))]
    return w.msg("sensor_msgs/msg/PointCloud2", header=w.header(stamp_ns, frame), height=1, width=len(xz),
                 fields=fields, is_bigendian=False, point_step=rec.dtype.itemsize,
                 row_step=rec.dtype.itemsize * len(xz), data=rec.view(np.uint8).reshape(-1), is_dense=True)


def simulate_lineprofiler_recording(path, *, format: str = "rosbag1", rng: np.random.Generator | None = None,
                                    poses: int = 16, hold: float = 0.3, move: float = 0.3, joint_rate: float = 100.0,
                                    data=None, truth=None, rig=None, base_frame: str = "base_link",
                                    flange_frame: str = "flange", laser_frame: str = "profiler",
                                    profiler_clock_offset: float = 0.0) -> LineProfilerRecordingTruth:
    """Simulate an FPDP scan (module docstring) and write it to ``path``; return its truth.

    ``data``, ``truth`` (both, from :func:`.simulate.simulate_fpdp` on ``rig``): write a scan already
    simulated (the same scan in several formats); otherwise ``poses`` poses are simulated with ``rng``
    (default seed 0). ``profiler_clock_offset`` [s] is added to the profiles' header stamps (a profiler on
    another clock; receive times and ``profile_stamps_ns`` unchanged).
    """
    from robocal.bags._simulate import LATENCY_NS, RECORDING_FORMATS, T0_NS, _Writer
    from robocal.rigs.lineprofiler.model import default_rig
    from robocal.rigs.lineprofiler.simulate import simulate_fpdp

    if format not in RECORDING_FORMATS:
        raise InputError(f"format must be one of {', '.join(RECORDING_FORMATS)}, got {format!r}")
    if not (hold > 0 and move > 0 and joint_rate > 0):
        raise InputError(f"hold, move and joint_rate must be > 0, got {hold}, {move}, {joint_rate}")
    rig = default_rig() if rig is None else rig
    if data is None:
        data, truth = simulate_fpdp(rig, np.random.default_rng(0) if rng is None else rng, n_poses=poses)
    q = np.asarray(data.q, float)
    n = len(q)
    cycle = move + hold
    # knots [s]: at q[0] from t = 0, then per pose (arrive, leave); holds [k cycle + move, (k + 1) cycle]
    knot_t = np.concatenate([[0.0], *[[k * cycle + move, (k + 1) * cycle] for k in range(n)]])
    knot_q = np.vstack([q[0], *[np.vstack([q[k], q[k]]) for k in range(n)]])
    tj = np.arange(int(np.floor(n * cycle * joint_rate)) + 1) / joint_rate
    qj = np.column_stack([np.interp(tj, knot_t, knot_q[:, c]) for c in range(q.shape[1])])
    hold_s = np.array([[k * cycle + move, (k + 1) * cycle] for k in range(n)])
    # the profile a third into each hold: between two joint samples, not on one
    t_prof = hold_s[:, 0] + hold / 3 + 0.25 / joint_rate
    j_ns = T0_NS + np.round(tj * 1e9).astype(np.int64)
    p_ns = T0_NS + np.round(t_prof * 1e9).astype(np.int64)
    T_flange = rig.chain.fk(qj)
    names = list(rig.chain.joint_names)
    path = Path(path)
    events = []
    with _Writer(path, format) as w:
        for k, s in enumerate(j_ns):
            events.append((int(s) + LATENCY_NS["joints"], len(events), lambda s=s, k=k: w.write(
                JOINTS_TOPIC, "sensor_msgs/msg/JointState", s + LATENCY_NS["joints"],
                w.msg("sensor_msgs/msg/JointState", header=w.header(s, ""), name=names, position=qj[k].copy(),
                      velocity=np.zeros(len(names)), effort=np.zeros(len(names))))))
            events.append((int(s) + LATENCY_NS["tf"], len(events), lambda s=s, k=k: w.write(
                "/tf", "tf2_msgs/msg/TFMessage", s + LATENCY_NS["tf"],
                w.tf([w.transform(s, base_frame, flange_frame, T_flange[k])]))))
        for k, s in enumerate(p_ns):
            events.append((int(s) + _PROFILE_LATENCY_NS, len(events), lambda s=s, k=k: w.write(
                PROFILE_TOPIC, "sensor_msgs/msg/PointCloud2", s + _PROFILE_LATENCY_NS,
                _cloud(w, s + int(round(profiler_clock_offset * 1e9)), np.asarray(data.profiles[k]), laser_frame))))
        for _, _, fn in sorted(events, key=lambda e: (e[0], e[1])):
            fn()
    hold_ns = T0_NS + np.round(hold_s * 1e9).astype(np.int64)
    return LineProfilerRecordingTruth(path, format, rig, data, truth, p_ns, hold_ns)
