"""Joint-offset and camera-mount calibration by Levenberg–Marquardt (seed 001, eqs. 6-8).

Each detected corner ``m = (P_img, P_cb, theta)`` gives the residual
``P_img - Proj(theta + alpha, P_cb; offsets)``; the sum of squares is
minimised over the selected parameters, starting from zero (seed 001). The
Jacobian is analytic (:meth:`HumanoidModel.project`) or SciPy's finite
differences. The result carries the residual RMS in x and y, per-view
residuals, > 3 sigma outliers by view and corner, and the identifiability
analysis of the shared estimation layer: rank, condition number, standard
deviations, strongest correlations, and no value for a parameter the data do
not determine.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import InputError, NotEnoughDataError
from robocal.estimation import LSQResult, Problem, analyze_jacobian, outlier_threshold, solve
from robocal.io import CalibrationResult
from robocal.rigs.humanoid.model import CAMERA_PARAMS, FEET, HumanoidModel
from robocal.rigs.humanoid.simulate import JOINT_RESOLUTION, HumanoidDataset

__all__ = ["PARAMETER_SETS", "resolve_parameters", "HumanoidCalibration", "calibrate", "build_problem"]

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
                raise InputError(f"unknown calibration parameter {lab!r}; known: sets {list(groups)} or labels "
                                 f"{labels}")
            if lab not in out:
                out.append(lab)
    if not out:
        raise InputError("no calibration parameter selected")
    return [lab for lab in labels if lab in out]


def _valid_views(data: HumanoidDataset) -> np.ndarray:
    if data.corners is None:
        raise InputError("the data set has no corners (detect them first)")
    return np.all(np.isfinite(data.corners), axis=(1, 2))


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


def corner_noise(model: HumanoidModel, data: HumanoidDataset, x) -> float:
    """Corner noise [px] from the residual part no joint-reading error can explain.

    Per view, the residual is projected onto the orthogonal complement of the
    columns of ``d uv / d theta``; ``sigma^2 = sum ||P r||^2 / sum (2N - rank)``.
    """
    V, N = data.corners.shape[:2]
    n = len(model.joint_names)
    uv, J = model.project(data.theta, data.feet, x, jacobian=True, check=False)
    r = (uv - data.corners).reshape(V, 2 * N)
    Jt = J[..., :n].reshape(V, 2 * N, n)
    ss, dof = 0.0, 0
    for v in range(V):
        U, sv, _ = np.linalg.svd(Jt[v], full_matrices=False)
        k = int(np.sum(sv > 1e-9 * max(sv.max(), 1e-300)))
        Uk = U[:, :k]
        e = r[v] - Uk @ (Uk.T @ r[v])
        ss += float(e @ e)
        dof += 2 * N - k
    return float(np.sqrt(ss / max(dof, 1)))


def build_problem(model: HumanoidModel, data: HumanoidDataset, free: Sequence[str], *, tie: bool = False,
                  x0=None, analytic: bool = True, corner_sigma: float = 0.3,
                  joint_sigma: float = 0.0) -> tuple[Problem, np.ndarray]:
    """The least-squares problem over one block ``p`` (all parameters, unselected ones fixed at ``x0``).

    Residuals: ``uv_pred - uv_meas`` [px] of each view, whitened by
    :func:`noise_weights` (so they are in units of the assumed noise; with
    ``joint_sigma = 0`` simply divided by ``corner_sigma``), shape
    ``(V, 2N)``: one observation per view. ``tie`` ties the RHipYawPitch offset to
    LHipYawPitch (one motor) when the tree does not already do so. Returns the
    problem and the per-view noise covariances (V, 2N, 2N) [px^2].
    """
    labels = model.parameter_labels()
    x0 = np.zeros(len(labels)) if x0 is None else np.asarray(x0, dtype=float)
    fixed = np.array([lab not in free for lab in labels])
    theta, feet, meas = data.theta, np.asarray(data.feet), data.corners
    V, N = meas.shape[:2]
    W, S = noise_weights(model, data, x0, corner_sigma=corner_sigma, joint_sigma=joint_sigma)

    def fun(p):
        r = (model.project(theta, feet, p["p"], check=False) - meas).reshape(V, 2 * N)
        return np.einsum("vij,vj->vi", W, r)

    def jac(p):
        _, J = model.project(theta, feet, p["p"], jacobian=True, check=False)
        return {"p": (W @ J.reshape(V, 2 * N, len(labels))).reshape(V * N * 2, len(labels))}

    units = model.parameter_units()
    scale = np.where(np.array(units) == "m", 1e-3, np.radians(0.5))
    prob = Problem().add_block("p", x0, fixed=fixed, labels=labels, unit=units, scale=scale)
    # one observation per view: the whitening mixes the corners of a view (corner outliers are
    # tested separately on the raw residuals, see calibrate)
    prob.add_residuals(fun, name="views", jacobian=jac if analytic else None, residual_dim=2 * N)
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

    # -- queries -----------------------------------------------------------------------------
    @property
    def labels(self) -> list[str]:
        return self.model.parameter_labels()

    @property
    def unidentifiable(self) -> list[str]:
        """Selected parameters the data do not determine (no value is reported for them)."""
        return [lab for lab in self.labels if lab in self.held or lab in self.lsq.unidentifiable]

    def value(self, label: str) -> float | None:
        """Estimate of a parameter; None for an unidentifiable one; fixed ones at their value."""
        if label in self.held or (label in self.lsq.std and self.lsq.std[label] is None):
            return None
        return float(self.params[self.labels.index(label)])

    def std(self, label: str) -> float | None:
        return self.lsq.std.get(label)

    @property
    def rms_xy(self) -> np.ndarray:
        """RMS of the residuals in x and y [px]."""
        return np.sqrt(np.mean(self.residuals ** 2, axis=(0, 1)))

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
        """Tree with offsets and the camera correction folded into the joint origins
        (unidentifiable parameters left at 0)."""
        p = np.where([self.value(lab) is None for lab in self.labels], 0.0, self.params)
        return self.model.corrected_tree(p).fold_offsets()

    def write_urdf(self, path) -> str:
        """Write the corrected URDF (use it with the raw sensor angles)."""
        return self.corrected_tree().to_urdf(path)

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
        """The shared result record (schema robocal.result/1)."""
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
            "rank": lsq.rank,
            "n_free": len(lsq.free_labels),
            "condition_number": lsq.condition_number,
            "singular_values": lsq.singular_values,
            "correlations": [[a, b, c] for a, b, c in lsq.correlations[:10]],
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
            "n_views": self.data.n_views,
            "n_corners": int(self.residuals.shape[0] * self.residuals.shape[1]),
            "joint_offsets_deg": {r["joint"]: r["offset [deg]"] for r in self.offsets_table() if r["estimated"]},
            "camera_correction": self.camera_correction(),
            "tied": {k: list(v) for k, v in lsq.tied.items()},
            "messages": self.messages,
            "jacobian": lsq.jac_method,
        }
        kw = {}
        if command is not None:
            kw["command"] = command
        return CalibrationResult(rig="humanoid", method=f"lm ({lsq.jac_method} Jacobian)", estimate=estimate,
                                 std=std, units=units, residual_rms=float(np.sqrt(np.mean(self.residuals ** 2))), residual_unit="px",
                                 warnings=list(self.warnings), inputs=inputs or {}, diagnostics=diag, **kw)

    def summary(self) -> str:
        """Plain-text summary: RMS, identifiability, the parameter table."""
        lsq = self.lsq
        lines = [f"views used: {self.data.n_views}, corners: {self.residuals.shape[0] * self.residuals.shape[1]}",
                 f"LM iterations: {lsq.iterations}; residual RMS x {self.rms_xy[0]:.3f} px, "
                 f"y {self.rms_xy[1]:.3f} px",
                 f"Jacobian rank {lsq.rank + len(self.held)} of {len(lsq.free_labels) + len(self.held)} free "
                 f"parameters, condition number {lsq.condition_number:.3g}"
                 + (f" (without the undetermined {', '.join(self.held)})" if self.held else "")]
        for r in self.parameter_rows():
            val = "not identifiable" if r["value"] is None else f"{r['value']:+.4f} +- {r['std']:.4f} {r['unit']}"
            lines.append(f"  {r['parameter']:<18s} {val}")
        if lsq.correlations:
            lines.append("strongest correlations: " + ", ".join(f"{a}/{b} {c:+.2f}"
                                                                 for a, b, c in lsq.correlations[:5]))
        for w in self.warnings:
            lines.append(f"warning [{w.code}]: {w.message}")
        return "\n".join(lines)


def calibrate(model: HumanoidModel, data: HumanoidDataset, *, parameters: str | Sequence[str] = "seed",
              tie: bool = False, jac: str = "analytic", method: str = "lm", x0=None,
              corner_sigma: float | None = None, joint_resolution: float = JOINT_RESOLUTION,
              outlier_sigma: float = 3.0, progress: bool = False) -> HumanoidCalibration:
    """Estimate the selected offsets from the corners of every complete view.

    Parameters
    ----------
    model : HumanoidModel
    data : HumanoidDataset
        Views with corners; views whose corners are NaN (board not fully
        found) are dropped with a message.
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

    Returns
    -------
    HumanoidCalibration
    """
    free = resolve_parameters(model, parameters)
    messages = list(data.messages)
    ok = _valid_views(data)
    for v in np.flatnonzero(~ok):
        messages.append(f"view {data.names[v]!r}: board not fully detected, view dropped")
    used = data.subset(ok)
    if used.n_views == 0:
        raise NotEnoughDataError("no view with a fully detected board")
    missing = [f for f in FEET if any(lab.startswith(f"board.{f}.") for lab in free) and f not in used.feet]
    if missing:
        raise NotEnoughDataError(f"no usable view of the {missing[0]} board, but its mounting offsets are "
                                 f"selected; drop them from the parameters or add views")
    n_res = used.corners.shape[0] * used.corners.shape[1] * 2
    if n_res < len(free):
        raise NotEnoughDataError(f"{n_res} residuals for {len(free)} parameters")
    joint_sigma = joint_resolution / np.sqrt(12.0)
    sig = 0.3 if corner_sigma is None else float(corner_sigma)
    prob, S = build_problem(model, used, free, tie=tie, x0=x0, analytic=True,
                            corner_sigma=sig, joint_sigma=joint_sigma)
    # Parameters the poses cannot determine are held at their start value and
    # reported without a value: LM would otherwise wander along the null space.
    pre = analyze_jacobian(prob.jacobian_at(), prob.free_labels)
    held = list(pre.unidentifiable)
    if held:
        solvable = [lab for lab in free if lab not in held and prob.ties.get(lab, (None,))[0] not in held]
        if not solvable:
            raise NotEnoughDataError(f"the views determine none of the selected parameters ({', '.join(held)})")
        warn_held = Diagnostic(
            "rank_deficient",
            f"the poses do not determine {', '.join(held)} (Jacobian rank {pre.rank} < {len(pre.labels)} at the "
            f"start; unobservable: {'; '.join(pre.null_directions())}): held at their start value, no value "
            f"reported", params=tuple(held))
        free = solvable
    prob, S = build_problem(model, used, free, tie=tie, x0=x0, analytic=(jac == "analytic"),
                            corner_sigma=sig, joint_sigma=joint_sigma)
    res = solve(prob, method=method, jac=None if jac == "analytic" else jac, progress=progress,
                outlier_sigma=outlier_sigma)
    first_iterations = res.iterations
    first_history = np.asarray(res.cost_history)
    if corner_sigma is None and joint_sigma > 0:
        # Second pass with the corner noise measured where joint errors cannot reach.
        sig = corner_noise(model, used, res.params["p"].reshape(-1))
        prob, S = build_problem(model, used, free, tie=tie, x0=res.params["p"].reshape(-1),
                                analytic=(jac == "analytic"), corner_sigma=sig, joint_sigma=joint_sigma)
        res = solve(prob, method=method, jac=None if jac == "analytic" else jac, progress=progress,
                    outlier_sigma=outlier_sigma)
    params = res.params["p"].reshape(-1)
    V, N = used.corners.shape[:2]
    resid = model.project(used.theta, used.feet, params, check=False) - used.corners
    view_rms = np.sqrt(np.mean(resid ** 2, axis=(1, 2)))
    # outliers on the raw corner residuals, each against its own 2x2 noise block
    idx = np.arange(N)
    blocks = np.stack([np.stack([S[:, 2 * idx, 2 * idx], S[:, 2 * idx, 2 * idx + 1]], -1),
                       np.stack([S[:, 2 * idx + 1, 2 * idx], S[:, 2 * idx + 1, 2 * idx + 1]], -1)], -2)
    score = np.einsum("vni,vnij,vnj->vn", resid, np.linalg.inv(blocks), resid) / res.residual_variance
    thr = outlier_threshold(outlier_sigma, 2)
    flat = np.flatnonzero(score.reshape(-1) > thr)
    outliers = [(used.names[int(i) // N], int(i) % N) for i in flat]
    warnings = [w for w in res.warnings if w.code != "outliers"]
    if held:
        warnings.insert(0, warn_held)
    if outliers:
        by_view: dict[str, list[int]] = {}
        for nm, c in outliers:
            by_view.setdefault(nm, []).append(c)
        text = "; ".join(f"{nm}: corners {cs}" for nm, cs in by_view.items())
        warnings.append(Diagnostic("outliers", f"{len(outliers)} corner residuals beyond {outlier_sigma:g} "
                                               f"sigma ({100 * len(outliers) / (V * N):.1f} %): {text}",
                                   indices=tuple(int(i) for i in flat)))
    dropped = [i for i, good in enumerate(ok) if not good]
    if dropped:
        warnings.append(Diagnostic("dropped", f"{len(dropped)} view(s) without a fully detected board were "
                                              f"dropped: {[data.names[i] for i in dropped]}",
                                   indices=tuple(dropped)))
    return HumanoidCalibration(model, used, res, params, free + held, resid, view_rms, outliers, messages,
                               warnings, score, sig, joint_resolution, first_iterations, held, first_history)
