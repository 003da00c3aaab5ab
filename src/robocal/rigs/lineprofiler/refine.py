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

The joint readings are taken as exact unless ``joint_sigma`` is given: then
each pose gets a joint correction with a Gaussian prior (errors in
variables). A reading error is shared by every point of its profile; treated
as point noise it is mis-weighted (poses count by their number of points)
and left out of the std -- with the seed comparison's encoder noise the
rotation error is 2-4.5x larger and the std 10-13x too small (docs/rigs/lineprofiler.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sps

from robocal.diagnostics import Diagnostic
from robocal.errors import InputError, NotEnoughDataError, RobocalError
from robocal.estimation import Problem, loss_derivatives, robust_cost, solve
from robocal.geometry import matrix_from_rotvec, rotvec_from_matrix, transform_from
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
    dq: np.ndarray | None = None  # (N, dof) joint corrections when joint_sigma was given


def refine_sphere(q, profiles, chain: DHChain, sphere_radius: float, X0, Q0, *, loss: str = "soft_l1",
                  sigma: float | None = None, hold=(), joint_sigma=None,
                  return_problem: bool = False) -> RefineResult:
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
    joint_sigma : float or array_like (dof,), optional
        Noise of the recorded joint values (encoder read-out, backlash; m or
        rad per joint). Without it the joint readings are taken as exact and
        every point is an independent observation -- then a pose's reading
        error, shared by all the points of its profile, is averaged as if it
        were point noise: the estimate weights the poses by their point count
        and its std is too small (see docs). With it, each pose gets a joint
        correction ``dq_i`` (labels ``dq[i].q<j>``) with the prior
        ``dq_i ~ N(0, joint_sigma^2)`` (errors in variables), the points are
        weighted by the profiler noise ``sigma`` (default: pooled from a
        circle fit per profile, which the pose errors do not touch) and the
        covariance of X and Q includes the joint noise. Needs a chain with
        ``jacobian(q)`` (a D-H chain, not a pose table).
    return_problem : bool
        Return the :class:`robocal.estimation.Problem` instead of solving it.

    Returns
    -------
    RefineResult
        ``lsq`` holds the core's :class:`robocal.estimation.LSQResult`
        (cost history, correlations, observation scores, ``summary()``);
        ``warnings`` its diagnostics (``rank_deficient``, ``weakly_determined``,
        ``outliers`` beyond the core's threshold (``lsq.outlier_sigma``: Bonferroni over the
        points, :func:`robocal.estimation.outlier_sigma`) with point indices and profiles,
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

    labels = list(_LAB) + ["Q.x", "Q.y", "Q.z"]
    hold = set(hold)
    unknown = hold - set(labels)
    if unknown:
        raise InputError(f"hold: unknown label(s) {sorted(unknown)} (known: {', '.join(labels)})")
    if joint_sigma is not None:
        return _refine_eiv(q, profiles, chain, Rr, X0, Q0, m, idx, loss=loss, sigma=sigma, hold=hold,
                           joint_sigma=joint_sigma, return_problem=return_problem)
    sc = sigma if sigma is not None else max(float(np.sqrt(np.mean(fun({"X": np.r_[0, 0, 0, X0[:3, 3]],
                                                                           "Q": Q0}) ** 2))), 1e-7)
    prob = Problem()
    prob.add_block("X", np.r_[0.0, 0.0, 0.0, X0[:3, 3]], labels=list(_LAB), unit=["rad"] * 3 + ["m"] * 3,
                   fixed=np.array([k in hold for k in _LAB]))
    prob.add_block("Q", Q0, labels=["Q.x", "Q.y", "Q.z"], unit="m",
                   fixed=np.array([k in hold for k in ("Q.x", "Q.y", "Q.z")]))
    prob.add_residuals(fun, name="point_to_sphere", jacobian=jac, residual_dim=1)
    if return_problem:
        return prob
    # the robust loss bites at 3 sigma; points beyond the core's outlier threshold (Bonferroni over
    # the points, robocal.estimation.outlier_sigma; sigma re-estimated with clipping, so the outliers
    # do not inflate it) are named; the covariance is s^2 (J^T W J)^+ with the loss's weights W,
    # parameters the poses cannot determine named and given no std
    lsq = solve(prob, method="trf", loss=loss, f_scale=3 * sc, x_scale="jac", xtol=1e-12, ftol=1e-12)
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
                           f"{lsq.outlier_sigma:.3g} sigma (sigma = {1e6 * np.sqrt(lsq.residual_variance):.3g} um) "
                           f"and were down-weighted by the {loss} loss: points [{shown}]; by profile (points): "
                           + ", ".join(f"{int(i)} ({int(c)})" for i, c in zip(prof, n_in)),
                           params=w.params, indices=w.indices)
        warnings.append(w)
    X = transform_from(matrix_from_rotvec(p["X"][:3]) @ R0, p["X"][3:])
    return RefineResult(X=X, Q=p["Q"].copy(), cov=cov, std=std, rms=float(lsq.rms), residuals=r,
                        n_points=len(m), undetermined=tuple(k for k in labels if std[k] is None),
                        warnings=warnings, lsq=lsq, per_profile_rms=per_profile,
                        sigma=float(np.sqrt(lsq.residual_variance)))


