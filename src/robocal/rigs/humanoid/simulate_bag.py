"""A simulated NAO calibration run written as a robot recording (ROS 1 bag, ROS 2 bag or MCAP), with its truth.

The rig's own simulator (:func:`.simulate.simulate_dataset`: true offsets,
poses showing one board, readings quantised to 0.1 deg, rendered images) makes
the views; this module lays them out in time as a NAO records them
(``naoqi_driver``'s topics):

* ``/joint_states``: all 26 NAO joints (NAOqi's names and order) at
  ``joint_rate``; the legs and head hold each view's readings for ``hold``
  seconds, then move linearly to the next view's in ``move`` seconds (the
  arms hold still throughout);
* the lower camera's images at ``image_rate`` for the whole run, stamped
  with its own header stamps: during a hold the view's rendered image, while
  moving the previous view's image (what a wrongly kept moving frame would
  pair with the wrong joint angles), before the first view a grey frame;
* its ``camera_info`` beside the images.

So a reader must interpolate joints at image stamps, refuse the frames taken
while moving, and merge the frames of one held pose, as
:func:`robocal.rigs.humanoid.bag.load_bag_input` does.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal.errors import InputError

__all__ = ["HumanoidRecordingTruth", "simulate_humanoid_recording", "IMAGE_TOPIC", "CAMERA_INFO_TOPIC",
           "JOINTS_TOPIC"]

IMAGE_TOPIC = "/nao/camera/bottom/image_raw"
CAMERA_INFO_TOPIC = "/nao/camera/bottom/camera_info"
JOINTS_TOPIC = "/joint_states"
#: Arm joints' held values [rad] (arms along the body, hands half open): not part of the model.
_ARMS = {"LShoulderPitch": 1.4, "LShoulderRoll": 0.2, "LElbowYaw": -1.2, "LElbowRoll": -0.5, "LWristYaw": 0.0,
         "LHand": 0.5, "RShoulderPitch": 1.4, "RShoulderRoll": -0.2, "RElbowYaw": 1.2, "RElbowRoll": 0.5,
         "RWristYaw": 0.0, "RHand": 0.5}


@dataclass
class HumanoidRecordingTruth:
    """What :func:`simulate_humanoid_recording` wrote.

    ``data`` is the simulated :class:`~.simulate.HumanoidDataset` (readings ``theta`` [rad] per view,
    feet, rendered images, ``truth``); ``params`` the true parameter vector (``model.parameter_labels()``
    order); ``hold_ns`` (V, 2) each view's still interval [ns, header clock]; ``image_stamps_ns`` every
    frame's stamp, ``still`` which of them are taken in a hold.
    """

    path: Path
    format: str
    model: object
    data: object
    params: np.ndarray
    hold_ns: np.ndarray
    image_stamps_ns: np.ndarray
    still: np.ndarray


def simulate_humanoid_recording(path, *, format: str = "rosbag1", rng: np.random.Generator | None = None,
                                views: int = 3, model=None, data=None, hold: float = 0.5, move: float = 0.5,
                                joint_rate: float = 50.0, image_rate: float = 4.0, encoding: str = "mono8",
                                camera_info: bool = True, rename: dict | None = None,
                                image_topic: str = IMAGE_TOPIC,
                                camera_clock_offset: float = 0.0) -> HumanoidRecordingTruth:
    """Simulate a NAO run (module docstring) and write it to ``path``; return its truth.

    Parameters
    ----------
    path : path
        A new ``.bag`` (``rosbag1``) or a new ROS 2 bag folder (``rosbag2``, ``mcap``).
    format : {"rosbag1", "rosbag2", "mcap"}
    rng : numpy.random.Generator
        Truth, poses and image noise (default seed 0); unused when ``data`` is given.
    views : int
        Views per foot (:func:`.simulate.simulate_dataset`'s ``n_per_foot``).
    model : HumanoidModel, optional
        Default: :func:`.model.default_model` (640 x 480 camera); a smaller camera renders faster.
    data : HumanoidDataset, optional
        Rendered views already simulated (the same run written in several formats).
    hold, move : float
        Seconds each pose is held, and taken to reach the next one.
    joint_rate, image_rate : float
        ``/joint_states`` and camera rates [Hz].
    encoding : str
        Image encoding (``mono8``, ``bgr8``, ``png``, ...; see :mod:`robocal.bags._simulate`).
    camera_info : bool
        Write the ``camera_info`` topic beside the images.
    rename : dict, optional
        Recorded joint names that differ from NAOqi's (``{"LKneePitch": "LKneePich"}``: a driver's typo).
    camera_clock_offset : float
        Seconds added to the camera topics' header stamps (a camera on another clock; receive times
        unchanged). ``image_stamps_ns`` are the true times.
    """
    from robocal.bags._simulate import LATENCY_NS, RECORDING_FORMATS, T0_NS, _camera_info, _image_msg, _Writer
    from robocal.rigs.humanoid.bag import NAO_JOINTS
    from robocal.rigs.humanoid.model import default_model
    from robocal.rigs.humanoid.simulate import DEFAULT_HEAD, quantise, simulate_dataset

    if format not in RECORDING_FORMATS:
        raise InputError(f"format must be one of {', '.join(RECORDING_FORMATS)}, got {format!r}")
    if not (hold > 0 and move > 0 and joint_rate > 0 and image_rate > 0):
        raise InputError(f"hold, move, joint_rate and image_rate must be > 0, got {hold}, {move}, {joint_rate}, "
                         f"{image_rate}")
    model = default_model() if model is None else model
    if data is None:
        rng = np.random.default_rng(0) if rng is None else rng
        data = simulate_dataset(model, rng, n_per_foot=views, render=True)
    if data.images is None or any(im is None for im in data.images) or data.truth is None:
        raise InputError("data must be a rendered simulation (simulate_dataset(..., render=True)) with its truth")
    names = model.joint_names
    V = data.n_views
    # key poses: rest (straight legs, head down at the feet), then each view's readings
    rest = np.zeros(len(names))
    for h, v in zip(model.head_joints, DEFAULT_HEAD):
        rest[names.index(h)] = v
    keys = np.vstack([rest, data.theta])
    cycle = hold + move
    t_end = hold + V * cycle  # a first hold at rest, then move + hold per view
    # knots of the piecewise-linear joint trajectory [s]: hold at rest, then (move, hold) per view
    knot_t = np.concatenate([[0.0, hold], *[[hold + k * cycle + move, hold + (k + 1) * cycle] for k in range(V)]])
    knot_q = np.vstack([keys[0], keys[0], *[np.vstack([keys[k + 1], keys[k + 1]]) for k in range(V)]])
    n_j = int(np.floor(t_end * joint_rate)) + 1
    tj = np.arange(n_j) / joint_rate
    qj = quantise(np.column_stack([np.interp(tj, knot_t, knot_q[:, c]) for c in range(len(names))]))
    # the holds are exactly the readings (quantise keeps values already on the 0.1 deg grid)
    hold_s = np.array([[hold + k * cycle + move, hold + (k + 1) * cycle] for k in range(V)])
    # frames half a camera period after t = 0: none falls on a knot
    ti = (np.arange(int(np.floor(t_end * image_rate))) + 0.5) / image_rate
    view_of = np.searchsorted(hold_s[:, 0], ti, side="right") - 1  # the last view whose hold began
    still = (view_of >= 0) & (ti <= hold_s[np.maximum(view_of, 0), 1])
    grey = np.full_like(np.asarray(data.images[0]), 128)

    rename = dict(rename or {})
    rec_names = [rename.get(n, n) for n in NAO_JOINTS]
    col = {n: k for k, n in enumerate(names)}

    def joint_row(k):
        return [float(qj[k, col[n]]) if n in col else _ARMS.get(n, 0.0) for n in NAO_JOINTS]

    j_ns = T0_NS + np.round(tj * 1e9).astype(np.int64)
    i_ns = T0_NS + np.round(ti * 1e9).astype(np.int64)
    path = Path(path)
    events = []

    def at(stamp, kind, fn):
        events.append((int(stamp) + LATENCY_NS[kind], len(events), fn))

    off = int(round(camera_clock_offset * 1e9))
    with _Writer(path, format) as w:
        for k, s in enumerate(j_ns):
            at(s, "joints", lambda s=s, k=k: w.write(
                JOINTS_TOPIC, "sensor_msgs/msg/JointState", s + LATENCY_NS["joints"],
                w.msg("sensor_msgs/msg/JointState", header=w.header(s, ""), name=list(rec_names),
                      position=np.array(joint_row(k)), velocity=np.zeros(len(rec_names)),
                      effort=np.zeros(len(rec_names)))))
        info_topic = image_topic.rsplit("/", 1)[0] + "/camera_info"
        for k, s in enumerate(i_ns):
            v = view_of[k]
            # in view v's hold its image; moving on from it still its image (the joints already elsewhere)
            img = grey if v < 0 else np.asarray(data.images[v])
            recv = s + LATENCY_NS["camera"]
            at(s, "camera", lambda s=s, img=img, recv=recv: w.write(image_topic,
                                                                    *_image_msg(w, s + off, recv, img, encoding)))
            if camera_info:
                at(s, "camera", lambda s=s, recv=recv: w.write(info_topic, "sensor_msgs/msg/CameraInfo", recv,
                                                               _camera_info(w, s + off, model.camera)))
        for _, _, fn in sorted(events, key=lambda e: (e[0], e[1])):
            fn()
    hold_ns = T0_NS + np.round(hold_s * 1e9).astype(np.int64)
    return HumanoidRecordingTruth(path, format, model, data, np.asarray(data.truth.params), hold_ns, i_ns, still)
