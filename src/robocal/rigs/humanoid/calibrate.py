"""Joint-offset and camera-mount calibration by Levenberg–Marquardt (seed 001, eqs. 6-8).

Each detected corner ``m = (P_img, P_cb, theta)`` gives the residual
``P_img - Proj(theta + alpha, P_cb; offsets)``; the sum of squares is
minimised over the selected parameters, starting from zero (seed 001). The
Jacobian is analytic (:meth:`HumanoidModel.project`) or SciPy's finite
differences. The result carries the residual RMS in x and y, per-view
residuals, > 3 sigma outliers by view and corner, and the identifiability
analysis of the shared estimation layer: rank, condition number, standard
deviations, strongest correlations, and no value for a parameter the data do
not determine. Corners missing from a view (NaN: removed at detection) are
left out of it; optionally (``reject_outliers``) the named outliers are removed
too and the problem re-solved once. Each view is one residual term holding
only its kept corners, so every count (degrees of freedom, residual variance,
RMS) is over the corners actually used.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import (ImplausibleInputError, InconsistentDataError, InputError, NonFiniteError,
                             NotEnoughDataError)
from robocal.estimation import LSQResult, Problem, analyze_jacobian, outlier_threshold, solve
from robocal.io import CalibrationResult
from robocal.rigs.humanoid.model import CAMERA_PARAMS, FEET, HumanoidModel
from robocal.rigs.humanoid.simulate import JOINT_RESOLUTION, HumanoidDataset

__all__ = ["PARAMETER_SETS", "resolve_parameters", "HumanoidCalibration", "calibrate", "check_options",
           "build_problem",
           "choose_gauge", "check_views_consistent", "plausibility_warnings", "implausible_offsets"]

#: Named parameter sets (``--params``): see :func:`resolve_parameters`.
PARAMETER_SETS = {
    "seed": "the seed's Table 1: camera roll/pitch/yaw, the 12 leg joint offsets, board yaw/x/y per foot (21)",
    "seed+camera_xy": "the seed's set plus the camera x/y shift (23)",
    "legs": "leg joint offsets only (12)",
    "all": "every parameter: head and leg joints, camera roll/pitch/yaw/x/y, boards",
}


def resolve_parameters(model: HumanoidModel, spec: str | Sequence[str] = "seed") -> list[str]:
    """Labels of the free parameters from a set name, a comma list or a sequence.

    Names: a set of :data:`PARAMETER_SETS`, a joint name, ``camera.roll`` ...
    ``camera.y``, ``board.left.yaw`` ..., or the groups ``camera``,
    ``camera_rotation``, ``boards``, ``legs``, ``head``; comma-separated.
    """
    if isinstance(spec, str):
        items = [s.strip() for s in spec.split(",") if s.strip()]
    else:
        items = list(spec)
    labels = model.parameter_labels()
    groups = {
        "seed": model.seed_parameters(),
        "seed+camera_xy": model.seed_parameters() + ["camera.x", "camera.y"],
        "legs": list(model.leg_joints),
        "head": list(model.head_joints),
        "camera": [f"camera.{p}" for p in CAMERA_PARAMS],
        "camera_rotation": ["camera.roll", "camera.pitch", "camera.yaw"],
        "boards": [lab for lab in labels if lab.startswith("board.")],
        "all": labels,
    }
    out: list[str] = []
    for it in items:
        add = groups.get(it, [it])
        for lab in add:
            if lab not in labels:
                hint = (" (the camera's z shift is not observable in this set-up, seed 001)"
                         if lab == "camera.z" else "")
                raise InputError(f"unknown calibration parameter {lab!r}{hint}; known: sets {list(groups)} or "
                                 f"labels {labels}")
            if lab not in out:
                out.append(lab)
    if not out:
        raise InputError("no calibration parameter selected")
    return [lab for lab in labels if lab in out]


def _valid_views(data: HumanoidDataset) -> np.ndarray:
    """Views (V,) bool with at least one corner (a corner is present when both coordinates are finite)."""
    return _present(data).any(axis=1)


def _present(data: HumanoidDataset) -> np.ndarray:
    """Corners (V, N) bool that are present (finite): NaN marks a corner removed at detection."""
    if data.corners is None:
        raise InputError("the data set has no corners (detect them first)")
    return np.all(np.isfinite(data.corners), axis=2)


def noise_weights(model: HumanoidModel, data: HumanoidDataset, x, *, corner_sigma: float,
                  joint_sigma: float) -> np.ndarray:
    """Per-view whitening matrices ``W_v`` (V, 2N, 2N) with ``W_v^T W_v = Sigma_v^-1``.

    ``Sigma_v = corner_sigma^2 I + joint_sigma^2 J_theta J_theta^T``: corner
    noise plus the joint readings' error (quantisation to 0.1 deg is a uniform
    error of std ``0.1 deg / sqrt(12)``), which moves all corners of a view
    together. ``J_theta`` equals the offset Jacobian (an offset adds to the
    reading), evaluated at ``x``, over the joints whose reading changes
    between views: a joint that stays still (the head) has one constant
    reading error, a bias the camera rotation absorbs, not noise.
    """
    V, N = data.corners.shape[:2]
    n = len(model.joint_names)
    moving = np.ptp(data.theta, axis=0) > 0
    if joint_sigma > 0 and np.any(moving):
        _, J = model.project(data.theta, data.feet, x, jacobian=True, check=False)
        Jt = J[..., :n][..., moving].reshape(V, 2 * N, int(moving.sum()))
        S = corner_sigma ** 2 * np.eye(2 * N) + joint_sigma ** 2 * Jt @ Jt.transpose(0, 2, 1)
    else:
        S = np.broadcast_to(corner_sigma ** 2 * np.eye(2 * N), (V, 2 * N, 2 * N))
    L = np.linalg.cholesky(S)
    return np.linalg.inv(L), S


def corner_noise(model: HumanoidModel, data: HumanoidDataset, x, keep=None) -> float:
    """Corner noise [px] from the residual part no joint-reading error can explain.

    Per view, the residual is projected onto the orthogonal complement of the
    columns of ``d uv / d theta``; ``sigma^2 = sum ||P r||^2 / sum (2N - rank)``.
    ``keep`` (V, N) bool, optional: only these corners count (rejected outliers left out); missing
    (NaN) corners never do.
    """
    V, N = data.corners.shape[:2]
    n = len(model.joint_names)
    uv, J = model.project(data.theta, data.feet, x, jacobian=True, check=False)
    r = (uv - data.corners).reshape(V, 2 * N)
    Jt = J[..., :n].reshape(V, 2 * N, n)
    rows = np.repeat(_present(data) if keep is None else np.asarray(keep, bool) & _present(data), 2, axis=1)
    ss, dof = 0.0, 0
    for v in range(V):
        if not rows[v].any():
            continue
        U, sv, _ = np.linalg.svd(Jt[v][rows[v]], full_matrices=False)
        k = int(np.sum(sv > 1e-9 * max(sv.max(), 1e-300)))
        Uk = U[:, :k]
        rv = r[v][rows[v]]
        e = rv - Uk @ (Uk.T @ rv)
        ss += float(e @ e)
        dof += int(rows[v].sum()) - k
    return float(np.sqrt(ss / max(dof, 1)))


def choose_gauge(pre) -> list[str]:
    """One parameter per null-space direction to hold fixed (the gauge), from an
    :class:`~robocal.estimation.Identifiability` of the selected problem.

    Pivoted QR on the transposed null-space basis ``N^T`` (k x n, column-scaled coordinates)
    picks the k parameters with the largest independent null-space components, so that fixing
    them removes every null direction and the k x k block of ``N`` stays well conditioned.
    Among near-equal components a parameter outside the seed's usual set (HeadYaw, HeadPitch,
    camera.x, camera.y) is preferred, as its value is the least interesting one.
    """
    import scipy.linalg

    N = np.asarray(pre.null_space)
    k = N.shape[1] if N.ndim == 2 else 0
    if k == 0:
        return []
    prefer = np.array([1.2 if lab in ("HeadYaw", "HeadPitch", "camera.x", "camera.y") else 1.0
                       for lab in pre.labels])
    _, _, piv = scipy.linalg.qr(N.T * prefer, pivoting=True, mode="economic")
    return [pre.labels[j] for j in sorted(piv[:k])]


def build_problem(model: HumanoidModel, data: HumanoidDataset, free: Sequence[str], *, tie: bool = False,
                  x0=None, analytic: bool = True, corner_sigma: float = 0.3,
                  joint_sigma: float = 0.0, keep=None) -> tuple[Problem, np.ndarray]:
    """The least-squares problem over one block ``p`` (all parameters, unselected ones fixed at ``x0``).

    One residual term per view (named by the view), holding ``uv_pred - uv_meas`` [px] of its
    kept corners only, whitened by the inverse Cholesky factor of their block of the view's
    noise covariance :func:`noise_weights` (the marginal of the noise model; in units of the
    assumed noise, with ``joint_sigma = 0`` simply divided by ``corner_sigma``): one observation
    of dimension ``2 K_v`` per view, as the whitening mixes the corners of a view (corner
    outliers are tested separately on the raw residuals, see :func:`calibrate`). ``keep`` (V, N)
    bool, optional: corners to use (default: the present ones, see :func:`_present`); a view
    without any is left out. So the residual count ``m``, the degrees of freedom and the
    residual variance count only the corners used. ``tie`` ties the RHipYawPitch offset to
    LHipYawPitch (one motor) when the tree does not already do so. Returns the problem and the
    per-view noise covariances (V, 2N, 2N) [px^2] of all corners.
    """
    labels = model.parameter_labels()
    x0 = np.zeros(len(labels)) if x0 is None else np.asarray(x0, dtype=float)
    fixed = np.array([lab not in free for lab in labels])
    theta, feet = data.theta, np.asarray(data.feet)
    V, N = data.corners.shape[:2]
    keep = _present(data) if keep is None else np.asarray(keep, bool) & _present(data)
    W_all, S = noise_weights(model, data, x0, corner_sigma=corner_sigma, joint_sigma=joint_sigma)
    meas = data.corners.reshape(V, 2 * N)
    P = len(labels)
    # model.project evaluates every view at once: the per-view terms share one evaluation per parameter
    # vector (the solver calls all terms with the same one)
    cache: dict = {}

    def projected(p, jacobian=False):
        key = p.tobytes()
        if cache.get("key") != key or (jacobian and cache["J"] is None):
            out = model.project(theta, feet, p, jacobian=jacobian, check=False)
            uv, J = out if jacobian else (out, None)
            cache.update(key=key, uv=uv, J=J)
        return cache["uv"], cache["J"]

    units = model.parameter_units()
    scale = np.where(np.array(units) == "m", 1e-3, np.radians(0.5))
    prob = Problem().add_block("p", x0, fixed=fixed, labels=labels, unit=units, scale=scale)
    names = data.names if len(set(data.names)) == V else [f"view{v:03d}" for v in range(V)]
    for v in range(V):
        rows = np.flatnonzero(np.repeat(keep[v], 2))
        if not rows.size:
            continue
        W = W_all[v] if rows.size == 2 * N else np.linalg.inv(np.linalg.cholesky(S[v][np.ix_(rows, rows)]))

        def fun(p, v=v, rows=rows, W=W):
            uv, _ = projected(p["p"])
            return W @ (uv[v].reshape(2 * N)[rows] - meas[v, rows])

        def jac(p, v=v, rows=rows, W=W):
            _, J = projected(p["p"], jacobian=True)
            return {"p": W @ J[v].reshape(2 * N, P)[rows]}

        prob.add_residuals(fun, name=str(names[v]), jacobian=jac if analytic else None, residual_dim=rows.size)
    if tie and not model.tied and "RHipYawPitch" in labels and "LHipYawPitch" in labels:
        if ("RHipYawPitch" in free) != ("LHipYawPitch" in free):
            raise InputError("tie needs both LHipYawPitch and RHipYawPitch among the free parameters")
        if "RHipYawPitch" in free:
            prob.tie("RHipYawPitch", "LHipYawPitch")
    return prob, S


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
        ``(view name, corner index)`` of > 3 sigma corners.
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

    def to_result(self, *, inputs: dict | None = None, command: str | None = None) -> CalibrationResult:
        """The shared result record (schema robocal.result/2)."""
        estimate, std, units = {}, {}, {}
        for lab, unit in zip(self.labels, self.model.parameter_units()):
            if lab not in self.free:
                continue
            estimate[lab] = self.value(lab)
            std[lab] = self.std(lab)
            units[lab] = unit
        lsq = self.lsq
        diag = {
            "iterations": self.first_iterations,
            "iterations_reweighted_pass": lsq.iterations,
            "cost_history": lsq.cost_history,
            "cost_history_first_pass": self.first_cost_history,
            "status": lsq.status,
            "message": lsq.message,
            "rank": self.jacobian_rank[0],
            "n_free": self.jacobian_rank[1],
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
            "views": [{"name": nm, "foot": f, "rms_px": float(r)}
                      for nm, f, r in zip(self.data.names, self.data.feet, self.view_rms)],
            "outlier_corners": [[v, c] for v, c in self.outlier_corners],
            # --reject-outliers: corners removed before the re-solve, by view name and corner index
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
            # enough to redraw the residual histograms and overlays (`robocal humanoid report`):
            # detected corners and residuals (predicted - detected) per view and corner [px], and
            # the image files (None for in-memory images)
            "corners_px": np.round(self.data.corners, 4).tolist(),
            "residuals_px": np.round(self.residuals, 5).tolist(),
            "images": [str(Path(im).resolve()) if isinstance(im, (str, Path)) else None
                       for im in self.data.images],
            "image_size": [self.model.camera.width, self.model.camera.height],
            "corner_sigma_measured": self.two_pass,
            "iterations_from_zero": self.first_iterations,
            "camera_correction": self.camera_correction(),
            "tied": {k: list(v) for k, v in lsq.tied.items()},
            "messages": self.messages,
            "jacobian": lsq.jac_method,
        }
        kw = {}
        if command is not None:
            kw["command"] = command
        return CalibrationResult(rig="humanoid", method=f"lm ({lsq.jac_method} Jacobian)", estimate=estimate,
                                 std=std, units=units, residual_unit="px",
                                 residual_rms=float(np.sqrt(np.mean(self.used_residuals ** 2))),
                                 warnings=list(self.warnings), inputs=inputs or {}, diagnostics=diag, **kw)

    def summary(self) -> str:
        """Plain-text summary: RMS, identifiability, the parameter table."""
        lsq = self.lsq
        lines = [f"views used: {self.data.n_views}, corners used: {self.used_residuals.shape[0]} of "
                 f"{self.residuals.shape[0] * self.residuals.shape[1]}",
                 f"LM iterations: {self.first_iterations} from zero"
                 + (f" + {lsq.iterations} with the measured corner noise" if self.two_pass else "")
                 + f"; residual RMS x {self.rms_xy[0]:.3f} px, y {self.rms_xy[1]:.3f} px",
                 self.rank_text()]
        if self.rejected_corners or self.rejected_views:
            lines.insert(1, "outliers rejected and re-solved once: " + self.rejection_text())
        elif self.reject_outliers:
            lines.insert(1, f"outlier rejection: no corner beyond {self.lsq.outlier_sigma:g} sigma, nothing removed")
        if self.missing_corners:
            lines.insert(1, "corners removed at detection (left out): " + _by_view_text(self.missing_corners))
        for r in self.parameter_rows():
            val = "not identifiable" if r["value"] is None else f"{r['value']:+.4f} +- {r['std']:.4f} {r['unit']}"
            lines.append(f"  {r['parameter']:<18s} {val}")
        if self.correlations:
            lines.append("strongest correlations: " + ", ".join(f"{a}/{b} {c:+.2f}"
                                                                 for a, b, c in self.correlations[:5]))
        return "\n".join(lines)

    def rejection_text(self) -> str:
        """What ``reject_outliers`` removed: corners by view, whole views ('' when nothing)."""
        if not (self.rejected_corners or self.rejected_views):
            return ""
        parts = [_by_view_text(self.rejected_corners, sep=" ")] if self.rejected_corners else []
        if self.rejected_views:
            parts.append(f"whole views {self.rejected_views}")
        return f"{self.n_rejected} corner(s) removed: " + "; ".join(parts)

    @property
    def n_rejected(self) -> int:
        """Corners removed by ``reject_outliers`` (the present corners of whole views included)."""
        if self.keep is None:
            return 0
        return int((_present(self.data) & ~self.keep).sum())

    def rank_text(self) -> str:
        """'Jacobian rank r of n free parameters ...', with the undetermined ones and the gauge."""
        r, n = self.jacobian_rank
        text = f"Jacobian rank {r} of {n} free parameters"
        if r < n:
            text += (f" ({len(self.unidentifiable)} not determined: {', '.join(self.unidentifiable)}; gauge "
                     f"{', '.join(self.held)} held at the start value)")
        return text + f", condition number {self.lsq.condition_number:.3g}" + \
            (f" (of the {len(self.lsq.free_labels)} solved)" if r < n else "")


#: Defaults of ``check_views_consistent(min_px=, ratio=)`` (``calibrate(consistency_px=,
#: consistency_ratio=)``, CLI ``--consistency-px``, ``--consistency-ratio``): a view is refused when its
#: corners lie further than this from the nominal prediction [px] and :data:`NOMINAL_RATIO` times the
#: median view's distance. Offsets of 0.5 deg (the simulator's
#: scale) put corners up to 28 px from it, 2 deg up to 110 px; a mislabelled foot 250 px, two
#: swapped joint records 136 px (measured, 20 x 16 simulated views).
NOMINAL_MIN_PX = 60.0
NOMINAL_RATIO = 4.0
#: After the solve: a joint or camera-rotation offset beyond this [rad] is implausible for an
#: assembled robot (NAO's are within ~1 deg, seed 001 Table 2).
PLAUSIBLE_OFFSET = np.radians(5.0)


def check_views_consistent(model: HumanoidModel, data: HumanoidDataset, x0=None, *,
                           min_px: float = NOMINAL_MIN_PX, ratio: float = NOMINAL_RATIO) -> np.ndarray:
    """Refuse views whose joint record or foot label does not match the image.

    For each view, the median distance [px] between the detected corners and the corners the
    model predicts from the joint readings at ``x0`` (default zero offsets, seed 001 eq. 5) is
    compared with ``max(min_px, ratio * median over views)`` (defaults 60 px and 4,
    :data:`NOMINAL_MIN_PX`, :data:`NOMINAL_RATIO`): offsets move every view's corners alike, a
    wrong record or foot moves one view's. Raise ``min_px`` for a robot whose offsets are larger
    than ~1 deg (2 deg put corners up to 110 px off, still under ``ratio`` times the median view).
    Raises :class:`InconsistentDataError` naming the first such view; returns the distances (V,) [px].
    """
    _check_consistency_thresholds(min_px, ratio)
    x0 = np.zeros(len(model.parameter_labels())) if x0 is None else np.asarray(x0, dtype=float)
    pred = model.project(data.theta, data.feet, x0, check=False)
    d = np.linalg.norm(pred - data.corners, axis=-1)
    # corners missing from the data (NaN) do not count; a view without any, or a board behind the
    # camera (NaN prediction), is as far as can be
    present = _present(data)
    d = np.where(present, np.where(np.isfinite(d), d, np.inf), np.nan)
    dist = np.full(len(d), np.inf)
    dist[present.any(axis=1)] = np.nanmedian(d[present.any(axis=1)], axis=1)
    typical = float(np.median(dist))
    tol = max(float(min_px), float(ratio) * typical)
    bad = np.flatnonzero(dist > tol)
    if bad.size:
        v = int(bad[np.argmax(dist[bad])])
        raise InconsistentDataError(
            f"view {data.names[v]!r} (feet: {data.feet[v]!r}, and its joints record): detected corners are "
            f"{dist[v]:.0f} px (median) from where the record puts them, expected < {tol:.0f} px (median view "
            f"{typical:.0f} px): the joint record or the foot label does not match the image"
            + (f" ({bad.size} such views: {[data.names[i] for i in bad]})" if bad.size > 1 else ""))
    return dist


def _check_consistency_thresholds(min_px, ratio) -> None:
    if not (np.isfinite(min_px) and min_px > 0):
        raise InputError(f"consistency threshold min_px (--consistency-px) must be a finite number > 0 px, "
                         f"got {min_px}")
    if not (np.isfinite(ratio) and ratio >= 1):
        raise InputError(f"consistency ratio (--consistency-ratio) must be a finite number >= 1, got {ratio}")


def implausible_offsets(model: HumanoidModel, free, params) -> list[tuple[str, float]]:
    """``(label, value [deg])`` of the free joint/camera-rotation offsets beyond :data:`PLAUSIBLE_OFFSET`."""
    labels = model.parameter_labels()
    units = model.parameter_units()
    return [(lab, float(np.degrees(params[labels.index(lab)]))) for lab in free
            if units[labels.index(lab)] == "rad" and not lab.startswith("board.")
            and abs(params[labels.index(lab)]) > PLAUSIBLE_OFFSET]


def plausibility_warnings(model: HumanoidModel, free, params, view_rms, names,
                          residual_variance: float, *, offsets: bool = True) -> list[Diagnostic]:
    """``inconsistent_data`` warnings after a solve: joint/camera-rotation offsets beyond
    :data:`PLAUSIBLE_OFFSET` (unless ``offsets`` is false: :func:`calibrate` judges those with
    :func:`robocal.plausibility.check_slips`), views whose RMS is 10x the median view's (and > 1 px),
    and a residual variance 25x the noise model's. Each suggests a wrong joint record, foot label or
    model."""
    out = []
    big = implausible_offsets(model, free, params) if offsets else []
    if big:
        out.append(Diagnostic("inconsistent_data", "implausible offsets (> {:.0f} deg): {}; check the joint "
                              "records, foot labels and model".format(
                                  np.degrees(PLAUSIBLE_OFFSET), ", ".join(f"{a} {b:+.1f} deg" for a, b in big)),
                              params=tuple(a for a, _ in big)))
    med = float(np.nanmedian(view_rms))  # NaN: a view removed by reject_outliers
    far = [i for i, r in enumerate(view_rms) if np.isfinite(r) and r > max(1.0, 10 * med)]
    if far:
        out.append(Diagnostic("inconsistent_data", f"view(s) fit far worse than the rest (RMS > 10x the median "
                              f"{med:.2f} px): " + ", ".join(f"{names[i]} {view_rms[i]:.1f} px" for i in far)
                              + "; check their joint records and foot labels", indices=tuple(far)))
    if residual_variance > 25.0:
        out.append(Diagnostic("inconsistent_data", f"residual variance {residual_variance:.3g} times the noise "
                              f"model's: the model does not explain the data"))
    return out


def check_options(model: HumanoidModel, *, parameters: str | Sequence[str] = "seed",
                  corner_sigma: float | None = None, joint_resolution: float = JOINT_RESOLUTION,
                  consistency_px: float = NOMINAL_MIN_PX, consistency_ratio: float = NOMINAL_RATIO,
                  max_rejected_fraction: float = 0.25) -> list[str]:
    """Check :func:`calibrate`'s options (raise :class:`InputError` naming the bad one) and return the
    free parameter labels; the CLI calls it before the slow corner detection."""
    if corner_sigma is not None and not (np.isfinite(corner_sigma) and corner_sigma > 0):
        raise InputError(f"corner_sigma must be a finite number > 0 px, got {corner_sigma}")
    if not (np.isfinite(joint_resolution) and joint_resolution >= 0):
        raise InputError(f"joint_resolution must be a finite number >= 0 rad, got {joint_resolution}")
    _check_consistency_thresholds(consistency_px, consistency_ratio)
    if not (0.0 <= max_rejected_fraction <= 1.0):
        raise InputError(f"max_rejected_fraction must be within [0, 1], got {max_rejected_fraction}")
    return resolve_parameters(model, parameters)


def calibrate(model: HumanoidModel, data: HumanoidDataset, *, parameters: str | Sequence[str] = "seed",
              tie: bool = False, jac: str = "analytic", method: str = "lm", x0=None,
              corner_sigma: float | None = None, joint_resolution: float = JOINT_RESOLUTION,
              outlier_sigma: float = 3.0, progress: bool = False,
              check_consistency: bool = True, consistency_px: float = NOMINAL_MIN_PX,
              consistency_ratio: float = NOMINAL_RATIO, reject_outliers: bool = False,
              max_rejected_fraction: float = 0.25, accept_implausible: bool = False,
              declared: dict | None = None) -> HumanoidCalibration:
    """Estimate the selected offsets from the corners of every view.

    Parameters
    ----------
    model : HumanoidModel
    data : HumanoidDataset
        Views with corners. NaN corners (removed at detection) are left out of
        their view; a view without any corner (board not fully found) is
        dropped with a message.
    parameters : str or sequence of str
        See :func:`resolve_parameters`; default the seed's 21.
    tie : bool
        One offset for both HipYawPitch joints (one motor).
    jac : {'analytic', '2-point', '3-point'}
    method : {'lm', 'trf'}
        ``'lm'`` is the seed's Levenberg–Marquardt.
    x0 : array_like, optional
        Start (default zero offsets, as the seed) and value of fixed parameters.
    corner_sigma : float, optional
        Corner noise [px]. Default: measured by :func:`corner_noise` after a
        first LM pass from zero (0.3 px assumed in that pass), then a second
        pass from there with the noise model complete. Only its ratio to the
        joint error changes the estimate; the covariance is rescaled by the
        residual variance.
    joint_resolution : float
        Joint sensor resolution [rad] (0.1 deg); its quantisation error (std
        ``resolution / sqrt(12)``) enters the per-view noise model (see
        :func:`noise_weights`). 0 treats the readings as exact.
    outlier_sigma : float
        Corners whose residual exceeds this many sigma (chi-square(2) test on
        the 2x2 noise block, scaled by the residual variance) are named.
    reject_outliers : bool
        Remove the corners named as outliers (``outlier_sigma``) and re-solve once from the
        solution, with the noise model marginalised to the kept corners (:func:`build_problem`
        ``keep``) and, when ``corner_sigma`` is measured, the corner noise re-measured without them.
        What was removed is reported (``rejected_corners``, ``rejected_views``, a ``low_quality``
        warning); corners still beyond ``outlier_sigma`` afterwards are named, not removed.
    max_rejected_fraction : float
        With ``reject_outliers``, a view with more than this fraction of its corners flagged is
        removed whole (its detection or joint record, not single corners, is then suspect).
    check_consistency : bool
        Refuse views whose corners are far from where the joint record and
        foot label put them (:func:`check_views_consistent`), and warn
        (``inconsistent_data``) about implausible offsets after the solve
        (:func:`plausibility_warnings`).
        With it, the data set is first checked for the likely slips
        (:func:`robocal.rigs.humanoid.slips.check_data`: transposed board, mirrored images, square,
        board centre or joint records in the wrong unit, swapped feet, reversed image list) and
        joint/camera offsets beyond :data:`PLAUSIBLE_OFFSET` after the solve are implausible
        (:class:`~robocal.errors.ImplausibleInputError`, naming the slip when one explains it).
    consistency_px, consistency_ratio : float
        The thresholds of that check [px, -]: a view is refused beyond
        ``max(consistency_px, consistency_ratio * median view)`` (defaults 60 px, 4).
    accept_implausible : bool
        Go on with implausible data as given: an ``implausible_input`` warning instead of the error
        (CLI ``--accept-implausible``).
    declared : dict, optional
        Units the data set's fields were written in (``load_dataset``'s ``info["declared"]``), so a
        slip is named in the file's units; default SI.

    Returns
    -------
    HumanoidCalibration
    """
    free = check_options(model, parameters=parameters, corner_sigma=corner_sigma,
                         joint_resolution=joint_resolution, consistency_px=consistency_px,
                         consistency_ratio=consistency_ratio, max_rejected_fraction=max_rejected_fraction)
    messages = list(data.messages)
    ok = _valid_views(data)
    for v in np.flatnonzero(~ok):
        if not any(m.startswith(f"view {data.names[v]!r}:") and "dropped" in m for m in messages):
            # (detection has said so already, with the reason)
            messages.append(f"view {data.names[v]!r}: no corners (board not fully or not correctly detected), "
                            f"view dropped")
    used = data.subset(ok)
    if used.n_views == 0:
        raise NotEnoughDataError("no view with a fully detected board")
    missing = [f for f in FEET if any(lab.startswith(f"board.{f}.") for lab in free) and f not in used.feet]
    if missing:
        raise NotEnoughDataError(f"no usable view of the {missing[0]} board, but its mounting offsets are "
                                 f"selected; drop them from the parameters or add views")
    present = _present(used)  # corners removed at detection are NaN: left out of their view
    missing_corners = [(used.names[v], int(c)) for v, c in zip(*np.nonzero(~present))]
    n_res = 2 * int(present.sum())
    if n_res < len(free):
        raise NotEnoughDataError(f"{n_res} residuals for {len(free)} parameters")
    slip_warnings: list[Diagnostic] = []
    if check_consistency:
        from robocal.rigs.humanoid.slips import check_data

        slip_warnings = check_data(model, used, declared=declared, consistency_px=consistency_px,
                                   accept_implausible=accept_implausible)
        if not slip_warnings:  # accepted implausible data would only be refused view by view here
            try:
                check_views_consistent(model, used, x0, min_px=consistency_px, ratio=consistency_ratio)
            except InconsistentDataError as exc:
                # some views only: a slip such as two swapped joint columns can explain them all
                from robocal.rigs.humanoid.slips import name_slip

                name_slip(model, used, declared=declared, consistency_px=consistency_px)
                raise exc
    joint_sigma = joint_resolution / np.sqrt(12.0)
    sig = 0.3 if corner_sigma is None else float(corner_sigma)
    prob, S = build_problem(model, used, free, tie=tie, x0=x0, analytic=True,
                            corner_sigma=sig, joint_sigma=joint_sigma)
    # Gauge: along each null-space direction LM would wander, so hold one parameter per direction
    # at its start value (k parameters for a k-dimensional null space) and solve for all others.
    # Parameters orthogonal to the null space are estimable: their least-squares estimate does not
    # depend on which point of the solution set the gauge picks, so they stay unbiased; the ones
    # with a null-space component are gauge-dependent and get no value. Holding every such
    # parameter instead (k' > k) removes directions the data do determine and biases the rest.
    pre = analyze_jacobian(prob.jacobian_at(), prob.free_labels)
    undetermined = list(pre.unidentifiable)
    # (a null direction spread so thinly that no parameter reaches the 0.1 component of
    # analyze_jacobian is left to LM, as before: nothing is held or withheld for it)
    gauge = choose_gauge(pre) if undetermined else []
    warn_held = None
    if undetermined:
        tied_to = {lab: prob.ties[lab][0] for lab in prob.ties} if prob.ties else {}
        undetermined += [lab for lab, master in tied_to.items() if master in undetermined]
        held_all = set(gauge) | {lab for lab, master in tied_to.items() if master in gauge}
        solvable = [lab for lab in free if lab not in held_all]
        if not solvable or all(lab in undetermined for lab in solvable):
            raise NotEnoughDataError(f"the {used.n_views} view(s) determine none of the selected parameters "
                                     f"({', '.join(undetermined)}): add views (`robocal humanoid plan` shows "
                                     f"how many poses determine the offsets) or select fewer parameters "
                                     f"(--params)")
        k = len(pre.labels) - pre.rank
        warn_held = Diagnostic(
            "rank_deficient",
            f"the poses do not determine {', '.join(undetermined)} (Jacobian rank {pre.rank} of "
            f"{len(pre.labels)} at the start; unobservable: {'; '.join(pre.null_directions())}): no value "
            f"reported for them; {', '.join(gauge)} held at the start value to fix the {k} null "
            f"direction(s), the others are estimated", params=tuple(undetermined))
        free = solvable
        gauge = sorted(held_all, key=model.parameter_labels().index)
    prob, S = build_problem(model, used, free, tie=tie, x0=x0, analytic=(jac == "analytic"),
                            corner_sigma=sig, joint_sigma=joint_sigma)
    try:
        res = _solve(prob, method=method, jac=None if jac == "analytic" else jac, progress=progress,
                     outlier_sigma=outlier_sigma)
    except ImplausibleInputError:  # diverged (a NaN corner): name the slip behind it when one explains it
        if check_consistency:
            from robocal.rigs.humanoid.slips import name_slip

            name_slip(model, used, declared=declared, consistency_px=consistency_px)
        raise
    first_iterations = res.iterations
    first_history = np.asarray(res.cost_history)
    two_pass = False
    if corner_sigma is None and joint_sigma > 0:
        # Second pass with the corner noise measured where joint errors cannot reach.
        sig = corner_noise(model, used, res.params["p"].reshape(-1), present)
        prob, S = build_problem(model, used, free, tie=tie, x0=res.params["p"].reshape(-1),
                                analytic=(jac == "analytic"), corner_sigma=sig, joint_sigma=joint_sigma)
        res = _solve(prob, method=method, jac=None if jac == "analytic" else jac, progress=progress,
                     outlier_sigma=outlier_sigma)
        two_pass = True
    params = res.params["p"].reshape(-1)
    V, N = used.corners.shape[:2]
    resid, view_rms, score, flat = _corner_stats(model, used, params, S, res.residual_variance, outlier_sigma,
                                                 present)
    keep, rejected, rejected_views = present, [], []
    outlier_warning = None
    if reject_outliers and flat.size:
        # Drop the flagged corners (a view that loses more than max_rejected_fraction of its corners as
        # a whole: so many bad corners say its detection or joint record is wrong) and re-solve once, from
        # the solution, with the noise model of the kept corners.
        keep = present.copy()
        keep.reshape(-1)[flat] = False
        lost = (present & ~keep).sum(axis=1)  # flagged now (corners missing from the data not counted)
        whole = np.flatnonzero(lost > max_rejected_fraction * N)
        rejected = [(used.names[int(i) // N], int(i) % N) for i in flat if int(i) // N not in whole]
        rejected_views = [used.names[v] for v in whole]
        keep[whole] = False
        gone = [f for f in FEET if any(lab.startswith(f"board.{f}.") for lab in free)
                and not keep[[i for i, ft in enumerate(used.feet) if ft == f]].any()]
        if gone or keep.sum() * 2 < len(free):
            raise NotEnoughDataError(f"--reject-outliers: removing the outlier corners ({len(flat)}) leaves "
                                     + (f"no view of the {gone[0]} board" if gone else "too few corners")
                                     + "; check the data or calibrate without rejection")
        first_outliers = [(used.names[int(i) // N], int(i) % N) for i in flat]
        outlier_warning = _outlier_diagnostic(first_outliers, flat, outlier_sigma, int(present.sum()),
                                              " (before rejection)")
        if corner_sigma is None and joint_sigma > 0:
            sig = corner_noise(model, used, params, keep)
        prob, S = build_problem(model, used, free, tie=tie, x0=params, analytic=(jac == "analytic"),
                                corner_sigma=sig, joint_sigma=joint_sigma, keep=keep)
        res = _solve(prob, method=method, jac=None if jac == "analytic" else jac, progress=progress,
                     outlier_sigma=outlier_sigma)
        params = res.params["p"].reshape(-1)
        resid, view_rms, score, flat = _corner_stats(model, used, params, S, res.residual_variance,
                                                     outlier_sigma, keep)
    outliers = [(used.names[int(i) // N], int(i) % N) for i in flat]
    warnings = [w for w in res.warnings if w.code != "outliers"]
    if warn_held is not None:
        warnings.insert(0, warn_held)
    if outlier_warning is not None:
        warnings.append(outlier_warning)
        text = _by_view_text(rejected)
        if rejected_views:
            text += ("; " if text else "") + f"whole view(s) {rejected_views} (more than " \
                    f"{100 * max_rejected_fraction:.0f} % of their corners beyond {outlier_sigma:g} sigma)"
        removed = present & ~keep
        warnings.append(Diagnostic("low_quality", f"--reject-outliers: removed {int(removed.sum())} corner(s) "
                                                  f"and re-solved once: {text}",
                                   indices=tuple(int(i) for i in np.flatnonzero(removed.reshape(-1)))))
    if outliers:
        warnings.append(_outlier_diagnostic(outliers, flat, outlier_sigma, int(present.sum()),
                                            " (after rejection, kept)" if outlier_warning is not None else ""))
    if missing_corners:
        warnings.append(Diagnostic("low_quality", f"{len(missing_corners)} corner(s) removed at detection, left "
                                                  f"out of their views: {_by_view_text(missing_corners)}",
                                   indices=tuple(int(i) for i in np.flatnonzero(~present.reshape(-1)))))
    dropped = [i for i, good in enumerate(ok) if not good]
    if dropped:
        warnings.append(Diagnostic("dropped", f"{len(dropped)} view(s) without a fully and correctly detected "
                                              f"board were dropped: {[data.names[i] for i in dropped]}",
                                   indices=tuple(dropped)))
    warnings = slip_warnings + warnings
    if check_consistency:
        vr = np.where(keep.any(axis=1), view_rms, np.nan)
        big = implausible_offsets(model, free, params)
        if big and not slip_warnings:  # (an accepted slip has said why already)
            rms = float(np.sqrt(np.nanmean(resid[keep] ** 2))) if keep.any() else float("nan")
            from robocal.rigs.humanoid.slips import check_data

            # the slips of the pre-check, tried now whatever the corner distance: the offsets say the data
            # are wrong, the distance figure says which slip explains them
            warnings += check_data(
                model, used, declared=declared, consistency_px=consistency_px, accept_implausible=accept_implausible,
                implausible_answer="implausible offsets (> {:.0f} deg) for an assembled robot: {} (reprojection RMS "
                                   "{:.3g} px); check the joint records, foot labels and model".format(
                                       np.degrees(PLAUSIBLE_OFFSET), ", ".join(f"{a} {b:+.1f} deg" for a, b in big),
                                       rms))
        warnings += plausibility_warnings(model, free, params, vr, used.names, res.residual_variance,
                                          offsets=bool(slip_warnings))
    selected = [lab for lab in model.parameter_labels() if lab in free or lab in gauge]
    return HumanoidCalibration(model, used, res, params, selected, resid, view_rms, outliers, messages,
                               warnings, score, sig, joint_resolution, first_iterations, list(gauge),
                               first_history, undetermined=undetermined, rank=pre.rank,
                               n_params=len(pre.labels), two_pass=two_pass, keep=keep,
                               rejected_corners=rejected, rejected_views=rejected_views,
                               missing_corners=missing_corners, reject_outliers=bool(reject_outliers))


def _solve(prob, **kw) -> LSQResult:
    """:func:`robocal.estimation.solve`, with a NaN residual turned into the one-line reason.

    The forward model returns NaN for a corner behind the camera (``project(check=False)``): LM only
    gets there when the corners and joint records cannot come from one robot (the slips
    :func:`robocal.rigs.humanoid.slips.check_data` names, or data accepted despite them), and
    wanders through offsets of tens of radians before. The parameter dump of the solver's message
    would tell the user nothing."""
    try:
        return solve(prob, **kw)
    except NonFiniteError as exc:
        if "returned NaN" not in exc.message:
            raise
        raise ImplausibleInputError(
            "the fit diverged: the offsets grew until a board fell behind the camera (a NaN corner), so "
            "the corners and joint records cannot come from one robot; check the joint records and their "
            "unit, the feet, the board (rows, cols, square, centre) and the camera") from None


def _corner_stats(model, data, params, S, residual_variance, outlier_sigma, keep=None):
    """Residuals (V, N, 2) [px], per-view RMS (V,) over the kept corners, outlier scores (V, N) and the
    flat indices of the kept corners beyond ``outlier_sigma``: each corner's raw residual against its
    own 2x2 noise block (chi-square(2)), scaled by the residual variance."""
    V, N = data.corners.shape[:2]
    resid = model.project(data.theta, data.feet, params, check=False) - data.corners
    k = np.all(np.isfinite(resid), axis=2) if keep is None else keep
    sq = np.sum(resid ** 2, axis=2)
    # a view without kept corners (removed whole) reports the RMS of its present ones
    k_rms = np.where(k.any(1)[:, None], k, np.isfinite(sq))
    view_rms = np.sqrt(np.sum(np.where(k_rms, sq, 0.0), 1) / np.maximum(k_rms.sum(1), 1) / 2)
    idx = np.arange(N)
    blocks = np.stack([np.stack([S[:, 2 * idx, 2 * idx], S[:, 2 * idx, 2 * idx + 1]], -1),
                       np.stack([S[:, 2 * idx + 1, 2 * idx], S[:, 2 * idx + 1, 2 * idx + 1]], -1)], -2)
    score = np.einsum("vni,vnij,vnj->vn", resid, np.linalg.inv(blocks), resid) / residual_variance
    thr = outlier_threshold(outlier_sigma, 2)
    flat = np.flatnonzero((score > thr).reshape(-1) & k.reshape(-1))
    return resid, view_rms, score, flat


def _outlier_diagnostic(outliers, flat, outlier_sigma, n_corners, note="") -> Diagnostic:
    text = _by_view_text(outliers)
    return Diagnostic("outliers", f"{len(outliers)} corner residuals beyond {outlier_sigma:g} sigma"
                                  f"{note} ({100 * len(outliers) / n_corners:.1f} %): {text}",
                      indices=tuple(int(i) for i in flat))


def _by_view_text(pairs, sep: str = ": ") -> str:
    """``'view000: corners [3, 18]; view004: corners [7]'`` from ``(view, corner)`` pairs."""
    by_view: dict[str, list[int]] = {}
    for nm, c in pairs:
        by_view.setdefault(nm, []).append(c)
    return "; ".join(f"{nm}{sep}corners {cs}" for nm, cs in by_view.items())