def _pooled_circle_sigma(profiles) -> float:
    """Profiler noise from a circle fit per profile (3 parameters each): the pose errors do not enter."""
    from robocal.geometry import fit_circle_2d

    ss, dof = 0.0, 0
    for p in profiles:
        if len(p) < 6:
            continue
        try:
            fit = fit_circle_2d(np.asarray(p, float))
        except RobocalError:
            continue
        ss += fit.rms**2 * len(p)
        dof += len(p) - 3
    if dof <= 0:
        raise NotEnoughDataError("joint_sigma: no profile with 6 or more points to estimate the profiler noise "
                                 "from; give sigma")
    return max(float(np.sqrt(ss / dof)), 1e-9)


def _refine_eiv(q, profiles, chain, Rr, X0, Q0, m, idx, *, loss, sigma, hold, joint_sigma, return_problem):
    """Errors-in-variables refinement: X, Q and one joint correction per pose with a Gaussian prior."""
    if not hasattr(chain, "jacobian"):
        raise InputError("joint_sigma needs an arm model (D-H chain) to move the joints; with recorded "
                         "end-effector poses give no joint_sigma")
    n, dof = q.shape
    sj = check_array(joint_sigma, "joint_sigma").astype(float)
    if sj.ndim > 1 or sj.size not in (1, dof):
        raise InputError(f"joint_sigma must be one value or {dof} (one per joint), got shape {sj.shape}")
    sj = np.broadcast_to(sj.reshape(-1), (dof,)).copy()
    if not np.all(np.isfinite(sj)) or np.any(sj < 0):
        raise InputError(f"joint_sigma must be finite and >= 0 per joint, got {sj.tolist()}")
    if not np.any(sj > 0):
        raise InputError("joint_sigma is 0 for every joint: leave it out (joint readings exact)")
    sp = float(sigma) if sigma is not None else _pooled_circle_sigma(profiles)
    R0 = X0[:3, :3]
    P = len(m)
    rows = np.arange(P)[:, None]
    cols = idx[:, None] * dof + np.arange(dof)

    def parts(p):
        RX = matrix_from_rotvec(p["X"][:3]) @ R0
        qq = q + p["dq"]
        T = chain.fk(qq)
        pl = m @ RX.T + p["X"][3:]
        w = np.einsum("nij,nj->ni", T[idx, :3, :3], pl) + T[idx, :3, 3]
        return RX, qq, T, pl, w

    def fun(p):
        return np.linalg.norm(parts(p)[4] - p["Q"], axis=1) - Rr

    def jac(p):
        RX, qq, T, pl, w = parts(p)
        d = w - p["Q"]
        u = d / np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
        uE = np.einsum("nji,nj->ni", T[idx, :3, :3], u)
        Jr = np.cross(m @ RX.T, uE)
        # the point moves by v_j + w_j x (w - tip) per joint (geometric Jacobian, in W):
        # d r / d q_j = u . v_j + ((w - tip) x u) . w_j
        uc = np.column_stack([u, np.cross(w - T[idx, :3, 3], u)])
        Jq = np.zeros((P, n * dof))
        Jq[rows, cols] = np.einsum("nk,nkj->nj", uc, chain.jacobian(qq)[idx])
        return {"X": np.column_stack([Jr, uE]), "Q": -u, "dq": Jq}

    labels = list(_LAB) + ["Q.x", "Q.y", "Q.z"]
    prob = Problem()
    prob.add_block("X", np.r_[0.0, 0.0, 0.0, X0[:3, 3]], labels=list(_LAB), unit=["rad"] * 3 + ["m"] * 3,
                   fixed=np.array([k in hold for k in _LAB]))
    prob.add_block("Q", Q0, labels=["Q.x", "Q.y", "Q.z"], unit="m",
                   fixed=np.array([k in hold for k in ("Q.x", "Q.y", "Q.z")]))
    jt = getattr(chain, "joint_types", ("",) * dof)
    prob.add_block("dq", np.zeros((n, dof)), labels=[f"dq[{i}].q{j + 1}" for i in range(n) for j in range(dof)],
                   unit=[("rad" if jt[j] == "revolute" else "m") for _ in range(n) for j in range(dof)],
                   fixed=np.tile(sj == 0, (n, 1)))
    prob.add_residuals(fun, name="point_to_sphere", jacobian=jac, residual_dim=1, sigma=sp)
    # no blocks=["dq"]: a block structure would make the core build an m x n sparsity pattern on
    # every call (~15 ms) that it does not use here (analytic Jacobian, dense: density ~1 either way)
    prob.add_residuals(lambda p: p["dq"].ravel(), name="joint_prior",
                       jacobian=lambda p: {"dq": np.eye(n * dof)}, residual_dim=1,
                       sigma=np.tile(np.where(sj > 0, sj, 1.0), n))
    if return_problem:
        return prob
    # The core's dense trust-region solver costs an SVD of the whole (points x (9 + dof N)) Jacobian
    # per iteration (and ~3-90 iterations); the joint corrections couple only to their own profile
    # and to X, Q (block-arrow normal equations). Converge on those with the per-pose blocks
    # eliminated (Schur complement), then hand the point to the core for the analysis (covariance,
    # rank, outliers: unchanged, on the full Jacobian).
    try:
        pre = _presolve_eiv(q, chain, m, idx, Rr, R0, sp, sj, np.r_[0.0, 0.0, 0.0, X0[:3, 3]], Q0,
                            np.array([k not in hold for k in labels]), loss)
    except (np.linalg.LinAlgError, FloatingPointError, ValueError):
        pre = None  # numerical trouble: the core alone, from the given start, as without the presolve
    gtol = 1e-8  # the core's default
    if pre is not None:
        prob.set_x0("X", pre[0]).set_x0("Q", pre[1]).set_x0("dq", pre[2])
        if pre[3] is not None:
            # converged (the Gauss-Newton step left is < ~1e-8 std): the gradient there is rounding;
            # let the core accept the point as it is (status 'gtol', 0 iterations) and only analyse
            # it, instead of one more dense SVD step that cannot improve it. Not converged: the core
            # goes on from the point with its usual tolerances.
            gtol = max(gtol, pre[3])
    lsq = solve(prob, method="trf", loss=loss, f_scale=3.0, x_scale="jac", xtol=1e-12, ftol=1e-12,
                gtol=gtol)
    p = lsq.params
    r = lsq.obs_residuals("point_to_sphere")
    cov = np.full((9, 9), np.nan)
    fi = [(labels.index(k), j) for j, k in enumerate(lsq.free_labels) if k in labels]
    if fi:
        a, b = map(list, zip(*fi))
        cov[np.ix_(a, a)] = lsq.cov[np.ix_(b, b)]
    std = {k: lsq.std.get(k) for k in labels}
    per_profile = np.array([np.sqrt(np.mean(r[idx == i] ** 2)) if np.any(idx == i) else 0.0 for i in range(n)])
    s = float(np.sqrt(lsq.residual_variance))
    warnings = []
    for w in lsq.warnings:
        if w.code == "outliers" and w.indices:
            pts = [i for i in w.indices if i < P]
            jts = [i - P for i in w.indices if i >= P]
            msg = []
            if pts:
                prof, n_in = np.unique(idx[pts], return_counts=True)
                shown = ", ".join(map(str, pts[:20])) + (", ..." if len(pts) > 20 else "")
                msg.append(f"{len(pts)} of {P} points ({100 * len(pts) / P:.2g} %) lie beyond "
                           f"{lsq.outlier_sigma:.3g} sigma (sigma = {1e6 * sp * s:.3g} um) and were down-weighted "
                           f"by the {loss} loss: points [{shown}]; by profile (points): "
                           + ", ".join(f"{int(i)} ({int(c)})" for i, c in zip(prof, n_in)))
            if jts:
                msg.append(f"joint corrections beyond {lsq.outlier_sigma:.3g} x joint_sigma at pose(s) "
                           + ", ".join(f"{k // dof} (q{k % dof + 1})" for k in jts[:20]))
            w = Diagnostic("outliers", "; ".join(msg), params=w.params, indices=tuple(pts))
        elif w.code == "weakly_determined" or (w.params and all(k.startswith("dq[") for k in w.params)):
            # the joint corrections can mimic much of a change of X (large variance inflation) and the
            # prior settles them: expected, and already in the std; confounding among X and Q alone
            # shows in the refinement without joint_sigma
            continue
        elif w.params:
            w = Diagnostic(w.code, w.message, params=tuple(k for k in w.params if not k.startswith("dq[")),
                           indices=w.indices)
        warnings.append(w)
    X = transform_from(matrix_from_rotvec(p["X"][:3]) @ R0, p["X"][3:])
    return RefineResult(X=X, Q=p["Q"].copy(), cov=cov, std=std, rms=float(np.sqrt(np.mean(r**2))), residuals=r,
                        n_points=P, undetermined=tuple(k for k in labels if std[k] is None), warnings=warnings,
                        lsq=lsq, per_profile_rms=per_profile, sigma=sp * s, dq=p["dq"].copy())


