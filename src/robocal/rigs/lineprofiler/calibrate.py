"""The rig's calibration as library calls: input file -> FPDP -> geometric refinement (or MCT).

:func:`load_input` reads and checks an input YAML and the files it names,
:func:`calibrate_input` calibrates it, :func:`to_result` makes the result
(:mod:`.result`; its report: :mod:`.report`); :func:`calibrate_file` is the
three in one call.

Input (YAML, units stated)::

    units: {length: mm, angle: deg}
    sphere_radius: 25.4
    arm: p1r2p3                 # or {convention: modified, joint_types: PRP, rows: [[alpha, a, theta, d], ...]}
    profiles: fpdp_profiles.csv # see robocal.rigs.lineprofiler.io
    robot_poses: poses.csv      # optional: T_W_E with timestamps, when profiles carry 't' instead of q
    sign: auto                  # or +1 / -1: side of the laser plane the sphere centre is on
    joint_sigma: [0.02, 0.02, 0.02]  # optional: read-out noise per joint (length unit for prismatic,
                                     # angle unit for revolute joints); the refinement then models it

``method: mct`` selects the multi-coordinate-transformation method (seed 004
§3, needs a laser tracker and a standard block; see
``examples/lineprofiler/mct_input.yaml``)::

    method: mct
    units: {length: mm, angle: deg}
    arm: p1r2p3                  # the last two joints must be R2 then P3
    tracker:
      arc: mct_arc.csv           # ball centres while R2 turns (q1..qn and x, y, z in the tracker frame)
      line: mct_line.csv         # ball centres while P3 slides
      block_faces: mct_block.csv # face (0, 1, 2), x, y, z: points probed on the block's corner faces
      sigma: 0.01                # optional, per axis; default: pooled from the arc, line and face fits
    heights: {h0: 40.0, h1: 85.0, sigma: 0.02}  # ball centre / frame 2's origin above P3's top face
    arm_sigma: {length: 0.3, angle: 0.1}        # optional: uncertainty of P3's D-H row (default: exact)
    block_size: [50, 50, 50]
    scan: mct_scan.csv           # profiles of the block corner during a P3 stroke (profile, x, z, q1..qn)
    encoder_sigma: 0.005         # optional: P3 read-out noise of each scan profile (default 0.005 mm; 0: exact)

The block scan's reference pose is its first profile's joint values.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal.errors import FileFormatError, InputError
from robocal.io import hash_inputs, load_document
from robocal.kinematics import DHChain
from robocal.progress import progress
from robocal.resources import require_memory
from robocal.rigs.lineprofiler.fpdp import FPDPResult, fpdp_calibrate
from robocal.rigs.lineprofiler.io import (
    interpolate_poses,
    load_block_faces_csv,
    load_poses,
    load_profiles_csv,
    load_tracker_csv,
)
from robocal.rigs.lineprofiler.mct import ENCODER_SIGMA, MCTResult, mct_calibrate
from robocal.rigs.lineprofiler.model import p1r2p3_chain
from robocal.rigs.lineprofiler.refine import RefineResult, refine_sphere

__all__ = ["PoseTable", "SphereInput", "MCTInput", "load_arm", "load_input", "calibrate_input", "calibrate_file",
           "calibrate_sphere", "load_mct_file", "result_from", "to_result"]


class PoseTable:
    """Stands in for a chain when end-effector poses are given directly: ``q`` is the pose index."""

    dof = 1

    def __init__(self, T_W_E):
        self.T = np.asarray(T_W_E, float)

    def check_q(self, q):
        return np.asarray(q, float)

    def fk(self, q):
        return self.T[np.asarray(q, int)[..., 0]]


def load_arm(doc) -> DHChain:
    """``arm: p1r2p3`` or a D-H table mapping (angles in the document's angle unit, lengths in its length unit)."""
    if "arm" not in doc or doc.raw("arm") == "p1r2p3":
        return p1r2p3_chain()
    arm = doc.sub("arm")
    conv = arm.str("convention", default="modified", choices=("modified", "standard"))
    types = arm.str("joint_types")
    rows = arm.array("rows", shape=(None, 4))
    from robocal.io import to_si

    au = doc.units.get("angle", "rad")
    lu = doc.units.get("length", "m")
    rows = np.column_stack([to_si(rows[:, 0], au), to_si(rows[:, 1], lu), to_si(rows[:, 2], au),
                            to_si(rows[:, 3], lu)])
    if len(types) != len(rows):
        raise FileFormatError(f"arm.joint_types has {len(types)} letters but arm.rows has {len(rows)} rows",
                              source=doc.source)
    return DHChain.from_table(rows, convention=conv, joint_types=types)


@dataclass
class SphereCalibration:
    fpdp: FPDPResult
    refined: RefineResult
    q: np.ndarray
    profiles: list


#: FPDP residual RMS (sphere centres through the arm, m) of a plausible scan: above both this share of
#: the sphere radius and :data:`FPDP_FLOOR`. The example: 0.16 mm on R = 25.4 mm (0.6 %); a radius 10 %
#: off gives 6.6 mm, a diameter given as the radius 23.6 mm, R in m read as mm 3.96 mm (every circle
#: larger than the sphere), R in mm read as m 14 m.
FPDP_MAX_SHARE = 0.05
#: FPDP residual (m) below which the radius is never judged implausible (arm accuracy of a large arm)
FPDP_FLOOR = 1e-3


def judge_sphere(q, profiles, chain, sphere_radius: float, f: FPDPResult, *, sign="auto", accept: bool = False,
                 radius_from: str = "`sphere_radius`", profiles_from: str = "the profiles", source: str | None = None):
    """Judge the sphere radius against the profiles through FPDP's residual; name the slip when implausible.

    The sphere centre each profile gives (its circle and ``sqrt(R^2 - r_c^2)`` off the laser plane)
    must be one point through the arm: with a wrong radius or wrongly scaled profile points the centres
    scatter by a share of R (:data:`FPDP_MAX_SHARE`). Slips tried (each one more FPDP, < 1 s on the
    example): the radius x1000, /1000, /2 (a diameter), the profile points /1000, x1000.

    Returns a Diagnostic (accepted) or None; raises :class:`~robocal.errors.ImplausibleInputError`.
    """
    from robocal.plausibility import Slip, check_slips

    R = float(sphere_radius)
    if not (f.rms > FPDP_MAX_SHARE * R and f.rms > FPDP_FLOOR):
        return None

    def refit(r=R, k=1.0):
        pr = profiles if k == 1.0 else [np.asarray(p) * k for p in profiles]
        g = fpdp_calibrate(q, pr, chain, r, sign=sign)
        ok = not (g.rms > FPDP_MAX_SHARE * r and g.rms > FPDP_FLOOR)
        return 1e3 * g.rms if ok else np.nan

    slips = [Slip("radius_mm_as_m", f"{radius_from} looks like mm, not m", "with /1000", lambda: refit(r=R / 1e3)),
             Slip("radius_m_as_mm", f"{radius_from} looks like m, not mm", "with x1000", lambda: refit(r=R * 1e3)),
             Slip("radius_is_diameter", f"{radius_from} looks like the diameter", "with /2",
                  lambda: refit(r=R / 2)),
             Slip("profiles_mm_as_m", f"x, z of {profiles_from} look like mm, not m", "with /1000",
                  lambda: refit(k=1e-3)),
             Slip("profiles_m_as_mm", f"x, z of {profiles_from} look like m, not mm", "with x1000",
                  lambda: refit(k=1e3))]
    return check_slips(what="FPDP residual", residual=1e3 * f.rms, unit="mm", plausible=False,
                       reason=(f"the sphere centres the profiles give scatter by {1e3 * f.rms:.3g} mm RMS through the "
                               f"arm, {100 * f.rms / R:.3g} % of the {1e3 * R:.4g} mm sphere radius (plausible: <= "
                               f"{100 * FPDP_MAX_SHARE:g} % or {1e3 * FPDP_FLOOR:g} mm): a wrong radius or arm model?"),
                       slips=slips, accept=accept, source=source)


#: tracker length along P3's line / P3's stroke (and the arc's swept angle / R2's turn) of plausible
#: MCT files: 1 up to tracker and encoder errors (the example: 1.0000 and 1.000); mm read as m is 1000,
#: deg read as rad 57.3
MCT_RATIO_RANGE = (0.8, 1.25)


def _mct_ratios(data):
    """(tracker length along the line / P3 stroke, arc angle / R2 turn) of MCT data (SI units)."""
    from robocal.geometry import fit_circle_3d, fit_line

    j3 = int(np.argmax(np.ptp(data.q_line, axis=0)))           # the joint that moves along the line
    s = (data.line_T - data.line_T.mean(axis=0)) @ fit_line(data.line_T).direction
    k_line = abs(np.polyfit(data.q_line[:, j3], s, 1)[0]) if np.ptp(data.q_line[:, j3]) > 0 else np.nan
    j2 = int(np.argmax(np.ptp(data.q_arc, axis=0)))
    arc = fit_circle_3d(data.arc_T)
    lo, hi = np.argmin(data.q_arc[:, j2]), np.argmax(data.q_arc[:, j2])
    a, b = data.arc_T[lo] - arc.centre, data.arc_T[hi] - arc.centre
    swept = np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b)
    turn = np.ptp(data.q_arc[:, j2])
    return float(k_line), float(swept / turn) if turn > 0 else np.nan


