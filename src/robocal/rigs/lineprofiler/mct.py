"""MCT -- multi-coordinate transformation (seed 004 §3, eqs. 5-12).

Only the last two joints move (R2, P3), so errors of the joints before them
do not enter; only link 3's D-H row is used.

1. R2 turns: the tracker ball draws an arc -> 3D circle fit: centre ``O_A``,
   axis ``n_A`` (oriented so that increasing q2 turns right-handed about it).
2. P3 slides: the ball draws a line -> line fit: direction ``n_B`` (along +q3).
3. Frame 2 in the tracker (eq. 6): ``z_2 = n_A``, P3's direction
   (``A_3``'s z axis, from the D-H row) ``= n_B``, origin
   ``O_A + (h1 - h0) n_A`` (h0: ball centre above P3's top face, h1: frame 2's
   origin above it). Then ``T_T_E = T_T_2 A_3(q3)`` (eq. 7).
4. Frame K at the ball centre with ``x = n_A``, ``y = n_B`` (eq. 8), kept for
   the report (the block is located in the tracker frame directly).
5. The block is probed by the tracker (three face planes -> ``T_T_B``) and
   scanned during a P3 stroke from ``q30``: profile ``i`` at ``q3_i`` lies in
   the laser frame at ``q30`` shifted by ``(q3_i - q30) u`` (eq. 9), ``u``
   P3's direction in L; their union is the cloud (eq. 10). ``u`` and the
   block pose ``T_L_B`` are fitted jointly to the three face planes
   (eqs. 11-12): ``T_T_L = T_T_B T_L_B^-1``.
6. ``X = T_T_E^-1 T_T_L`` (eq. 5).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from robocal.diagnostics import Diagnostic
from robocal.errors import DegenerateGeometryError, InputError, NotEnoughDataError
from robocal.estimation import analyze_jacobian
from robocal.geometry import (
    fit_circle_3d,
    fit_line,
    fit_plane,
    invert_transform,
    matrix_from_rotvec,
    project_to_rotation,
    rotvec_from_matrix,
    so3_left_jacobian,
    transform_from,
    wahba_rotation,
)
from robocal.kinematics import DHChain
from robocal.validation import check_array, check_points

__all__ = ["MCTResult", "BlockScanFit", "frame2_in_tracker", "block_frame_from_planes", "fit_block_scan",
           "mct_calibrate", "mct_covariance", "ENCODER_SIGMA"]

_X_LABELS = ("X.rx", "X.ry", "X.rz", "X.tx", "X.ty", "X.tz")


@dataclass
class MCTResult:
    """Outcome of :func:`mct_calibrate` (tracker frame T, metres).

    ``X`` = ``T_E_L``; ``T_T_2``, ``T_T_E`` (at ``q30``), ``T_T_K``, ``T_T_B``,
    ``T_L_B``, ``T_T_L``: the intermediate frames of eqs. 6-12; ``u_L``: P3's
    direction in L; ``arc_rms``, ``line_rms``, ``block_rms``, ``scan_rms``:
    fit residuals (m); ``scan_residuals``: point-to-face distances of the
    block scan (m).

    ``X_cov`` (6, 6) over ``X.rx, X.ry, X.rz`` (rotation vector of
    ``R_perturbed R_X^T``, rad, as in :func:`.refine.refine_sphere`) and
    ``X.tx, X.ty, X.tz`` (m), ``X_std`` its root diagonal: first-order
    propagation of the tracker noise (``tracker_sigma``, m per axis), the
    height errors (``height_sigma``, m), the block-scan fit's covariance,
    the P3 encoder's read-out noise of the scan profiles
    (``encoder_sigma``, m per reading) and, when stated, P3's D-H row
    (``dh_sigma``); ``cov_terms`` the standard deviations by source (see
    :func:`mct_covariance`). NaN where the data do not determine X.
    """

    X: np.ndarray
    T_T_2: np.ndarray
    T_T_E: np.ndarray
    T_T_K: np.ndarray
    T_T_B: np.ndarray
    T_L_B: np.ndarray
    T_T_L: np.ndarray
    u_L: np.ndarray
    n_A: np.ndarray
    O_A: np.ndarray
    n_B: np.ndarray
    arc_rms: float
    line_rms: float
    block_rms: float
    scan_rms: float
    n_scan_points: int
    scan_residuals: np.ndarray | None = None
    X_cov: np.ndarray | None = None
    X_std: np.ndarray | None = None
    tracker_sigma: float | None = None
    height_sigma: float | None = None
    dh_sigma: tuple = (0.0, 0.0)
    encoder_sigma: float | None = None
    cov_terms: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)


@dataclass
class BlockScanFit:
    """Outcome of :func:`fit_block_scan` (laser frame L at ``q30``, metres).

    ``T_L_B`` block corner frame, ``u`` P3's direction in L, ``rms`` and
    ``residuals`` point-to-face distances, ``ident`` the fit's
    identifiability (covariance over ``u.a, u.b, B.rx, B.ry, B.rz, B.tx,
    B.ty, B.tz`` scaled by the residual variance). :meth:`perturbed` maps a
    step in those 8 parameters to ``(T_L_B, u)`` -- what error propagation
    differentiates. ``dx_dq3`` (8, S): first-order change of those
    parameters per metre of error in each profile's P3 reading ``q3[i]``
    (implicit-function theorem on the fit's normal equations), for the
    encoder term of :func:`mct_covariance`.
    """

    T_L_B: np.ndarray
    u: np.ndarray
    rms: float
    residuals: np.ndarray
    n_points: int
    ident: object
    x: np.ndarray
    _unpack: object = field(repr=False, default=None)
    dx_dq3: np.ndarray | None = None

    def perturbed(self, dx) -> tuple[np.ndarray, np.ndarray]:
        u, R, t = self._unpack(self.x + np.asarray(dx, float))
        return transform_from(R, t), u


def _link(chain: DHChain, index: int, q_value: float) -> np.ndarray:
    """Transform ``A_i`` of link ``index`` (0-based) at joint value ``q_value``."""
    return chain.link_transform(index, q_value)


def frame2_in_tracker(arc_T, q2_arc, line_T, q3_line, h0: float, h1: float, chain: DHChain):
    """Eq. 6: ``T_T_2`` from the arc (R2) and the line (P3) of the tracker ball.

    Returns ``(T_T_2, O_A, n_A, n_B, arc_fit, line_fit)``.
    """
    arc_T = check_points(arc_T, "arc points", min_count=3)
    line_T = check_points(line_T, "line points", min_count=2)
    q2_arc = check_array(q2_arc, "q2 of the arc", shape=(len(arc_T),))
    q3_line = check_array(q3_line, "q3 of the line", shape=(len(line_T),))
    if np.ptp(q2_arc) < np.deg2rad(5):
        raise DegenerateGeometryError(f"the R2 arc spans only {np.rad2deg(np.ptp(q2_arc)):.3g} deg: "
                                      "turn R2 by at least 5 deg (20-60 deg recommended)")
    if np.ptp(q3_line) <= 0:
        raise DegenerateGeometryError("the P3 stroke has no length: move P3 while the tracker records")
    return _frame2(fit_circle_3d(arc_T), fit_line(line_T), arc_T, q2_arc, line_T, q3_line, h0, h1, chain)


def _frame2(arc, line, arc_T, q2_arc, line_T, q3_line, h0, h1, chain):
    """Eq. 6 from the fitted arc and line (the part of :func:`frame2_in_tracker` after the fits)."""
    lo, hi = np.argmin(q2_arc), np.argmax(q2_arc)
    turn = np.cross(arc_T[lo] - arc.centre, arc_T[hi] - arc.centre)
    n_A = arc.axis * np.sign(turn @ arc.axis)
    n_B = line.direction * np.sign((line_T[np.argmax(q3_line)] - line_T[np.argmin(q3_line)]) @ line.direction)
    # P3's direction in frame 2 from P3's own D-H row; R2's axis is z_2
    A_P3 = _link(chain, chain.n_links - 1, 0.0)
    R_T_2 = wahba_rotation(np.array([[0.0, 0.0, 1.0], A_P3[:3, 2]]), np.array([n_A, n_B]))
    T_T_2 = transform_from(R_T_2, arc.centre + (h1 - h0) * n_A)
    return T_T_2, arc.centre, n_A, n_B, arc, line


def block_frame_from_planes(face_points) -> tuple[np.ndarray, float]:
    """``T_X_B`` of a block corner from points on its three faces ``x_B = 0``, ``y_B = 0``, ``z_B = 0``.

    Each face's plane is fitted (its normal oriented away from the other faces'
    points, i.e. outwards); the rotation is the nearest one to the three
    normals, the origin the planes' intersection. Returns ``(T, rms)``.
    """
    if len(face_points) != 3:
        raise InputError(f"a block corner needs points on 3 faces, got {len(face_points)}")
    fits = [fit_plane(check_points(p, f"face {k} points", min_count=3)) for k, p in enumerate(face_points)]
    allp = np.concatenate(face_points)
    normals, ds = [], []
    for f in fits:
        n, d = f.normal, f.d
        if np.mean(allp @ n - d) > 0:  # other faces' points must lie behind (inside the block)
            n, d = -n, -d
        normals.append(n)
        ds.append(d)
    N = np.array(normals)
    det = np.linalg.det(N)
    if abs(det) < 0.1:
        raise DegenerateGeometryError("block faces are nearly parallel: cannot build the block frame")
    if det < 0:
        raise InputError("block faces are listed in left-handed order: faces 0, 1, 2 must be x_B = 0, y_B = 0, "
                         "z_B = 0 of a right-handed corner frame (swap two of them)")
    corner = np.linalg.solve(N, np.array(ds))
    R = project_to_rotation(N.T)  # columns ~ x_B, y_B, z_B
    rms = float(np.sqrt(np.mean(np.concatenate([f.residuals for f in fits]) ** 2)))
    return transform_from(R, corner), rms


def _segment(cloud: np.ndarray, n_planes: int = 3, tol: float = 0.3e-3, iters: int = 300, n_score: int = 2000):
    """Greedy deterministic RANSAC: label each point with one of ``n_planes`` planes (-1: none).

    All ``iters`` hypotheses of a plane are scored at once on a fixed random
    subset of at most ``n_score`` points (a count, not a fit: the subset ranks
    them as the full cloud would, to within its sampling noise); the best one
    then labels every point. :func:`fit_block_scan` relabels by the fitted
    corner afterwards, so the segmentation only has to be roughly right.
    """
    labels = np.full(len(cloud), -1)
    rest = np.arange(len(cloud))
    rng = np.random.default_rng(12345)  # fixed: segmentation must be repeatable, not random
    for k in range(n_planes):
        if len(rest) < 3:
            break
        P = cloud[rest]
        sub = P[rng.choice(len(P), n_score, replace=False)] if len(P) > n_score else P
        s = rng.integers(0, len(P), (iters, 3))  # repeated indices give a zero normal: skipped
        n = np.cross(P[s[:, 1]] - P[s[:, 0]], P[s[:, 2]] - P[s[:, 0]])
        nn = np.linalg.norm(n, axis=1)
        ok = nn > 1e-12
        if not np.any(ok):
            break
        n = n[ok] / nn[ok, None]
        d = np.einsum("ij,ij->i", n, P[s[ok, 0]])
        score = np.sum(np.abs(sub @ n.T - d) < tol, axis=0)
        j = int(np.argmax(score))
        best = np.abs(P @ n[j] - d[j]) < tol
        labels[rest[best]] = k
        rest = rest[~best]
    return labels


def _block_scan_residuals(mu, su, lu, u0, b1, b2, R0):
    """Residuals of eq. 11 and their analytic Jacobian over ``x = (a, b, w, t)`` (8,).

    Point ``j`` (``mu[j]`` in L, P3 offset ``su[j]``, face ``lu[j]``) lies at
    ``p = mu + su u`` with ``u = v / |v|``, ``v = u0 + a b1 + b b2``; its
    residual is its coordinate along the face normal, ``r = n . (p - t)``
    with ``n = R[:, lu]``, ``R = exp(w) R0``. Derivatives: ``dr/dt = -n``,
    ``dr/dw = (n x (p - t)) J_l(w)``, ``dr/d(a, b) = su n . (I - u u^T) b_k / |v|``.
    """
    rows = np.arange(len(lu))

    def fun(x):
        v = u0 + x[0] * b1 + x[1] * b2
        R = matrix_from_rotvec(x[2:5]) @ R0
        p_B = (mu + su[:, None] * (v / np.linalg.norm(v)) - x[5:8]) @ R  # R^T (p - t)
        return p_B[rows, lu]

    def jac(x):
        v = u0 + x[0] * b1 + x[1] * b2
        nv = np.linalg.norm(v)
        u = v / nv
        n = (matrix_from_rotvec(x[2:5]) @ R0).T[lu]  # (K, 3) face normals in L
        d = mu + su[:, None] * u - x[5:8]
        Jab = su[:, None] * (n @ ((np.eye(3) - np.outer(u, u)) / nv) @ np.column_stack([b1, b2]))
        return np.column_stack([Jab, np.cross(n, d) @ so3_left_jacobian(x[2:5]), -n])

    return fun, jac


def fit_block_scan(profiles, q3, q30: float, size, *, u0=(0.0, -1.0, 0.0), tol: float = 0.3e-3):
    """Eqs. 9-11: P3 direction ``u`` in L and block pose ``T_L_B`` from a scan of the block corner.

    Parameters
    ----------
    profiles : sequence of (M_i, 2) arrays, ``(x, z)`` in L at P3 = ``q3[i]``
    q3 : (S,) P3 readings; ``q30`` the reference reading
    size : block edges (m)
    u0 : starting guess of P3's direction in L (the profiler's nominal scan axis)

    Returns
    -------
    BlockScanFit
    """
    q3 = check_array(q3, "scan q3", shape=(len(profiles),))
    m, s, pid = [], [], []
    for i, p in enumerate(profiles):
        p = check_array(p, f"scan profile {i}", shape=("M", 2))
        m.append(np.column_stack([p[:, 0], np.zeros(len(p)), p[:, 1]]))
        s.append(np.full(len(p), q3[i] - q30))
        pid.append(np.full(len(p), i))
    m = np.concatenate(m)
    s = np.concatenate(s)
    pid = np.concatenate(pid)
    if len(m) < 30:
        raise NotEnoughDataError(f"the block scan has {len(m)} points; at least 30 on the three faces are needed")
    u0 = np.asarray(u0, float) / np.linalg.norm(u0)
    cloud = m + s[:, None] * u0  # eq. 9-10 with the nominal direction (an affine shear of the truth)
    lab = _segment(cloud, 3, tol=tol + 0.05 * np.abs(s).max())  # 3 deg of shear allowed
    use = lab >= 0
    faces = [cloud[lab == k] for k in range(3)]
    if min(len(f) for f in faces) < 10:
        raise DegenerateGeometryError("the block scan does not show three faces: tilt the block so its corner "
                                      "faces the profiler")
    # initial pose from the sheared planes; assign the face order by right-handedness
    fits = [fit_plane(f) for f in faces]
    N = np.array([f.normal * (-1 if f.normal @ (f.centroid - cloud[use].mean(0)) < 0 else 1) for f in fits])
    ds = np.array([n @ f.centroid for n, f in zip(N, fits)])
    if np.linalg.det(N) < 0:
        N[[0, 1]], ds[[0, 1]] = N[[1, 0]], ds[[1, 0]]
        lab = np.where(lab == 0, 1, np.where(lab == 1, 0, lab))
    R0 = project_to_rotation(N.T)
    t0 = np.linalg.solve(N, ds)
    mu, su, lu = m[use], s[use], lab[use]
    b1 = np.cross(u0, [1.0, 0, 0]) if abs(u0[0]) < 0.9 else np.cross(u0, [0, 1.0, 0])
    b1 /= np.linalg.norm(b1)
    b2 = np.cross(u0, b1)

    def unpack(x):
        u = u0 + x[0] * b1 + x[1] * b2
        u /= np.linalg.norm(u)
        return u, matrix_from_rotvec(x[2:5]) @ R0, x[5:8]

    fun, jac = _block_scan_residuals(mu, su, lu, u0, b1, b2, R0)
    x0 = np.r_[0, 0, 0, 0, 0, t0]
    ls = least_squares(fun, x0, jac=jac, method="lm", xtol=1e-12, ftol=1e-12)
    # relabel every point by its nearest face of the fitted corner (dropping far
    # ones) and refit until the labels settle: the first fit starts from the
    # sheared cloud, whose labels near the edges can be wrong
    size = np.asarray(size, float)
    labels = None
    for _ in range(6):
        u, R, t = unpack(ls.x)
        p_B = (m + s[:, None] * u - t) @ R
        inside = np.all(p_B < 3 * tol, axis=1) & np.all(p_B > -size - 3 * tol, axis=1)
        lab2 = np.argmin(np.abs(p_B), axis=1)
        near = inside & (np.abs(p_B[np.arange(len(p_B)), lab2]) < 3 * tol)
        new = np.where(near, lab2, -1)
        if labels is not None and np.array_equal(new, labels):
            break
        labels = new
        mu, su, lu, use = m[near], s[near], lab2[near], near
        fun, jac = _block_scan_residuals(mu, su, lu, u0, b1, b2, R0)
        ls = least_squares(fun, ls.x, jac=jac, method="lm", xtol=1e-12, ftol=1e-12)
    u, R, t = unpack(ls.x)
    r = ls.fun
    s2 = float(r @ r / max(len(r) - 8, 1))
    ident = analyze_jacobian(ls.jac, ["u.a", "u.b", "B.rx", "B.ry", "B.rz", "B.tx", "B.ty", "B.tz"],
                             residual_variance=s2)
    # a reading error e_i of q3[i] moves profile i's points by e_i u: each
    # residual (the point's coordinate along its face normal R[:, lab]) by
    # e_i u.R[:, lab]; the fit answers with dx = -J^+ dr
    D = np.zeros((len(lu), len(profiles)))
    D[np.arange(len(lu)), pid[use]] = (u @ R)[lu]
    dx_dq3 = -np.linalg.pinv(ls.jac) @ D
    return BlockScanFit(transform_from(R, t), u, float(np.sqrt(np.mean(r * r))), r.copy(), int(use.sum()), ident,
                        ls.x.copy(), unpack, dx_dq3)


def _block_permutation(T_T_B, T_L_B, u_L, n_B) -> tuple[int, ...]:
    """A cube corner looks the same after a 120 deg turn about its diagonal, so the
    scan alone cannot say which face is x_B: the cyclic relabelling that maps P3's
    direction in L (``u_L``) onto the tracker's ``n_B``."""
    best = None
    for perm in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        R_T_L = T_T_B[:3, :3] @ T_L_B[:3, perm].T
        score = (R_T_L @ u_L) @ n_B
        if best is None or score > best[0]:
            best = (score, perm)
    return best[1]