def _loss_weights(z: np.ndarray, loss: str) -> tuple[np.ndarray, np.ndarray]:
    """``rho'(z)`` and ``rho'(z) + 2 z rho''(z)`` of SciPy's losses, ``z = (f / f_scale)^2``.

    The gradient of the cost is ``J^T rho' f``; ``J^T (rho' + 2 z rho'') J`` is the Gauss-Newton
    matrix SciPy's trust-region method uses for a robust loss (floored at machine epsilon)."""
    if loss == "linear":
        return np.ones_like(z), np.ones_like(z)
    r1, r2 = loss_derivatives(z, loss)
    return r1, np.maximum(r1 + 2.0 * z * r2, np.finfo(float).eps)


def _presolve_eiv(q, chain, m, idx, Rr, R0, sp, sj, x_X, x_Q, free_g, loss, *, f_scale=3.0, max_iter=200):
    """Minimise the errors-in-variables cost on its block-arrow normal equations.

    Same residuals (``r / sp`` per point, ``dq / joint_sigma`` per free joint of each pose), loss,
    ``f_scale`` and Jacobian as the problem handed to the core (rotation as a left increment), so
    the minimum is the same; losses ``linear``, ``soft_l1``, ``huber`` (convex) only. Levenberg-
    Marquardt on the reweighted Gauss-Newton system (SciPy's weights for a robust loss): the joint
    corrections ``dq_i`` (a few per pose) are eliminated pose by pose (``S = A - sum_i B_i D_i^-1
    B_i^T``, 9 x 9 at most; a direction ``S`` does not see, X.ty with Q.z without ``hold``, is not
    moved), so an iteration costs O(points), not an SVD of the dense Jacobian. Returns ``(X, Q, dq,
    gtol)``: start values for the core and, if converged (step left < ~1e-8 std), a gradient
    tolerance above the rounding of the gradient there (else None); None if it cannot start.
    """
    if loss not in ("linear", "soft_l1", "huber"):
        # a redescending loss (cauchy, arctan) is not convex: its Gauss-Newton weights vanish and a
        # different descent path can end in a different minimum (with arctan even dq -> infinity,
        # where the prior's cost saturates); the core alone, as without the presolve
        return None
    n, dof = q.shape
    P = len(m)
    fj = sj > 0
    nd = int(fj.sum())
    sjf = sj[fj]
    gi = np.flatnonzero(free_g)
    ng = gi.size
    E = sps.csr_array((np.ones(P), (idx, np.arange(P))), shape=(n, P))  # sums over each profile's points
    pX, Q, dq = np.array(x_X, float), np.array(x_Q, float), np.zeros((n, dof))
    # The Jacobian's rotation columns are derivatives for a left increment, exp(w) exp(p) R0, exact
    # only at p = 0: compose the increments (R_X <- exp(w) R_X) so the model is exact at every step
    # (else a linear crawl near the end). A held rotation component is a fixed coordinate of p,
    # which composed increments do not keep, and with the core's additive steps in p the zero of
    # the left-increment gradient is not the minimum: the core alone then, as without the presolve.
    if not np.all(free_g[:3]):
        return None
    Ra = matrix_from_rotvec(pX[:3]) @ R0  # anchor: R_X = exp(pX[:3]) Ra, pX[:3] = 0
    pX[:3] = 0.0

    # the points are stored profile after profile: per-pose slices (BLAS on (M_i, 3) blocks) instead
    # of gathering one 4 x 4 pose per point
    cuts = np.searchsorted(idx, np.arange(n + 1))
    segs = [(i, slice(cuts[i], cuts[i + 1])) for i in range(n) if cuts[i + 1] > cuts[i]]

    def evaluate(pX, Q, dq, with_jac):
        RX = matrix_from_rotvec(pX[:3]) @ Ra
        qq = q + dq
        T = chain.fk(qq)
        pl = m @ RX.T + pX[3:]
        w = np.empty_like(pl)
        for i, sl in segs:
            w[sl] = pl[sl] @ T[i, :3, :3].T + T[i, :3, 3]
        d = w - Q
        dn = np.linalg.norm(d, axis=1)
        f = np.concatenate([(dn - Rr) / sp, (dq[:, fj] / sjf).ravel()])
        cost = robust_cost(f, loss, f_scale)
        if not with_jac:
            return cost, f
        u = d / np.maximum(dn, 1e-300)[:, None]
        G = chain.jacobian(qq)[:, :, fj]  # (n, 6, nd)
        uE = np.empty_like(u)
        Jd = np.empty((P, nd))
        for i, sl in segs:
            uE[sl] = u[sl] @ T[i, :3, :3]
            # as in _refine_eiv's jac: d r / d q_j = u . v_j + ((w - tip) x u) . w_j
            Jd[sl] = u[sl] @ G[i, :3] + np.cross(w[sl] - T[i, :3, 3], u[sl]) @ G[i, 3:]
        Jg = np.column_stack([np.cross(pl - pX[3:], uE), uE, -u])[:, gi] / sp
        return cost, f, Jg, Jd / sp

    try:
        cost, f, Jg, Jd = evaluate(pX, Q, dq, True)
    except RobocalError:
        return None
    if not np.isfinite(cost) or ng == 0:
        return None

    def _finish(gnorm=None):
        out = pX.copy()
        out[:3] = rotvec_from_matrix(Ra @ R0.T)
        return out, Q, dq, gnorm

    lam = 1e-4
    eye_d = np.eye(nd)
    for _ in range(max_iter):
        wg, wh = _loss_weights((f / f_scale) ** 2, loss)  # gradient and Gauss-Newton weights
        g = wg * f
        gp, hp = g[:P], wh[:P]
        Jgw = Jg * hp[:, None]
        A = Jgw.T @ Jg
        ga = Jg.T @ gp
        B = (E @ (Jgw[:, :, None] * Jd[:, None, :]).reshape(P, ng * nd)).reshape(n, ng, nd)
        D = (E @ ((Jd * hp[:, None])[:, :, None] * Jd[:, None, :]).reshape(P, nd * nd)).reshape(n, nd, nd)
        D = D + (wh[P:].reshape(n, nd) / sjf**2)[:, :, None] * eye_d
        gd = E @ (Jd * gp[:, None]) + g[P:].reshape(n, nd) / sjf
        dA, dD = np.diag(A).copy(), np.einsum("nii->ni", D).copy()
        accepted = False
        while lam < 1e12:
            Dl = D + (lam * dD)[:, :, None] * eye_d
            Di = np.linalg.inv(Dl)
            BDi = B @ Di  # (n, ng, nd)
            S = A + lam * np.diag(dA) - np.einsum("nij,nkj->ik", BDi, B)
            b = -ga + np.einsum("nij,nj->i", BDi, gd)
            # scaled pseudo-inverse: a direction the poses cannot see (X.ty with Q.z) is not moved
            s = np.sqrt(np.where(np.diag(S) > 0, np.diag(S), 1.0))
            ev, V = np.linalg.eigh(S / np.outer(s, s))
            keep = ev > 1e-12 * max(ev[-1], 1e-300)
            dg = (V[:, keep] @ ((V[:, keep].T @ (b / s)) / ev[keep])) / s
            ddq = -np.einsum("nij,nj->ni", Di, gd + np.einsum("nji,j->ni", B, dg))
            step9 = np.zeros(9)
            step9[gi] = dg
            pX_new, Q_new = pX + step9[:6], Q + step9[6:]
            # dec = -g.step ~ the step's size squared in units of the std: stop below ~1e-8 std (the
            # cost itself is only resolved to ~1e-13 relative, hence the tolerance on accepting)
            dec = -(ga @ dg + np.sum(gd * ddq))
            if dec <= 1e-20 * (1.0 + cost):
                # what is left of the gradient is rounding in sums of large terms of both signs
                # (columns of norm ~1e6 here); its size depends on the order of summation, so the
                # core's differs from this one: bound it scale-free, as MINPACK's gtol does, by
                # 1e-10 x (largest column norm) x (norm of the weighted residuals)
                cn = max(np.max(np.linalg.norm(Jg, axis=0)), np.sqrt(np.max(E @ Jd**2)), np.max(1.0 / sjf))
                gmax = max(np.max(np.abs(ga), initial=0.0), np.max(np.abs(gd), initial=0.0))
                return _finish(max(4.0 * gmax, 1e-10 * cn * float(np.linalg.norm(g))))
            dq_new = dq.copy()
            dq_new[:, fj] += ddq
            try:
                cost_new, f_new = evaluate(pX_new, Q_new, dq_new, False)
            except RobocalError:
                cost_new = np.inf
            if np.isfinite(cost_new) and cost_new <= cost + 1e-13 * abs(cost):
                accepted = True
                break
            lam *= 10.0
        if not accepted:
            break
        pX, Q, dq = pX_new, Q_new, dq_new
        Ra = matrix_from_rotvec(pX[:3]) @ Ra
        pX[:3] = 0.0
        cost, f, Jg, Jd = evaluate(pX, Q, dq, True)
        lam = max(lam / 10.0, 1e-12)
    return _finish()  # not converged: the core goes on from here