def judge_mct(data, *, files: dict, accept: bool = False, source: str | None = None):
    """Judge MCT tracker readings against the joint readings; name the slip when implausible.

    Along P3's line the ball moves as far as P3 slides; around R2's arc it turns as far as R2 turns.
    A tracker file in m under an ``[mm]`` header (or joints the other way) makes the first ratio 1000
    or 0.001, joint angles in rad under ``[deg]`` the second 0.017 (:data:`MCT_RATIO_RANGE`). Cheap:
    one line and one circle fit. ``files``: ``{"line": name, "arc": name}`` for the message.
    """
    from dataclasses import replace as _replace

    from robocal.plausibility import Slip, check_slips

    try:
        k_line, k_arc = _mct_ratios(data)
    except (InputError, ValueError, np.linalg.LinAlgError):
        return None                             # degenerate files: the calibration's own errors name them
    lo, hi = MCT_RATIO_RANGE

    def off(k):
        return 100 * (max(k, 1 / k) - 1) if np.isfinite(k) and k > 0 else np.inf

    out = None
    if not lo <= k_line <= hi:
        def line_with(T=1.0):
            k = _mct_ratios(_replace(data, line_T=data.line_T * T))[0]
            return off(k) if lo <= k <= hi else np.nan
        line, name = files.get("line", "the line file"), "P3 stroke"
        out = check_slips(
            what=f"mismatch of the tracker length and the {name}", residual=off(k_line), unit="%", plausible=False,
            reason=(f"along the line of {line} the tracker ball moves {k_line:.4g} x as far as the joint readings "
                    f"say P3 slides (plausible {lo:g}..{hi:g})"),
            slips=[Slip("tracker_mm_as_m", f"x, y, z of {line} look like mm, not m (or its P3 readings m, not mm)",
                        "with /1000", lambda: line_with(1e-3)),
                   Slip("tracker_m_as_mm", f"x, y, z of {line} look like m, not mm (or its P3 readings mm, not m)",
                        "with x1000", lambda: line_with(1e3))],
            accept=accept, source=source)
    if not lo <= k_arc <= hi and out is None:
        arc = files.get("arc", "the arc file")

        def arc_with(f):
            q = data.q_arc.copy()
            j2 = int(np.argmax(np.ptp(q, axis=0)))
            q[:, j2] *= f
            k = _mct_ratios(_replace(data, q_arc=q))[1]
            return off(k) if lo <= k <= hi else np.nan
        out = check_slips(
            what="mismatch of the tracker arc and the R2 turn", residual=off(k_arc), unit="%", plausible=False,
            reason=(f"around the arc of {arc} the tracker ball turns {k_arc:.4g} x as far as the joint readings "
                    f"say R2 turns (plausible {lo:g}..{hi:g})"),
            slips=[Slip("angle_rad_as_deg", f"the R2 readings of {arc} look like rad, not deg", "with rad -> deg",
                        lambda: arc_with(180 / np.pi)),
                   Slip("angle_deg_as_rad", f"the R2 readings of {arc} look like deg, not rad", "with deg -> rad",
                        lambda: arc_with(np.pi / 180))],
            accept=accept, source=source)
    return out


