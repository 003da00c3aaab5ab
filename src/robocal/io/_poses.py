"""Pose lists: one reader and writer for every rig (robot logs, tracker poses, trajectories).

Formats (``T_parent_child``, quaternions **scalar-last** ``(qx, qy, qz, qw)``
as SciPy and ROS, units in the header or in ``units:``)::

    # CSV with a header (commas, or spaces / tabs); the timestamp column is optional
    t [s], x [m], y [m], z [m], qx, qy, qz, qw
    t [s], x [m], y [m], z [m], rx [rad], ry [rad], rz [rad]     # translation + axis-angle vector

    # CSV, planar poses (a ground robot's odometry or reference)
    t [s], x [m], y [m], theta [rad]

    # CSV without a header (numbers only; # lines are comments; metres and radians),
    # read by the number of values a row:
    #   8: t x y z qx qy qz qw   (the TUM trajectory format)      7: x y z qx qy qz qw
    #   6: x y z rx ry rz        (axis-angle)                       16 / 17: [t] 4x4 row-major
    #   12 / 13: [t] 3x4 row-major [R | t]

    # YAML / JSON
    units: {length: mm}
    poses:
      - {t: 0.0, p: [x, y, z], q: [qx, qy, qz, qw]}   # or R: 3x3, or rotvec: [rx, ry, rz] (rad),
      - {T: 4x4}                                       # or T: 4x4; an entry may be a bare 4x4 list,
                                                       # and the file a bare list of entries

    # OpenCV FileStorage (.yml/.yaml starting %YAML:1.0, or .xml): every 4x4 (or 3x4) matrix in file
    # order, a sequence of them, or one (4N x 4) / (N x 16) matrix

:attr:`PoseList.form` says which form was found (one line, for a summary).
A non-unit quaternion, a matrix that is not a rotation, NaN, timestamps that
do not increase, rows of different lengths and mixed timed/untimed entries are
one-line errors naming the file and the line (or entry).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal.errors import FileFormatError, InputError
from robocal.io._atomic import atomic_write_text
from robocal.io._load import _parse_text, _read_text, load_csv, parse_document
from robocal.io._units import to_si

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
        Timestamps [s], strictly increasing (unless read with ``strict_times=False``); None when the file
        has none.
    planar : bool
        Whether the file held planar ``x, y, theta`` poses (then ``z = 0``
        and the rotation is about z).
    source : str
    heading : (N,) ndarray or None
        A planar file's ``theta`` [rad] as written (not wrapped to
        ``(-pi, pi]``: a heading past a full turn keeps its count).
    form : str
        The form the reader found, in words ("CSV without a header, 8 values a row: TUM t x y z qx qy
        qz qw (m, rad)").
    """

    T: np.ndarray
    t: np.ndarray | None
    planar: bool = False
    source: str = ""
    heading: np.ndarray | None = None
    form: str = ""

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


_SEP = re.compile(r"[,;\s]+")
#: a header cell may hold a unit in brackets with spaces ("x [m]"): split on whitespace outside brackets
_HEADER_SEP = re.compile(r"\s+(?![^\[]*\])")

#: headerless rows by their number of values: (description, has time, layout)
_HEADERLESS = {
    8: ("TUM t x y z qx qy qz qw", True, "quat"),
    7: ("x y z qx qy qz qw", False, "quat"),
    6: ("x y z rx ry rz (axis-angle)", False, "rotvec"),
    16: ("4x4 row-major", False, "4x4"),
    17: ("t + 4x4 row-major", True, "4x4"),
    12: ("3x4 row-major [R | t]", False, "3x4"),
    13: ("t + 3x4 row-major [R | t]", True, "3x4"),
}


#: the SI unit a header column without one is read in
_SI_OF = {"t": "s", "x": "m", "y": "m", "z": "m", "rx": "rad", "ry": "rad", "rz": "rad", "theta": "rad"}


def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _check_rotations(R, src: str, where, atol: float = 1e-4) -> None:
    """Vectorised :func:`~robocal.validation.check_rotation_matrix`: the first bad entry named."""
    err = np.abs(R @ np.swapaxes(R, -1, -2) - np.eye(3)).max(axis=(-2, -1))
    det = np.linalg.det(R)
    bad = np.flatnonzero(~((err <= atol) & (det > 0)))
    if bad.size:
        k = int(bad[0])
        raise FileFormatError(f"{where(k)}: the rotation is not a rotation matrix (|R R^T - I| = {err[k]:.3g}, "
                              f"det {det[k]:.3g}; expected orthonormal with det +1)", source=src)


