"""Input files of the projector rig (YAML/JSON with explicit units, CSV with units in headers).

Calibration input (``robocal projector calibrate INPUT``)::

    units: {length: cm, angle: deg}          # document defaults per kind
    projector:                               # the head (seed Table 1)
      name: A
      H: 290                                 # floor at z_0 = -H
      d1: 12                                 # optional, default 0
      d2: 5                                  # optional
      offsets: [0, 0]                        # joint zero offsets, optional
      tilt_limit: 75                         # optional (angle)
      rate_limits: {value: [90, 90], unit: deg/s}   # optional
      pan_range: [-270, 270]                 # optional: unwrapped pan stops (angle); default endless
      tilt_min: -75                          # optional: lowest tilt (angle, >= -tilt_limit); default 0
    points:
      world: [[0, 0], [60, 60], [0, 90]]     # ^W P_i, (N, 2) or (N, 3) with z = 0
      projector: [[240, -90, -290], ...]     # ^0 P_i (N, 3) -- or:
      joint_angles: [[t1, t2], ...]          # theta_i (N, 2) -- or:
      file: points.csv                       # columns x, y [length], theta1, theta2 [angle]
    noise: {value: 5, unit: mm}              # optional: world measurement sigma
    joint_noise: {value: [0.05, 0.05], unit: deg}   # optional: encoder sigma (pan, tilt); needs noise
    tilt_offset_limit: {value: 5, unit: deg} # optional: bound on an estimated tilt offset (default 5 deg)
    methods: [seed, closed_form, nonlinear]  # optional
    estimate: [h, tilt_offset]               # optional extra unknowns (needs joint angles)
    seed: {alpha: 0.5, order: [2, 1, 0]}     # optional: eq. (29) step, eq. (12) roles
    strict: false                            # true: inconsistent distances are an error
    truth: {...}                             # optional (written by `simulate`): true projector

Path input (``robocal projector path INPUT``)::

    units: {length: m, angle: deg, speed: m/s, time: s, angular_rate: deg/s}
    projectors: [ {name, H, d1, ..., yaw, t_0_W: [x, y, z]} | {name, H, ..., result: result.json}, ...]
                                             # t_0_W z must be -H; 'result' or yaw/t_0_W, not both
    walls: [[x0, y0, x1, y1], ...]           # optional, floor-to-ceiling partitions
    path: {waypoints: [[x, y], ...], speed: 0.3, dt: 0.1}   # or {file: path.csv} with t, x, y
                                             # dt optional (default 0.05 s)

Unknown keys in a ``projector`` / ``projectors[]`` mapping, at the top of a path
input and in its ``path`` mapping are an error naming the key (a misspelt
optional key such as ``tilt_mim`` would otherwise silently take its default).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robocal.errors import FileFormatError, RobocalError, SingularConfigurationError
from robocal.geometry import matrix_from_angle
from robocal.io import Document, load_csv, load_document, load_result
from robocal.rigs.projector.model import HORIZON_TOL, ProjectorModel

__all__ = ["CalibrationInput", "load_calibration_input", "projector_from_doc", "projector_to_yaml",
           "extrinsics_from_result", "load_path_input", "PathInput"]


#: Keys of a ``projector:`` mapping; with extrinsics also :data:`EXTRINSIC_KEYS`.
PROJECTOR_KEYS = ("name", "H", "d1", "d2", "offsets", "tilt_limit", "rate_limits", "pan_range", "tilt_min", "units")
EXTRINSIC_KEYS = ("yaw", "R_0_W", "t_0_W", "result")
PATH_INPUT_KEYS = ("units", "projectors", "walls", "path")
PATH_KEYS = ("units", "waypoints", "speed", "dt", "file")


def extrinsics_from_result(res, *, source: str) -> dict:
    """``{R_0_W, t_0_W[, d1_from_h, offsets]}`` of a projector result: its pose ``T_0_W`` (``robocal.result/2``).

    A ``robocal.result/1`` file of this rig wrote ``R_0_W`` and ``t_0_W`` as
    separate keys; it is still read. ``h`` (when estimated) is returned as
    ``h`` for the caller to turn into ``d1 = H - h``.
    """
    if res.rig != "projector":
        raise FileFormatError(f"result of rig {res.rig!r}, expected 'projector'", source=source)
    e = res.estimate
    try:
        if "T_0_W" in res.poses:
            T = res.pose("T_0_W").T
            out = {"R_0_W": T[:3, :3], "t_0_W": T[:3, 3]}
        else:  # robocal.result/1
            out = {"R_0_W": np.asarray(e["R_0_W"], dtype=float), "t_0_W": np.asarray(e["t_0_W"], dtype=float)}
        if "h" in e:
            out["h"] = float(e["h"])
        if "offsets" in e:
            out["offsets"] = tuple(float(v) for v in e["offsets"])
    except (KeyError, TypeError, ValueError) as exc:
        raise FileFormatError(f"not a projector result (missing/invalid {exc})", source=source) from None
    return out


def projector_from_doc(doc: Document, *, extrinsics: bool = False) -> ProjectorModel:
    """A :class:`ProjectorModel` from a ``projector:`` mapping (units from the document)."""
    doc.require_known_keys(PROJECTOR_KEYS + (EXTRINSIC_KEYS if extrinsics else ()))
    kw = dict(H=doc.float("H", kind="length", positive=True))
    kw["d1"] = doc.float("d1", kind="length", default=0.0)
    kw["d2"] = doc.float("d2", kind="length", default=0.0)
    if "offsets" in doc:
        kw["offsets"] = tuple(doc.array("offsets", kind="angle", shape=(2,)))
    if "tilt_limit" in doc:
        kw["tilt_limit"] = doc.float("tilt_limit", kind="angle")
    if "rate_limits" in doc:
        kw["rate_limits"] = tuple(doc.array("rate_limits", kind="angular_rate", shape=(2,)))
    if "pan_range" in doc:
        kw["pan_range"] = tuple(doc.array("pan_range", kind="angle", shape=(2,)))
    if "tilt_min" in doc:
        kw["tilt_min"] = doc.float("tilt_min", kind="angle")
    kw["name"] = str(doc.raw("name", "projector"))
    if extrinsics:
        both = [k for k in ("yaw", "R_0_W", "t_0_W") if k in doc]
        if "result" in doc:
            if both:
                raise doc.error("result", f"give either 'result' or the extrinsics {both}, not both (which one "
                                          f"counts?)")
            res = load_result(doc.path("result"))
            try:
                x = extrinsics_from_result(res, source=str(doc.path("result")))
            except FileFormatError as exc:
                raise doc.error("result", exc.message) from None
            kw["R_0_W"], kw["t_0_W"] = x["R_0_W"], x["t_0_W"]
            if "h" in x:
                kw["d1"] = kw["H"] - x["h"]
            if "offsets" in x:
                kw["offsets"] = x["offsets"]
        else:
            if "yaw" in doc:
                kw["R_0_W"] = matrix_from_angle("z", doc.float("yaw", kind="angle"))
            elif "R_0_W" in doc:
                kw["R_0_W"] = doc.array("R_0_W", shape=(3, 3))
            kw["t_0_W"] = doc.array("t_0_W", kind="length", shape=(3,))
            R = kw.get("R_0_W", np.eye(3))
            # {0} sits H above the floor: with a level base (R about z only) t_z must be -H
            if abs(R[2, 2] - 1.0) < 1e-9 and abs(kw["t_0_W"][2] + kw["H"]) > 1e-6 * max(1.0, kw["H"]):
                raise doc.error("t_0_W", f"z = {kw['t_0_W'][2]:.6g} m must equal -H = {-kw['H']:.6g} m (the floor "
                                         f"is z_0 = -H; wrong unit or sign?)")
    try:
        return ProjectorModel(**kw)
    except RobocalError as exc:
        raise type(exc)(f"field '{doc.prefix or 'projector'}': {exc.message}", source=doc.source) from None


def projector_to_yaml(m: ProjectorModel, *, extrinsics: bool = False) -> dict:
    """A ``projector:`` mapping in mm / deg (what :func:`projector_from_doc` reads)."""
    d = {"name": m.name, "H": {"value": round(m.H * 1e3, 6), "unit": "mm"},
         "d1": {"value": round(m.d1 * 1e3, 6), "unit": "mm"}, "d2": {"value": round(m.d2 * 1e3, 6), "unit": "mm"},
         "offsets": {"value": [float(np.degrees(o)) for o in m.offsets], "unit": "deg"},
         "tilt_limit": {"value": float(np.degrees(m.tilt_limit)), "unit": "deg"},
         "rate_limits": {"value": [float(np.degrees(r)) for r in m.rate_limits], "unit": "deg/s"}}
    if m.pan_range is not None:
        d["pan_range"] = {"value": [float(np.degrees(r)) for r in m.pan_range], "unit": "deg"}
    if m.tilt_min != 0.0:
        d["tilt_min"] = {"value": float(np.degrees(m.tilt_min)), "unit": "deg"}
    if extrinsics:
        d["yaw"] = {"value": float(np.degrees(math.atan2(m.R_0_W[1, 0], m.R_0_W[0, 0]))), "unit": "deg"}
        d["t_0_W"] = {"value": [float(v * 1e3) for v in m.t_0_W], "unit": "mm"}
    return d


@dataclass
class CalibrationInput:
    source: str
    model: ProjectorModel
    points_W: np.ndarray
    points_0: np.ndarray | None
    theta: np.ndarray | None
    sigma: float | None
    methods: tuple
    estimate: tuple
    seed_alpha: float
    seed_order: list | None
    strict: bool
    truth: ProjectorModel | None
    files: list
    joint_noise: tuple | None = None
    tilt_offset_limit: float | None = None


def load_calibration_input(path) -> CalibrationInput:
    """Read and validate a calibration input file (see the module docstring)."""
    doc = load_document(path)
    model = projector_from_doc(doc.sub("projector"))
    pts = doc.sub("points")
    files = [path]
    p0 = th = None
    if "file" in pts:
        csv_path = pts.path("file")
        files.append(csv_path)
        tab = load_csv(csv_path, required=("x", "y"))
        pw = np.column_stack([tab.column("x", kind="length"), tab.column("y", kind="length")])
        if "theta1" in tab and "theta2" in tab:
            th = np.column_stack([tab.column("theta1", kind="angle"), tab.column("theta2", kind="angle")])
        elif all(c in tab for c in ("x0", "y0", "z0")):
            p0 = np.column_stack([tab.column(c, kind="length") for c in ("x0", "y0", "z0")])
        else:
            raise FileFormatError("needs columns theta1, theta2 (angles) or x0, y0, z0 (projector frame)",
                                  source=str(csv_path))
    else:
        pw = pts.array("world", kind="length", shape=("N", None))
        if pw.shape[-1] not in (2, 3):
            raise pts.error("world", f"must have shape (N, 2) or (N, 3), got {tuple(pw.shape)}")
        if "joint_angles" in pts:
            th = pts.array("joint_angles", kind="angle", shape=("N", 2))
        elif "projector" in pts:
            p0 = pts.array("projector", kind="length", shape=("N", 3))
        else:
            raise pts.error("projector", "is missing: give 'projector' (^0P, (N, 3)) or 'joint_angles' ((N, 2))")
        n_other = (th if th is not None else p0).shape[0]
        if pw.shape[0] != n_other:
            raise pts.error("world", f"has {pw.shape[0]} points but the projector side has {n_other}")
    if th is not None:
        _check_joint_angles(th, model, pts.error if "file" not in pts else None, files[-1])
    sigma = doc.float("noise", kind="length", default=None)
    if sigma is not None and not sigma > 0:
        raise doc.error("noise", f"must be > 0, got {sigma:g}")
    joint_noise = None
    if "joint_noise" in doc:
        jn = doc.array("joint_noise", kind="angle", shape=(2,))
        if np.any(jn < 0):
            raise doc.error("joint_noise", f"must be >= 0 (pan, tilt), got {np.degrees(jn).tolist()} deg")
        if np.any(jn > 0) and sigma is None:
            raise doc.error("joint_noise", "needs 'noise' (the world measurement sigma) beside it: the two make "
                                           "each point's floor covariance")
        joint_noise = (float(jn[0]), float(jn[1]))
    tilt_offset_limit = None
    if "tilt_offset_limit" in doc:
        tilt_offset_limit = doc.float("tilt_offset_limit", kind="angle", positive=True)
        if not tilt_offset_limit < math.pi / 2:
            raise doc.error("tilt_offset_limit", f"must be below 90 deg, got {math.degrees(tilt_offset_limit):g} deg")
    methods = doc.raw("methods", ["seed", "closed_form", "nonlinear"])
    estimate = doc.raw("estimate", [])
    for key, val in (("methods", methods), ("estimate", estimate)):
        if not isinstance(val, list) or not all(isinstance(v, str) for v in val):
            raise doc.error(key, f"must be a list of names, got {val!r}")
    seed = doc.sub("seed", {})
    alpha = seed.float("alpha", default=0.5)
    order = seed.raw("order", None)
    if order is not None and (not isinstance(order, list) or not all(isinstance(i, int) for i in order)):
        raise seed.error("order", f"must be a list of point indices, got {order!r}")
    truth = projector_from_doc(doc.sub("truth"), extrinsics=True) if "truth" in doc else None
    return CalibrationInput(str(path), model, pw, p0, th, sigma, tuple(methods), tuple(estimate), alpha, order,
                            doc.bool("strict", default=False), truth, files, joint_noise, tilt_offset_limit)


def _check_joint_angles(th: np.ndarray, model: ProjectorModel, field_error, csv_path) -> None:
    """Joint angles whose tilt (with its zero offset) reaches the horizon cannot come from a floor spot.

    The usual cause is an angle unit mix-up (degrees declared as rad turn 55 deg into 55 rad), so the
    message says so and names the row.
    """
    tilt = th[:, 1] + model.offsets[1]
    bad = np.flatnonzero(np.cos(tilt) <= HORIZON_TOL)
    if bad.size == 0:
        return
    k = int(bad[0])
    pan_as_tilt = np.abs(th[:, 0] + model.offsets[1]) <= model.tilt_limit
    if np.all(pan_as_tilt):  # the pan column would be valid tilts: the columns are swapped, not the unit
        msg = (f"`points.joint_angles` columns look swapped (tilt, pan instead of pan, tilt): row {k} (0-based) has "
               f"tilt theta2 = {math.degrees(th[k, 1]):.6g} deg, at or beyond the horizon ({bad.size} such row(s)), "
               f"while every theta1 is within the tilt limit; give the columns as pan, tilt")
    else:
        msg = (f"row {k} (0-based): tilt theta2 = {th[k, 1]:.6g} rad (= {math.degrees(th[k, 1]):.6g} deg) puts the beam "
               f"at or above the horizon, so the spot never reaches the floor ({bad.size} such row(s)); are the angles "
               f"in the declared unit (degrees declared as rad?)")
    if field_error is not None:
        raise field_error("joint_angles", msg, SingularConfigurationError)
    raise SingularConfigurationError(f"columns theta1, theta2: {msg}", source=str(csv_path))


@dataclass
class PathInput:
    source: str
    projectors: list
    walls: np.ndarray
    t: np.ndarray
    points: np.ndarray
    velocity: np.ndarray | None
    files: list


def load_path_input(path) -> PathInput:
    """Read a path-planning input file (see the module docstring)."""
    from robocal.rigs.projector.path import sample_polyline

    doc = load_document(path)
    doc.require_known_keys(PATH_INPUT_KEYS)
    projs = [projector_from_doc(d, extrinsics=True) for d in doc.items_list("projectors")]
    if not projs:
        raise doc.error("projectors", "must list at least one projector")
    walls = doc.array("walls", kind="length", shape=("W", 4), default=np.zeros((0, 4)))
    pth = doc.sub("path")
    pth.require_known_keys(PATH_KEYS)
    files = [path]
    if "file" in pth:
        f = pth.path("file")
        files.append(f)
        tab = load_csv(f, required=("t", "x", "y"))
        t = tab.column("t", kind="time")
        pts = np.column_stack([tab.column("x", kind="length"), tab.column("y", kind="length")])
        vel = None
    else:
        wp = pth.array("waypoints", kind="length", shape=("M", 2))
        speed = pth.float("speed", kind="speed", positive=True)
        dt = pth.float("dt", kind="time", default=0.05, positive=True)
        try:
            t, pts, vel = sample_polyline(wp, speed, dt)
        except RobocalError as exc:
            raise pth.error("waypoints", exc.message, type(exc)) from None
    return PathInput(str(path), projs, walls, t, pts, vel, files)