def _compose(arc_T, q2_arc, line_T, q3_line, h0, h1, faces, T_L_B, perm, chain, q30, u_L=None):
    """Eqs. 6, 7, 12, 5 from the measurements: ``(X, T_T_2, T_T_E, T_T_B, T_L_B (relabelled), T_T_L, fits)``.

    ``perm=None`` chooses the block's face labelling (:func:`_block_permutation`,
    needs ``u_L``); ``fits`` ends with the permutation used.
    """
    T_T_2, O_A, n_A, n_B, arc, line = frame2_in_tracker(arc_T, q2_arc, line_T, q3_line, h0, h1, chain)
    T_T_E = T_T_2 @ _link(chain, chain.n_links - 1, q30) @ chain.T_tool  # eq. 7
    T_T_B, block_rms = block_frame_from_planes(faces)
    if perm is None:
        perm = _block_permutation(T_T_B, T_L_B, u_L, n_B)
    T_L_B = T_L_B.copy()
    T_L_B[:3, :3] = T_L_B[:3, perm]
    T_T_L = T_T_B @ invert_transform(T_L_B)  # eq. 12
    X = invert_transform(T_T_E) @ T_T_L  # eq. 5
    return X, T_T_2, T_T_E, T_T_B, T_L_B, T_T_L, (O_A, n_A, n_B, arc, line, block_rms, perm)


