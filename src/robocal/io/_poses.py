"""Pose lists: one reader and writer for every rig (robot logs, tracker poses, trajectories).

Formats (``T_parent_child``, quaternions **scalar-last** ``(qx, qy, qz, qw)``
as SciPy and ROS, units in the header or in ``units:``)::

    # CSV, 3-D poses; the timestamp column is optional
    t [s], x [m], y [m], z [m], qx, qy, qz, qw

    # CSV, planar poses (a ground robot's odometry or reference)
    t [s], x [m], y [m], theta [rad]

    # YAML / JSON
    units: {length: mm}
    poses:
      - {t: 0.0, p: [x, y, z], q: [qx, qy, qz, qw]}   # or R: 3x3 instead of q

A non-unit quaternion, a matrix that is not a rotation, NaN, timestamps that
do not increase and mixed timed/untimed entries are errors naming the file
and the row.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal.errors import FileFormatError, InputError
from robocal.io._atomic import atomic_write_text
from robocal.io._load import load_csv, load_document

__all__ = ["PoseList", "load_poses", "write_poses", "interpolate_poses"]

#: How far from 1 a quaternion's norm may be (files round to ~6-9 digits; a slip is far larger).
QUATERNION_NORM_TOL = 1e-3


@dataclass(frozen=True)
class PoseList:
    """Poses read from a file.

    Attributes
    ----------
    T : (N, 4, 4) ndarray
        ``T_parent_child`` per entry, metres.
    t : (N,) ndarray or None
        Timestamps [s], strictly increasing; None when the file has none.
    planar : bool
        Whether the file held planar ``x, y, theta`` poses (then ``z = 0``
        and the rotation is about z).
    source : str
    heading : (N,) ndarray or None
        A planar file's ``theta`` [rad] as written (not wrapped to
        ``(-pi, pi]``: a heading past a full turn keeps its count).
    """

    T: np.ndarray
    t: np.ndarray | None
    planar: bool = False
    source: str = ""
    heading: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.T)

    @property
    def xy_theta(self) -> np.ndarray:
        """``(N, 3)`` planar poses ``x, y`` [m] and heading ``theta`` [rad] (the rotation about z).

        A planar file's headings as written; else the rotation's angle about z in ``(-pi, pi]``.
        """
        th = self.heading if self.heading is not None else np.arctan2(self.T[:, 1, 0], self.T[:, 0, 0])
        return np.column_stack([self.T[:, 0, 3], self.T[:, 1, 3], th])


def _transforms(R, p) -> np.ndarray:
    T = np.zeros((len(p), 4, 4))
    T[:, :3, :3] = R
    T[:, :3, 3] = p
    T[:, 3, 3] = 1.0
    return T


def _rotations_from_quats(qs, src: str, where) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    qs = np.asarray(qs, float)
    n = np.linalg.norm(qs, axis=1)
    bad = np.flatnonzero(~(np.abs(n - 1) <= QUATERNION_NORM_TOL))
    if bad.size:
        raise FileFormatError(f"{where(int(bad[0]))}: quaternion (qx, qy, qz, qw) has norm {n[bad[0]]:.6g}, "
                              "expected a unit quaternion (scalar-last)", source=src)
    return Rotation.from_quat(qs).as_matrix()


def _check_times(t, src: str, where) -> None:
    d = np.diff(t)
    if np.any(~(d > 0)):
        k = int(np.flatnonzero(~(d > 0))[0]) + 1
        raise FileFormatError(f"{where(k)}: timestamps must increase strictly, t = {t[k]:.6f} s follows "
                              f"{t[k - 1]:.6f} s", source=src)


def load_poses(path) -> PoseList:
    """Read a pose list (module docstring for the formats); SI units out."""
    from robocal.validation import check_rotation_matrix

    path = Path(path)
    src = str(path)
    if path.suffix.lower() in (".csv", ".txt"):
        tab = load_csv(path)
        if all(c in tab for c in ("x", "y", "z", "qx", "qy", "qz", "qw")):
            p = np.column_stack([tab.column(c, kind="length") for c in "xyz"])
            R = _rotations_from_quats(np.column_stack([tab.column(c) for c in ("qx", "qy", "qz", "qw")]), src,
                                      tab.where)
            planar, heading = False, None
        elif all(c in tab for c in ("x", "y", "theta")):
            xy = np.column_stack([tab.column("x", kind="length"), tab.column("y", kind="length")])
            th = tab.column("theta", kind="angle")
            c, s = np.cos(th), np.sin(th)
            R = np.zeros((len(th), 3, 3))
            R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
            p = np.column_stack([xy, np.zeros(len(th))])
            planar, heading = True, th
        else:
            raise FileFormatError("a pose CSV needs the columns x, y, z, qx, qy, qz, qw (3-D poses) or "
                                  "x, y, theta (planar poses), with units in the header (x [m])", source=src)
        t = tab.column("t", kind="time") if "t" in tab else None
        if t is not None:
            _check_times(t, src, tab.where)
        return PoseList(_transforms(R, p), t, planar, src, heading)
    doc = load_document(path)
    items = doc.items_list("poses")
    if not items:
        raise FileFormatError("field 'poses' is empty", source=src)
    Rs, ps, ts = [], [], []
    for k, it in enumerate(items):
        ps.append(it.array("p", kind="length", shape=(3,)))
        if "q" in it:
            Rs.append(_rotations_from_quats(it.array("q", shape=(4,))[None], src, lambda _, k=k: f"poses[{k}].q")[0])
        elif "R" in it:
            try:
                Rs.append(check_rotation_matrix(it.array("R", shape=(3, 3)), f"poses[{k}].R", atol=1e-4))
            except InputError as exc:
                raise FileFormatError(exc.message, source=src) from None
        else:
            raise FileFormatError(f"poses[{k}] needs 'q' (qx, qy, qz, qw) or 'R'", source=src)
        if "t" in it:
            ts.append(it.float("t", kind="time"))
    if ts and len(ts) != len(ps):
        raise FileFormatError("either every pose has a timestamp 't' or none", source=src)
    t = np.array(ts) if ts else None
    if t is not None:
        _check_times(t, src, lambda k: f"poses[{k}].t")
    return PoseList(_transforms(np.array(Rs), np.array(ps)), t, False, src)


def write_poses(path, T, t=None) -> Path:
    """Write 3-D poses as ``t [s], x [m], y [m], z [m], qx, qy, qz, qw`` (scalar-last, ``w >= 0``), atomically."""
    from scipy.spatial.transform import Rotation

    T = np.asarray(T, dtype=float)
    q = Rotation.from_matrix(T[:, :3, :3]).as_quat(canonical=True)
    head = (["t [s]"] if t is not None else []) + ["x [m]", "y [m]", "z [m]", "qx", "qy", "qz", "qw"]
    rows = [", ".join(head)]
    for i, Ti in enumerate(T):
        vals = ([f"{t[i]:.6f}"] if t is not None else []) + [f"{v:.9f}" for v in (*Ti[:3, 3], *q[i])]
        rows.append(", ".join(vals))
    return atomic_write_text(Path(path), "\n".join(rows) + "\n")


def interpolate_poses(t_src, T_src, t_query) -> np.ndarray:
    """Poses at ``t_query``: SLERP (SciPy) for the rotation, linear for the translation.

    Raises :class:`~robocal.errors.InputError` for unsorted source times or
    queries outside ``[t_src[0], t_src[-1]]`` (no extrapolation).
    """
    from scipy.spatial.transform import Rotation, Slerp

    t_src = np.asarray(t_src, float)
    t_query = np.asarray(t_query, float)
    T_src = np.asarray(T_src, float)
    if len(t_src) != len(T_src):
        raise InputError(f"{len(t_src)} timestamps but {len(T_src)} poses: counts must match")
    if len(t_src) < 2 or np.any(~(np.diff(t_src) > 0)):
        raise InputError("pose timestamps must be strictly increasing (at least 2)")
    out = ~((t_query >= t_src[0]) & (t_query <= t_src[-1]))
    if np.any(out):
        raise InputError(f"{out.sum()} query time(s) outside the pose stream [{t_src[0]:g}, {t_src[-1]:g}] s, "
                         f"first {t_query[out][0]:g} s: no extrapolation")
    R = Slerp(t_src, Rotation.from_matrix(T_src[:, :3, :3]))(t_query).as_matrix()
    p = np.column_stack([np.interp(t_query, t_src, T_src[:, k, 3]) for k in range(3)])
    return _transforms(R, p)
