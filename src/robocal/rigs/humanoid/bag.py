"""The humanoid rig's input from a robot recording: joint states + lower-camera images (issue 15).

``robocal humanoid calibrate --bag FILE --joints /joint_states --images TOPIC
[--camera-info TOPIC | --camera CAM.yaml]`` reads a ROS 1 ``.bag``, a ROS 2 bag
or an ``.mcap`` recording (:mod:`robocal.bags`, no ROS install) and builds the
same :class:`~robocal.rigs.humanoid.workflow.HumanoidInput` a data-set file
gives, so the calibration runs through the rig's usual checks.

Per image (its **header stamp**, the camera driver's clock):

1. the joint angles are interpolated linearly at the stamp from the joint
   states (their header stamps); the *gap* to the nearest joint sample is
   reported, and an image more than :data:`MAX_GAP_PERIODS` joint-state
   periods from a sample, or outside the joint stream, is refused;
2. an image is refused when a joint moves around it: the joint samples within
   :data:`STILL_WINDOW_PERIODS` periods of the stamp must agree to the joint
   resolution (seed 001 takes images only once the robot is still: camera and
   joint sensors are not synchronous, and NAO's camera has no exposure stamp);
3. consecutive still images with the same joint readings are one pose: the
   middle frame serves, the others are named (a 30 Hz camera records dozens of
   frames of each held pose; they are not independent views);
4. the foot is the one whose board the nominal model (zero offsets) puts in
   the image, facing the camera; a pose showing neither board (or both) is refused.

Only the frames used are decoded. Every refusal is a note in the result
(``diagnostics["messages"]``); no usable image left is a one-line error.

Joint names: the model's joints are NAO's standard names, which NAOqi and
``naoqi_driver`` publish on ``/joint_states``; :data:`JOINT_NAMES` maps a model
joint to its name in a recording (the identity for a NAO), and ``joint_map``
(``--joint-map LKneePitch=l_knee ...``) overrides it for another driver.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal.bags._tf import CLOCK_MISMATCH
from robocal.errors import InputError, NotEnoughDataError

__all__ = ["JOINT_NAMES", "NAO_JOINTS", "MAX_GAP_PERIODS", "STILL_WINDOW_PERIODS", "CLOCK_MISMATCH", "load_bag_input",
           "parse_joint_map"]

#: Every joint NAOqi / naoqi_driver publish on ``/joint_states`` for a NAO H25, in their order.
NAO_JOINTS = ("HeadYaw", "HeadPitch", "LShoulderPitch", "LShoulderRoll", "LElbowYaw", "LElbowRoll", "LWristYaw",
              "LHand", "LHipYawPitch", "LHipRoll", "LHipPitch", "LKneePitch", "LAnklePitch", "LAnkleRoll",
              "RHipYawPitch", "RHipRoll", "RHipPitch", "RKneePitch", "RAnklePitch", "RAnkleRoll", "RShoulderPitch",
              "RShoulderRoll", "RElbowYaw", "RElbowRoll", "RWristYaw", "RHand")

#: The model's joint (URDF name) -> its name on the robot's ``/joint_states``. The shipped NAO model uses
#: NAOqi's names, so the table is the identity; a joint not listed keeps its model name.
JOINT_NAMES = {name: name for name in ("HeadYaw", "HeadPitch", "LHipYawPitch", "LHipRoll", "LHipPitch", "LKneePitch",
                                        "LAnklePitch", "LAnkleRoll", "RHipYawPitch", "RHipRoll", "RHipPitch",
                                        "RKneePitch", "RAnklePitch", "RAnkleRoll")}

#: An image further than this many joint-state periods from the nearest joint sample is refused.
MAX_GAP_PERIODS = 3.0
#: Half-width [joint-state periods] of the window whose samples must agree for an image to be still:
#: 1.5 periods holds the two samples bracketing the stamp and one more on each side.
STILL_WINDOW_PERIODS = 1.5


def parse_joint_map(items) -> dict:
    """``["LKneePitch=l_knee", ...]`` (``--joint-map``) -> ``{"LKneePitch": "l_knee"}``."""
    out = {}
    for item in items or ():
        if isinstance(item, dict):
            out.update(item)
            continue
        model, sep, bag = str(item).partition("=")
        if not sep or not model.strip() or not bag.strip():
            raise InputError(f"--joint-map: expected MODEL_JOINT=RECORDED_NAME, got {item!r}")
        out[model.strip()] = bag.strip()
    return out


def _bag_files(bag: Path) -> list[Path]:
    """The files of a recording, for the result's input hashes (a ROS 2 bag is a folder)."""
    if bag.is_dir():
        return sorted(p for p in bag.iterdir() if p.is_file())
    return [bag]