def _x_delta(X, X0) -> np.ndarray:
    """(6,) rotation vector of ``R R0^T`` and ``t - t0``."""
    return np.r_[rotvec_from_matrix(X[:3, :3] @ X0[:3, :3].T), X[:3, 3] - X0[:3, 3]]


def _tracker_sigma(arc, line, block_rms: float, n_face_points: int) -> float:
    """Per-axis tracker noise (m) pooled from the arc, line and face-plane fits.

    A point's distance to a fitted circle or line has two noise components,
    to a plane one; the fits use 6 (circle), 4 (line) and 3 x 3 (the three
    planes) degrees of freedom. ``block_rms`` is the planes' RMS over their
    ``n_face_points`` points (:func:`block_frame_from_planes`).
    """
    ss = np.sum(arc.residuals ** 2) + np.sum(line.residuals ** 2) + block_rms ** 2 * n_face_points
    dof = 2 * len(arc.residuals) - 6 + 2 * len(line.residuals) - 4 + n_face_points - 9
    return float(np.sqrt(ss / dof)) if dof > 0 else float("nan")


def mct_covariance(data, chain: DHChain, scan: BlockScanFit, perm, X, *, tracker_sigma: float,
                   height_sigma: float, dh_sigma: tuple[float, float] = (0.0, 0.0), encoder_sigma: float = 0.0,
                   step: float = 1e-7) -> tuple[np.ndarray, dict]:
    """First-order covariance (6, 6) of the MCT hand-eye matrix ``X`` (seed 004 eq. 5).

    ``X`` is a function of every tracker point (arc, line, block faces), of
    the two heights and of the block-scan fit's 8 parameters; the three groups
    are independent. Its Jacobian is taken by forward differences (``step`` m
    on the tracker points and heights, the same in the scan's parameter units)
    -- the chain of fits (3D circle, line, three planes, Wahba) has no closed
    form derivative worth writing -- and ``cov = sum_g J_g Sigma_g J_g^T``
    with ``Sigma = tracker_sigma^2 I`` for the tracker, ``height_sigma^2 I``
    for ``(h0, h1)`` and the scan fit's own covariance. Coordinates as
    :attr:`MCTResult.X_cov`. Returns ``(cov, terms)``, ``terms`` the per-group
    contributions to the standard deviations (for the report).

    ``dh_sigma = (length m, angle rad)``: uncertainty of P3's own D-H row
    (``alpha, a, theta, d`` of the last link), the only part of the arm MCT
    uses (eqs. 6-7); its errors otherwise pass into X unseen (the seed
    comparison's 0.3 mm / 0.1 deg arm errors give a 0.3 mm error of X). A
    group ``"D-H row of P3"`` when non-zero.

    ``encoder_sigma`` (m): random read-out error of P3's encoder, independent
    for each scan profile's ``q3`` (eq. 9 places profile ``i`` at
    ``(q3_i - q30) u``, so an error ``e_i`` shifts it by ``e_i u``). It
    enters through the block-scan fit (:attr:`BlockScanFit.dx_dq3`, exact to
    first order), as the group ``"P3 encoder"`` when non-zero. ``q30`` itself
    is only the reference at which both the laser frame and ``T_T_E`` are
    taken (eqs. 7, 9): a common offset of every reading cancels in X, and a
    constant encoder offset is part of P3's D-H row (``d``), covered by
    ``dh_sigma``. R2's encoder and the P3 readings of the tracker line do
    not enter (the arc and line are fitted geometrically; their readings
    only orient the axes). The scan fit's own covariance (``"block scan"``)
    is scaled by its residual variance, which already holds the encoder's
    share as if it were independent point noise -- a double count of
    ``(encoder_sigma |u . n|)^2`` against the profiler's point noise
    (a few % in variance for 10 um vs 37 um).
    """
    q2, q3 = np.asarray(data.q_arc)[:, -2], np.asarray(data.q_line)[:, -1]
    q30 = float(np.asarray(data.q_scan0)[-1])
    arc_T, line_T = np.asarray(data.arc_T, float), np.asarray(data.line_T, float)
    faces = [np.asarray(f, float) for f in data.block_faces_T]
    h = np.array([data.h0, data.h1], float)

    _, _, T_T_E0, T_T_B0, T_L_B0, T_T_L0, (_, _, _, arc0, line0, _, _) = _compose(
        arc_T, q2, line_T, q3, h[0], h[1], faces, scan.T_L_B, perm, chain, q30)
    A_tool = _link(chain, chain.n_links - 1, q30) @ chain.T_tool

    def column(Xp):
        return _x_delta(Xp, X) / step

    def x_from_frame2(arc, line, arc_pts, line_pts, hh):  # frame 2 moved, the laser frame in T did not
        T_T_2 = _frame2(arc, line, arc_pts, q2, line_pts, q3, hh[0], hh[1], chain)[0]
        return invert_transform(T_T_2 @ A_tool) @ T_T_L0

    cols_tr = []
    for k in range(arc_T.size):
        p = arc_T.copy()
        p.flat[k] += step
        cols_tr.append(column(x_from_frame2(fit_circle_3d(p), line0, p, line_T, h)))
    for k in range(line_T.size):
        p = line_T.copy()
        p.flat[k] += step
        cols_tr.append(column(x_from_frame2(arc0, fit_line(p), arc_T, p, h)))
    # a face point moves only its own plane: refit the block frame alone
    inv_T_T_E, inv_T_L_B = invert_transform(T_T_E0), invert_transform(T_L_B0)
    for j, f in enumerate(faces):
        for k in range(f.size):
            fj = f.copy()
            fj.flat[k] += step
            T_T_B, _ = block_frame_from_planes([fj if i == j else faces[i] for i in range(3)])
            cols_tr.append(column(inv_T_T_E @ T_T_B @ inv_T_L_B))
    J_tr = np.array(cols_tr).T
    J_h = np.array([column(x_from_frame2(arc0, line0, arc_T, line_T, h + step * e)) for e in np.eye(2)]).T
    J_s = []
    for e in np.eye(len(scan.x)):
        T_L_B_s, _ = scan.perturbed(step * e)
        T_L_B_s[:3, :3] = T_L_B_s[:3, perm]
        J_s.append(column(inv_T_T_E @ T_T_B0 @ invert_transform(T_L_B_s)))
    J_s = np.array(J_s).T
    C_tr = tracker_sigma ** 2 * J_tr @ J_tr.T
    C_h = height_sigma ** 2 * J_h @ J_h.T
    C_s = J_s @ scan.ident.cov @ J_s.T  # NaN rows of an unidentifiable scan parameter propagate
    cov = C_tr + C_h + C_s
    terms = {"tracker": np.sqrt(np.diag(C_tr)), "heights": np.sqrt(np.diag(C_h)),
             "block scan": np.sqrt(np.diag(C_s))}
    if encoder_sigma > 0:
        J_q = J_s @ scan.dx_dq3  # (6, S): X per metre of error in each scan reading
        C_q = encoder_sigma ** 2 * J_q @ J_q.T
        cov = cov + C_q
        terms["P3 encoder"] = np.sqrt(np.diag(C_q))
    if any(dh_sigma):
        last = chain.n_links
        names = [f"{k}_{last}" for k in ("alpha", "a", "theta", "d")]
        sig = np.array([dh_sigma[1] if k in ("alpha", "theta") else dh_sigma[0]
                        for k in ("alpha", "a", "theta", "d")])
        J_dh = []
        for name in names:
            params = chain.params.copy()
            params[chain.param_names.index(name)] += step
            J_dh.append(column(_compose(arc_T, q2, line_T, q3, h[0], h[1], faces, scan.T_L_B, perm,
                                        chain.with_params(params), q30)[0]))
        J_dh = np.array(J_dh).T
        C_dh = (J_dh * sig**2) @ J_dh.T
        cov = cov + C_dh
        terms["D-H row of P3"] = np.sqrt(np.diag(C_dh))
    return cov, terms