def _from_matrices(M, src: str, where) -> tuple[np.ndarray, np.ndarray]:
    """(R, p) of (N, 3, 4) or (N, 4, 4) matrices, checked (a 4x4's last row must be 0 0 0 1)."""
    if M.shape[1] == 4:
        last = np.abs(M[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1)
        bad = np.flatnonzero(~(last <= 1e-9))
        if bad.size:
            raise FileFormatError(f"{where(int(bad[0]))}: the last row of a 4x4 pose must be 0 0 0 1, got "
                                  f"{np.round(M[bad[0], 3], 6).tolist()}", source=src)
    R = M[:, :3, :3]
    _check_rotations(R, src, where)
    return R, M[:, :3, 3]


def _load_headerless(kept, src: str, strict_times: bool = True) -> PoseList:
    rows, lines, ncol = [], [], None
    for n, ln in kept:
        toks = _SEP.split(ln.strip())
        bad = next((tk for tk in toks if not _is_number(tk)), None)
        if bad is not None:
            raise FileFormatError(f"line {n}: {bad[:20]!r} is not a number (a pose file without a header holds "
                                  "numbers only)", source=src)
        if ncol is None:
            ncol = len(toks)
            if ncol not in _HEADERLESS:
                raise FileFormatError(
                    f"line {n}: {ncol} values a row; a pose file without a header has "
                    + ", ".join(f"{k} ({d})" for k, (d, _, _) in _HEADERLESS.items())
                    + "; or give a header row (t [s], x [m], ..., qx, qy, qz, qw)", source=src)
        elif len(toks) != ncol:
            raise FileFormatError(f"line {n}: {len(toks)} values, expected {ncol} as on line {kept[0][0]}",
                                  source=src)
        rows.append([float(tk) for tk in toks])
        lines.append(n)
    data = np.array(rows, float)
    lines = np.array(lines)

    def where(k):
        return f"line {lines[k]}"
    bad = np.argwhere(~np.isfinite(data))
    if bad.size:
        raise FileFormatError(f"{where(int(bad[0][0]))}: value {data[tuple(bad[0])]} is not finite", source=src)
    desc, timed, layout = _HEADERLESS[ncol]
    t, v = (data[:, 0], data[:, 1:]) if timed else (None, data)
    if layout == "quat":
        p, R = v[:, :3], _rotations_from_quats(v[:, 3:7], src, where)
    elif layout == "rotvec":
        from robocal.geometry import matrix_from_rotvec

        p, R = v[:, :3], matrix_from_rotvec(v[:, 3:6])
    else:
        R, p = _from_matrices(v.reshape(len(v), -1, 4), src, where)
    if t is not None and strict_times:
        _check_times(t, src, where)
    return PoseList(_transforms(R, p), t, False, src,
                    form=f"CSV without a header, {ncol} values a row: {desc} (m, rad)")


def _load_table(path: Path, src: str, strict_times: bool = True) -> PoseList:
    text = _read_text(path, src)
    lines = text.splitlines()

    def skipped(ln):
        return not ln.strip() or ln.lstrip().startswith(("#", "%"))

    first = next((n for n, ln in enumerate(lines, 1) if not skipped(ln)), None)
    if first is None:
        raise FileFormatError("no pose rows (only blank or # comment lines)", source=src)
    head = lines[first - 1]
    cells = [c for c in (head.split(",") if "," in head else _HEADER_SEP.split(head.strip())) if c.strip()]
    # a header names every column: a first row with any number in it is data (and its junk an error)
    if any(_is_number(c.strip()) for c in cells):
        return _load_headerless([(n, ln) for n, ln in enumerate(lines, 1) if not skipped(ln)], src, strict_times)
    # a header without units (the TUM order "t x y z qx qy qz qw" as a header row) is read in SI units, and
    # said so; spaces / tabs as separators are rewritten as commas, line for line, so that the table's
    # errors keep the file's line numbers
    named = [c.strip() for c in cells]
    assumed = [c for c in named if "[" not in c and c in _SI_OF]
    if assumed or "," not in head or "%" in text:
        header = ", ".join(f"{c} [{_SI_OF[c]}]" if c in assumed else c for c in named)
        rows_text = [header if n == first else
                     (ln if "," in head else ", ".join(c for c in _SEP.split(ln.strip()) if c)) if not skipped(ln)
                     else "" for n, ln in enumerate(lines, 1)]
        text = "\n".join(rows_text)
    # else: a comma table with units in its header, as load_csv reads it (a 12,000-row log: no Python per line)
    tab = load_csv(path, text=text)
    if all(c in tab for c in ("x", "y", "z", "qx", "qy", "qz", "qw")):
        p = np.column_stack([tab.column(c, kind="length") for c in "xyz"])
        R = _rotations_from_quats(np.column_stack([tab.column(c) for c in ("qx", "qy", "qz", "qw")]), src,
                                  tab.where)
        planar, heading, what = False, None, "x y z qx qy qz qw"
    elif all(c in tab for c in ("x", "y", "z", "rx", "ry", "rz")):
        from robocal.geometry import matrix_from_rotvec

        p = np.column_stack([tab.column(c, kind="length") for c in "xyz"])
        R = matrix_from_rotvec(np.column_stack([tab.column(c, kind="angle") for c in ("rx", "ry", "rz")]))
        planar, heading, what = False, None, "x y z rx ry rz (axis-angle)"
    elif all(c in tab for c in ("x", "y", "theta")):
        xy = np.column_stack([tab.column("x", kind="length"), tab.column("y", kind="length")])
        th = tab.column("theta", kind="angle")
        c, s = np.cos(th), np.sin(th)
        R = np.zeros((len(th), 3, 3))
        R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
        p = np.column_stack([xy, np.zeros(len(th))])
        planar, heading, what = True, th, "planar x y theta"
    else:
        raise FileFormatError("a pose CSV needs the columns x, y, z, qx, qy, qz, qw (3-D poses), x, y, z, rx, "
                              "ry, rz (axis-angle) or x, y, theta (planar poses), with units in the header "
                              "(x [m]); or no header at all (TUM: t x y z qx qy qz qw)", source=src)
    t = tab.column("t", kind="time") if "t" in tab else None
    if t is not None:
        if strict_times:
            _check_times(t, src, tab.where)
        what = "t " + what
    units = f"; no units in the header for {', '.join(assumed)}: SI assumed" if assumed else ""
    return PoseList(_transforms(R, p), t, planar, src, heading,
                    form=f"CSV with a header ({'commas' if ',' in head else 'spaces'}): {what}{units}")


def _load_filestorage(path: Path, src: str) -> PoseList:
    """Every 4x4 / 3x4 matrix of an OpenCV FileStorage file, in file order (or one stacked matrix)."""
    import cv2

    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error as exc:
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else "parse error"
        raise FileFormatError(f"not a readable OpenCV FileStorage file: {msg[:160]}", source=src) from None
    if not fs.isOpened():
        raise FileFormatError("not a readable OpenCV FileStorage file", source=src)
    mats, keys = [], []

    def take(node, key):
        if node.isSeq():
            for i in range(node.size()):
                take(node.at(i), f"{key}[{i}]")
            return
        m = node.mat() if node.isMap() else None
        if m is None:
            return
        m = np.asarray(m, float)
        if m.ndim == 2 and m.shape in ((4, 4), (3, 4)):
            mats.append(m[None]), keys.append(key)
        elif m.ndim == 2 and m.shape[1] == 4 and m.shape[0] % 4 == 0:
            mats.append(m.reshape(-1, 4, 4)), keys.extend(f"{key}[{i}]" for i in range(m.shape[0] // 4))
        elif m.ndim == 2 and m.shape[1] in (16, 12):
            mats.append(m.reshape(len(m), -1, 4)), keys.extend(f"{key}[{i}]" for i in range(len(m)))

    root = fs.root()
    for key in root.keys():
        take(root.getNode(key), key)
    fs.release()
    if not mats:
        raise FileFormatError("an OpenCV FileStorage pose file needs 4x4 (or 3x4) matrices, a sequence of them, "
                              "or one (4N x 4) / (N x 16) matrix; found none", source=src)
    shapes = {m.shape[1] for m in mats}
    if len(shapes) > 1:
        raise FileFormatError("mixes 4x4 and 3x4 matrices", source=src)
    M = np.concatenate(mats)
    if not np.all(np.isfinite(M)):
        k = int(np.flatnonzero(~np.isfinite(M).all(axis=(1, 2)))[0])
        raise FileFormatError(f"matrix {keys[k]}: a value is not finite", source=src)
    R, p = _from_matrices(M, src, lambda k: f"matrix {keys[k]}")
    span = keys[0] if len(keys) == 1 else f"{keys[0]} ... {keys[-1]}"
    return PoseList(_transforms(R, p), None, False, src,
                    form=f"OpenCV FileStorage: {len(keys)} {M.shape[1]}x4 matrices ({span}, m)")


def load_poses(path, *, strict_times: bool = True) -> PoseList:
    """Read a pose list (module docstring for the formats); SI units out; :attr:`PoseList.form` says which form.

    ``strict_times=False`` keeps timestamps that do not increase (a recorded stream's repeats and jumps back)
    for the caller to drop and count (``robocal.handeye.clock.clean_stamps``); by default they are an error.
    """
    from robocal.io._load import Document
    from robocal.validation import check_rotation_matrix

    path = Path(path)
    src = str(path)
    suffix = path.suffix.lower()
    if suffix in (".csv", ".txt", ".tum"):
        return _load_table(path, src, strict_times)
    if suffix == ".xml":
        return _load_filestorage(path, src)
    if suffix not in (".yaml", ".yml", ".json"):
        raise FileFormatError(f"a pose file is .csv/.txt/.tum, .yaml/.yml/.json or an OpenCV .xml, got "
                              f"{path.suffix or 'no suffix'!r}", source=src)
    text = _read_text(path, src)
    if text.lstrip().startswith("%YAML") or "!!opencv-matrix" in text:
        return _load_filestorage(path, src)
    data = _parse_text(text, suffix, src)
    if isinstance(data, list):                  # a bare list of entries
        doc = Document({"units": {"length": "m", "angle": "rad", "time": "s"}, "poses": data}, src)
        form = "a YAML list of poses (no units: m, rad, s)"
    else:
        doc = parse_document(text, suffix=suffix, source=src)
        form = "YAML 'poses:'"
    raw = doc.raw("poses")
    if not isinstance(raw, list):
        raise FileFormatError(f"field 'poses' must be a list, got {type(raw).__name__}", source=src)
    if not raw:
        raise FileFormatError("field 'poses' is empty", source=src)
    Rs, ps, ts, kinds = [], [], [], set()
    for k, v in enumerate(raw):
        if isinstance(v, list):                     # a bare 4x4 (or 3x4) matrix, metres
            M = np.asarray(v, float) if _numeric_matrix(v) else None
            if M is None or M.shape not in ((4, 4), (3, 4)) or not np.all(np.isfinite(M)):
                raise FileFormatError(f"poses[{k}]: expected a mapping (p + q / R / rotvec, or T) or a finite 4x4 "
                                      f"matrix, got {str(v)[:40]}", source=src)
            R, p = _from_matrices(M[None], src, lambda _, k=k: f"poses[{k}]")
            Rs.append(R[0]), ps.append(p[0]), kinds.add("4x4")
            continue
        if not isinstance(v, dict):
            raise FileFormatError(f"poses[{k}]: expected a mapping (p + q / R / rotvec, or T) or a 4x4 matrix, "
                                  f"got {str(v)[:40]!r}", source=src)
        it = Document(v, doc.source, f"poses[{k}]", dict(doc.units), doc.units_error)
        if "T" in it:
            M = it.array("T")
            if M.shape not in ((4, 4), (3, 4)):
                raise FileFormatError(f"poses[{k}].T: expected a 4x4 matrix, got shape {M.shape}", source=src)
            R, p = _from_matrices(M[None], src, lambda _, k=k: f"poses[{k}].T")
            unit = it.units.get("length")          # the document's length unit applies to T's translation
            Rs.append(R[0]), ps.append(to_si(p[0], unit, "length") if unit else p[0]), kinds.add("T")
        else:
            ps.append(it.array("p", kind="length", shape=(3,)))
            if "q" in it:
                Rs.append(_rotations_from_quats(it.array("q", shape=(4,))[None], src,
                                                lambda _, k=k: f"poses[{k}].q")[0])
                kinds.add("p + q")
            elif "R" in it:
                try:
                    Rs.append(check_rotation_matrix(it.array("R", shape=(3, 3)), f"poses[{k}].R", atol=1e-4))
                except InputError as exc:
                    raise FileFormatError(exc.message, source=src) from None
                kinds.add("p + R")
            elif "rotvec" in it:
                from robocal.geometry import matrix_from_rotvec

                Rs.append(matrix_from_rotvec(it.array("rotvec", kind="angle", shape=(3,))))
                kinds.add("p + rotvec")
            else:
                raise FileFormatError(f"poses[{k}] needs 'q' (qx, qy, qz, qw), 'R', 'rotvec' or 'T'", source=src)
        if "t" in it:
            ts.append(it.float("t", kind="time"))
    if ts and len(ts) != len(ps):
        raise FileFormatError("either every pose has a timestamp 't' or none", source=src)
    t = np.array(ts) if ts else None
    if t is not None and strict_times:
        _check_times(t, src, lambda k: f"poses[{k}].t")
    return PoseList(_transforms(np.array(Rs), np.array(ps)), t, False, src,
                    form=f"{form}, {len(ps)} entries ({', '.join(sorted(kinds))}){', timed' if t is not None else ''}")


def _numeric_matrix(v) -> bool:
    try:
        a = np.asarray(v, float)
    except (TypeError, ValueError):
        return False
    return a.ndim == 2


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