def _camera(rec, images: str, camera_info: str | None, camera) -> tuple[object, str]:
    """The camera model and where it came from: ``--camera`` file, ``--camera-info`` topic, or the image's sibling."""
    from robocal.bags import read_camera_info

    if camera is not None and camera_info is not None:
        raise InputError("give --camera FILE or --camera-info TOPIC, not both")
    if camera is not None:
        from robocal.camera import load_camera

        return load_camera(camera), str(camera)
    if camera_info is None:
        # ROS's convention: <ns>/image_raw beside <ns>/camera_info
        sibling = images.rsplit("/", 1)[0] + "/camera_info"
        if sibling not in rec.topics:
            raise InputError(f"{rec.path}: no camera for {images}: no topic {sibling}; give --camera-info TOPIC or "
                             "--camera CAM.yaml")
        camera_info = sibling
    return read_camera_info(rec, camera_info), f"{rec.path}: topic {camera_info}"


def _grey(img: np.ndarray) -> np.ndarray:
    """uint8 grey from any image the bag reader returns (BGR(A) colour, 16-bit mono)."""
    import cv2

    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)
    return img


def _feet(model, theta: np.ndarray, images) -> tuple[list, list]:
    """Per pose, the foot whose board the image shows, or None; and why not.

    The board is found in the image (pixel-level, no sub-pixel refinement: only its centre is
    used) and its centre compared with where the nominal model (zero offsets) puts each foot's
    board at the pose's joint angles: the nearer foot's board is the one seen. Visibility alone
    cannot decide: the resting leg's board often lies in the image too (the seed shows one board
    at a time). Offsets of ~0.5 deg move the prediction by ~5 px; a foot is kept when the other
    board's prediction is at least twice as far.
    """
    from robocal.camera import detect_checkerboard
    from robocal.errors import DetectionError
    from robocal.rigs.humanoid.model import FEET

    centres = []
    for foot in FEET:
        T = model.T_opt_board(theta, foot)
        p = np.einsum("vij,nj->vni", T[:, :3, :3], model.object_points) + T[:, None, :3, 3]
        front = np.all(p[..., 2] > 0.05, axis=1)
        uv = model.camera.project(np.where(p[..., 2:3] > 0.05, p, 1.0), check=False)
        facing = np.einsum("vi,vi->v", T[:, :3, 2], T[:, :3, 3]) / np.linalg.norm(T[:, :3, 3], axis=1)
        c = uv.mean(axis=1)
        c[~(front & (facing > 0.0))] = np.nan  # behind the camera, or the board's back to it
        centres.append(c)
    feet, why = [], []
    for v, img in enumerate(images):
        try:
            found = detect_checkerboard(img, model.board, refine=False).mean(axis=0)
        except DetectionError:
            feet.append(None)
            why.append("no whole board detected")
            continue
        d = np.array([np.linalg.norm(c[v] - found) for c in centres])  # NaN: that board cannot be in view
        if np.all(np.isnan(d)):
            feet.append(None)
            why.append("a board detected where the nominal model puts neither foot's board in view")
            continue
        k = int(np.nanargmin(d))
        other = d[1 - k]
        if np.isfinite(other) and other < 2.0 * d[k]:
            feet.append(None)
            why.append(f"the board detected is {d[k]:.0f} px from the {FEET[k]} board's predicted place and "
                       f"{other:.0f} px from the {FEET[1 - k]} one's: which foot is ambiguous")
            continue
        feet.append(FEET[k])
        why.append("")
    return feet, why