def calibrate_sphere(q, profiles, chain, sphere_radius: float, *, sign="auto", joint_sigma=None,
                     accept_implausible: bool = False, names: dict | None = None) -> SphereCalibration:
    """FPDP (linear, seed eqs. 3-4) then the geometric refinement on every point.

    ``joint_sigma`` (per joint, m or rad): noise of the joint readings; the
    refinement then estimates one joint correction per pose (see
    :func:`~.refine.refine_sphere`), otherwise it takes the readings as exact.
    The radius is judged against the profiles first (:func:`judge_sphere`): an
    implausible one raises :class:`~robocal.errors.ImplausibleInputError` unless
    ``accept_implausible``; ``names`` (``radius_from``, ``profiles_from``, ``source``)
    name the input for that message.
    """
    f = fpdp_calibrate(q, profiles, chain, sphere_radius, sign=sign)
    d = judge_sphere(q, profiles, chain, sphere_radius, f, sign=sign, accept=accept_implausible, **(names or {}))
    if d is not None:
        f.warnings.insert(0, d)
    used = f.used
    hold = [k for k in f.undetermined if k.startswith("X.")]
    qu, pu = np.asarray(q)[used], [profiles[i] for i in used]
    g = refine_sphere(qu, pu, chain, sphere_radius, f.X, f.Q, hold=hold)
    if joint_sigma is not None:
        weak = [w for w in g.warnings if w.code == "weakly_determined"]
        g = refine_sphere(qu, pu, chain, sphere_radius, g.X, g.Q, hold=hold, joint_sigma=joint_sigma)
        g.warnings = weak + g.warnings
    for k in f.undetermined:  # Q.z etc. only determined given the held X component
        g.std[k] = None
    g.undetermined = tuple(sorted(set(g.undetermined) | set(f.undetermined)))
    return SphereCalibration(f, g, np.asarray(q), list(profiles))


