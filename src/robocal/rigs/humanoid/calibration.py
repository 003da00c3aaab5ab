"""The outcome of a humanoid calibration: estimates, offset tables, corrected URDF, result record.

:class:`HumanoidCalibration` holds what :func:`robocal.rigs.humanoid.calibrate.calibrate`
found (the solver's record, residuals, outliers, the gauge) and answers the
questions a robot framework asks of it: the per-joint offsets, the camera
mounting correction, the corrected URDF. :meth:`HumanoidCalibration.to_result`
writes the shared result record (``docs/results.md``) with every figure the
report and the printed summary need in ``diagnostics``, so that both are built
from the result alone (:func:`summary_text`, :func:`robocal.rigs.humanoid.report.build_report`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robocal.estimation import LSQResult
from robocal.io import CalibrationResult, to_jsonable
from robocal.rigs.humanoid.model import CAMERA_PARAMS, HumanoidModel
from robocal.rigs.humanoid.problem import present_corners
from robocal.rigs.humanoid.simulate import HumanoidDataset

__all__ = ["HumanoidCalibration", "parameter_rows", "summary_text", "rank_text", "rejection_text", "by_view_text", "SOLVER_FIELDS"]

#: The fields of the solver's record (:meth:`LSQResult.to_dict`) kept in ``diagnostics["solver"]``: what
#: the report's solver table shows (the residual arrays are kept per corner, see ``residuals_px``).
SOLVER_FIELDS = ("method", "loss", "jac_method", "status", "message", "iterations", "nfev", "cost", "rms",
                 "residual_variance", "dof", "rank", "free_labels", "condition_number", "outlier_sigma")

@dataclass
class HumanoidCalibration:
    """Outcome of :func:`calibrate`.

    Attributes
    ----------
    model : HumanoidModel
    data : HumanoidDataset
        The views used (views without a complete board removed).
    lsq : LSQResult
        The solver's record (covariance, std, correlations, warnings ...).
    params : ndarray, shape (P,)
        Full parameter vector at the solution (fixed ones at their start value).
    free : list of str
        Selected parameters (tied ones included).
    residuals : ndarray, shape (V, N, 2) [px]
        Predicted minus detected corners.
    view_rms : ndarray, shape (V,) [px]
    outlier_corners : list of (str, int)
        ``(view name, corner index)`` of the corners beyond ``outlier_sigma``.
    messages : list of str
        Dropped views and other notes.
    held : list of str
        The gauge: one parameter per null-space direction, held at its start value.
    undetermined : list of str
        Parameters with a null-space component (no value or std reported; ``held`` among them).
    rank, n_params : int
        Rank of the column-scaled Jacobian of the selected problem at the start, and its number
        of free parameters (tied ones counted once), before the gauge is held.
    two_pass : bool
        True when the corner noise was measured and a second LM pass run (``lsq`` is that pass).
    keep : ndarray of bool, shape (V, N)
        Corners used in the final solve: the present ones (not removed at detection) less those
        removed by ``calibrate(reject_outliers=True)``. ``residuals`` covers every corner (NaN for
        missing ones); RMS values, degrees of freedom and the residual variance are over the kept ones.
    rejected_corners : list of (str, int)
        ``(view name, corner index)`` removed as outliers before the re-solve.
    rejected_views : list of str
        Views removed whole (too many of their corners flagged).
    missing_corners : list of (str, int)
        ``(view name, corner index)`` absent from the data (NaN: removed at detection, see
        :func:`robocal.rigs.humanoid.detect.detect_views`), left out of their view.
    reject_outliers : bool
        Whether outlier rejection was asked for (it removes nothing when no corner is flagged).
    outlier_sigma : float
        The threshold [sigma] the corners were tested at (default of :func:`calibrate`: Bonferroni over
        the corners, :func:`robocal.estimation.outlier_sigma`).
    files : list of str
        Names of the files written beside the result (``offsets.yaml``, the corrected URDF), if any.
    """

    model: HumanoidModel
    data: HumanoidDataset
    lsq: LSQResult
    params: np.ndarray
    free: list
    residuals: np.ndarray
    view_rms: np.ndarray
    outlier_corners: list
    messages: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    corner_scores: np.ndarray | None = None
    corner_sigma: float = 0.3
    joint_resolution: float = 0.0
    first_iterations: int = 0
    held: list = field(default_factory=list)
    first_cost_history: np.ndarray | None = None
    undetermined: list = field(default_factory=list)
    rank: int | None = None
    n_params: int | None = None
    two_pass: bool = False
    keep: np.ndarray | None = None
    rejected_corners: list = field(default_factory=list)
    rejected_views: list = field(default_factory=list)
    missing_corners: list = field(default_factory=list)
    reject_outliers: bool = False
    outlier_sigma: float = 3.0
    files: list = field(default_factory=list)

    # -- queries -----------------------------------------------------------------------------
    @property
    def labels(self) -> list[str]:
        return self.model.parameter_labels()

    @property
    def unidentifiable(self) -> list[str]:
        """Selected parameters the data do not determine (no value is reported for them): those with
        a component in the Jacobian's null space (the gauge ``held`` is among them)."""
        bad = set(self.undetermined) | set(self.held) | set(self.lsq.unidentifiable)
        return [lab for lab in self.labels if lab in bad]

    @property
    def jacobian_rank(self) -> tuple[int, int]:
        """``(rank, number of free parameters)`` of the selected problem, before any gauge is held."""
        if self.rank is None:
            return self.lsq.rank, len(self.lsq.free_labels)
        return self.rank, self.n_params

    @property
    def correlations(self) -> list:
        """Strongest correlations among the determined parameters ``(a, b, r)`` (the ones of
        undetermined parameters depend on the gauge and mean nothing)."""
        bad = set(self.unidentifiable)
        return [(a, b, c) for a, b, c in self.lsq.correlations if a not in bad and b not in bad]

    def value(self, label: str) -> float | None:
        """Estimate of a parameter; None for an unidentifiable one; fixed ones at their value."""
        if label in self.unidentifiable or (label in self.lsq.std and self.lsq.std[label] is None):
            return None
        return float(self.params[self.labels.index(label)])

    def std(self, label: str) -> float | None:
        if label in self.unidentifiable:
            return None
        return self.lsq.std.get(label)

    @property
    def rms_xy(self) -> np.ndarray:
        """RMS of the residuals in x and y [px] (over the kept corners)."""
        return np.sqrt(np.mean(self.used_residuals ** 2, axis=0))

    @property
    def used_residuals(self) -> np.ndarray:
        """Residuals (K, 2) [px] of the corners used in the final solve."""
        return self.residuals.reshape(-1, 2) if self.keep is None else self.residuals[self.keep]

    def offsets_table(self) -> list[dict]:
        """Per-joint offset table (deg), the form a robot framework loads."""
        rows = []
        for j in self.model.joint_names:
            est = j in self.free
            v, s = (self.value(j), self.std(j)) if est else (0.0, None)
            rows.append({"joint": j, "estimated": est,
                         "offset [deg]": None if v is None else float(np.degrees(v)),
                         "std [deg]": None if s is None else float(np.degrees(s)),
                         "offset [rad]": v})
        return rows

    def camera_correction(self) -> dict:
        """Camera mounting correction: roll/pitch/yaw [rad], x/y [m] (None where not identifiable)."""
        return {p: (self.value(f"camera.{p}") if f"camera.{p}" in self.free else 0.0) for p in CAMERA_PARAMS}

    def corrected_tree(self):
        """Tree with offsets and the camera correction folded into the joint origins.

        Undetermined parameters enter at the solution the gauge picked (the gauge ``held`` at its
        start value, the others fitted): that combination, not its parts, is what the data fix, so
        the tree reproduces the calibrated projection.
        """
        return self.model.corrected_tree(self.params).fold_offsets()

    def limit_shifts(self) -> dict:
        """``{joint: c}`` [rad]: the offset folded into each movable joint's origin (a mimic joint's own
        plus ``multiplier`` times its leader's, as :meth:`KinematicTree.fold_offsets`). The corrected
        URDF's variable is the sensor angle ``theta = q - c``, so its limits are the model's minus ``c``."""
        tree = self.model.corrected_tree(self.params)
        out = {}
        for j in tree.joints:
            if j.movable:
                lead = j.mimic.multiplier * tree.joint(j.mimic.joint).offset if j.mimic else 0.0
                out[j.name] = j.offset + lead
        return out

    def urdf_text(self, *, inputs: dict | None = None, created: str | None = None) -> str:
        """The corrected URDF: offsets and camera correction folded into the joint origins, each joint's
        ``<limit>`` shifted by ``-c`` (:meth:`limit_shifts`) so the physical range ``q = theta + c``
        stays the model's, and a provenance comment before ``<robot>`` (robocal version, UTC date,
        inputs ``{path: sha256}`` as ``hash_inputs`` gives them, offsets and camera correction applied).

        ``urdf_from_tree`` writes the limits of the tree unchanged and no comment, so both are added
        here on its text."""
        import datetime as _dt
        import xml.etree.ElementTree as ET

        from robocal import __version__

        text = self.corrected_tree().to_urdf()
        decl, body = text.split("\n", 1) if text.startswith("<?xml") else ('<?xml version="1.0"?>', text)
        root = ET.fromstring(body)
        shifts = self.limit_shifts()
        joints = {j.name: j for j in self.model.tree.joints}  # mimic joints included
        for elem in root.findall("joint"):
            name, lim = elem.get("name"), elem.find("limit")
            j = joints.get(name)
            if lim is None or name not in shifts or j is None or j.limits is None:
                continue
            lim.set("lower", repr(float(j.limits[0] - shifts[name])))
            lim.set("upper", repr(float(j.limits[1] - shifts[name])))
        ET.indent(root)
        created = created or _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat().replace(
            "+00:00", "Z")
        lines = [f"Calibrated by robocal {__version__} (rig humanoid, seed 001 method) on {created}."]
        inputs = dict(inputs or {})
        if inputs:
            first = next(iter(inputs))
            lines.append(f"input: {first} sha256 {inputs[first]}")
            more = [k for k in inputs if k != first]
            urdfs = [k for k in more if str(k).lower().endswith(".urdf")]
            lines += [f"input: {k} sha256 {inputs[k]}" for k in urdfs]
            if len(more) > len(urdfs):
                lines.append(f"and {len(more) - len(urdfs)} image file(s), hashes in result.json")
        else:
            lines.append(f"input: data set in memory ({self.data.n_views} views), no file")
        lines.append("Joint variables are the raw sensor angles theta: the origins carry q = theta + c and each "
                     "<limit> is the model's minus c (same physical range).")
        lines.append("c applied [deg] (std null: not determined by the data, the gauge's solution; no std: not "
                     "calibrated):")
        for lab, c in shifts.items():
            sd = self.std(lab) if lab in self.free else None
            lines.append(f"  {lab} {np.degrees(c):+.6f}" + ("" if lab not in self.free else
                                                             " (std null)" if sd is None else
                                                             f" (std {np.degrees(sd):.6f})"))
        n = len(self.model.joint_names)
        cam = self.params[n:n + 5]
        lines.append(f"camera correction in {self.model.camera_link} (Trans(x, y, 0) Rz(yaw) Ry(pitch) Rx(roll)): "
                     f"roll {np.degrees(cam[0]):+.4f} deg, pitch {np.degrees(cam[1]):+.4f} deg, yaw "
                     f"{np.degrees(cam[2]):+.4f} deg, x {cam[3] * 1e3:+.3f} mm, y {cam[4] * 1e3:+.3f} mm")
        comment = "\n     ".join(ln.replace("--", "- -") for ln in lines)
        return f"{decl}\n<!-- {comment}\n-->\n" + ET.tostring(root, encoding="unicode") + "\n"

    def write_urdf(self, path, *, inputs: dict | None = None) -> str:
        """Write the corrected URDF (use it with the raw sensor angles): :meth:`urdf_text`, atomically."""
        from robocal.io import atomic_write_text

        text = self.urdf_text(inputs=inputs)
        atomic_write_text(path, text)
        return text

    def parameter_rows(self, truth=None) -> list[dict]:
        """Table of every free parameter: value and std in deg/mm, optional truth and error in sigmas."""
        rows = []
        for lab, unit in zip(self.labels, self.model.parameter_units()):
            if lab not in self.free:
                continue
            k = np.degrees(1.0) if unit == "rad" else 1e3
            v, s = self.value(lab), self.std(lab)
            row = {"parameter": lab, "value": None if v is None else v * k,
                   "std": None if s is None else s * k, "unit": "deg" if unit == "rad" else "mm"}
            if truth is not None:
                t = truth[self.labels.index(lab)]
                row["truth"] = t * k
                row["error/std"] = None if (v is None or not s) else (v - t) / s
            rows.append(row)
        return rows

    def to_result(self, *, inputs: dict | None = None, command: str | None = None,
                  truth=None) -> CalibrationResult:
        """The shared result record (schema robocal.result/2).

        The estimate holds every free parameter [rad or m] (None where the data do not determine
        it); ``diagnostics`` holds what the report and the summary are built from. ``truth``
        (P,), optional: the simulated parameter vector; its values for the free parameters and
        the NEES check of the errors against the reported covariance
        (:func:`robocal.estimation.truth_check`) are added as ``simulation_truth`` and
        ``truth_check``.
        """
        estimate, std, units = {}, {}, {}
        for lab, unit in zip(self.labels, self.model.parameter_units()):
            if lab not in self.free:
                continue
            estimate[lab] = self.value(lab)
            std[lab] = self.std(lab)
            units[lab] = unit
        lsq = self.lsq
        record = lsq.to_dict()
        solver = {k: record.get(k) for k in SOLVER_FIELDS}
        # the threshold the corners were tested at; the solver's own test over whole views is not reported
        solver["outlier_sigma"] = self.outlier_sigma
        diag = {
            "iterations": self.first_iterations,
            "iterations_reweighted_pass": lsq.iterations,
            "cost_history": lsq.cost_history,
            "cost_history_first_pass": self.first_cost_history,
            "status": lsq.status,
            "message": lsq.message,
            "solver": solver,
            "rank": self.jacobian_rank[0],
            "n_free": self.jacobian_rank[1],
            "n_solved": len(lsq.free_labels),
            "gauge_held": list(self.held),
            "condition_number": lsq.condition_number,
            "singular_values": lsq.singular_values,
            "correlations": [[a, b, c] for a, b, c in self.correlations[:10]],
            "unidentifiable": self.unidentifiable,
            "weakly_determined": lsq.weakly_determined,
            "rms_x_px": float(self.rms_xy[0]),
            "rms_y_px": float(self.rms_xy[1]),
            "noise_model": {"corner_sigma_px": self.corner_sigma,
                            "joint_resolution_rad": self.joint_resolution,
                            "residual_variance_ratio": lsq.residual_variance},
            "outlier_sigma": self.outlier_sigma,
            "views": [{"name": nm, "foot": f, "rms_px": float(r)}
                      for nm, f, r in zip(self.data.names, self.data.feet, self.view_rms)],
            "outlier_corners": [[v, c] for v, c in self.outlier_corners],
            # reject_outliers: corners removed before the re-solve, by view name and corner index
            # (the board's object-point order, row by row), and views removed whole
            "rejected_corners": [[v, c] for v, c in self.rejected_corners],
            "rejected_views": list(self.rejected_views),
            "reject_outliers": self.reject_outliers,
            # corners absent from the data (removed at detection: refinement wandered off, or off the
            # board's homography), by view name and corner index; left out of their view
            "missing_corners": [[v, c] for v, c in self.missing_corners],
            "n_corners_used": int(self.used_residuals.shape[0]),
            "n_corners_rejected": self.n_rejected,
            "n_views": self.data.n_views,
            "n_corners": int(self.residuals.shape[0] * self.residuals.shape[1]),
            "joint_offsets_deg": {r["joint"]: r["offset [deg]"] for r in self.offsets_table() if r["estimated"]},
            "offsets_table": [{k: v for k, v in r.items() if k != "offset [rad]"} for r in self.offsets_table()],
            # enough to redraw the residual histograms and overlays (`robocal report`): detected
            # corners and residuals (predicted - detected) per view and corner [px], and the image
            # files (None for in-memory images)
            "corners_px": np.round(self.data.corners, 4).tolist(),
            "residuals_px": np.round(self.residuals, 5).tolist(),
            "images": [str(Path(im).resolve()) if isinstance(im, (str, Path)) else None
                       for im in self.data.images],
            "image_size": [self.model.camera.width, self.model.camera.height],
            "corner_sigma_measured": self.two_pass,
            "iterations_from_zero": self.first_iterations,
            "camera_frame": self.model.camera_link,
            "camera_correction": self.camera_correction(),
            "tied": {k: list(v) for k, v in lsq.tied.items()},
            "messages": self.messages,
            "jacobian": lsq.jac_method,
        }
        if self.files:
            diag["files"] = list(self.files)
        if truth is not None:
            truth = np.asarray(truth, dtype=float)
            labels = list(estimate)
            t = np.array([truth[self.labels.index(lab)] for lab in labels])
            diag["simulation_truth"] = dict(zip(labels, t.tolist()))
            diag["truth_check"] = self.truth_check(truth).to_dict()
        kw = {}
        if command is not None:
            kw["command"] = command
        # in JSON types already, so that the report built from this record equals the one rebuilt from the file
        return CalibrationResult(rig="humanoid", method=f"lm ({lsq.jac_method} Jacobian)", estimate=estimate,
                                 std=std, units=units, residual_unit="px",
                                 residual_rms=float(np.sqrt(np.mean(self.used_residuals ** 2))),
                                 warnings=list(self.warnings), inputs=inputs or {}, diagnostics=to_jsonable(diag),
                                 **kw)

    def truth_check(self, truth):
        """NEES of the determined free parameters' errors against their covariance
        (:func:`robocal.estimation.truth_check`); ``truth`` (P,) the simulated parameter vector."""
        from robocal.estimation import truth_check

        truth = np.asarray(truth, dtype=float)
        labels = [lab for lab in self.labels if lab in self.free and self.value(lab) is not None
                  and self.std(lab) is not None]
        # the covariance of the solved parameters (a tied one follows its master exactly: left out,
        # as its error adds nothing the master's does not carry)
        solved = list(self.lsq.free_labels)
        labels = [lab for lab in labels if lab in solved]
        idx = [solved.index(lab) for lab in labels]
        cov = np.asarray(self.lsq.cov)[np.ix_(idx, idx)]
        err = np.array([self.value(lab) - truth[self.labels.index(lab)] for lab in labels])
        return truth_check(err, cov, names=labels)

    def summary(self) -> str:
        """Plain-text summary: RMS, identifiability, the parameter table (:func:`summary_text` of the result)."""
        return summary_text(self.to_result())

    def rejection_text(self) -> str:
        """What ``reject_outliers`` removed: corners by view, whole views ('' when nothing)."""
        return rejection_text(self.to_result().diagnostics)

    @property
    def n_rejected(self) -> int:
        """Corners removed by ``reject_outliers`` (the present corners of whole views included)."""
        if self.keep is None:
            return 0
        return int((present_corners(self.data) & ~self.keep).sum())

    def rank_text(self) -> str:
        """'Jacobian rank r of n free parameters ...', with the undetermined ones and the gauge."""
        return rank_text(self.to_result().diagnostics)