def load_bag_input(bag, *, joints: str = "/joint_states", images: str | None = None, camera_info: str | None = None,
                   camera=None, joint_map=None, max_gap_periods: float = MAX_GAP_PERIODS,
                   show_progress: bool = False):
    """A :class:`~robocal.rigs.humanoid.workflow.HumanoidInput` from a recording (module docstring).

    Parameters
    ----------
    bag : path
        ROS 1 ``.bag``, ROS 2 bag folder / ``.db3`` or ``.mcap``.
    joints : str
        ``sensor_msgs/JointState`` topic (positions in rad, ROS's unit).
    images : str
        The lower head camera's image topic (``sensor_msgs/Image`` or ``CompressedImage``).
    camera_info, camera : optional
        The camera: a ``CameraInfo`` topic, or a camera file (OpenCV, ROS, robocal); default the
        ``camera_info`` topic beside ``images``.
    joint_map : dict or list of "MODEL=RECORDED", optional
        Recorded names of model joints that differ from :data:`JOINT_NAMES`.
    max_gap_periods : float
        Refuse an image further than this many joint-state periods from a joint sample.

    Raises
    ------
    MissingTopicError, InputError
        A topic not in the recording (closest names offered), a joint the model needs not on the
        joint topic (closest names offered), an image size other than the camera's.
    NotEnoughDataError
        No image usable (each refusal counted by reason).
    """
    from robocal.bags import image_name, iter_images, open_recording, read_joint_states
    from robocal.bags._messages import IMAGE_TYPES
    from robocal.rigs.humanoid.dataset import _joint_unit_slip
    from robocal.rigs.humanoid.model import HumanoidModel
    from robocal.rigs.humanoid.simulate import JOINT_RESOLUTION, HumanoidDataset
    from robocal.rigs.humanoid.workflow import HumanoidInput

    bag = Path(bag)
    if not images:
        raise InputError("give the head camera's image topic with --images (robocal bag inspect FILE lists the "
                         "recording's topics)", source=str(bag))
    names_map = {**JOINT_NAMES, **parse_joint_map(joint_map)}
    with open_recording(bag) as rec:
        images = rec.topic(images, IMAGE_TYPES).name
        cam, cam_from = _camera(rec, images, camera_info, camera)
        model = HumanoidModel.from_urdf(camera=cam)
        unknown = [k for k in parse_joint_map(joint_map) if k not in model.recorded_joints]
        if unknown:
            from robocal.bags import closest_names

            raise InputError(f"--joint-map: the model has no joint '{unknown[0]}'"
                             f"{closest_names(unknown[0], model.recorded_joints)}")
        js = read_joint_states(rec, joints, show_progress=show_progress)
        # a joint the model needs and the topic lacks: the reader's one-line error offers the closest names
        try:
            q = np.column_stack([js[names_map.get(j, j)] for j in model.joint_names])
        except InputError as exc:
            raise exc.with_source(str(rec.path)) from None
        raw = [(r, rec.header_stamp_ns(data)) for _, r, data in rec.raw(images, show_progress=False)]
        stamps = np.asarray([s for _, s in raw], np.int64)
        # clocks: median receive - header of each stream; transports differ by ms, two clocks by much more
        d_img = float(np.median([r - s for r, s in raw])) / 1e9 if raw else float("nan")
        d_js = js.clock_offset
        source = str(rec.path)
        where = f"{source}: topic {js.topic}"

        ok = np.all(np.isfinite(q), axis=1)  # samples of other drivers on the topic may lack the legs
        t_j, q = js.stamps_ns[ok], q[ok]
        order = np.argsort(t_j, kind="stable")
        t_j, q = t_j[order], q[order]
        if len(t_j) < 2:
            raise NotEnoughDataError(f"{where}: {len(t_j)} message(s) with every leg and head joint; need 2 or more "
                                     "to interpolate at the image stamps")
        period = float(np.median(np.diff(t_j)))
        if period <= 0:
            raise InputError(f"{where}: the joint states' header stamps do not advance (median period {period} ns)")
        if not len(stamps):
            raise NotEnoughDataError(f"{source}: topic {images} holds no image")
        stamps = np.sort(stamps)

        # 1. joints at each image stamp, and the gap to the nearest joint sample
        i = np.clip(np.searchsorted(t_j, stamps), 1, len(t_j) - 1)
        t0, t1 = t_j[i - 1], t_j[i]
        w = np.clip((stamps - t0) / np.maximum(t1 - t0, 1), 0.0, 1.0)[:, None]
        theta = (1 - w) * q[i - 1] + w * q[i]
        gap = np.minimum(np.abs(stamps - t0), np.abs(t1 - stamps)) / 1e9
        outside = (stamps < t_j[0]) | (stamps > t_j[-1])
        far = ~outside & (gap > max_gap_periods * period / 1e9)
        # 2. still: the samples within the window agree to the joint resolution
        half = int(round(STILL_WINDOW_PERIODS * period))
        lo, hi = np.searchsorted(t_j, stamps - half), np.searchsorted(t_j, stamps + half, side="right")
        moving, speed = np.zeros(len(stamps), bool), [None] * len(stamps)
        tol = JOINT_RESOLUTION + 1e-9
        for k in np.flatnonzero(~outside & ~far):
            a, b = min(lo[k], i[k] - 1), max(hi[k], i[k] + 1)
            span = np.ptp(q[a:b], axis=0)
            if np.any(span > tol):
                j = int(np.argmax(span))
                moving[k] = True
                speed[k] = (model.joint_names[j], np.degrees(span[j]) / ((t_j[b - 1] - t_j[a]) / 1e9))

        notes = [f"recording {source}: joints from {js.topic} ({1e9 / period:.1f} Hz, header stamps) interpolated "
                 f"at the header stamps of {images} ({len(stamps)} frames; receive - header {1e3 * d_img:.1f} ms, "
                 f"joints {1e3 * d_js:.1f} ms); camera from {cam_from}"]
        if abs(d_img - d_js) > CLOCK_MISMATCH:
            notes.append(f"the images' and joints' header stamps look like two clocks (receive - header differs by "
                         f"{d_img - d_js:+.3f} s; a few ms is transport): the joint angles are taken at the "
                         "images' stamps, so they are off by the clocks' offset")
        # one note per reason (a camera running a minute past the joints is 1800 frames, not 1800 notes)
        if outside.any():
            beyond = np.maximum(t_j[0] - stamps, stamps - t_j[-1])[outside] / 1e9
            notes.append(f"{int(outside.sum())} frame(s) outside the joint stream, refused (first "
                         f"{image_name(images, int(stamps[outside][0]))}; up to {beyond.max():.3f} s beyond it)")
        if far.any():
            notes.append(f"{int(far.sum())} frame(s) further than {max_gap_periods:g} joint-state periods "
                         f"({max_gap_periods * period / 1e6:.1f} ms) from a joint sample, refused (first "
                         f"{image_name(images, int(stamps[far][0]))}, largest gap {1e3 * gap[far].max():.1f} ms)")
        n_moving = int(moving.sum())
        if n_moving:
            first = int(np.argmax(moving))
            jname, v = speed[first]
            notes.append(f"{n_moving} frame(s) taken while a joint moved, refused (first "
                         f"{image_name(images, int(stamps[first]))}: {jname} {v:.2g} deg/s)")

        # 3. consecutive still frames with the same readings: one pose, its middle frame
        usable = ~(outside | far | moving)
        groups, cur = [], []
        for k in range(len(stamps)):
            if usable[k] and cur and np.all(np.abs(theta[k] - theta[cur[0]]) <= tol):
                cur.append(k)
                continue
            if cur:
                groups.append(cur)
            cur = [k] if usable[k] else []
        if cur:
            groups.append(cur)
        picks = [g[len(g) // 2] for g in groups]
        merged = sum(len(g) - 1 for g in groups)
        if merged:
            notes.append(f"{merged} frame(s) repeat a still pose another frame serves (one view per pose: the "
                         "middle frame of each)")

        counts = {"outside the joint stream": int(outside.sum()), "too far from a joint sample": int(far.sum()),
                  "taken while a joint moved": n_moving}

        def none_usable(extra=None):
            c = {**counts, **(extra or {})}
            # every frame off the joint stream: the camera stamps on another clock than the joints
            hint = ("; the images' header stamps are on another clock than the joints' ('robocal bag inspect' "
                    "shows each topic's clock)" if outside.all() else "")
            return NotEnoughDataError(f"{source}: no usable image on {images}: {len(stamps)} frame(s), "
                                      + ", ".join(f"{n} {r}" for r, n in c.items() if n) + hint)

        if not picks:
            raise none_usable()
        # the loader's check of joint records (and its deg-as-rad slip), before any image is decoded
        th = theta[picks]
        tol_lim = 0.5 * JOINT_RESOLUTION + 1e-12
        try:
            model.check_limits(th, source=f"{where} (at the stamps of {images})", tolerance=tol_lim)
        except InputError as exc:
            _joint_unit_slip(model, th, "rad", tol_lim, exc, source=f"{where}: position")
            raise
        frames = dict(iter_images(rec, images, stamps[picks], tolerance=0.0, show_progress=show_progress))
    imgs = [_grey(frames[int(stamps[k])]) for k in picks]
    h, wid = imgs[0].shape[:2]
    if (wid, h) != (model.camera.width, model.camera.height):
        raise InputError(f"{source}: topic {images}: images are {wid} x {h} px, the camera ({cam_from}) is "
                         f"{model.camera.width} x {model.camera.height} px")

    # 4. the foot whose board the image shows
    feet, why = _feet(model, th, imgs)
    for k, f, y in zip(picks, feet, why):
        if f is None:
            notes.append(f"frame {image_name(images, int(stamps[k]))}: {y}, refused")
    keep = [j for j, f in enumerate(feet) if f is not None]
    if not keep:
        raise none_usable({"showing no board of a foot": len(picks)})
    idx = [picks[j] for j in keep]
    g = gap[idx]
    notes.append(f"{len(idx)} view(s) from {len(stamps)} frames; gap image -> nearest joint sample median "
                 f"{1e3 * np.median(g):.1f} ms, max {1e3 * g.max():.1f} ms")
    data = HumanoidDataset([feet[j] for j in keep], th[keep], images=[imgs[j] for j in keep],
                           names=[image_name(images, int(stamps[k])) for k in idx], messages=notes)
    info = {"joint_resolution": JOINT_RESOLUTION, "inputs": _bag_files(bag),
            "declared": {"board.square": "m", "board.centre": "m", "joints": "rad"},
            "bag": {"path": str(bag), "joints": js.topic, "images": images, "camera": cam_from,
                    "gap_s": gap[idx].tolist(), "joint_period_s": period / 1e9}}
    return HumanoidInput(bag, model, data, info, None)