@dataclass
class MCTCalibration:
    mct: MCTResult
    data: object
    chain: DHChain


def load_mct_file(doc, chain: DHChain):
    """The :class:`~.simulate.MCTData` of a ``method: mct`` input document, its files and the sigmas."""
    from robocal.rigs.lineprofiler.simulate import MCTData

    tr = doc.sub("tracker")
    arc_path, line_path, faces_path = tr.path("arc"), tr.path("line"), tr.path("block_faces")
    q_arc, arc_T = load_tracker_csv(arc_path, dof=chain.dof, joint_types=chain.joint_types)
    q_line, line_T = load_tracker_csv(line_path, dof=chain.dof, joint_types=chain.joint_types)
    for path, pts, need, what in ((arc_path, arc_T, 3, "a 3D circle needs 3 or more (9 or more over 20-60 deg "
                                   "of R2 recommended)"), (line_path, line_T, 2, "a line needs 2 or more "
                                                            "(9 or more recommended)")):
        if len(pts) < need:
            raise FileFormatError(f"{len(pts)} tracker reading(s): {what}", source=str(path))
    faces = load_block_faces_csv(faces_path)
    heights = doc.sub("heights")
    h0 = heights.float("h0", kind="length")
    h1 = heights.float("h1", kind="length")
    h_sigma = heights.float("sigma", kind="length", default=0.02e-3)
    t_sigma = tr.float("sigma", kind="length", default=None)
    for name, v in (("heights.sigma", h_sigma), ("tracker.sigma", t_sigma)):
        if v is not None and v < 0:
            raise FileFormatError(f"field '{name}' must be >= 0, got {v:g} m", source=doc.source)
    size = doc.array("block_size", kind="length", shape=(3,))
    if np.any(size <= 0):
        raise FileFormatError(f"field 'block_size' must hold 3 positive edge lengths, got {size.tolist()} m",
                              source=doc.source)
    scan_path = doc.path("scan")
    profiles, q_scan, _ = load_profiles_csv(scan_path, dof=chain.dof, joint_types=chain.joint_types)
    if q_scan is None:
        raise FileFormatError("the block scan needs the joint columns q1..qn of every profile", source=str(scan_path))
    if len(profiles) < 3:
        raise FileFormatError(f"the block scan has {len(profiles)} profiles; a P3 stroke of at least 3 (20 or more "
                              "recommended) is needed", source=str(scan_path))
    data = MCTData(q_arc, arc_T, q_line, line_T, h0, h1, q_scan[0].copy(), faces, tuple(size), q_scan[:, -1],
                   profiles)
    enc_sigma = doc.float("encoder_sigma", kind="length", default=ENCODER_SIGMA)
    if not (np.isfinite(enc_sigma) and enc_sigma >= 0):
        raise FileFormatError(f"field 'encoder_sigma' must be >= 0 (P3 read-out noise per scan profile), "
                              f"got {enc_sigma:g} m", source=doc.source)
    dh_sigma = (0.0, 0.0)
    if "arm_sigma" in doc:
        arm_sigma = doc.sub("arm_sigma")
        dh_sigma = (arm_sigma.float("length", kind="length", default=0.0),
                    arm_sigma.float("angle", kind="angle", default=0.0))
        if min(dh_sigma) < 0:
            raise FileFormatError(f"field 'arm_sigma' must hold lengths/angles >= 0, got {dh_sigma}",
                                  source=doc.source)
    return data, [arc_path, line_path, faces_path, scan_path], t_sigma, h_sigma, dh_sigma, enc_sigma