def parameter_rows(result: CalibrationResult) -> list[dict]:
    """The parameter table of a result: value and std in deg/mm, with the simulated truth and the
    error in sigmas when the result has them (``diagnostics["simulation_truth"]``)."""
    truth = result.diagnostics.get("simulation_truth")
    rows = []
    for lab, v in result.estimate.items():
        unit = result.units.get(lab)
        k = np.degrees(1.0) if unit == "rad" else 1e3
        s = result.std.get(lab)
        row = {"parameter": lab, "value": None if v is None else v * k, "std": None if s is None else s * k,
               "unit": "deg" if unit == "rad" else "mm"}
        if truth is not None and lab in truth:
            t = truth[lab]
            row["truth"] = t * k
            row["error/std"] = None if (v is None or not s) else (v - t) / s
        rows.append(row)
    return rows


def rank_text(d: dict) -> str:
    """'Jacobian rank r of n free parameters ...' from a result's diagnostics, with the undetermined
    parameters and the gauge."""
    r, n = d.get("rank"), d.get("n_free")
    text = f"Jacobian rank {r} of {n} free parameters"
    under = r is not None and n is not None and r < n
    if under:
        und = d.get("unidentifiable") or []
        text += (f" ({len(und)} not determined: {', '.join(und)}; gauge "
                 f"{', '.join(d.get('gauge_held') or [])} held at the start value)")
    cond = d.get("condition_number")
    # (a result file writes an infinite condition number as null)
    text += ", condition number " + ("inf" if cond is None else f"{float(cond):.3g}")
    return text + (f" (of the {d['n_solved']} solved)" if under and "n_solved" in d else "")


