"""The rig's workflow as library calls: input file -> FPDP -> geometric refinement -> result + report.

Input (YAML, units stated)::

    units: {length: mm, angle: deg}
    sphere_radius: 25.4
    arm: p1r2p3                 # or {convention: modified, joint_types: PRP, rows: [[alpha, a, theta, d], ...]}
    profiles: fpdp_profiles.csv # see robocal.rigs.lineprofiler.io
    robot_poses: poses.csv      # optional: T_W_E with timestamps, when profiles carry 't' instead of q
    sign: auto                  # or +1 / -1: side of the laser plane the sphere centre is on
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal.errors import FileFormatError
from robocal.io import CalibrationResult, hash_inputs, load_document
from robocal.kinematics import DHChain
from robocal.report import Report, new_figure
from robocal.rigs.lineprofiler.fpdp import FPDPResult, fpdp_calibrate
from robocal.rigs.lineprofiler.io import interpolate_poses, load_poses, load_profiles_csv
from robocal.rigs.lineprofiler.model import p1r2p3_chain
from robocal.rigs.lineprofiler.refine import RefineResult, refine_sphere

__all__ = ["PoseTable", "load_arm", "calibrate_file", "calibrate_sphere", "result_from", "report_from"]


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


def calibrate_sphere(q, profiles, chain, sphere_radius: float, *, sign="auto") -> SphereCalibration:
    """FPDP (linear, seed eqs. 3-4) then the geometric refinement on every point."""
    f = fpdp_calibrate(q, profiles, chain, sphere_radius, sign=sign)
    used = f.used
    g = refine_sphere(np.asarray(q)[used], [profiles[i] for i in used], chain, sphere_radius, f.X, f.Q,
                      hold=[k for k in f.undetermined if k.startswith("X.")])
    for k in f.undetermined:  # Q.z etc. only determined given the held X component
        g.std[k] = None
    g.undetermined = tuple(sorted(set(g.undetermined) | set(f.undetermined)))
    return SphereCalibration(f, g, np.asarray(q), list(profiles))


def calibrate_file(path) -> tuple[SphereCalibration, dict]:
    """Run :func:`calibrate_sphere` on an input YAML; returns the calibration and the input hashes."""
    doc = load_document(path)
    chain = load_arm(doc)
    R = doc.float("sphere_radius", kind="length", positive=True)
    prof_path = doc.path("profiles")
    profiles, q, t = load_profiles_csv(prof_path, dof=chain.dof)
    files = [path, prof_path]
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
    return calibrate_sphere(q, profiles, chain, R, sign=sign), hash_inputs(files)


def result_from(cal: SphereCalibration, inputs=None) -> CalibrationResult:
    f, g = cal.fpdp, cal.refined
    und = set(g.undetermined)
    t = [None if f"X.t{c}" in und else float(g.X[i, 3]) for i, c in enumerate("xyz")]
    est = {"T_E_L.rotation": g.X[:3, :3].tolist(), "T_E_L.translation": t,
           "sphere_centre": [None if f"Q.{c}" in und else float(g.Q[i]) for i, c in enumerate("xyz")],
           "fpdp.translation": [None if f"X.t{c}" in und else float(f.X[i, 3]) for i, c in enumerate("xyz")],
           "fpdp.rotation": f.X[:3, :3].tolist()}
    std = {"T_E_L.rotvec": [g.std[f"X.r{c}"] for c in "xyz"], "T_E_L.translation": [g.std[f"X.t{c}"] for c in "xyz"],
           "sphere_centre": [g.std[f"Q.{c}"] for c in "xyz"]}
    return CalibrationResult(
        rig="lineprofiler", method="fpdp+geometric", estimate=est, std=std,
        units={"T_E_L.rotation": "1", "T_E_L.translation": "m", "sphere_centre": "m", "T_E_L.rotvec": "rad",
               "fpdp.translation": "m", "fpdp.rotation": "1"},
        residual_rms=g.rms, residual_unit="m", warnings=list(f.warnings) + list(g.warnings), inputs=inputs or {},
        diagnostics={"frames": "T_E_L: laser frame L -> end-effector frame E (hand-eye X)",
                     "undetermined": sorted(und), "fpdp_rank": f.rank, "fpdp_unknowns": f.n_unknowns,
                     "fpdp_rms_m": f.rms, "n_profiles_used": int(len(f.used)), "n_points": g.n_points,
                     "noise_sigma_m": g.sigma, "signs": f.signs.tolist()})


def report_from(result: CalibrationResult, cal: SphereCalibration | None = None, *, extra_sections=()) -> Report:
    rep = Report("lineprofiler: hand-eye calibration of a line laser", subtitle=result.method)
    s = rep.section("Estimate")
    und = result.diagnostics.get("undetermined", [])
    s.status(not und, "all components determined" if not und else
             f"not determined by these poses: {', '.join(und)} (no value reported)")
    s.parameters({k: v for k, v in result.estimate.items() if not k.startswith("fpdp.")}, result.std, result.units)
    s.diagnostics(result.warnings)
    if cal is not None:
        fig, ax = new_figure(1, 2, size=(10, 3.4))
        r = cal.refined.residuals * 1e6
        ax[0].hist(r, bins=60)
        ax[0].set_xlabel("point-to-sphere residual [um]")
        ax[1].bar(np.arange(len(cal.refined.per_profile_rms)), cal.refined.per_profile_rms * 1e6)
        ax[1].set_xlabel("profile")
        ax[1].set_ylabel("RMS [um]")
        rep.section("Residuals").figure(fig, "geometric refinement residuals (all raw points)")
        rows = [{"profile": int(c.index), "x_c [mm]": 1e3 * c.centre[0], "z_c [mm]": 1e3 * c.centre[1],
                 "r_c [mm]": 1e3 * c.radius, "side": int(sg), "points": c.n_points}
                for c, sg in zip(cal.fpdp.cuts, cal.fpdp.signs)]
        rep.section("FPDP circle cuts (seed Table 1)").table(rows, digits=4)
    for sec in extra_sections:
        rep.extend([sec])
    return rep


def load_result_report(path) -> Report:
    from robocal.io import load_result

    return report_from(load_result(Path(path)))