#: peak working memory per profile point of ``calibrate_file`` (bytes): 1.0 GB for 10^6 points in 16
#: profiles (``/usr/bin/time -f %M robocal lineprofiler calibrate``, docs/rigs/lineprofiler.md), rounded up
_BYTES_PER_POINT = 1200


def refine_memory(n_points: int, n_profiles: int, dof: int = 0) -> float:
    """Estimated peak bytes of :func:`calibrate_sphere` on ``n_points`` points in ``n_profiles`` profiles.

    ``dof`` > 0: with ``joint_sigma``, whose refinement hands the core a dense Jacobian of
    ``n_points x (9 + n_profiles dof)`` (it and ~3 working copies: SVD, scaling) plus the prior's
    ``(n_profiles dof)^2`` identity: this grows with points x profiles, the one term here that is not
    linear in the data (10^6 points in 2,000 profiles of a 3-joint arm: ~190 GB, refused before work).
    """
    base = float(n_points) * _BYTES_PER_POINT
    if dof <= 0:
        return base
    cols = n_profiles * dof
    return base + 4.0 * 8.0 * n_points * cols + 8.0 * cols * cols


@dataclass
class SphereInput:
    """A ``method: fpdp`` input, read and checked: joint readings (or pose indices with a
    :class:`PoseTable`), profiles (m), the arm, the sphere radius (m), the side ``sign``, the joints'
    read-out noise (m / rad, or None), names for messages, and every file read (for the hashes)."""

    q: np.ndarray
    profiles: list
    chain: object
    sphere_radius: float
    sign: object
    joint_sigma: np.ndarray | None
    names: dict
    files: list


@dataclass
class MCTInput:
    """A ``method: mct`` input, read and checked (see :func:`load_mct_file`); ``files`` every file read."""

    data: object
    chain: DHChain
    tracker_sigma: float | None
    height_sigma: float
    dh_sigma: tuple
    encoder_sigma: float
    judge_files: dict
    source: str
    files: list


def _stages(desc: str, n: int, enabled: bool = True):
    """A stage bar on a terminal: ``tick()`` starts the next of ``n`` stages."""
    it = iter(progress(range(n), desc=desc, total=n, enabled=enabled))
    return lambda: next(it, None)