def rejection_text(d: dict) -> str:
    """What ``reject_outliers`` removed (from a result's diagnostics): corners by view, whole views
    ('' when nothing)."""
    corners, views = d.get("rejected_corners") or [], d.get("rejected_views") or []
    if not (corners or views):
        return ""
    parts = [by_view_text(corners, sep=" ")] if corners else []
    if views:
        parts.append(f"whole views {list(views)}")
    return f"{d['n_corners_rejected']} corner(s) removed: " + "; ".join(parts)


def summary_text(result: CalibrationResult) -> str:
    """The lines ``robocal humanoid calibrate`` prints, from the result alone: views and corners
    used, LM passes, residual RMS, identifiability, the parameter table, the strongest correlations
    and, for a simulated input, the truth check."""
    d = result.diagnostics
    lines = [f"views used: {d['n_views']}, corners used: {d['n_corners_used']} of {d['n_corners']}",
             f"LM iterations: {d['iterations']} from zero"
             + (f" + {d['iterations_reweighted_pass']} with the measured corner noise"
                if d["corner_sigma_measured"] else "")
             + f"; residual RMS x {d['rms_x_px']:.3f} px, y {d['rms_y_px']:.3f} px",
             rank_text(d)]
    if d.get("rejected_corners") or d.get("rejected_views"):
        lines.insert(1, "outliers rejected and re-solved once: " + rejection_text(d))
    elif d.get("reject_outliers"):
        lines.insert(1, f"outlier rejection: no corner beyond {d['outlier_sigma']:.3g} sigma, nothing removed")
    if d.get("missing_corners"):
        lines.insert(1, "corners removed at detection (left out): " + by_view_text(d["missing_corners"]))
    for r in parameter_rows(result):
        val = "not identifiable" if r["value"] is None else f"{r['value']:+.4f} +- {r['std']:.4f} {r['unit']}"
        lines.append(f"  {r['parameter']:<18s} {val}")
    corr = d.get("correlations") or []
    if corr:
        lines.append("strongest correlations: " + ", ".join(f"{a}/{b} {c:+.2f}" for a, b, c in corr[:5]))
    if d.get("truth_check"):
        tc = d["truth_check"]
        z = {k: v for k, v in (tc.get("z") or {}).items() if v is not None}
        worst = max(z, key=lambda k: abs(z[k])) if z else None
        lines.append(f"simulation truth: NEES {tc['nees']:.2f} over {tc['dof']} parameters (limit "
                     f"{tc['threshold']:.1f}, p = {tc['alpha']:g}): "
                     + ("consistent with" if tc["passed"] else "NOT consistent with")
                     + " the reported uncertainty"
                     + (f"; worst |error|/std {abs(z[worst]):.2f} ({worst})" if worst else ""))
    if d.get("files"):
        lines.append("also written beside the result: " + ", ".join(d["files"]))
    lines = [f"note: {m}" for m in d.get("messages") or []] + lines
    return "\n".join(lines)


def by_view_text(pairs, sep: str = ": ") -> str:
    """``'view000: corners [3, 18]; view004: corners [7]'`` from ``(view, corner)`` pairs."""
    by_view: dict[str, list[int]] = {}
    for nm, c in pairs:
        by_view.setdefault(nm, []).append(c)
    return "; ".join(f"{nm}{sep}corners {cs}" for nm, cs in by_view.items())
