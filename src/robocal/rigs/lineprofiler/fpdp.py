"""FPDP -- fixed point, different poses (seed 004 §2, eqs. 3-4).

A precision sphere of known radius ``R`` stays fixed while the arm scans it
from many poses. Per profile: fit a circle in the laser plane (centre
``(x_c, z_c)``, radius ``r_c``); the sphere centre in L is
``c = (x_c, s sqrt(R^2 - r_c^2), z_c)`` with a sign ``s`` the profile alone
cannot tell. Because the centre ``Q`` is fixed in the world,
``T_W_E(q_i) X c_i = Q`` for every pose (eq. 3), which is linear in the
entries of ``R_X``, ``t_X`` and ``Q``: ``G x = F`` (eq. 4), solved by least
squares, then ``R_X`` is projected onto SO(3) and ``t_X, Q`` re-solved.

When every end-effector rotation is about one axis (the seed's P1R2P3 arm),
``G`` is rank deficient: X's translation along that axis and ``Q``'s
component along it enter only as a sum. The seed reports ``p_y = 0`` there;
this module names the undetermined components (``rank_deficient`` warning)
and reports no value (``None``/NaN) for them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import DegenerateGeometryError, InputError, NotEnoughDataError, RobocalError
from robocal.estimation import analyze_jacobian
from robocal.geometry import fit_circle_2d, project_to_rotation, transform_from
from robocal.kinematics import DHChain
from robocal.validation import check_array

__all__ = ["CircleCut", "FPDPResult", "circle_cuts", "fpdp_calibrate", "X_LABELS", "T_LABELS"]

X_LABELS = tuple(f"X.r{i}{j}" for i in range(1, 4) for j in range(1, 4)) + ("X.tx", "X.ty", "X.tz")
T_LABELS = ("X.tx", "X.ty", "X.tz", "Q.x", "Q.y", "Q.z")


@dataclass(frozen=True)
class CircleCut:
    """Circle fitted to one profile: ``centre (x_c, z_c)`` and ``radius`` (m) in L, its RMS and point count."""

    index: int
    centre: np.ndarray
    radius: float
    rms: float
    n_points: int
    radius_std: float


@dataclass
class FPDPResult:
    """Outcome of :func:`fpdp_calibrate`.

    Attributes
    ----------
    X : ndarray (4, 4)
        ``T_E_L``; undetermined translation components hold their share of the
        least-squares minimum-norm solution (e.g. ``X.ty`` and ``Q.z`` split
        their sum; not 0 in general) only so that ``X`` and ``Q`` together can
        seed a refinement -- never report them, and move them only together.
    Q : ndarray (3,)
        Sphere centre in the world (undetermined components likewise).
    undetermined : tuple of str
        Labels (``X.tx``.. ``Q.z``) the data cannot determine.
    t_std, Q_std : ndarray (3,)
        Standard deviations (NaN where undetermined).
    centres_L : ndarray (N, 3)
        Sphere centre in L per used profile; ``signs`` (N,) the chosen side.
    residuals : ndarray (N, 3)
        ``T_W_E(q_i) X c_i - Q`` (m).
    """

    X: np.ndarray
    Q: np.ndarray
    undetermined: tuple
    t_std: np.ndarray
    Q_std: np.ndarray
    rot_std: float
    centres_L: np.ndarray
    signs: np.ndarray
    cuts: list
    used: np.ndarray
    residuals: np.ndarray
    rms: float
    rank: int
    n_unknowns: int
    warnings: list = field(default_factory=list)

    def translation_report(self) -> dict:
        """``{"tx": value or None, ...}``: None for undetermined components."""
        return {k[2:]: (None if k in self.undetermined else float(self.X[i, 3]))
                for i, k in enumerate(("X.tx", "X.ty", "X.tz"))}


def circle_cuts(profiles, *, min_points: int = 10, max_rms: float | None = None):
    """Fit a circle to each profile; returns (cuts, dropped indices with reasons)."""
    cuts, dropped = [], []
    for i, p in enumerate(profiles):
        pts = check_array(p, f"profile {i}", shape=("M", 2))
        if pts.ndim != 2 or len(pts) < min_points:
            dropped.append((i, f"{len(pts)} points < {min_points}"))
            continue
        try:
            fit = fit_circle_2d(pts)
        except RobocalError as exc:
            dropped.append((i, str(exc)))
            continue
        if max_rms is not None and fit.rms > max_rms:
            dropped.append((i, f"circle rms {fit.rms:.3g} m > {max_rms:.3g} m"))
            continue
        cuts.append(CircleCut(i, fit.centre, fit.radius, fit.rms, len(pts), float(fit.std[2])))
    return cuts, dropped


def _system(T_W_E: np.ndarray, c_L: np.ndarray):
    """G (3N, 15), F (3N,) of eq. 4: R_E R_X c + R_E t_X - Q = -p_E, x = [vec_r(R_X), t_X, Q]."""
    n = len(c_L)
    G = np.zeros((n, 3, 15))
    RE = T_W_E[:, :3, :3]
    G[:, :, :9] = np.einsum("nij,nk->nijk", RE, c_L).reshape(n, 3, 9)
    G[:, :, 9:12] = RE
    G[:, :, 12:] = -np.eye(3)
    return G.reshape(-1, 15), -T_W_E[:, :3, 3].reshape(-1)


def _lsq_rms(G, F):
    x, *_ = np.linalg.lstsq(G, F, rcond=1e-10)
    r = G @ x - F
    return float(np.sqrt(np.mean(r * r))), x


def _centres(cuts, R, signs):
    r = np.array([c.radius for c in cuts])
    y = np.sqrt(np.maximum(R * R - r * r, 0.0))
    return np.column_stack([[c.centre[0] for c in cuts], signs * y, [c.centre[1] for c in cuts]])


def _assign(T_W_E, cuts, R, x):
    """Per-pose sign closest to a candidate solution x = [vec R_X, t_X, Q]."""
    Mx = x[:9].reshape(3, 3)
    out = np.empty(len(cuts))
    for s0 in (1.0, -1.0):
        c = _centres(cuts, R, np.full(len(cuts), s0))
        w = np.einsum("nij,nj->ni", T_W_E[:, :3, :3], c @ Mx.T + x[9:12]) + T_W_E[:, :3, 3]
        d = np.linalg.norm(w - x[12:], axis=1)
        if s0 > 0:
            dp = d
        else:
            out = np.where(dp <= d, 1.0, -1.0)
    return out


def _auto_signs(T_W_E, cuts, R, k: int = 6):
    """Sign pattern by consistency across poses.

    Exhaustive over the 2^k patterns of a few k-pose subsets (the cuts
    farthest from the centre plane first, where the side matters), each
    candidate extended to all poses by picking the nearer centre, and the
    pattern with the smallest full least-squares residual kept.
    """
    n = len(cuts)
    r = np.array([c.radius for c in cuts])
    order = np.argsort(r)  # small circle = far from the centre plane
    k = min(k, n)
    subsets = [order[:k], order[k:2 * k], order[::max(n // k, 1)][:k], order[n // 3:n // 3 + k]]
    pats = ((np.arange(2**k)[:, None] >> np.arange(k)) & 1) * 2.0 - 1.0
    best = (np.inf, np.ones(n))
    for sub in subsets:
        if len(sub) < min(5, n):
            continue
        sub = np.asarray(sub)
        for pat in pats[:, : len(sub)]:
            signs = np.ones(n)
            signs[sub] = pat
            G, F = _system(T_W_E[sub], _centres([cuts[i] for i in sub], R, pat))
            x, *_ = np.linalg.lstsq(G, F, rcond=1e-10)
            if np.linalg.det(x[:9].reshape(3, 3)) <= 0:
                continue
            full = _assign(T_W_E, cuts, R, x)
            rms, xf = _lsq_rms(*_system(T_W_E, _centres(cuts, R, full)))
            # flipping every sign mirrors the centres: the linear system then fits an
            # improper "rotation" (det -1) just as well -- only det > 0 is physical
            if rms < best[0] and np.linalg.det(xf[:9].reshape(3, 3)) > 0:
                best = (rms, full)
    rms, signs = best
    for _ in range(n):  # polish: single flips while they lower the residual
        improved = False
        for i in range(n):
            trial = signs.copy()
            trial[i] *= -1
            r2, xt = _lsq_rms(*_system(T_W_E, _centres(cuts, R, trial)))
            if r2 < rms * (1 - 1e-9) and np.linalg.det(xt[:9].reshape(3, 3)) > 0:
                rms, signs, improved = r2, trial, True
        if not improved:
            break
    return signs


def fpdp_calibrate(q, profiles, chain: DHChain, sphere_radius: float, *, sign="auto", min_points: int = 10,
                   min_profiles: int = 5) -> FPDPResult:
    """Hand-eye matrix from a fixed sphere scanned from many poses (seed 004 eqs. 3-4).

    Parameters
    ----------
    q : array_like, shape (N, dof)
        Joint readings per profile (m, rad).
    profiles : sequence of array_like, shape (M_i, 2)
        ``(x, z)`` points in L (m) on the sphere.
    chain : DHChain
        Arm model giving ``T_W_E(q)``.
    sphere_radius : float
        Known radius (m).
    sign : {'auto', +1, -1}
        Side of the laser plane the sphere centre is on (``y_L`` sign).
        ``'auto'``: the sign pattern with the smallest closure residual
        (all +, all -, then single flips while they help).
    min_points : int
        Profiles with fewer points are dropped (``dropped`` warning).

    Raises
    ------
    NotEnoughDataError
        Fewer than ``min_profiles`` usable profiles.
    """
    q = chain.check_q(q)
    if q.ndim != 2:
        raise InputError(f"q must have shape (N, {chain.dof}), got {q.shape}")
    if len(q) != len(profiles):
        raise InputError(f"q has {len(q)} poses but there are {len(profiles)} profiles: counts must match")
    R = float(sphere_radius)
    if not R > 0:
        raise InputError(f"sphere_radius must be > 0, got {sphere_radius!r}")
    cuts, dropped = circle_cuts(profiles, min_points=min_points)
    warnings: list[Diagnostic] = []
    if dropped:
        warnings.append(Diagnostic("dropped", "profiles not used: " + "; ".join(f"#{i}: {why}" for i, why in dropped),
                                   indices=tuple(i for i, _ in dropped)))
    if len(cuts) < min_profiles:
        raise NotEnoughDataError(
            f"FPDP needs at least {min_profiles} profiles with >= {min_points} sphere points each, got {len(cuts)} "
            f"(dropped: {', '.join(f'#{i} ({w})' for i, w in dropped)})")
    used = np.array([c.index for c in cuts])
    big = [c.index for c in cuts if c.radius > R + 3 * max(c.radius_std, 1e-9)]
    if big:
        warnings.append(Diagnostic("inconsistent_data", f"circle radius exceeds the sphere radius {R:g} m in "
                                   f"{len(big)} profile(s): wrong radius or not a sphere cut", indices=tuple(big)))
    T_W_E = chain.fk(q[used])
    if sign == "auto":
        signs = _auto_signs(T_W_E, cuts, R)
    elif sign in (1, -1, 1.0, -1.0):
        signs = np.full(len(cuts), float(sign))
    else:
        raise InputError(f"sign must be 'auto', +1 or -1, got {sign!r}")
    c_L = _centres(cuts, R, signs)
    G, F = _system(T_W_E, c_L)
    labels = list(X_LABELS) + ["Q.x", "Q.y", "Q.z"]
    ident = analyze_jacobian(G, labels)
    _, x = _lsq_rms(G, F)
    R_X = project_to_rotation(x[:9].reshape(3, 3))
    # step 2: t_X and Q with R_X fixed (linear, may still be rank deficient)
    G2 = G[:, 9:]
    F2 = F - G[:, :9] @ R_X.reshape(-1)
    ident2 = analyze_jacobian(G2, list(T_LABELS))
    x2, *_ = np.linalg.lstsq(G2, F2, rcond=1e-10)
    res = (G2 @ x2 - F2).reshape(-1, 3)
    dof = max(G2.shape[0] - ident2.rank, 1)
    s2 = float(np.sum(res**2) / dof)
    ident2 = ident2.with_variance(s2)
    undetermined = tuple(lab for lab in T_LABELS if lab in ident2.unidentifiable)
    if undetermined:
        dirs = "; ".join(ident2.null_directions())
        warnings.append(Diagnostic(
            "rank_deficient",
            f"FPDP: G has rank {ident.rank} < {len(labels)} (seed 004 §4.3): the data cannot determine "
            f"{', '.join(undetermined)} -- every rotation of the end effector is about one axis; "
            f"unobservable direction: {dirs}. No value is reported for them.",
            params=undetermined))
    if ident.rank < 12 and not undetermined:
        raise DegenerateGeometryError(f"FPDP: the poses do not determine the rotation of X (rank {ident.rank})")
    if len(cuts) < len(q) and not dropped:
        pass
    t_std = ident2.std[:3]
    Q_std = ident2.std[3:]
    # rotation spread: the unconstrained 3x3 block's deviation from orthonormality is its noise scale
    rot_std = float(np.linalg.norm(x[:9].reshape(3, 3) - R_X) / 3)
    X = transform_from(R_X, x2[:3])
    return FPDPResult(X=X, Q=x2[3:].copy(), undetermined=undetermined, t_std=t_std, Q_std=Q_std, rot_std=rot_std,
                      centres_L=c_L, signs=signs, cuts=cuts, used=used, residuals=res,
                      rms=float(np.sqrt(np.mean(res**2))), rank=ident.rank, n_unknowns=len(labels), warnings=warnings)
