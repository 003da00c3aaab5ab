"""Hand-eye input from a recording: ``robocal handeye calibrate --bag FILE --base B --gripper G ...`` (issue 15).

Two ways in, from a ROS 1 bag, a ROS 2 bag or MCAP (:mod:`robocal.bags`, no ROS install):

* ``--images TOPIC`` (``sensor_msgs/Image`` or ``CompressedImage``) with ``--target TARGET.yaml`` and
  the camera (``--camera-info TOPIC``, ``--camera FILE``, or by default the ``camera_info`` topic beside
  the image topic): each frame's target pose with its covariance by the same detection + planar PnP as
  ``calibrate-images`` (:func:`robocal.handeye.images.view_poses`), weighting the refinement;
* ``--target-poses TOPIC``: the target in the camera from the user's own detector
  (``geometry_msgs/PoseStamped``, ``PoseWithCovarianceStamped`` -- its covariance then weights the
  views -- or ``TransformStamped``): ``T_cam_target`` with the message's ``header.frame_id`` the camera.

The robot pose of each frame is ``T_base_gripper``: the tf tree (``/tf`` + ``/tf_static``) resolved from
``--base`` to ``--gripper`` and interpolated (SLERP + linear) at the frame's **header stamp** (the time
the driver says the image was exposed); receive (log) times are not used for pairing, only to compare
the two streams' clocks. A frame whose stamp is farther than :data:`MAX_GAP_PERIODS` tf periods from
the nearest tf sample (a hole in ``/tf``) or outside the tf's recorded span is dropped and named; none
left is a one-line error. The chain's edges, the largest gap and each view's gap are in the result.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robocal.bags._tf import CLOCK_MISMATCH, tf_clock_offset
from robocal.diagnostics import Diagnostic
from robocal.errors import DetectionError, InputError, NotEnoughDataError
from robocal.handeye.workflow import PosePair

__all__ = ["MAX_GAP_PERIODS", "CLOCK_MISMATCH", "POSE_TYPES", "BagPosePair", "load_bag_pair"]

#: A frame farther than this many (slowest dynamic edge's) tf periods from the nearest tf sample is dropped:
#: within a normal stream the nearest sample is at most half a period away, so this is a hole of >= 4 periods.
MAX_GAP_PERIODS = 2.0
#: Message types ``--target-poses`` takes (the target in the camera frame).
POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped",
              "geometry_msgs/msg/TransformStamped")


@dataclass
class BagPosePair(PosePair):
    """A :class:`~robocal.handeye.workflow.PosePair` read from a recording, with what the calibration and the
    result take from it: ``pose_sigmas`` (N, 2) rotation [rad] / translation [m] std per view (or None),
    ``pose_covariances`` (N, 6, 6) of the image views (as ``calibrate-images`` gives them, or None),
    ``warnings`` (views dropped or down-weighted, clocks), ``diagnostics`` (merged into the result's)."""

    bag: Path | None = None
    extra_files: tuple = ()
    source_names: tuple = ("T_base_gripper", "T_cam_target")
    pose_sigmas: np.ndarray | None = None
    pose_covariances: np.ndarray | None = None
    warnings: list = field(default_factory=list)
    diagnostics: dict = field(default_factory=dict)

    @property
    def names(self) -> tuple[str, str]:
        return self.source_names

    @property
    def files(self) -> list[Path]:
        return [self.bag, *self.extra_files]


def _given(options: dict) -> list[str]:
    return [f"--{k.replace('_', '-')}" for k, v in options.items() if v is not None]


def load_bag_pair(bag=None, gripper_poses=None, target_poses=None, *, base=None, gripper=None, images=None,
                  camera_info=None, camera=None, target=None, target_pose_topic=None, every=None,
                  clock_offset="none", progress: bool = True, **_) -> BagPosePair:
    """``T_base_gripper`` and ``T_cam_target`` of the frames of a recording (module docstring).

    Parameters
    ----------
    bag : path
        ROS 1 ``.bag``, ROS 2 bag folder / ``.db3``, or ``.mcap``.
    gripper_poses, target_poses : path, optional
        The pose-list files of the other way in; given with ``bag`` they are an error.
    base, gripper : str
        tf frames: ``T_base_gripper`` is the pose of ``gripper`` in ``base`` (tf's ``base -> gripper``).
    images : str
        Image topic (with ``target`` and a camera).
    camera_info, camera : str, path
        CameraInfo topic, or a camera file (:func:`robocal.camera.load_camera`); default: the
        ``camera_info`` topic beside ``images`` (``/cam/image_raw`` -> ``/cam/camera_info``).
    target : path
        Target file (:func:`robocal.camera.load_target`).
    target_pose_topic : str
        Instead of ``images``: a topic of the target's pose in the camera.
    every : int
        Take every ``every``-th frame (default 1).
    clock_offset : "none" or seconds
        Added to the frames' header stamps to put them on the tf's clock (a camera stamping on its own
        clock, ``robocal bag inspect`` shows the offsets). ``"auto"`` (estimated from two dense pose
        streams, :mod:`robocal.handeye.clock`) is refused: a recording's frames are too sparse for it here.
    """
    if bag is None:
        if gripper_poses is None and target_poses is None and not _given(
                dict(base=base, gripper=gripper, images=images, camera_info=camera_info, camera=camera,
                     target=target, target_poses=target_pose_topic, every=every)):
            raise InputError("give two pose lists (GRIPPER_POSES TARGET_POSES) or a recording (--bag FILE --base "
                             "FRAME --gripper FRAME --images TOPIC --target TARGET.yaml)")
        if gripper_poses is not None and target_poses is None and not _given(dict(
                base=base, gripper=gripper, images=images, target_poses=target_pose_topic)):
            raise InputError(f"one pose list given ({gripper_poses}): give the target poses too, or a recording "
                             "with --bag")
        used = _given(dict(base=base, gripper=gripper, images=images, camera_info=camera_info, camera=camera,
                           target=target, target_poses=target_pose_topic, every=every))
        raise InputError(f"{', '.join(used)} read a recording: give it with --bag FILE", source="--bag")
    bag = Path(bag)
    if gripper_poses is not None or target_poses is not None:
        raise InputError(f"give pose lists or --bag, not both ({gripper_poses or target_poses} with --bag {bag})",
                         source="--bag")
    every = 1 if every is None else int(every)
    if every < 1:
        raise InputError(f"must be >= 1, got {every}", source="--every")
    from robocal.handeye.clock import parse_clock_offset

    mode = parse_clock_offset(clock_offset)
    if mode == "auto":
        raise InputError("auto is not estimated from a recording's frames: give the offset in seconds (the "
                         "frames' header stamps + SECONDS = the tf's clock) or none", source="--clock-offset")
    offset_ns = 0 if mode == "none" else int(round(float(mode) * 1e9))
    if (images is None) == (target_pose_topic is None):
        raise InputError("give the camera's view of the target: --images TOPIC (with --target) or --target-poses "
                         "TOPIC, one of the two (robocal bag inspect FILE lists the topics)", source=str(bag))
    from robocal.bags import open_recording, read_tf

    with open_recording(bag) as rec:
        tree = read_tf(rec, show_progress=progress)
        if base is None or gripper is None:
            raise InputError(f"give the robot's frames with --base and --gripper (T_base_gripper: the gripper in "
                             f"the base); tf frames: {', '.join(tree.frames[:20])}", source=str(bag))
        chain = _chain(tree, base, gripper)
        if images is not None:
            pair = _from_images(rec, tree, chain, base, gripper, images, camera_info, camera, target, every,
                                offset_ns, progress)
        else:
            pair = _from_pose_topic(rec, tree, chain, base, gripper, target_pose_topic, every, offset_ns, progress)
    pair.diagnostics["recording"]["clock_offset_s"] = offset_ns / 1e9
    if offset_ns:
        pair.diagnostics["recording"]["stamps"] += f" (each + the clock offset, {offset_ns / 1e9:+.6f} s)"
    return pair


def _chain(tree, base: str, gripper: str) -> list:
    """The tf edges from ``base`` to ``gripper`` (frame typos: the closest names, from the bags core)."""
    up_b, up_g = tree.path(base, gripper)
    chain = [tree.edges[f] for f in up_b[:-1]] + [tree.edges[f] for f in up_g[:-1]]
    if all(e.static for e in chain):
        raise InputError(f"{tree.source}: tf {base} -> {gripper} is static (only /tf_static links them): the robot "
                         "does not move in this recording, or --gripper is not the arm's moving frame")
    return chain


def _robot_at(tree, chain, base, gripper, stamps_ns, names, what: str):
    """``(PoseStream, kept, warnings)``: the robot pose at the frames' stamps, frames outside the tf span or
    in a tf hole dropped (``kept``: indices into ``stamps_ns``)."""
    dyn = [e for e in chain if not e.static]
    lo, hi = max(int(e.stamps_ns[0]) for e in dyn), min(int(e.stamps_ns[-1]) for e in dyn)
    period = max(1.0 / e.rate for e in dyn if e.rate > 0) if any(e.rate > 0 for e in dyn) else 0.0
    inside = (stamps_ns >= lo) & (stamps_ns <= hi)
    t0 = int(stamps_ns[0]) if len(stamps_ns) else lo
    if not inside.any():
        raise InputError(
            f"{tree.source}: none of the {len(stamps_ns)} {what} header stamps "
            f"({(stamps_ns.min() - lo) / 1e9:+.3f} .. {(stamps_ns.max() - lo) / 1e9:+.3f} s from the tf start) lies "
            f"in the tf span of {base} -> {gripper} (0 .. {(hi - lo) / 1e9:.3f} s): the camera stamping on another "
            "clock? ('robocal bag inspect FILE' shows each topic's clock)")
    warns = []
    if not inside.all():
        out = np.flatnonzero(~inside)
        warns.append(Diagnostic("frames_outside_tf", f"{len(out)} {what}(s) stamped outside the tf span of {base} "
                                f"-> {gripper} (no extrapolation), dropped: " + ", ".join(names[k] for k in out[:6])
                                + (" ..." if len(out) > 6 else "")))
    idx = np.flatnonzero(inside)
    ps = tree.lookup(base, gripper, stamps_ns[idx])
    limit = MAX_GAP_PERIODS * period
    holes = ps.gap > limit if period > 0 else np.zeros(len(idx), bool)
    if holes.any():
        warns.append(Diagnostic("tf_gaps", f"{int(holes.sum())} {what}(s) farther than {1e3 * limit:.0f} ms "
                                f"({MAX_GAP_PERIODS:g} tf periods) from the nearest tf sample, dropped: "
                                + ", ".join(f"{names[k]} ({1e3 * g:.0f} ms)" for k, g in
                                            zip(idx[holes][:6], ps.gap[holes][:6]))))
        if holes.all():
            raise InputError(f"{tree.source}: every {what} is farther than {1e3 * limit:.0f} ms from the nearest "
                             f"tf sample of {base} -> {gripper} (largest gap {1e3 * ps.gap.max():.0f} ms)")
    return _rows(ps, np.flatnonzero(~holes)), idx[~holes], warns, t0


def _unique_stamps(stamps, recv, topic: str, what: str):
    """``(stamps, recv, warnings)`` with a repeated header stamp's later messages dropped (a driver that does
    not advance its stamp: which pose a repeated stamp has is unknowable), counted and named."""
    first = np.sort(np.unique(stamps, return_index=True)[1])
    if len(first) == len(stamps):
        return stamps, recv, []
    from robocal.bags import image_name

    rep = np.setdiff1d(np.arange(len(stamps)), first)
    return stamps[first], recv[first], [Diagnostic(
        "repeated_stamps", f"{len(rep)} {what}(s) of {topic} repeat an earlier header stamp, dropped: "
        + ", ".join(image_name(topic, s) for s in stamps[rep][:4]) + (" ..." if len(rep) > 4 else ""))]


def _rows(ps, idx):
    """The :class:`~robocal.bags.PoseStream` ``ps`` at rows ``idx``."""
    from robocal.bags import PoseStream

    idx = np.asarray(idx, int)
    return PoseStream(ps.parent, ps.child, ps.stamps_ns[idx], ps.T[idx], ps.gap[idx], ps.edges)


def _clock_check(chain, recv_ns, stamps_ns, what: str) -> list:
    """``(warnings, (frames' offset, tf's offset))``: median receive - header [s] of each stream, and a
    ``clock_mismatch`` warning when they differ by more than :data:`CLOCK_MISMATCH`."""
    d_img, d_tf = float(np.median(recv_ns - stamps_ns)) / 1e9, tf_clock_offset(chain)
    if abs(d_img - d_tf) <= CLOCK_MISMATCH:
        return [], (d_img, d_tf)
    return [Diagnostic("clock_mismatch", f"the {what} and tf header stamps look like two clocks: receive minus "
                       f"header is {1e3 * d_img:.0f} ms for the {what}s, {1e3 * d_tf:.0f} ms for tf (expected: a "
                       f"few ms apart); the robot poses are taken at the {what}s' header stamps, so they are off "
                       "by the clocks' offset")], (d_img, d_tf)


def _default_camera_info(rec, topic: str) -> str:
    from robocal.bags._messages import CAMERA_INFO_TYPES

    ns = topic.rstrip("/")
    if ns.endswith("/compressed"):
        ns = ns[: -len("/compressed")]
    sibling = ns.rsplit("/", 1)[0] + "/camera_info"
    if sibling in rec.topics:
        return sibling
    infos = rec.topics_of_type(CAMERA_INFO_TYPES)
    raise InputError(f"{rec.path}: no topic {sibling} beside {topic}: give the camera with --camera-info TOPIC "
                     f"(CameraInfo topics: {', '.join(infos) or 'none'}) or --camera FILE")


def _from_images(rec, tree, chain, base, gripper, topic, camera_info, camera, target, every, offset_ns, progress):
    from robocal.bags import image_name, iter_images, read_camera_info
    from robocal.bags._messages import IMAGE_TYPES
    from robocal.camera import load_camera, load_target
    from robocal.handeye.images import view_poses
    from robocal.handeye.commands import _view_covariances
    from robocal.resources import require_memory

    if target is None:
        raise InputError("--images needs the target file: --target TARGET.yaml", source="--target")
    if camera is not None and camera_info is not None:
        raise InputError("give the camera once: --camera FILE or --camera-info TOPIC", source="--camera")
    topic = rec.topic(topic, IMAGE_TYPES).name
    target_obj = load_target(target)
    if camera is not None:
        cam, cam_from = load_camera(camera), str(camera)
    else:
        info = camera_info or _default_camera_info(rec, topic)
        cam, cam_from = read_camera_info(rec, info), f"CameraInfo of {rec.topic(info).name}"
    stamps, recv = [], []
    for _, r, data in rec.raw(topic, show_progress=progress):  # stamps from the raw header: no pixel decoded
        stamps.append(rec.header_stamp_ns(data))
        recv.append(r)
    if not stamps:
        raise InputError(f"{rec.path}: topic {topic} holds no images")
    n_topic = len(stamps)
    stamps, recv = np.asarray(stamps, np.int64)[::every], np.asarray(recv, np.int64)[::every]
    stamps, recv, warns = _unique_stamps(stamps, recv, topic, "image")
    names = [image_name(topic, s) for s in stamps]
    w1, clocks = _clock_check(chain, recv, stamps + offset_ns, "image")
    robot, kept, w2, t0 = _robot_at(tree, chain, base, gripper, stamps + offset_ns, names, "image")
    warns += w1
    warns += w2
    require_memory(len(kept) * cam.width * cam.height * 3.0, f"{len(kept)} decoded {cam.width}x{cam.height} images "
                   f"of {topic}", source=str(rec.path))
    # the robot row of each decoded frame by its stamp, not by position (frames come in receive order)
    row = {int(s): i for i, s in enumerate(stamps[kept])}
    decoded, seen = [], set()
    for s, img in iter_images(rec, topic, stamps[kept], tolerance=0.0, show_progress=progress):
        if s not in seen:  # a later message repeating a stamp matches it too: the first one only
            seen.add(s)
            decoded.append((s, img))
    robot = _rows(robot, [row[int(s)] for s, _ in decoded])
    frames = [(image_name(topic, s), img) for s, img in decoded]
    try:
        views = view_poses([img for _, img in frames], cam, target_obj, names=[n for n, _ in frames])
    except (NotEnoughDataError, DetectionError) as exc:  # no board found, or in fewer than 3 frames
        raise type(exc)(f"topic {topic}: {exc.message} (target {target})", source=str(rec.path)) from None
    pair = BagPosePair(
        robot.T[views.index], views.T_cam_target, rec.path, rec.path, (robot.stamps_ns[views.index] - t0) / 1e9,
        ("", ""), bag=rec.path, extra_files=tuple(Path(p) for p in (camera, target) if p is not None),
        source_names=(f"{rec.path.name} tf {base} -> {gripper}", f"{rec.path.name} {topic}"),
        pose_sigmas=views.sigmas, pose_covariances=_view_covariances(views), warnings=warns + list(views.warnings))
    gap = robot.gap[views.index]
    pair.diagnostics = {
        **_recording(rec, chain, base, gripper, topic, n_topic, every, len(kept), clocks, gap, "image"),
        "pose_files": {f"{rec.path.name} tf": f"{base} -> {gripper} at the images' header stamps (largest gap to a "
                                              f"tf sample {1e3 * gap.max():.1f} ms)",
                       f"{rec.path.name} {topic}": f"{len(views.names)} of {n_topic} images"
                                                   + (f" (every {every})" if every > 1 else "")
                                                   + f" of a {target_obj.kind}; camera: {cam_from}"},
        "views": [{"image": n, "pose": int(i), "rms_px": float(r), "ambiguity": float(a),
                   "rotation_std_rad": float(s[0]), "translation_std_m": float(s[1]), "tf_gap_s": float(g)}
                  for n, i, r, a, s, g in zip(views.names, views.index, views.rms_px, views.ambiguity,
                                              views.sigmas, gap)]}
    return pair


def _from_pose_topic(rec, tree, chain, base, gripper, topic, every, offset_ns, progress):
    from robocal.bags import image_name, read_arrays

    topic = rec.topic(topic, POSE_TYPES).name
    arr = read_arrays(rec, topic, show_progress=progress)
    if not len(arr.stamps_ns):
        raise InputError(f"{rec.path}: topic {topic} holds no poses")
    n_topic = len(arr.stamps_ns)
    sel = np.arange(0, n_topic, every)
    first = np.sort(np.unique(arr.stamps_ns[sel], return_index=True)[1])
    warns = [] if len(first) == len(sel) else _unique_stamps(arr.stamps_ns[sel], arr.receive_ns[sel], topic,
                                                             "target pose")[2]
    sel = sel[first]
    stamps, recv = arr.stamps_ns[sel], arr.receive_ns[sel]
    names = [image_name(topic, s) for s in stamps]
    w1, clocks = _clock_check(chain, recv, stamps + offset_ns, "target pose")
    warns += w1
    robot, kept, w2, t0 = _robot_at(tree, chain, base, gripper, stamps + offset_ns, names, "target pose")
    warns += w2
    if len(kept) < 3:
        raise NotEnoughDataError(f"topic {topic}: {len(kept)} target pose(s) with a robot pose; hand-eye "
                                 "calibration needs at least 3", source=str(rec.path))
    sigmas = None
    if "covariance" in arr.fields:  # ROS order: x, y, z, rotation about x, y, z; row-major 6 x 6
        d = arr["covariance"][sel[kept]].reshape(-1, 6, 6).diagonal(axis1=1, axis2=2)
        if np.all(d > 0):
            sigmas = np.column_stack([np.sqrt(d[:, 3:].mean(1)), np.sqrt(d[:, :3].mean(1))])
    pair = BagPosePair(
        robot.T, arr["T"][sel[kept]], rec.path, rec.path, (robot.stamps_ns - t0) / 1e9, ("", ""), bag=rec.path,
        source_names=(f"{rec.path.name} tf {base} -> {gripper}", f"{rec.path.name} {topic}"), pose_sigmas=sigmas,
        warnings=warns)
    pair.diagnostics = {
        **_recording(rec, chain, base, gripper, topic, n_topic, every, len(kept), clocks, robot.gap, "target pose"),
        "pose_files": {f"{rec.path.name} tf": f"{base} -> {gripper} at the target poses' header stamps (largest gap "
                                              f"to a tf sample {1e3 * robot.gap.max():.1f} ms)",
                       f"{rec.path.name} {topic}": f"{len(kept)} of {n_topic} {arr.msgtype.rsplit('/', 1)[-1]} "
                                                   f"(T_cam_target, camera frame '{arr.frame_id}')"
                                                   + ("; weighted by their covariance" if sigmas is not None else "")}}
    return pair


def _recording(rec, chain, base, gripper, topic, n_topic, every, n_used, clocks, gap, what) -> dict:
    return {"recording": {
        "file": str(rec.path), "base": base, "gripper": gripper,
        "tf_chain": [f"{e.parent} -> {e.child} ({'static' if e.static else f'dynamic, {e.rate:.1f} Hz'})"
                     for e in chain],
        "topic": topic, "messages": n_topic, "every": every, "used": n_used,
        "stamps": f"robot poses interpolated at the {what}s' header stamps; receive times only compared",
        "receive_minus_header_s": {what: clocks[0], "tf": clocks[1]},
        "largest_tf_gap_s": float(gap.max()) if len(gap) else None}}


def report_section(rep, diagnostics: dict) -> None:
    """The report's section on where the poses came from: the recording (file, frames, tf chain, stamps,
    clocks) when there is one, and one row per view (its image, RMS, ambiguity, pose stds, tf gap)."""
    rec, views = diagnostics.get("recording"), diagnostics.get("views")
    s = rep.section("Recording" if rec else "Views")
    if rec:
        clocks = rec.get("receive_minus_header_s") or {}
        rows = [("file", rec["file"]), ("T_base_gripper", f"tf {rec['base']} -> {rec['gripper']}"),
                ("tf chain", "; ".join(rec["tf_chain"])), ("topic", rec["topic"]),
                ("frames used", f"{rec['used']} of {rec['messages']}"
                 + (f" (every {rec['every']})" if rec["every"] > 1 else "")),
                ("stamps", rec["stamps"]),
                ("receive - header [ms]", ", ".join(f"{k}: {1e3 * v:.1f}" for k, v in clocks.items())),
                ("largest tf gap [ms]", "" if rec["largest_tf_gap_s"] is None else
                 f"{1e3 * rec['largest_tf_gap_s']:.1f}")]
        s.table([{"quantity": k, "value": v} for k, v in rows], ["quantity", "value"])
    if views:
        s.table([{"view": v["image"], "pose": v["pose"], "RMS [px]": v["rms_px"], "ambiguity": v["ambiguity"],
                  "rotation std [mrad]": 1e3 * v["rotation_std_rad"],
                  "translation std [mm]": 1e3 * v["translation_std_m"],
                  **({"tf gap [ms]": 1e3 * v["tf_gap_s"]} if "tf_gap_s" in v else {})} for v in views],
                digits=4, caption="each view's target pose (planar PnP): reprojection RMS, ambiguity (RMS of the "
                                  "best / second pose), first-order std used as its weight")
