"""Files of the line-profiler rig: profile CSVs, pose lists (CSV/YAML), time alignment.

Profiles CSV (one row per point, as profiler software exports them)::

    profile, x [mm], z [mm], q1 [mm], q2 [deg], q3 [mm]      # joint values per row
    profile, x [mm], z [mm], t [s]                           # or a timestamp

``profile`` is the profile index; joint columns are ``q1 .. qn`` with their
units (length or angle) in the header; rows of one profile must repeat the
same joint values / timestamp.

Pose lists: CSV ``t [s], x [m], y [m], z [m], qx, qy, qz, qw`` or YAML
``{units: {length: mm}, poses: [{t: .., p: [x, y, z], q: [qx, qy, qz, qw]}]}``
(quaternions **scalar-last**, ``T_parent_child``; ``R: 3x3`` accepted in YAML
instead of ``q``). Non-unit quaternions, non-orthonormal matrices, NaN and
mismatched counts are errors naming file and row.

MCT tracker files (seed 004 §3): ball centres measured by the laser tracker
while one joint moves, one row per reading, with the arm's joint values::

    q1 [mm], q2 [deg], q3 [mm], x [mm], y [mm], z [mm]    # tracker frame T

and the points probed on the standard block's three corner faces::

    face, x [mm], y [mm], z [mm]    # face 0: x_B = 0, 1: y_B = 0, 2: z_B = 0

(faces listed so that x_B, y_B, z_B form a right-handed frame).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal.errors import FileFormatError
from robocal.io import atomic_write_text, interpolate_poses, load_csv, to_si, unit_kind, write_poses
from robocal.io import load_poses as _core_load_poses

__all__ = ["load_profiles_csv", "write_profiles_csv", "load_poses", "write_poses_csv", "interpolate_poses",
           "load_tracker_csv", "write_tracker_csv", "load_block_faces_csv", "write_block_faces_csv"]


def _joint_columns(tab, dof: int | None, src: str, joint_types=None):
    """``q1 .. qn`` columns in SI (m or rad by their header unit), or None when the file has none.

    With ``joint_types`` (``"revolute"`` / ``"prismatic"`` per joint) each
    column's unit must be an angle or a length accordingly: ``q3 [deg]`` on a
    prismatic joint is a file error, not 1.57 m.
    """
    qcols = sorted([c for c in tab.columns if c.startswith("q") and c[1:].isdigit()], key=lambda c: int(c[1:]))
    if dof is not None and qcols and len(qcols) != dof:
        raise FileFormatError(f"the arm has {dof} joints but the file has joint columns {qcols}", source=src)
    if not qcols:
        return None
    cols = []
    for j, c in enumerate(qcols):
        unit = tab.units.get(c)
        if unit is None:
            raise FileFormatError(f"column '{c}' needs a unit, e.g. '{c} [mm]' or '{c} [deg]'", source=src)
        kind = unit_kind(unit)
        if joint_types is not None:
            want = "angle" if joint_types[j] == "revolute" else "length"
            if kind != want:
                raise FileFormatError(f"column '{c} [{unit}]': joint {j + 1} is {joint_types[j]}, so its values "
                                      f"need {'an' if want == 'angle' else 'a'} {want} unit (e.g. "
                                      f"'{c} [{'deg' if want == 'angle' else 'mm'}]'), got {kind}", source=src)
        cols.append(to_si(tab.columns[c], unit, kind, name=f"column '{c}'"))
    return np.column_stack(cols)


def _joint_header(dof: int, angle_joints) -> list[str]:
    return [f"q{j + 1} [{'deg' if j in angle_joints else 'mm'}]" for j in range(dof)]


def _joint_text(q, angle_joints) -> list[str]:
    return [f"{np.rad2deg(v) if j in angle_joints else 1e3 * v:.6f}" for j, v in enumerate(q)]


def load_profiles_csv(path, *, dof: int | None = None, joint_types=None):
    """Read profiles; returns ``(profiles list of (M, 2) in m, q (N, dof) in m/rad or None, t (N,) or None)``.

    ``joint_types`` (the chain's): check each joint column's unit kind against its joint.
    """
    tab = load_csv(path, required=("profile", "x", "z"))
    src = str(path)
    x = tab.column("x", kind="length")
    z = tab.column("z", kind="length")
    idx = tab.column("profile")
    bad = np.flatnonzero((idx != np.round(idx)) | (idx < 0))
    if bad.size:
        raise FileFormatError(f"{tab.where(bad[0])}: column 'profile' must hold non-negative integers, "
                              f"got {idx[bad[0]]:g}", source=src)
    q = _joint_columns(tab, dof, src, joint_types)
    t = tab.column("t", kind="time") if "t" in tab else None
    if q is None and t is None:
        raise FileFormatError("need joint columns q1..qn or a timestamp column 't [s]'", source=src)
    # rows grouped by one stable sort (a mask per profile was O(profiles x rows): 10^6 points in
    # 2,000 profiles are 2 x 10^9 comparisons)
    order = np.argsort(idx, kind="stable")
    ids, starts = np.unique(idx[order], return_index=True)
    bounds = np.append(starts, len(idx))
    ids = ids.astype(int)
    profiles, qs, ts = [], [], []
    for k, i in enumerate(ids):
        rows = order[bounds[k]:bounds[k + 1]]
        profiles.append(np.column_stack([x[rows], z[rows]]))
        for arr, out, name in ((q, qs, "joint values"), (t, ts, "timestamp")):
            if arr is None:
                continue
            a = arr[rows]
            diff = np.flatnonzero(np.abs(a - a[0]).reshape(len(a), -1).max(axis=1) > 1e-12)
            if diff.size:
                first, other = rows[[0, diff[0]]]
                raise FileFormatError(f"profile {i}: {name} differ between its rows ({tab.where(other)} against "
                                      f"its first, {tab.where(first)}); every row of a profile must repeat them",
                                      source=src)
            out.append(a[0])
    return profiles, (np.array(qs) if q is not None else None), (np.array(ts) if t is not None else None)


def write_profiles_csv(path, profiles, q=None, t=None, *, angle_joints=()) -> Path:
    """Write profiles (m) as mm; joints in mm, or deg for indices in ``angle_joints``."""
    head = ["profile", "x [mm]", "z [mm]"]
    if q is not None:
        head += _joint_header(np.shape(q)[1], angle_joints)
    if t is not None:
        head.append("t [s]")
    lines = [", ".join(head)]
    for i, p in enumerate(profiles):
        extra = []
        if q is not None:
            extra += _joint_text(q[i], angle_joints)
        if t is not None:
            extra.append(f"{t[i]:.6f}")
        tail = (", " + ", ".join(extra)) if extra else ""
        lines += [f"{i}, {1e3 * a:.5f}, {1e3 * b:.5f}{tail}" for a, b in p]
    return atomic_write_text(path, "\n".join(lines) + "\n")


def load_poses(path):
    """Read a pose list (:func:`robocal.io.load_poses`, the core reader of every rig); ``(T (N, 4, 4) m, t (N,) or None)``."""
    poses = _core_load_poses(path)
    return poses.T, poses.t


# the hand-eye files are the core's pose lists: one writer and one interpolation for all rigs
write_poses_csv = write_poses


def load_tracker_csv(path, *, dof: int | None = None, joint_types=None):
    """Tracker readings with joint values; returns ``(q (n, dof) m/rad, p_T (n, 3) m)``."""
    tab = load_csv(path, required=("x", "y", "z"))
    src = str(path)
    q = _joint_columns(tab, dof, src, joint_types)
    if q is None:
        raise FileFormatError("need the joint columns q1..qn (with units) of every tracker reading", source=src)
    return q, np.column_stack([tab.column(c, kind="length") for c in "xyz"])


def write_tracker_csv(path, q, p_T, *, angle_joints=()) -> Path:
    """Write tracker readings (m) as mm; joints in mm, or deg for indices in ``angle_joints``."""
    rows = [", ".join(_joint_header(np.shape(q)[1], angle_joints) + ["x [mm]", "y [mm]", "z [mm]"])]
    rows += [", ".join(_joint_text(qi, angle_joints) + [f"{1e3 * v:.5f}" for v in p]) for qi, p in zip(q, p_T)]
    return atomic_write_text(path, "\n".join(rows) + "\n")


def load_block_faces_csv(path) -> list[np.ndarray]:
    """Points probed on the block's three corner faces; returns three (m_k, 3) arrays (m), faces 0, 1, 2."""
    tab = load_csv(path, required=("face", "x", "y", "z"))
    src = str(path)
    face = tab.column("face")
    if not np.all(np.isin(face, (0, 1, 2))):
        bad = int(np.flatnonzero(~np.isin(face, (0, 1, 2)))[0])
        raise FileFormatError(f"{tab.where(bad)}: column 'face' must be 0, 1 or 2 (x_B = 0, y_B = 0, z_B = 0), "
                              f"got {face[bad]:g}", source=src)
    p = np.column_stack([tab.column(c, kind="length") for c in "xyz"])
    faces = [p[face == k] for k in range(3)]
    few = [k for k, f in enumerate(faces) if len(f) < 3]
    if few:
        raise FileFormatError(f"face {few[0]} has {len(faces[few[0]])} points: a plane needs at least 3 "
                              "(10 or more recommended)", source=src)
    return faces


def write_block_faces_csv(path, faces) -> Path:
    """Write the three faces' tracker points (m) as mm with their face index."""
    rows = ["face, x [mm], y [mm], z [mm]"]
    rows += [f"{k}, " + ", ".join(f"{1e3 * v:.5f}" for v in p) for k, f in enumerate(faces) for p in f]
    return atomic_write_text(path, "\n".join(rows) + "\n")
