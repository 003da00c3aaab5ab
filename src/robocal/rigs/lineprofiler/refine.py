"""Geometric refinement of X on every raw profile point (beyond seed 004).

Minimises the point-to-sphere distance of all profile points,

.. math:: r_{ij} = \\lVert T_{WE}(q_i)\\, X\\, m_{ij} - Q \\rVert - R,

over ``X = T_E_L`` (rotation-vector increment and translation) and the sphere
centre ``Q`` jointly. No circle fit, no sign ambiguity (the side of the
sphere follows from X). Solved by :func:`robocal.estimation.solve` (SciPy's
trust-region reflective method with a robust loss and the analytic
Jacobian), which also gives the covariance ``s^2 (J^T W J)^+`` (``W`` the
loss's weights, ``s`` the point noise re-estimated with outlier clipping),
names the parameters the poses cannot determine (``X.ty`` and ``Q.z`` on the
P1R2P3 arm: no value or standard deviation) and the outlier points by index;
the rig adds which profiles they are in.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import InputError, NotEnoughDataError
from robocal.estimation import Problem, solve
from robocal.geometry import matrix_from_rotvec, transform_from
from robocal.kinematics import DHChain
from robocal.validation import check_array

__all__ = ["RefineResult", "refine_sphere"]

_LAB = ("X.rx", "X.ry", "X.rz", "X.tx", "X.ty", "X.tz")


@dataclass
class RefineResult:
    """``X`` (4, 4), ``Q`` (3,), ``cov`` (9, 9) over ``X.rx..X.tz, Q.x..Q.z`` (NaN where
    undetermined), ``std`` by label (None where undetermined), residual ``rms`` (m)."""

    X: np.ndarray
    Q: np.ndarray
    cov: np.ndarray
    std: dict
    rms: float
    residuals: np.ndarray
    n_points: int
    undetermined: tuple
    warnings: list = field(default_factory=list)
    lsq: object = None
    per_profile_rms: np.ndarray | None = None
    sigma: float = float("nan")


def refine_sphere(q, profiles, chain: DHChain, sphere_radius: float, X0, Q0, *, loss: str = "soft_l1",
                  sigma: float | None = None, hold=(), return_problem: bool = False) -> RefineResult:
    """Refine ``X`` and the sphere centre on all raw points (point-to-sphere distance).

    Parameters
    ----------
    q : array_like, shape (N, dof)
    profiles : sequence of (M_i, 2) arrays, ``(x, z)`` in L (m)
    chain : DHChain
    sphere_radius : float (m)
    X0 : (4, 4) starting ``T_E_L`` (e.g. from FPDP, or a CAD value)
    Q0 : (3,) starting sphere centre in the world
    loss : str
        Robust loss (``'linear'`` for plain least squares); the scale is set
        from the profiler noise ``sigma`` or, if None, from the start residuals.
    hold : sequence of str
        Labels held at their start value -- pass FPDP's ``undetermined`` so an
        unobservable component does not drift; they are still reported as
        undetermined (no std).
    return_problem : bool
        Return the :class:`robocal.estimation.Problem` instead of solving it.

    Returns
    -------
    RefineResult
        ``lsq`` holds the core's :class:`robocal.estimation.LSQResult`
        (cost history, correlations, observation scores, ``summary()``);
        ``warnings`` its diagnostics (``rank_deficient``, ``weakly_determined``,
        ``outliers`` beyond 4 sigma with point indices and profiles,
        ``not_converged``); ``sigma`` the point noise (m).
    """
    q = chain.check_q(q)
    if len(q) != len(profiles):
        raise InputError(f"q has {len(q)} poses but there are {len(profiles)} profiles: counts must match")
    X0 = check_array(X0, "X0", shape=(4, 4))
    Q0 = check_array(Q0, "Q0", shape=(3,))
    pts, idx = [], []
    for i, p in enumerate(profiles):
        p = check_array(p, f"profile {i}", shape=("M", 2))
        pts.append(np.column_stack([p[:, 0], np.zeros(len(p)), p[:, 1]]))
        idx.append(np.full(len(p), i))
    m = np.concatenate(pts)
    idx = np.concatenate(idx)
    if len(m) < 12:
        raise NotEnoughDataError(f"geometric refinement needs at least 12 profile points, got {len(m)}")
    T = chain.fk(q)[idx]  # (P, 4, 4) per point
    R0 = X0[:3, :3]
    Rr = float(sphere_radius)

    def world(p):
        RX = matrix_from_rotvec(p["X"][:3]) @ R0
        pl = m @ RX.T + p["X"][3:]
        return np.einsum("nij,nj->ni", T[:, :3, :3], pl) + T[:, :3, 3]

    def fun(p):
        return np.linalg.norm(world(p) - p["Q"], axis=1) - Rr

    def jac(p):
        RX = matrix_from_rotvec(p["X"][:3]) @ R0
        pl = m @ RX.T + p["X"][3:]
        w = np.einsum("nij,nj->ni", T[:, :3, :3], pl) + T[:, :3, 3]
        d = w - p["Q"]
        u = d / np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
        uE = np.einsum("nji,nj->ni", T[:, :3, :3], u)  # u expressed in E
        # d(pl)/d(omega) = -[RX m]x (left increment), so d r/d omega = (RX m) x uE
        Jr = np.cross(m @ RX.T, uE)
        return {"X": np.column_stack([Jr, uE]), "Q": -u}

    sc = sigma if sigma is not None else max(float(np.sqrt(np.mean(fun({"X": np.r_[0, 0, 0, X0[:3, 3]],
                                                                           "Q": Q0}) ** 2))), 1e-7)
    labels = list(_LAB) + ["Q.x", "Q.y", "Q.z"]
    hold = set(hold)
    unknown = hold - set(labels)
    if unknown:
        raise InputError(f"hold: unknown label(s) {sorted(unknown)} (known: {', '.join(labels)})")
    prob = Problem()
    prob.add_block("X", np.r_[0.0, 0.0, 0.0, X0[:3, 3]], labels=list(_LAB), unit=["rad"] * 3 + ["m"] * 3,
                   fixed=np.array([k in hold for k in _LAB]))
    prob.add_block("Q", Q0, labels=["Q.x", "Q.y", "Q.z"], unit="m",
                   fixed=np.array([k in hold for k in ("Q.x", "Q.y", "Q.z")]))
    prob.add_residuals(fun, name="point_to_sphere", jacobian=jac, residual_dim=1)
    if return_problem:
        return prob
    # the robust loss bites at 3 sigma; points beyond 4 sigma (sigma re-estimated with clipping,
    # so the outliers do not inflate it) are named; the covariance is s^2 (J^T W J)^+ with the
    # loss's weights W, parameters the poses cannot determine named and given no std
    lsq = solve(prob, method="trf", loss=loss, f_scale=3 * sc, x_scale="jac", xtol=1e-12, ftol=1e-12,
                outlier_sigma=4.0)
    p = lsq.params
    r = lsq.residuals
    free = lsq.free_labels
    cov = np.full((9, 9), np.nan)
    fi = [labels.index(k) for k in free]
    cov[np.ix_(fi, fi)] = lsq.cov
    std = {k: lsq.std.get(k) for k in labels}  # held labels: None (not determined by this fit)
    per_profile = np.array([np.sqrt(np.mean(r[idx == i] ** 2)) if np.any(idx == i) else 0.0
                            for i in range(len(profiles))])
    warnings = []
    for w in lsq.warnings:
        if w.code == "outliers" and w.indices:
            # the core counts observations in weighted-residual units; here they are points and metres
            pts = list(w.indices)
            prof, n_in = np.unique(idx[pts], return_counts=True)
            shown = ", ".join(map(str, pts[:20])) + (", ..." if len(pts) > 20 else "")
            w = Diagnostic("outliers", f"{len(pts)} of {len(r)} points ({100 * len(pts) / len(r):.2g} %) lie beyond "
                           f"4 sigma (sigma = {1e6 * np.sqrt(lsq.residual_variance):.3g} um) and were down-weighted "
                           f"by the {loss} loss: points [{shown}]; by profile (points): "
                           + ", ".join(f"{int(i)} ({int(c)})" for i, c in zip(prof, n_in)),
                           params=w.params, indices=w.indices)
        warnings.append(w)
    X = transform_from(matrix_from_rotvec(p["X"][:3]) @ R0, p["X"][3:])
    return RefineResult(X=X, Q=p["Q"].copy(), cov=cov, std=std, rms=float(lsq.rms), residuals=r,
                        n_points=len(m), undetermined=tuple(k for k in labels if std[k] is None),
                        warnings=warnings, lsq=lsq, per_profile_rms=per_profile,
                        sigma=float(np.sqrt(lsq.residual_variance)))
