"""Geometric refinement of X on every raw profile point (beyond seed 004).

Minimises the point-to-sphere distance of all profile points,

.. math:: r_{ij} = \\lVert T_{WE}(q_i)\\, X\\, m_{ij} - Q \\rVert - R,

over ``X = T_E_L`` (rotation-vector increment and translation) and the sphere
centre ``Q`` jointly. No circle fit, no sign ambiguity (the side of the
sphere follows from X), and the covariance comes from the estimation layer
(``s^2 (J^T J)^-1``), with parameters the poses cannot determine (``X.ty`` and
``Q.z`` on the P1R2P3 arm) named and given no standard deviation.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scipy.optimize import least_squares

from robocal.diagnostics import Diagnostic
from robocal.errors import InputError, NotEnoughDataError
from robocal.estimation import Problem, analyze_jacobian
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
    prob = Problem()
    labels = list(_LAB) + ["Q.x", "Q.y", "Q.z"]
    hold = set(hold)
    unknown = hold - set(_LAB) - {"Q.x", "Q.y", "Q.z"}
    if unknown:
        raise InputError(f"hold: unknown label(s) {sorted(unknown)} (known: {', '.join(_LAB)}, Q.x, Q.y, Q.z)")
    prob = Problem()
    prob.add_block("X", np.r_[0.0, 0.0, 0.0, X0[:3, 3]], labels=list(_LAB), unit=["rad"] * 3 + ["m"] * 3,
                   fixed=np.array([k in hold for k in _LAB]))
    prob.add_block("Q", Q0, labels=["Q.x", "Q.y", "Q.z"], unit="m",
                   fixed=np.array([k in hold for k in ("Q.x", "Q.y", "Q.z")]))
    prob.add_residuals(fun, name="point_to_sphere", jacobian=jac, residual_dim=1)
    if return_problem:
        return prob
    # Solved with SciPy directly and analysed with robocal.estimation.analyze_jacobian
    # (written when estimation.solve took a chi-square quantile per observation, seconds
    # on 10k points; it now takes one per residual size, so moving to solve() is open).
    free = np.array([k not in hold for k in labels])
    x0 = np.r_[0.0, 0.0, 0.0, X0[:3, 3], Q0]

    def unpack(x):
        full = x0.copy()
        full[free] = x
        return {"X": full[:6], "Q": full[6:]}

    def jfree(x):
        J = jac(unpack(x))
        return np.column_stack([J["X"], J["Q"]])[:, free]

    ls = least_squares(lambda x: fun(unpack(x)), x0[free], jac=jfree, method="trf",
                       loss=loss, f_scale=3 * sc, x_scale="jac", xtol=1e-12, ftol=1e-12)
    p = unpack(ls.x)
    r = fun(p)
    # noise level from the inliers (3-sigma clipped MAD), so outliers do not inflate it
    s_rob = 1.4826 * np.median(np.abs(r - np.median(r)))
    inl = np.abs(r) < 4 * max(s_rob, 1e-12)
    s2 = float(np.sum(r[inl] ** 2) / max(inl.sum() - free.sum(), 1))
    ident = analyze_jacobian(jfree(ls.x)[inl], [k for k, f in zip(labels, free) if f], residual_variance=s2)
    cov = np.full((9, 9), np.nan)
    fi = np.flatnonzero(free)
    cov[np.ix_(fi, fi)] = ident.cov
    std = {k: None for k in labels}
    for j, k in zip(fi, ident.labels):
        v = ident.std[list(ident.labels).index(k)]
        std[k] = None if not np.isfinite(v) else float(v)
    per_profile = np.array([np.sqrt(np.mean(r[idx == i] ** 2)) if np.any(idx == i) else 0.0
                            for i in range(len(profiles))])
    warnings = ident.diagnostics()
    n_out = int((~inl).sum())
    if n_out:
        bad = np.flatnonzero(per_profile > 3 * np.median(per_profile))
        warnings.append(Diagnostic("outliers", f"{n_out} of {len(r)} points ({100 * n_out / len(r):.2g} %) beyond "
                                   f"4 sigma (sigma = {np.sqrt(s2):.3g} m) were down-weighted by the {loss} loss"
                                   + (f"; profiles with high RMS: {bad.tolist()}" if bad.size else ""),
                                   indices=tuple(int(i) for i in bad)))
    if not ls.success:
        warnings.append(Diagnostic("not_converged", f"refinement stopped: {ls.message}"))
    X = transform_from(matrix_from_rotvec(p["X"][:3]) @ R0, p["X"][3:])
    return RefineResult(X=X, Q=p["Q"].copy(), cov=cov, std=std, rms=float(np.sqrt(np.mean(r**2))), residuals=r,
                        n_points=len(m), undetermined=tuple(k for k in labels if std[k] is None),
                        warnings=warnings, lsq=ls, per_profile_rms=per_profile, sigma=float(np.sqrt(s2)))