#: Default P3 encoder read-out noise per scan profile (m): 5 um, a linear axis's repeatability and
#: trigger jitter at scan speed; state the real figure (``encoder_sigma``), 0 for exact readings.
ENCODER_SIGMA = 5e-6


def mct_calibrate(data, chain: DHChain, *, tracker_sigma: float | None = None, height_sigma: float = 0.02e-3,
                  dh_sigma: tuple[float, float] = (0.0, 0.0), encoder_sigma: float = ENCODER_SIGMA,
                  covariance: bool = True) -> MCTResult:
    """Hand-eye matrix by the MCT method (seed 004 eqs. 5-12) from :class:`~.simulate.MCTData`-like input.

    ``data`` needs: ``q_arc`` (n, 3), ``arc_T`` (n, 3), ``q_line`` (k, 3),
    ``line_T`` (k, 3), ``h0``, ``h1``, ``q_scan0`` (3,), ``block_faces_T``
    (3 arrays), ``block_size``, ``scan_q3`` (S,), ``scan_profiles``.

    ``tracker_sigma`` (m per axis; default: pooled from the arc, line and
    face fits), ``height_sigma`` (m, the measured ``h0`` and ``h1``),
    ``encoder_sigma`` (m, read-out noise of each scan profile's P3 value;
    default :data:`ENCODER_SIGMA` = 5 um) and ``dh_sigma`` ((m, rad) of
    P3's D-H row; default: taken as exact) set the covariance of ``X``
    (:func:`mct_covariance`); ``covariance=False`` skips it (Monte Carlo
    loops).
    """
    if chain.dof < 2 or chain.joint_types[-2:] != ("revolute", "prismatic"):
        raise InputError(f"MCT needs a chain ending in a revolute then a prismatic joint, got {chain.joint_types}")
    q_arc = check_array(data.q_arc, "q_arc", shape=("n", chain.dof))
    q_line = check_array(data.q_line, "q_line", shape=("n", chain.dof))
    if len(q_arc) != len(data.arc_T):
        raise InputError(f"q_arc has {len(q_arc)} rows but arc_T has {len(data.arc_T)}: counts must match")
    if len(q_line) != len(data.line_T):
        raise InputError(f"q_line has {len(q_line)} rows but line_T has {len(data.line_T)}: counts must match")
    if len(data.scan_q3) != len(data.scan_profiles):
        raise InputError(f"scan_q3 has {len(data.scan_q3)} values but there are {len(data.scan_profiles)} profiles")
    warnings: list[Diagnostic] = []
    for name, qq, moving in (("q_arc", q_arc, chain.dof - 2), ("q_line", q_line, chain.dof - 1)):
        still = [j for j in range(chain.dof) if j != moving]
        drift = np.ptp(qq[:, still], axis=0).max() if still else 0.0
        if drift > 1e-6:
            warnings.append(Diagnostic("inconsistent_data",
                                       f"{name}: joints other than the moving one changed by up to {drift:.3g}"))
    q_scan0 = check_array(data.q_scan0, "q_scan0", shape=(chain.dof,))
    if abs(q_scan0[-2] - q_line[0, -2]) > 1e-9:
        warnings.append(Diagnostic("inconsistent_data", "R2 at the block scan differs from R2 during the P3 stroke; "
                                   "frame 2 is built at the stroke's R2 value"))
    q30 = float(q_scan0[-1])
    # P3 direction in L starts from the nominal scan axis of the profiler
    scan = fit_block_scan(data.scan_profiles, data.scan_q3, q30, data.block_size, u0=(0.0, -1.0, 0.0))
    X, T_T_2, T_T_E, T_T_B, T_L_B, T_T_L, (O_A, n_A, n_B, arc, line, block_rms, perm) = _compose(
        data.arc_T, q_arc[:, -2], data.line_T, q_line[:, -1], data.h0, data.h1, data.block_faces_T, scan.T_L_B,
        None, chain, q30, u_L=scan.u)
    ball = line.point + n_B * ((O_A - line.point) @ n_B)
    y_K = n_B - (n_B @ n_A) * n_A
    y_K /= np.linalg.norm(y_K)
    T_T_K = transform_from(np.column_stack([n_A, y_K, np.cross(n_A, y_K)]), ball)  # eq. 8
    # consistency: P3's direction seen by the tracker (n_B) and by the scan (u in L) must agree through X
    e_dir = np.rad2deg(np.arccos(np.clip((T_T_L[:3, :3] @ scan.u) @ n_B, -1, 1)))
    if e_dir > 0.5:
        warnings.append(Diagnostic("inconsistent_data", f"P3 direction from the block scan and from the tracker "
                                   f"differ by {e_dir:.3g} deg"))
    warnings += list(arc.warnings)
    warnings += scan.ident.diagnostics()
    res = MCTResult(X=X, T_T_2=T_T_2, T_T_E=T_T_E, T_T_K=T_T_K, T_T_B=T_T_B, T_L_B=T_L_B, T_T_L=T_T_L, u_L=scan.u,
                    n_A=n_A, O_A=O_A, n_B=n_B, arc_rms=arc.rms, line_rms=line.rms, block_rms=block_rms,
                    scan_rms=scan.rms, n_scan_points=scan.n_points, scan_residuals=scan.residuals, warnings=warnings)
    if covariance:
        n_face = sum(len(f) for f in data.block_faces_T)
        sig = _tracker_sigma(arc, line, block_rms, n_face) if tracker_sigma is None else float(tracker_sigma)
        dh_sigma = tuple(float(v) for v in dh_sigma)
        if not all(np.isfinite(v) and v >= 0 for v in (sig, height_sigma, encoder_sigma, *dh_sigma)) \
                or len(dh_sigma) != 2:
            raise InputError(f"tracker, height, encoder and D-H sigmas must be finite and >= 0 (dh_sigma a "
                             f"(length, angle) pair), got {sig!r}, {height_sigma!r}, {encoder_sigma!r} and "
                             f"{dh_sigma!r}")
        cov, terms = mct_covariance(data, chain, scan, perm, X, tracker_sigma=sig, height_sigma=float(height_sigma),
                                    dh_sigma=dh_sigma, encoder_sigma=float(encoder_sigma))
        res.X_cov, res.X_std, res.cov_terms = cov, np.sqrt(np.diag(cov)), terms
        res.tracker_sigma, res.height_sigma, res.dh_sigma = sig, float(height_sigma), dh_sigma
        res.encoder_sigma = float(encoder_sigma)
        bad = [lab for lab, v in zip(_X_LABELS, res.X_std) if not np.isfinite(v)]
        if bad:
            warnings.append(Diagnostic("rank_deficient", "no standard deviation for " + ", ".join(bad) +
                                       ": the block scan does not determine them", params=tuple(bad)))
    return res