def load_input(path) -> SphereInput | MCTInput:
    """Read and check a ``calibrate`` input YAML (module docstring) and every file it names.

    Errors name the file (and field or row). For FPDP the refinement's memory is checked here,
    before any work (:func:`refine_memory`).
    """
    doc = load_document(path)
    chain = load_arm(doc)
    method = doc.str("method", default="fpdp", choices=("fpdp", "mct"))
    if method == "mct":
        data, files, t_sigma, h_sigma, dh_sigma, enc_sigma = load_mct_file(doc, chain)
        tr = doc.sub("tracker")
        return MCTInput(data, chain, t_sigma, h_sigma, dh_sigma, enc_sigma,
                        judge_files={"line": Path(tr.str("line")).name, "arc": Path(tr.str("arc")).name},
                        source=str(path), files=[Path(path), *files])
    R = doc.float("sphere_radius", kind="length", positive=True)
    prof_path = doc.path("profiles")
    # 10^6 profile points take minutes (read ~45 %, FPDP + refinement the rest): a stage bar on a terminal
    tick = _stages("lineprofiler: read profiles", 1)
    tick()
    profiles, q, t = load_profiles_csv(prof_path, dof=chain.dof, joint_types=chain.joint_types)
    files = [Path(path), prof_path]
    if "robot_poses" in doc:
        pose_path = doc.path("robot_poses")
        files.append(pose_path)
        T, tp = load_poses(pose_path)
        if t is not None and tp is not None:
            T = interpolate_poses(tp, T, t)
        elif len(T) != len(profiles):
            raise FileFormatError(f"{len(T)} robot poses but {len(profiles)} profiles and no timestamps to align "
                                  "them: counts must match", source=str(pose_path))
        chain, q = PoseTable(T), np.arange(len(T))[:, None]
    elif q is None:
        raise FileFormatError("profiles carry timestamps but no 'robot_poses' file is given", source=str(path))
    sign = doc.raw("sign", "auto")
    joint_sigma = None
    if "joint_sigma" in doc:
        if isinstance(chain, PoseTable):
            raise FileFormatError("'joint_sigma' needs joint readings and an arm model; with 'robot_poses' the "
                                  "end-effector poses are given directly: leave it out", source=doc.source)
        from robocal.io import to_si

        js = doc.array("joint_sigma", shape=(chain.dof,))
        au, lu = doc.units.get("angle", "rad"), doc.units.get("length", "m")
        joint_sigma = np.array([float(to_si(v, au if t == "revolute" else lu)) for v, t in zip(js, chain.joint_types)])
        if not (np.all(np.isfinite(joint_sigma)) and np.all(joint_sigma >= 0) and np.any(joint_sigma > 0)):
            raise FileFormatError(f"field 'joint_sigma' must hold {chain.dof} values >= 0, not all 0, got "
                                  f"{js.tolist()}", source=doc.source)
    n_points = sum(len(p) for p in profiles)
    require_memory(refine_memory(n_points, len(profiles), chain.dof if joint_sigma is not None else 0),
                   f"the refinement of {n_points:,} profile points in {len(profiles):,} profiles"
                   + (" with joint_sigma" if joint_sigma is not None else ""), source=str(prof_path))
    tick()
    return SphereInput(q, profiles, chain, R, sign, joint_sigma,
                       names={"radius_from": f"`sphere_radius` ({R * 1e3:.4g} mm as read)",
                              "profiles_from": Path(prof_path).name, "source": str(path)},
                       files=files)


def calibrate_input(inp: SphereInput | MCTInput, *, accept_implausible: bool = False, progress: bool = True,
                    **_) -> SphereCalibration | MCTCalibration:
    """Calibrate a loaded input: FPDP + geometric refinement (:func:`calibrate_sphere`) or MCT.

    ``accept_implausible``: go on (with an ``implausible_input`` warning) when the sphere radius or the
    tracker readings are implausible for the data (:func:`judge_sphere`, :func:`judge_mct`).
    """
    if isinstance(inp, MCTInput):
        judged = judge_mct(inp.data, files=inp.judge_files, accept=accept_implausible, source=inp.source)
        res = mct_calibrate(inp.data, inp.chain, tracker_sigma=inp.tracker_sigma, height_sigma=inp.height_sigma,
                            dh_sigma=inp.dh_sigma, encoder_sigma=inp.encoder_sigma)
        if judged is not None:
            res.warnings.insert(0, judged)
        return MCTCalibration(res, inp.data, inp.chain)
    tick = _stages("lineprofiler: FPDP + refinement", 1, enabled=progress)
    tick()
    cal = calibrate_sphere(inp.q, inp.profiles, inp.chain, inp.sphere_radius, sign=inp.sign,
                           joint_sigma=inp.joint_sigma, accept_implausible=accept_implausible, names=inp.names)
    tick()
    return cal


def calibrate_file(path, *, accept_implausible: bool = False) -> tuple[SphereCalibration | MCTCalibration, dict]:
    """Calibrate from an input YAML (FPDP + refinement, or ``method: mct``); returns it and the input hashes.

    :func:`load_input` then :func:`calibrate_input`.
    """
    inp = load_input(path)
    return calibrate_input(inp, accept_implausible=accept_implausible), hash_inputs(inp.files)


def result_from(cal: SphereCalibration | MCTCalibration, inputs=None):
    """The result file's content (:func:`robocal.rigs.lineprofiler.result.result_from`)."""
    from robocal.rigs.lineprofiler.result import result_from as _result_from

    return _result_from(cal, inputs)


def to_result(cal: SphereCalibration | MCTCalibration, inp: SphereInput | MCTInput | None = None):
    """The workflow's ``to_result`` step: :func:`result_from` with the content hashes of every file read."""
    return result_from(cal, hash_inputs(inp.files) if inp is not None else None)
