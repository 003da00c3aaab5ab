"""The line-profiler rig's FPDP input from a robot recording (issue 15): profiles + joint states or tf.

``robocal lineprofiler calibrate --bag FILE --profiles TOPIC (--joints TOPIC | --base FRAME --flange FRAME)
--sphere-radius MM`` reads a ROS 1 ``.bag``, a ROS 2 bag or an ``.mcap``
(:mod:`robocal.bags`, no ROS install) and builds the same
:class:`~robocal.rigs.lineprofiler.calibrate.SphereInput` the FPDP input file
gives; FPDP, the geometric refinement and the radius check then run unchanged.

**Profiles** are ``sensor_msgs/PointCloud2``, what the ROS drivers of line-laser
profilers publish (ROS-Industrial's ``keyence_experimental`` for the Keyence
LJ-V, Micro-Epsilon's scanCONTROL driver on ``/scancontrol_pointcloud``; a
``LaserScan`` cannot carry a triangulating profiler's points, which are not
rays from one origin): one cloud per profile, in the profiler's measuring frame L, points
``(x, 0, z)`` [m] in its ``x_L - z_L`` plane (seed 004 eq. 2). Invalid points
(NaN: a driver's dropouts in an organised cloud) are left out; a point more than
:data:`PLANE_TOLERANCE` off the plane is an error (the cloud is then in another
frame than L, e.g. already transformed to the base). The field names ``x, y, z``
are required; other fields (intensity) are ignored.

**Arm poses** at each profile's header stamp: either the joint states
(``--joints``, the arm's D-H model from ``INPUT`` or P1R2P3; joint names
``--joint-names`` in chain order, default the chain's names), interpolated
linearly, or the flange pose from tf (``--base``/``--flange``, SLERP +
linear: :meth:`robocal.bags.TfTree.lookup`), used as given end-effector poses.
A profile further than :data:`MAX_GAP_PERIODS` periods of the pose stream from
its nearest sample, or outside the stream, is dropped and named (a ``dropped``
warning in the result); a profile with fewer than :data:`MIN_POINTS` valid
points is dropped likewise.

``INPUT`` (optional with ``--bag``): an FPDP input file for the arm (``arm``),
``sphere_radius`` and ``sign``; its ``profiles`` / ``robot_poses`` are not read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robocal.bags._tf import CLOCK_MISMATCH, tf_clock_offset
from robocal.diagnostics import Diagnostic
from robocal.errors import InputError, NotEnoughDataError
from robocal.rigs.lineprofiler.calibrate import PoseTable, SphereInput

__all__ = ["BagSphereInput", "load_bag_input", "MAX_GAP_PERIODS", "PLANE_TOLERANCE", "MIN_POINTS", "CLOCK_MISMATCH"]

#: A profile further than this many periods of the joint / tf stream from its nearest sample is dropped.
MAX_GAP_PERIODS = 3.0
#: Largest |y| [m] of a profile point: the measuring plane is y_L = 0; a float32 driver's y is 0 exactly,
#: a cloud in another frame is off by centimetres.
PLANE_TOLERANCE = 1e-4
#: A profile with fewer valid points is dropped (a circle fit needs 3; FPDP judges the rest).
MIN_POINTS = 3


@dataclass
class BagSphereInput(SphereInput):
    """A :class:`SphereInput` read from a recording; ``notes``: ``dropped`` diagnostics for the result."""

    notes: list = field(default_factory=list)
    gap: np.ndarray | None = None


def _bag_files(bag: Path) -> list[Path]:
    return sorted(p for p in bag.iterdir() if p.is_file()) if bag.is_dir() else [bag]


def _at_stamps(t_s: np.ndarray, values: np.ndarray, stamps: np.ndarray):
    """``values`` (N, k) interpolated linearly at ``stamps`` (sorted ``t_s``, int ns); the gap [s] to the nearest."""
    i = np.clip(np.searchsorted(t_s, stamps), 1, len(t_s) - 1)
    t0, t1 = t_s[i - 1], t_s[i]
    w = np.clip((stamps - t0) / np.maximum(t1 - t0, 1), 0.0, 1.0)[:, None]
    return (1 - w) * values[i - 1] + w * values[i], np.minimum(np.abs(stamps - t0), np.abs(t1 - stamps)) / 1e9


def load_bag_input(bag, *, profiles: str | None = None, joints: str | None = None, joint_names=None,
                   base: str | None = None, flange: str | None = None, sphere_radius: float | None = None,
                   input_path=None, max_gap_periods: float = MAX_GAP_PERIODS,
                   show_progress: bool = False) -> BagSphereInput:
    """A :class:`BagSphereInput` from a recording (module docstring).

    Parameters
    ----------
    bag : path
    profiles : str
        ``sensor_msgs/PointCloud2`` topic of the profiles (frame L).
    joints : str, optional
        ``sensor_msgs/JointState`` topic (m for prismatic, rad for revolute joints: ROS's units).
    joint_names : sequence of str, optional
        The chain's joints as named on ``joints``, in chain order (default: the chain's own names).
    base, flange : str, optional
        tf frames: ``T_base_flange`` is ``T_W_E`` (instead of ``joints``).
    sphere_radius : float, optional
        [m]; default ``INPUT``'s ``sphere_radius``.
    input_path : path, optional
        FPDP input file giving ``arm``, ``sphere_radius``, ``sign``.
    """
    from robocal.bags import open_recording, read_joint_states, read_point_clouds, read_tf

    bag = Path(bag)
    src = str(bag)
    files = _bag_files(bag)
    chain, R, sign = None, None, "auto"
    if input_path is not None:
        from robocal.io import load_document
        from robocal.rigs.lineprofiler.calibrate import load_arm

        doc = load_document(input_path)
        chain = load_arm(doc)
        if "sphere_radius" in doc:
            R = doc.float("sphere_radius", kind="length", positive=True)
        sign = doc.raw("sign", "auto")
        files.insert(0, Path(input_path))
    if chain is None:
        from robocal.rigs.lineprofiler.model import p1r2p3_chain

        chain = p1r2p3_chain()
    if sphere_radius is not None:
        if not (np.isfinite(sphere_radius) and sphere_radius > 0):
            raise InputError(f"--sphere-radius must be a length > 0, got {sphere_radius * 1e3:g} mm")
        R = float(sphere_radius)
    if R is None:
        raise InputError("give the sphere radius: --sphere-radius MM (or an INPUT file with sphere_radius)")
    if not profiles:
        raise InputError("give the profile topic with --profiles (robocal bag inspect FILE lists the recording's "
                         "topics)", source=src)
    if (joints is None) == (base is None and flange is None) or (base is None) != (flange is None):
        raise InputError("give the arm's poses as --joints TOPIC, or as tf frames --base FRAME --flange FRAME "
                         "(one of the two)", source=src)

    with open_recording(bag) as rec:
        pc = read_point_clouds(rec, profiles, ("x", "y", "z"), show_progress=show_progress)
        where = f"{rec.path}: topic {pc.topic}"
        if not len(pc.points):
            raise NotEnoughDataError(f"{where} holds no profile")
        stamps = pc.stamps_ns
        if joints is not None:
            js = read_joint_states(rec, joints, show_progress=show_progress)
            names = list(joint_names) if joint_names else list(chain.joint_names)
            if len(names) != chain.dof:
                raise InputError(f"--joint-names: the arm has {chain.dof} joints, got {len(names)} names ({names})")
            try:
                q_s = np.column_stack([js[n] for n in names])
            except InputError as exc:
                hint = "" if joint_names else " (name the arm's joints in chain order with --joint-names)"
                raise InputError(f"{exc.message}{hint}", source=str(rec.path)) from None
            ok = np.all(np.isfinite(q_s), axis=1)
            t_s, q_s = js.stamps_ns[ok], q_s[ok]
            order = np.argsort(t_s, kind="stable")
            t_s, q_s = t_s[order], q_s[order]
            if len(t_s) < 2:
                raise NotEnoughDataError(f"{rec.path}: topic {js.topic}: {len(t_s)} message(s) with every arm "
                                         f"joint ({', '.join(names)}); need 2 or more")
            stream = f"{js.topic} ({', '.join(names)})"
            period = float(np.median(np.diff(t_s)))
            d_pose = js.clock_offset
        else:
            tree = read_tf(rec, show_progress=show_progress)
            up_p, up_c = tree.path(base, flange)
            dyn = [tree.edges[f] for f in up_p[:-1] + up_c[:-1] if not tree.edges[f].static]
            t_s = (np.array([max(e.stamps_ns[0] for e in dyn), min(e.stamps_ns[-1] for e in dyn)], np.int64)
                   if dyn else np.array([stamps.min(), stamps.max()], np.int64))
            period = max((float(np.median(np.diff(e.stamps_ns))) for e in dyn if len(e.stamps_ns) > 1), default=0.0)
            stream = f"tf {base} -> {flange}"
            d_pose = tf_clock_offset(dyn) if dyn else pc.clock_offset
    outside = (stamps < t_s[0]) | (stamps > t_s[-1])
    keep = ~outside
    if joints is not None:
        q, gap = _at_stamps(t_s, q_s, stamps)
    else:
        ps = tree.lookup(base, flange, stamps[keep]) if keep.any() else None
        gap = np.zeros(len(stamps))
        if ps is not None:
            gap[keep] = ps.gap
    far = keep & (gap > max_gap_periods * period / 1e9) if period > 0 else np.zeros(len(stamps), bool)
    xz, few, off_plane = [], np.zeros(len(stamps), bool), []
    for k, p in enumerate(pc.points):
        p = p[np.all(np.isfinite(p), axis=1)]
        if len(p) and np.max(np.abs(p[:, 1])) > PLANE_TOLERANCE:
            off_plane.append((k, float(np.max(np.abs(p[:, 1])))))
        few[k] = len(p) < MIN_POINTS
        xz.append(p[:, [0, 2]])
    if off_plane:
        k, y = off_plane[0]
        raise InputError(f"{where}: {len(off_plane)} profile(s) with points off the laser plane y = 0 (first: "
                         f"message {k}, |y| up to {1e3 * y:.3g} mm; tolerance {1e3 * PLANE_TOLERANCE:g} mm): the "
                         f"clouds must be in the profiler's measuring frame L ('{pc.frame_id}' is not)")
    notes = []
    if abs(pc.clock_offset - d_pose) > CLOCK_MISMATCH:
        notes.append(Diagnostic("clock_mismatch", f"the profiles' and the {stream}'s header stamps look like two "
                                f"clocks: receive - header is {1e3 * pc.clock_offset:.0f} ms for the profiles, "
                                f"{1e3 * d_pose:.0f} ms for the poses (expected: a few ms apart); the poses are "
                                "taken at the profiles' stamps, so they are off by the clocks' offset"))
    for mask, why in ((outside, f"outside the span of {stream}"),
                      (far, f"further than {max_gap_periods:g} periods ({max_gap_periods * period / 1e6:.1f} ms) "
                            f"from a sample of {stream}"),
                      (few & ~outside & ~far, f"with fewer than {MIN_POINTS} valid points")):
        if mask.any():
            idx = np.flatnonzero(mask)
            notes.append(Diagnostic("dropped", f"{len(idx)} profile(s) of {pc.topic} {why}: dropped (first at "
                                               f"{stamps[idx[0]] / 1e9:.6f} s)", indices=tuple(int(i) for i in idx)))
    use = keep & ~far & ~few
    if not use.any():
        raise NotEnoughDataError(f"{where}: no usable profile: {len(stamps)} message(s), {int(outside.sum())} "
                                 f"outside the span of {stream}, {int(far.sum())} too far from a sample, "
                                 f"{int((few & keep & ~far).sum())} with fewer than {MIN_POINTS} points")
    prof = [xz[k] for k in np.flatnonzero(use)]
    from robocal.resources import require_memory
    from robocal.rigs.lineprofiler.calibrate import refine_memory

    n_points = sum(len(p) for p in prof)
    require_memory(refine_memory(n_points, len(prof)), f"the refinement of {n_points:,} profile points in "
                   f"{len(prof):,} profiles", source=src)
    if joints is not None:
        q_use, arm = q[use], chain
    else:
        arm = PoseTable(ps.T[use[keep]])
        q_use = np.arange(int(use.sum()))[:, None]
    names = {"radius_from": f"the sphere radius ({R * 1e3:.4g} mm)", "profiles_from": f"topic {pc.topic}",
             "source": src}
    return BagSphereInput(q_use, prof, arm, R, sign, None, names, files, notes=notes, gap=gap[use])
