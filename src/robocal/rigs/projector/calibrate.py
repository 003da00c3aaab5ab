"""World-to-projector extrinsic calibration (seed 000, §2.2) and two better solvers.

Data: floor points measured in the world ``^W P_i`` (z = 0) and the same spots
in the projector frame ``^0 P_i = f(theta_i)`` from the joint angles (seed
eq. 6). Unknown: ``R_0_W, t_0_W`` with ``^0P = R ^WP + t`` (seed eq. 1).

Three solvers:

(a) :func:`seed_method` -- the seed's algorithm as published: unit difference
    vectors (eq. 12), a closed-form initial rotation from composed Gibbs
    vectors (eqs. 15-23) and the iterative refinement of eqs. (24)-(29) with
    the Moore-Penrose pseudo-inverse, keeping the cost per iteration (Fig. 4).
(b) :func:`closed_form` -- the maximum-likelihood rigid fit (Umeyama/Kabsch,
    :func:`robocal.geometry.rigid_fit`) for any N >= 3.
(c) :func:`nonlinear` -- least squares on the floor-plane spot error with
    :mod:`robocal.estimation`: yaw and floor translation, optionally
    ``h = H - d1`` and the tilt zero offset; covariance included.

Noise model: the world measurements ``^W P`` (tape, total station) carry
isotropic floor noise ``sigma`` per coordinate; the joint encoders carry
``joint_noise`` (pan, tilt), mapped to the floor per point by the spot model's
joint Jacobian (:func:`floor_covariance`, issue 19).
Because ``{W}``'s floor (z_W = 0) and the model's floor (z_0 = -H) are both
planes, a rigid transform between them is a rotation about ``z`` plus a
translation: only the yaw, ``t_x``, ``t_y`` are determined by floor points
(``t_z = -H`` by definition of ``{0}``; a roll/pitch of the base would
violate the model's level-floor assumption, seed §2.1).
"""

from __future__ import annotations

import math
import sys
import warnings
from dataclasses import dataclass, field

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import (
    ConvergenceError,
    RobocalError,
    DegenerateGeometryError,
    InconsistentDataError,
    InputError,
    NotEnoughDataError,
    ShapeError,
    UnitError,
)
from robocal.estimation import Problem, solve
from robocal.geometry import (
    compose_gibbs,
    matrix_from_gibbs,
    matrix_from_rotvec,
    rigid_fit,
    rotation_angle,
    rotx,
    roty,
    rotz,
    skew,
)
from robocal.rigs.projector.model import NearSingularityWarning, ProjectorModel, UnreachablePointError
from robocal.validation import check_array

__all__ = [
    "ExtrinsicEstimate",
    "ConsistencyReport",
    "CalibrationRun",
    "check_correspondences",
    "distance_consistency",
    "seed_initial_rotation",
    "seed_method",
    "closed_form",
    "nonlinear",
    "calibrate",
    "yaw_of",
    "floor_pose_jacobian",
    "floor_prediction_columns",
    "rotation_error",
    "beyond_tilt_limit",
    "floor_covariance",
    "deleted_residual_outliers",
    "spread_ratio",
    "TILT_OFFSET_LIMIT",
]

METHODS = ("seed", "closed_form", "nonlinear")


def yaw_of(R) -> np.ndarray:
    """Rotation angle about ``z`` (rad) of (..., 3, 3) matrices: ``atan2(R10, R00)``."""
    R = np.asarray(R, dtype=float)
    return np.arctan2(R[..., 1, 0], R[..., 0, 0])


# ----------------------------------------------------------------------- checks
def _as_floor_points(p, name: str, *, z=None) -> np.ndarray:
    p = check_array(p, name)
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ShapeError(f"{name} must have shape (N, 2) or (N, 3), got {tuple(p.shape)}")
    if p.shape[1] == 2:
        p = np.column_stack([p, np.full(p.shape[0], 0.0 if z is None else z)])
    return p


def check_correspondences(points_W, points_0, *, min_points: int = 3, rel_tol: float = 1e-6,
                          unit_check: bool = True):
    """Validate paired floor points; returns ``(points_W, points_0)`` as (N, 3) float arrays (m).

    Every test is O(N log N) in time and O(N) in memory (a k-d tree for duplicates,
    distances to the centroid for the unit check), so 10^6 points are checked in seconds.

    Parameters
    ----------
    points_W : array_like, shape (N, 2) or (N, 3)
        World floor points (z = 0 when 2 columns are given).
    points_0 : array_like, shape (N, 3)
        The same spots in ``{0}`` (all at ``z_0 = -H``).
    unit_check : bool
        Raise :class:`UnitError` when the two sets differ in scale by more than 2x
        (:func:`calibrate` does this check itself, naming the likely slip).

    Raises
    ------
    ShapeError, NonFiniteError
        Wrong shapes, NaN/inf.
    NotEnoughDataError
        Fewer than ``min_points`` pairs.
    DegenerateGeometryError
        Duplicated points (named by index) or all points on one line.
    UnitError
        Distances in the two frames differ by a factor typical of mixed units.
    """
    from scipy.spatial import cKDTree

    pw = _as_floor_points(points_W, "points_W")
    p0 = check_array(points_0, "points_0")
    if p0.ndim != 2 or p0.shape[1] != 3:
        raise ShapeError(f"points_0 must have shape (N, 3), got {tuple(p0.shape)}")
    if pw.shape[0] != p0.shape[0]:
        raise ShapeError(f"points_W and points_0 must hold the same number of points, got {pw.shape[0]} and "
                         f"{p0.shape[0]}")
    n = pw.shape[0]
    if n < min_points:
        raise NotEnoughDataError(f"extrinsic calibration needs at least {min_points} non-collinear floor points, "
                                 f"got {n}")
    scale = max(np.ptp(pw, axis=0).max(), np.ptp(p0, axis=0).max(), 1e-300)
    for name, p in (("points_W", pw), ("points_0", p0)):
        dist, idx = cKDTree(p).query(p, k=2)  # the nearest other point of each
        dup = np.flatnonzero(dist[:, 1] <= rel_tol * scale)
        if dup.size:
            i = int(dup[0])
            j = int(idx[i, 1]) if int(idx[i, 1]) != i else int(idx[i, 0])
            raise DegenerateGeometryError(f"{name}: points {min(i, j)} and {max(i, j)} coincide (duplicated point)")
        c = p - p.mean(axis=0)
        sv = np.linalg.svd(c, compute_uv=False)
        if sv[1] <= 1e-6 * sv[0]:
            raise DegenerateGeometryError(f"{name}: all {n} points lie on one line (second singular value "
                                          f"{sv[1] / sv[0]:.2g} of the first): the rotation about it is undetermined")
    if unit_check:
        ratio = spread_ratio(pw, p0)
        if not 0.5 < ratio < 2.0:
            raise UnitError(f"distances in {{0}} are {ratio:.3g} times those in {{W}}: are the two point sets "
                            f"in the same length unit (m, cm, mm)?")
    return pw, p0


def spread_ratio(points_W, points_0) -> float:
    """Median over the points of ``|^0P_i - c_0| / |^WP_i - c_W|`` (c: centroids), O(N).

    1 for a rigid correspondence; 1000 when one set is in mm and the other in m.
    The median keeps one gross outlier from moving it.
    """
    pw = np.asarray(points_W, dtype=float)[:, :2]
    p0 = np.asarray(points_0, dtype=float)[:, :2]
    dw = np.linalg.norm(pw - pw.mean(axis=0), axis=1)
    d0 = np.linalg.norm(p0 - p0.mean(axis=0), axis=1)
    ok = dw > 1e-3 * max(float(dw.max()), 1e-300)
    return float(np.median(d0[ok] / dw[ok]))


#: Peak working memory of :func:`calibrate` per point (bytes): 1.4 kB measured at 10^6 points (BENCHMARKS.md),
#: with margin; checked before the work starts (robocal.resources.require_memory).
CAL_BYTES_PER_POINT = 2048
#: Above this many points the steps that then take seconds show a progress bar (on a terminal).
LARGE_N = 50_000
#: Above this many points the pairwise check uses anchor points (O(N) pairs) instead of all N (N - 1) / 2 pairs.
ALL_PAIRS_MAX = 100
#: Number of anchor points of the O(N) pairwise check.
N_ANCHORS = 64
#: The O(N) check keeps at most this many bad pairs (the worst), names at most MAX_SUSPECTS points and tabulates
#: at most MAX_TABLE_PAIRS pairs: a model error (a wrong h or tilt offset) can make most pairs bad.
MAX_KEPT_PAIRS = 1_000_000
MAX_SUSPECTS = 200
MAX_TABLE_PAIRS = 10_000
#: Family-wise false-alarm rate of the pairwise check when the noise is stated (Bonferroni over the pairs).
CONSISTENCY_ALPHA = 0.01


@dataclass
class ConsistencyReport:
    """Pairwise-distance check of a rigid correspondence set (before solving).

    A rigid transform preserves distances, so ``|^W P_i - ^W P_j|`` must equal
    ``|^0 P_i - ^0 P_j|`` up to noise. ``pairs`` lists ``(i, j, d_W, d_0,
    d_0 - d_W, relative)`` (m) of every pair checked when there are at most
    :data:`ALL_PAIRS_MAX` points (else only the bad ones); ``bad_pairs`` those
    beyond tolerance; ``suspects`` the points whose removal explains the bad
    pairs, the most implicated first; ``n_pairs`` the number of pairs checked.
    """

    pairs: list
    bad_pairs: list
    suspects: list
    threshold: str
    warnings: list = field(default_factory=list)
    scale: float | None = None  # relative distance error shared by all pairs, when it explains the bad pairs
    n_pairs: int = 0

    @property
    def consistent(self) -> bool:
        return not self.bad_pairs

    def rows(self, limit: int = 5000) -> list[dict]:
        bad = {(b[0], b[1]) for b in self.bad_pairs}
        return [dict(i=i, j=j, d_W=dw, d_0=d0, diff=df, rel=rel, ok=(i, j) not in bad)
                for i, j, dw, d0, df, rel in self.pairs[:limit]]


def _pair_index(n: int):
    """Yields ``(i, j)`` index arrays of the pairs to check, in chunks of O(N).

    Up to :data:`ALL_PAIRS_MAX` points: all pairs ``i < j``. Above: each of
    :data:`N_ANCHORS` anchor points (evenly spread over the index) with every
    other point, each pair once. A bad point then meets 64 anchors (so it is
    still in the most bad pairs), and a bad anchor meets every point.
    """
    if n <= ALL_PAIRS_MAX:
        iu, ju = np.triu_indices(n, 1)
        yield iu, ju
        return
    anchors = np.unique(np.linspace(0, n - 1, N_ANCHORS).round().astype(int))
    is_anchor = np.zeros(n, bool)
    for k, a in enumerate(anchors):
        is_anchor[a] = True
        j = np.flatnonzero(~is_anchor)  # earlier anchors already met this one
        yield np.full(j.size, a), j


def _pair_sigma(pw, p0, cov0, i, j, sigma):
    """Std (m) of ``d_0 - d_W`` for pairs ``(i, j)``: world noise on both points, plus the joint-noise
    covariance ``cov0`` (N, 2, 2) of the {0} spots projected on the pair's direction."""
    var = np.full(i.size, 2.0 * sigma * sigma)
    if cov0 is not None:
        u = p0[j, :2] - p0[i, :2]
        u /= np.maximum(np.linalg.norm(u, axis=1), 1e-300)[:, None]
        C = cov0[i] + cov0[j]
        var += np.einsum("ni,nij,nj->n", u, C, u)
    return np.sqrt(var)


def distance_consistency(points_W, points_0, *, sigma: float | None = None, n_sigma: float | None = None,
                         rel_tol: float = 0.02, scale_hint: str = "the model's scale is wrong",
                         cov_0=None, alpha: float = CONSISTENCY_ALPHA) -> ConsistencyReport:
    """Compare pairwise distances in ``{W}`` and ``{0}`` and name inconsistent points.

    Threshold per pair: ``n_sigma`` times the std of ``d_0 - d_W`` when the world
    noise ``sigma`` (m) is known (``sqrt(2) sigma``, plus the joint noise's
    covariance ``cov_0`` (N, 2, 2, m^2, in ``{0}``) of both spots along the
    pair), else ``rel_tol`` of the distance. Default ``n_sigma``: the two-sided
    Gaussian quantile of ``alpha / n_pairs`` (Bonferroni), so that a consistent
    set raises a false alarm with probability <= ``alpha`` whatever N (4.0 sigma
    for 190 pairs, 5.6 for 640 000). Suspects are found greedily: the point in
    most bad pairs (ties: the larger summed excess) is removed until no bad pair
    is left, so the worst point is named first.

    Memory and time are O(N): above :data:`ALL_PAIRS_MAX` points only the pairs
    with :data:`N_ANCHORS` anchor points are checked (see :func:`_pair_index`).

    A model error (``H - d1`` or the tilt offset wrong) scales every ``{0}``
    distance alike, which would make most points "suspects". So with N >= 4,
    when removing one relative scale ``d_0 ~ (1 + s) d_W`` (the median ratio) leaves
    at most a third of the bad pairs, the warning reports the scale ``s`` and
    ``scale_hint`` instead, and names only the points still inconsistent after it.
    """
    from scipy import special

    from robocal.progress import progress

    pw, p0 = check_correspondences(points_W, points_0, unit_check=False)
    n = pw.shape[0]
    n_pairs = n * (n - 1) // 2 if n <= ALL_PAIRS_MAX else sum(len(i) for i, _ in _pair_index(n))
    if sigma and n_sigma is None:
        n_sigma = max(3.0, float(math.sqrt(2.0) * special.erfcinv(alpha / max(n_pairs, 1))))
    elif n_sigma is None:
        n_sigma = 4.0
    cov0 = None if cov_0 is None else np.asarray(cov_0, dtype=float)

    def chunks():
        for i, j in _pair_index(n):
            dW = np.linalg.norm(pw[i, :2] - pw[j, :2], axis=1)
            d0 = np.linalg.norm(p0[i, :2] - p0[j, :2], axis=1)
            lim = n_sigma * _pair_sigma(pw, p0, cov0, i, j, sigma) if sigma else rel_tol * dW
            yield i, j, dW, d0, lim

    keep_all = n <= ALL_PAIRS_MAX
    # the median relative difference, for the scale test below: from the first anchors' pairs (O(N))
    ratios = []
    for i, j in _pair_index(n):
        ratios.append((np.linalg.norm(p0[i, :2] - p0[j, :2], axis=1) - np.linalg.norm(pw[i, :2] - pw[j, :2], axis=1))
                      / np.linalg.norm(pw[i, :2] - pw[j, :2], axis=1))
        if len(ratios) >= 8:
            break
    sc_med = float(np.median(np.concatenate(ratios)))  # the median: one bad point must not drag the scale
    stream = progress(chunks(), desc="pairwise distances", total=N_ANCHORS, enabled=n > LARGE_N)
    parts = []
    n_bad_all = n_after_all = 0
    per_chunk = MAX_KEPT_PAIRS // N_ANCHORS
    for i, j, dW, d0, lim in stream:
        if keep_all:
            parts.append((i, j, dW, d0, lim))
            continue
        # keep only the pairs bad as they are or after removing the median scale, and of those at most
        # per_chunk with the largest excess: a model error can make most of 64 N pairs bad (O(N) memory)
        diff = d0 - dW
        ex = np.maximum(np.abs(diff), np.abs(diff - sc_med * dW)) / lim
        n_bad_all += int(np.count_nonzero(np.abs(diff) > lim))
        n_after_all += int(np.count_nonzero(np.abs(diff - sc_med * dW) > lim))
        b = np.flatnonzero(ex > 1.0)
        if b.size > per_chunk:
            b = b[np.argpartition(-ex[b], per_chunk)[:per_chunk]]
        parts.append((i[b], j[b], dW[b], d0[b], lim[b]))
    cat = [np.concatenate(x) for x in zip(*parts)]
    ii, jj, dW, d0, lim = cat
    diff = d0 - dW
    is_bad = np.abs(diff) > lim
    threshold = (f"{n_sigma:.3g} sigma of d_0 - d_W (sqrt(2) x {sigma * 1e3:.3g} mm world noise"
                 + (", plus the joint noise along each pair" if cov0 is not None else "")
                 + f"; {n_pairs} pairs, false-alarm rate <= {100 * alpha:g} %)" if sigma
                 else f"{100 * rel_tol:g} % of the distance")
    scale = None
    blamed = is_bad
    n_bad = int(is_bad.sum()) if keep_all else n_bad_all
    if n >= 4 and n_bad >= 3:
        sc = sc_med
        after = np.abs(diff - sc * dW) > lim
        n_after = int(after.sum()) if keep_all else n_after_all
        if n_after <= n_bad / 3:
            scale, blamed = sc, after
    suspects: list[int] = []
    left_i, left_j = ii[blamed], jj[blamed]
    excess = (np.abs(diff) / lim)[blamed]
    while left_i.size and len(suspects) < MAX_SUSPECTS:
        both = np.concatenate([left_i, left_j])
        counts = np.bincount(both, minlength=n).astype(float)
        ex = np.bincount(both, weights=np.concatenate([excess, excess]), minlength=n)
        k = int(np.argmax(counts + 0.5 * ex / (ex.max() + 1.0)))  # count first; the excess breaks ties
        suspects.append(k)
        keep = (left_i != k) & (left_j != k)
        left_i, left_j, excess = left_i[keep], left_j[keep], excess[keep]
    more = bool(left_i.size)
    if not keep_all:  # the table: the worst bad pairs first
        order = np.flatnonzero(is_bad)
        order = order[np.argsort(-(np.abs(diff) / lim)[order])][:MAX_TABLE_PAIRS]
        ii, jj, dW, d0, diff, lim, is_bad = (a[order] for a in (ii, jj, dW, d0, diff, lim, is_bad))
    sel = slice(None) if keep_all else is_bad
    rows = list(zip(ii[sel].tolist(), jj[sel].tolist(), dW[sel].tolist(), d0[sel].tolist(), diff[sel].tolist(),
                    (diff / dW)[sel].tolist()))
    bad = rows if not keep_all else [r for r, b in zip(rows, is_bad) if b]
    pairs = rows if keep_all else bad
    warns = []
    if scale is not None:
        warns.append(Diagnostic(
            "inconsistent_data",
            f"pairwise distances in {{0}} are uniformly {100 * scale:+.2f} % of those in {{W}} ({n_bad} of "
            f"{n_pairs} pairs beyond {threshold}): a scale error of the model, not of single points: {scale_hint}"
            + (f"; after removing the scale, suspect point(s) {suspects[:20]}{' ...' if len(suspects) > 20 or more else ''}"
               if suspects else
               "; after removing the scale every pair agrees"),
            indices=tuple(suspects)))
    elif bad:
        worst = max(bad, key=lambda b: abs(b[5]))
        desc = "; ".join(f"{b[0]}-{b[1]}: {100 * b[5]:+.1f} % ({b[4] * 1e3:+.1f} mm)"
                         for b in sorted(bad, key=lambda b: -abs(b[4]))[:6])
        warns.append(Diagnostic(
            "inconsistent_data",
            f"pairwise distances in {{W}} and {{0}} disagree beyond {threshold} ({desc}); a rigid transform cannot "
            f"fit them: suspect point(s) {suspects[:20]}{' ...' if len(suspects) > 20 or more else ''} (the first most "
            f"implicated; worst pair {worst[0]}-{worst[1]}, {100 * worst[5]:+.1f} %)",
            indices=tuple(suspects)))
    return ConsistencyReport(pairs, bad, suspects, threshold, warns, scale, n_pairs)


def _spots(model: ProjectorModel, th: np.ndarray) -> np.ndarray:
    """``f(theta)`` (seed eq. 6) of measured spots, without the beyond-the-tilt-limit Python warning:
    :func:`calibrate` reports those points as a ``near_singularity`` diagnostic instead."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NearSingularityWarning)
        return model.spot(th)


def beyond_tilt_limit(model: ProjectorModel, points_0, what: str) -> Diagnostic | None:
    """A ``near_singularity`` diagnostic naming the calibration spots beyond ``model.tilt_limit``, else None.

    Such a spot was aimed where the head should not go (the tilt limit keeps the
    beam away from the horizon singularity, seed §2.1, where the spot error grows
    as ``1 / cos^2(theta2)``); usually ``tilt_limit`` or the joint angles (their
    unit) are wrong. ``points_0`` (N, 3) in ``{0}`` (m).
    """
    p0 = np.asarray(points_0, dtype=float)
    ok = model.reachable(p0, floor_tol=1e-6 * max(1.0, model.H))
    if np.all(ok):
        return None
    idx = [int(i) for i in np.flatnonzero(~ok)]
    r = np.hypot(p0[idx, 0], p0[idx, 1])
    tilt = np.degrees(np.arctan2(r, model.h))
    return Diagnostic(
        "near_singularity",
        f"{what}: point(s) {idx[:10]}{' ...' if len(idx) > 10 else ''} lie beyond the tilt limit of "
        f"{math.degrees(model.tilt_limit):g} deg (tilt up to {tilt.max():.1f} deg, {r.max():.3g} m from the nadir; "
        f"reachable radius {model.floor_radius:.3g} m): check projector.tilt_limit, the points and the angle unit",
        indices=tuple(idx))


# ------------------------------------------------------------------ estimates
@dataclass
class ExtrinsicEstimate:
    """One solver's estimate of ``^0P = R_0_W ^WP + t_0_W``.

    Attributes
    ----------
    method : str
        ``'seed'``, ``'closed_form'`` or ``'nonlinear'``.
    R_0_W : ndarray, shape (3, 3)
    t_0_W : ndarray, shape (3,)
        Metres.
    std : dict
        Standard deviations: ``yaw`` (rad), ``t_x``, ``t_y`` (m), and any extra
        parameter; ``None`` where not available or not identifiable.
    residuals : ndarray, shape (N, 2)
        Floor residuals ``^WP_measured - ^WP_predicted`` (m).
    rms : float
        RMS of the residual vectors (m).
    cost_history : ndarray
        The solver's cost per iteration (seed: ``eps^T eps`` of eq. 27).
    iterations : int
    warnings : list of Diagnostic
    extra : dict
        Method-specific values (seed: ``R_init``; nonlinear: ``h``, offsets, ...).
    cov : ndarray or None
        Covariance of the free parameters ``labels``.
    labels : list of str
    """

    method: str
    R_0_W: np.ndarray
    t_0_W: np.ndarray
    std: dict
    residuals: np.ndarray
    rms: float
    cost_history: np.ndarray
    iterations: int
    warnings: list = field(default_factory=list)
    extra: dict = field(default_factory=dict)
    cov: np.ndarray | None = None
    labels: list = field(default_factory=list)

    @property
    def yaw(self) -> float:
        """Rotation of ``R_0_W`` about ``z`` (rad)."""
        return float(yaw_of(self.R_0_W))

    @property
    def T_0_W(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.R_0_W
        T[:3, 3] = self.t_0_W
        return T


def _floor_residuals(pw, p0, R, t) -> np.ndarray:
    pred = (p0 - t) @ R  # R^T (p0 - t)
    return (pw - pred)[:, :2]


def _rms(res: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(res * res, axis=-1))))


# ------------------------------------------------------------- (a) the seed
def _gibbs(axis: np.ndarray, angle: float) -> np.ndarray:
    """Gibbs vector ``tan(angle/2) k`` (seed, text before eq. 19)."""
    if abs(angle) >= math.pi - 1e-12:
        raise DegenerateGeometryError("seed method: a difference vector is reversed between {W} and {0} "
                                      "(rotation by pi): its Gibbs vector is infinite")
    return math.tan(angle / 2.0) * axis


def _align(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, float]:
    """Axis ``u x v / |u x v|`` and angle ``arccos(u^T v)`` of the rotation taking u to v."""
    w = np.cross(u, v)
    n = np.linalg.norm(w)
    ang = math.acos(min(1.0, max(-1.0, float(u @ v))))
    if n < 1e-15:  # already aligned: any axis, zero angle (seed assumes u x v != 0)
        return np.array([0.0, 0.0, 1.0]), 0.0 if ang < 1.0 else ang
    return w / n, ang


def _units(v: np.ndarray, what: str, others, ref) -> np.ndarray:
    """Rows of ``v`` normalised (eq. 12), naming the first zero one (a duplicated point)."""
    nv = np.linalg.norm(v, axis=1)
    if np.any(nv == 0):
        k = int(np.flatnonzero(nv == 0)[0])
        raise DegenerateGeometryError(f"seed method: {what}{others[k]} - {what}{ref} is a zero vector (duplicated point)")
    return v / nv[:, None]


def seed_initial_rotation(a, b, c, d) -> np.ndarray:
    """Closed-form rotation with ``R c = d`` and ``R a`` closest to ``b`` (seed eqs. 15-23).

    ``m = r(c x d, acos c.d) (x) r(-a x b, acos a.b)`` (eq. 20, Gibbs
    composition of eq. 19); ``tan(theta2/2) = (d x b + (d x m) x b)^+ (b x m)``
    (eq. 22 with the vector pseudo-inverse ``u^+ = u^T / |u|^2``);
    ``R = R(d, theta2) R(c x d, acos c.d)`` (eq. 23). Exact when the two vector
    pairs are consistent, an approximation otherwise.
    """
    a, b, c, d = (np.asarray(v, dtype=float) for v in (a, b, c, d))
    k_ab, ang_ab = _align(a, b)
    k_cd, ang_cd = _align(c, d)
    r_cd = _gibbs(k_cd, ang_cd)
    m = compose_gibbs(r_cd, _gibbs(-k_ab, ang_ab))  # eq. 20
    u = np.cross(d, b) + np.cross(np.cross(d, m), b)  # eq. 22, left factor
    v = np.cross(b, m)
    uu = float(u @ u)
    tau2 = float(u @ v) / uu if uu > 1e-24 else 0.0  # eq. 23: pseudo-inverse of a vector
    return matrix_from_rotvec(2.0 * math.atan(tau2) * d) @ matrix_from_gibbs(r_cd)


def seed_method(points_W, points_0, *, alpha: float = 0.5, eps0: float = 1e-12, max_iter: int = 500,
                order=None) -> ExtrinsicEstimate:
    """The seed's extrinsic calibration, as published (seed 000 eqs. 12-29).

    1. Unit difference vectors to the reference point (eq. 12): for N = 3 with
       the reference last, ``a = unit(^WP1 - ^WP3)``, ``b = unit(^0P1 - ^0P3)``,
       ``c = unit(^WP2 - ^WP3)``, ``d = unit(^0P2 - ^0P3)``, so ``R a = b``,
       ``R c = d`` (eq. 13). For N > 3 every other point gives one more pair
       (a direct generalisation; the seed uses three points).
    2. Initial ``R`` from the first two pairs, :func:`seed_initial_rotation`.
    3. Iterate ``R <- Rx(dx) Ry(dy) Rz(dz) R`` (eq. 24) with
       ``[dx, dy, dz] = alpha J^+ eps`` (eq. 29), ``J = -[[b^]x; [d^]x]``
       (eq. 26), ``eps = Y - Y^``. The seed writes ``J^T (J J^T)^-1``, but J is
       (3(N-1) x 3) and ``J J^T`` is singular; the Moore-Penrose pseudo-inverse
       ``(J^T J)^-1 J^T`` is what makes ``L' < 0`` (eq. 27). Stop when
       ``|eps_{k+1} - eps_k| < eps0``.
    4. The paper does not say how ``t`` is obtained; its published ``t`` is
       ``^0P - R ^WP`` at the reference point, used here.

    Parameters
    ----------
    points_W, points_0 : array_like, shape (N, 3)
        Paired points (m); see :func:`check_correspondences`.
    alpha : float
        Step factor of eq. (29) (the seed gives no value).
    eps0 : float
        Stopping threshold of Step 3.
    max_iter : int
    order : sequence of int, optional
        The points in the roles ``P_1, P_2, ..., P_N`` of eq. (12): the last is
        the reference every difference is taken to, the first two give the
        eq.-(23) initial value. Default: as given.

    Returns
    -------
    ExtrinsicEstimate
        ``cost_history`` holds ``eps^T eps`` before each step (the seed's Fig. 4);
        ``extra['R_init']`` the eq.-23 rotation.
    """
    pw, p0 = check_correspondences(points_W, points_0)
    n = pw.shape[0]
    if not 0 < alpha <= 1:
        raise InputError(f"alpha must be in (0, 1], got {alpha!r}")
    order = list(range(n)) if order is None else [int(i) for i in order]
    if sorted(order) != list(range(n)):
        raise InputError(f"seed order must be a permutation of 0..{n - 1}, got {order}")
    ref = order[-1]
    others = order[:-1]
    A = _units(pw[others] - pw[ref], "^WP", others, ref)
    B = _units(p0[others] - p0[ref], "^0P", others, ref)
    R = seed_initial_rotation(A[0], B[0], A[1], B[1])
    R_init = R.copy()
    Y = B.reshape(-1)

    def step(R):
        Yh = A @ R.T
        eps = Y - Yh.reshape(-1)
        J = -skew(Yh).reshape(-1, 3)  # eq. 26: -[[b^]x; [d^]x; ...]
        return eps, J

    eps, J = step(R)
    costs = [float(eps @ eps)]
    converged = False
    it = 0
    from robocal.progress import progress

    for it in progress(range(1, max_iter + 1), desc="seed method, eq. (29)", enabled=n > LARGE_N):
        # eq. 29, Moore-Penrose: J^+ = (J^T J)^+ J^T exactly, a 3 x 3 pseudo-inverse instead of a (3N x 3) SVD
        delta = alpha * (np.linalg.pinv(J.T @ J) @ (J.T @ eps))
        R = rotx(delta[0]) @ roty(delta[1]) @ rotz(delta[2]) @ R  # eq. 24
        eps_new, J = step(R)
        costs.append(float(eps_new @ eps_new))
        if np.linalg.norm(eps_new - eps) < eps0:
            eps = eps_new
            converged = True
            break
        eps = eps_new
    t = p0[ref] - R @ pw[ref]
    res = _floor_residuals(pw, p0, R, t)
    warns = []
    if not converged:
        warns.append(Diagnostic("not_converged", f"seed method: |eps_(k+1) - eps_k| >= {eps0:g} after {max_iter} "
                                                 f"iterations (alpha = {alpha:g})"))
    return ExtrinsicEstimate("seed", R, t, {"yaw": None, "t_x": None, "t_y": None}, res, _rms(res), np.array(costs),
                             it, warns, {"R_init": R_init, "alpha": alpha, "order": order, "converged": converged,
                                         "seed_cost": costs[-1]})


# ----------------------------------------------------------- (b) closed form
def floor_pose_jacobian(points_0, yaw: float, t_0_W) -> np.ndarray:
    """Jacobian (2N, 3) of the floor residuals ``^WP - Rz(-yaw)(^0P - t)_xy`` w.r.t. (yaw, t_x, t_y).

    With isotropic world noise ``sigma``, ``sigma^2 (J^T J)^-1`` is the
    Cramér-Rao bound of the floor pose (:func:`robocal.estimation.fisher_bound`).
    """
    p0 = check_array(points_0, "points_0", shape=("N", 3))
    c, s = math.cos(yaw), math.sin(yaw)
    d = p0[:, :2] - np.asarray(t_0_W, dtype=float)[:2]
    J = np.zeros((p0.shape[0], 2, 3))
    J[:, 0, 0] = s * d[:, 0] - c * d[:, 1]
    J[:, 1, 0] = c * d[:, 0] + s * d[:, 1]
    J[:, 0, 1], J[:, 0, 2] = c, s
    J[:, 1, 1], J[:, 1, 2] = -s, c
    return J.reshape(-1, 3)


def _pose_information(p0, yaw, t) -> np.ndarray:
    J = floor_pose_jacobian(p0, yaw, t)
    return J.T @ J


def closed_form(points_W, points_0, *, sigma: float | None = None, cov=None) -> ExtrinsicEstimate:
    """Maximum-likelihood rigid fit (Umeyama/Kabsch) of ``^WP = R_W_0 ^0P + t_W_0``, N >= 3.

    The noise sits on ``^WP`` (the measured world points), so the fit maps
    the exact model points ``^0P`` onto them (``robocal.geometry.rigid_fit``)
    and is inverted. Standard deviations from the floor-pose Fisher information
    with ``sigma`` (or the residual estimate when ``sigma`` is None and N > 3).
    With per-point floor covariances ``cov`` (N, 2, 2, m^2: world noise plus the
    joint noise mapped to the floor, :func:`floor_covariance`) the unweighted fit
    is no longer the ML estimate, and its covariance is the sandwich
    ``(J^T J)^-1 J^T Sigma J (J^T J)^-1``.
    """
    pw, p0 = check_correspondences(points_W, points_0, unit_check=False)
    fit = rigid_fit(p0, pw)
    R = fit.R.T
    t = -R @ fit.t
    res = _floor_residuals(pw, p0, R, t)
    n = pw.shape[0]
    # floor residuals have 2 components per point and 3 pose dof
    s = sigma if sigma else (math.sqrt(float(np.sum(res * res)) / (2 * n - 3)) if n > 2 else None)
    std = {"yaw": None, "t_x": None, "t_y": None}
    cov_p = None
    if s:
        J = floor_pose_jacobian(p0, float(yaw_of(R)), t)
        Ninv = np.linalg.inv(J.T @ J)
        if cov is not None and sigma:
            Jb = J.reshape(n, 2, 3)
            meat = np.einsum("nai,nab,nbj->ij", Jb, cov, Jb)
            cov_p = Ninv @ meat @ Ninv
        else:
            cov_p = s * s * Ninv
        std = {"yaw": math.sqrt(cov_p[0, 0]), "t_x": math.sqrt(cov_p[1, 1]), "t_y": math.sqrt(cov_p[2, 2])}
    return ExtrinsicEstimate("closed_form", R, t, std, res, _rms(res), np.array([float(np.sum(res * res)) / 2]), 0, [],
                             {"sigma_used": s}, cov_p, ["yaw", "t_x", "t_y"])


def floor_covariance(model: ProjectorModel, theta, yaw: float = 0.0, *, sigma: float = 0.0,
                     joint_noise=(0.0, 0.0)) -> np.ndarray:
    """Covariance (N, 2, 2, m^2) of each floor residual ``^WP_i - Rz(-yaw) f_xy(theta_i)``.

    ``sigma^2 I + J_theta diag(joint_noise^2) J_theta^T`` (issue 19): isotropic
    world noise ``sigma`` (m) plus the encoder noise ``joint_noise`` (pan, tilt,
    rad) mapped to the floor by the spot model's joint Jacobian (seed eqs. 6, 9,
    rotated into ``{W}``). The tilt part, ``h / cos^2(tilt)`` along the radius,
    grows fast with the tilt; the pan part, ``h tan(tilt)`` across it. With
    ``yaw = 0`` the covariance is that of ``f_xy`` in ``{0}``.
    """
    th = np.asarray(theta, dtype=float)
    jn = np.asarray(joint_noise, dtype=float)
    cols = floor_prediction_columns(yaw, np.zeros(2), theta=th, h=model.h, offsets=model.offsets)
    a, b = cols["pan_offset"], cols["tilt_offset"]  # d pred / d theta1, d theta2 (the offsets add to theta)
    C = (jn[0] ** 2) * a[:, :, None] * a[:, None, :] + (jn[1] ** 2) * b[:, :, None] * b[:, None, :]
    C[:, 0, 0] += sigma * sigma
    C[:, 1, 1] += sigma * sigma
    return C


def _whitener(C: np.ndarray) -> np.ndarray:
    """``L^-1`` (N, 2, 2) with ``C = L L^T``: ``L^-1 r`` has unit covariance."""
    return np.linalg.inv(np.linalg.cholesky(C))


# ---------------------------------------------------------- (c) nonlinear LS
EXTRA_PARAMS = ("h", "pan_offset", "tilt_offset")


def floor_prediction_columns(yaw: float, t_xy, *, spots_xy=None, theta=None, h: float | None = None,
                             offsets=(0.0, 0.0)) -> dict:
    """``d pred / d p`` (M, 2) per parameter of the floor prediction ``pred = Rz(-yaw) (f - t)_xy`` (seed eqs. 1, 6).

    Either the spots ``f_xy`` (M, 2) in {0} are given (columns ``yaw``, ``t_x``,
    ``t_y``), or joint angles ``theta`` (M, 2) with ``h`` and ``offsets``: then
    ``f = h tan(a2) (sin a1, cos a1)`` with ``a = theta + offsets`` (seed eq. 6)
    and the columns ``h``, ``pan_offset``, ``tilt_offset`` are added. One source
    for the residual Jacobian of :func:`nonlinear` and the error map's
    propagation (:func:`robocal.rigs.projector.evaluate.floor_prediction_jacobian`).
    """
    c, s = math.cos(yaw), math.sin(yaw)
    cols = {}
    if theta is not None:
        a1 = theta[:, 0] + offsets[0]
        a2 = theta[:, 1] + offsets[1]
        ta, s1, c1 = np.tan(a2), np.sin(a1), np.cos(a1)
        rho = h * ta
        spots_xy = np.column_stack([rho * s1, rho * c1])

        def rot(v):  # Rz(-yaw) applied to floor vectors
            return np.column_stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1]])

        cols["h"] = rot(np.column_stack([ta * s1, ta * c1]))
        cols["pan_offset"] = rot(np.column_stack([rho * c1, -rho * s1]))
        cols["tilt_offset"] = rot((h / np.cos(a2) ** 2)[:, None] * np.column_stack([s1, c1]))
    d = np.asarray(spots_xy, dtype=float) - np.asarray(t_xy, dtype=float)[:2]
    cols["yaw"] = np.column_stack([-s * d[:, 0] + c * d[:, 1], -c * d[:, 0] - s * d[:, 1]])
    cols["t_x"] = np.tile([-c, s], (len(d), 1))
    cols["t_y"] = np.tile([-s, -c], (len(d), 1))
    return cols


def nonlinear(points_W, *, theta=None, points_0=None, model: ProjectorModel | None = None, estimate=(),
              sigma: float | None = None, x0: ExtrinsicEstimate | None = None, absolute_sigma: bool = False,
              loss: str = "linear", joint_noise=None, hold=()) -> ExtrinsicEstimate:
    """Nonlinear least squares on the floor spot error (robocal.estimation).

    Residual per point: ``^WP_i - [R_0_W^T (f(theta_i) - t_0_W)]_xy`` (m), with
    ``f`` the spot model (seed eq. 6). Parameter blocks: ``R`` (rotation vector,
    only ``rz`` free: see the module docstring), ``t`` (``t_z = -H`` fixed),
    and, with joint angles, ``h = H - d1``, ``pan_offset``, ``tilt_offset`` when
    named in ``estimate``.

    The pan zero offset is **not identifiable** from floor points: turning the
    pan by ``o1`` rotates every spot about the nadir, which a change of yaw and
    ``t`` reproduces exactly. Asking for it yields a ``rank_deficient`` warning
    and ``std = None``.

    Noise model (issue 19): each point's residual has the covariance
    :func:`floor_covariance` (world noise ``sigma`` plus the encoder noise
    ``joint_noise`` mapped to the floor); the residuals are whitened with it,
    so weights, covariance and the outlier test all use it. The covariance
    depends on ``h`` and the offsets: it is taken at the start, and the fit is
    repeated once with it taken at the first solution.

    Outliers (with a stated ``sigma``): each point's studentized deleted
    residual ``t_i^2 = e_i^T (I - H_ii)^-1 e_i`` (whitened residual ``e_i``,
    2x2 hat-matrix block ``H_ii``; chi-square with 2 dof) is compared with the
    chi-square quantile of ``0.01 / N`` (Bonferroni: <= 1 % false alarms per
    data set); the worst point is named first, dropped, and the test repeated
    on the rest (backward elimination, linearised), so one gross point does not
    drag its neighbours over the threshold.

    Parameters
    ----------
    points_W : array_like, shape (N, 2) or (N, 3)
    theta : array_like, shape (N, 2), optional
        Joint angles (rad) for each spot; requires ``model``.
    points_0 : array_like, shape (N, 3), optional
        Spots in ``{0}`` when joint angles are not available (then ``estimate``
        must be empty).
    model : ProjectorModel
        Provides ``H, d1`` and offsets (initial values).
    estimate : sequence of {'h', 'pan_offset', 'tilt_offset'}
    sigma : float, optional
        World measurement noise (m); with ``absolute_sigma`` taken as known.
    x0 : ExtrinsicEstimate, optional
        Start (default: the closed form).
    joint_noise : (float, float), optional
        Encoder noise (pan, tilt) std (rad); needs ``sigma`` and joint angles.
    hold : sequence of str
        Parameters of ``estimate`` held at the model's value (physical bounds, see :func:`calibrate`).
    """
    estimate = tuple(estimate)
    unknown = [e for e in estimate if e not in EXTRA_PARAMS]
    if unknown:
        raise InputError(f"estimate: unknown parameter(s) {unknown} (known: {', '.join(EXTRA_PARAMS)})")
    if theta is None:
        if points_0 is None:
            raise InputError("nonlinear: give joint angles theta (with model) or points_0")
        if estimate:
            raise InputError(f"nonlinear: estimating {list(estimate)} needs joint angles, only points_0 were given")
        pw, p0 = check_correspondences(points_W, points_0, unit_check=False)
        th = None
        H = float(-np.mean(p0[:, 2]))
        model = ProjectorModel(H=H) if model is None else model
    else:
        if model is None:
            raise InputError("nonlinear: joint angles need a ProjectorModel (H, d1)")
        th = check_array(theta, "theta", shape=("N", 2))
        if th.ndim != 2:
            raise ShapeError(f"theta must have shape (N, 2), got {tuple(th.shape)}")
        p0 = _spots(model, th)
        pw, p0 = check_correspondences(points_W, p0, unit_check=False)
    jn = None
    if joint_noise is not None and np.any(np.asarray(joint_noise, dtype=float) > 0):
        if not sigma:
            raise InputError("joint_noise needs the world noise (noise:) too: the two make each point's covariance")
        jn = np.asarray(joint_noise, dtype=float)
    H = model.H
    free = tuple(e for e in estimate if e not in hold)
    start = x0 or closed_form(pw, p0, sigma=sigma)
    n = pw.shape[0]
    target = pw[:, :2]
    # {0} points given directly come from encoder readings too: their angles by IK (seed eq. 8)
    th_cov = th if th is not None else (model.ik(p0, check_reach=False, on_nadir="ignore") if jn is not None
                                        else None)

    def build(x_start, params_start, Winv):
        prob = Problem()
        prob.add_block("R", [0.0, 0.0, x_start[0]], fixed=[True, True, False], labels=["rx", "ry", "yaw"],
                       unit="rad")
        prob.add_block("t", [x_start[1], x_start[2], -H], fixed=[False, False, True],
                       labels=["t_x", "t_y", "t_z"], unit="m")
        if th is not None:
            prob.add_block("h", [params_start[0]], fixed=["h" not in free], labels=["h"], unit="m")
            prob.add_block("offsets", list(params_start[1:]), fixed=["pan_offset" not in free,
                                                                      "tilt_offset" not in free],
                           labels=["pan_offset", "tilt_offset"], unit="rad")

        def raw(q):
            c, s = math.cos(q["R"][2]), math.sin(q["R"][2])
            if th is None:
                sp = p0[:, :2]
            else:
                a1 = th[:, 0] + q["offsets"][0]
                a2 = th[:, 1] + q["offsets"][1]
                rho = q["h"][0] * np.tan(a2)
                sp = np.column_stack([rho * np.sin(a1), rho * np.cos(a1)])
            d = sp - q["t"][:2]
            # R_0_W = Rz(yaw) => ^WP_xy = Rz(-yaw) (f - t)_xy
            pred = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
            return target - pred

        def residuals(q):
            r = raw(q)
            return r if Winv is None else np.einsum("nij,nj->ni", Winv, r)

        def jacobian(q):  # residual = target - pred
            if th is None:
                cols = floor_prediction_columns(q["R"][2], q["t"], spots_xy=p0[:, :2])
            else:
                cols = floor_prediction_columns(q["R"][2], q["t"], theta=th, h=q["h"][0], offsets=q["offsets"])
            if Winv is not None:
                cols = {k: np.einsum("nij,nj->ni", Winv, v) for k, v in cols.items()}
            out = {"R": np.zeros((2 * n, 3)), "t": np.zeros((2 * n, 3))}
            out["R"][:, 2] = -cols["yaw"].reshape(-1)
            out["t"][:, 0], out["t"][:, 1] = -cols["t_x"].reshape(-1), -cols["t_y"].reshape(-1)
            if th is not None:
                out["h"] = -cols["h"].reshape(-1, 1)
                out["offsets"] = -np.stack([cols["pan_offset"], cols["tilt_offset"]], axis=-1).reshape(-1, 2)
            return out

        # whitened residuals have unit covariance: sigma 1 (in units of each point's own covariance)
        prob.add_residuals(residuals, name="floor", jacobian=jacobian, residual_dim=2,
                           sigma=1.0 if Winv is not None else (sigma if sigma else None))
        return prob, raw

    x_start = [start.yaw, start.t_0_W[0], start.t_0_W[1]]
    p_start = [model.h, *model.offsets]
    Winv = None
    passes = 1
    if jn is not None:
        Winv = _whitener(floor_covariance(model, th_cov, start.yaw, sigma=sigma, joint_noise=jn))
        passes = 2
    res = raw = None
    for k in range(passes):
        prob, raw = build(x_start, p_start, Winv)
        # trf, not lm: MINPACK keeps iterating on an exact (zero-residual) fit until max_nfev
        res = solve(prob, method="trf", loss=loss, absolute_sigma=absolute_sigma and bool(sigma),
                    progress=n > LARGE_N and sys.stderr.isatty())
        if not np.all(np.isfinite(res.x)):
            raise ConvergenceError("nonlinear: the solver returned a non-finite estimate")
        x_start = [float(res.params["R"][2]), float(res.params["t"][0]), float(res.params["t"][1])]
        if th is not None:
            p_start = [float(res.params["h"][0]), *map(float, res.params["offsets"])]
        if k + 1 < passes:  # the covariance at the first solution's h and offsets
            m_k = model.with_(d1=H - p_start[0], offsets=tuple(p_start[1:])) if th is not None else model
            Winv = _whitener(floor_covariance(m_k, th_cov, x_start[0], sigma=sigma, joint_noise=jn))
    yaw = float(res.params["R"][2])
    R = rotz(yaw)
    t = np.array(res.params["t"], dtype=float)
    resid = raw(res.params)
    std = {"yaw": res.std.get("yaw"), "t_x": res.std.get("t_x"), "t_y": res.std.get("t_y")}
    extra = {}
    if th is not None:
        extra["h"] = float(res.params["h"][0])
        extra["offsets"] = [float(v) for v in res.params["offsets"]]
        for lab in estimate:
            std[lab] = res.std.get(lab) if lab in free else None
    warns = list(res.warnings)
    if sigma and absolute_sigma and loss == "linear":
        # the solver's per-observation test sees residuals pulled towards a gross point by the fit itself
        warns = [w for w in warns if w.code != "outliers"]
        order, scores, thr = deleted_residual_outliers(res.weighted_residuals.reshape(n, 2),
                                                       res.jac.toarray() if hasattr(res.jac, "toarray") else res.jac)
        extra["outlier_scores"] = scores
        if order:
            shown = ", ".join(f"{i} ({math.sqrt(scores[i]):.1f} sigma)" for i in order[:10])
            warns.append(Diagnostic(
                "outliers",
                f"{len(order)} of {n} point(s) inconsistent with the fit of the others: [{shown}"
                f"{', ...' if len(order) > 10 else ''}] (studentized deleted residual beyond "
                f"{math.sqrt(thr):.2f} sigma, the chi-square(2) quantile of 1 %/N; worst first)",
                indices=tuple(order)))
    extra["whitened"] = Winv is not None
    return ExtrinsicEstimate("nonlinear", R, t, std, resid, _rms(resid), np.asarray(res.cost_history),
                             res.iterations, warns, dict(extra, lsq=res), res.cov, list(res.free_labels))


def deleted_residual_outliers(e, J, *, alpha: float = 0.01, max_removed: int = 20):
    """Points whose studentized deleted residual exceeds the Bonferroni chi-square(2) bound, worst first.

    Parameters
    ----------
    e : ndarray, shape (N, 2)
        Whitened residuals (unit covariance under the model).
    J : ndarray, shape (2N, p)
        Jacobian of the whitened residuals w.r.t. the free parameters.

    Returns
    -------
    order : list of int
        The flagged points, the worst first. After each flagged point the fit
        is updated without it (one Gauss-Newton step: exact for the linearised
        model) and the rest re-tested, at most ``max_removed`` times; points
        still beyond the bound after that follow by score.
    scores : ndarray, shape (N,)
        ``t_i^2 = e_i^T (I - H_ii)^-1 e_i`` of the full fit (chi-square, 2 dof).
    threshold : float
        The chi-square(2) quantile of ``alpha / N``: ``-2 ln(alpha / N)``.
    """
    n = e.shape[0]
    thr = -2.0 * math.log(alpha / n)  # chi-square(2) survival function is exp(-x/2)
    Jb = np.asarray(J, dtype=float).reshape(n, 2, -1)
    active = np.ones(n, bool)
    e_cur = np.array(e, dtype=float)
    order: list[int] = []
    scores0 = None
    exhausted = True
    for _ in range(max_removed + 1):
        Ja = Jb[active].reshape(-1, Jb.shape[2])
        Ninv = np.linalg.pinv(Ja.T @ Ja)
        Hii = np.einsum("nai,ij,nbj->nab", Jb, Ninv, Jb)
        M = np.eye(2)[None] - Hii  # residual covariance of a point in the fit
        sc = np.where(active, np.einsum("na,nab,nb->n", e_cur, np.linalg.inv(np.where(active[:, None, None], M,
                                                                                        np.eye(2)[None])), e_cur),
                      -np.inf)
        if scores0 is None:
            scores0 = sc.copy()
        k = int(np.argmax(sc))
        if not sc[k] > thr or active.sum() - 1 <= Jb.shape[2] // 2 + 1:
            exhausted = False
            break
        order.append(k)
        active[k] = False
        # one Gauss-Newton step of the fit without the dropped points (the whitened model is nearly linear)
        Ja = Jb[active].reshape(-1, Jb.shape[2])
        dx = -np.linalg.lstsq(Ja, e_cur[active].reshape(-1), rcond=None)[0]
        e_cur = e_cur + (Jb @ dx)
    rest = ([int(i) for i in np.argsort(-scores0) if active[i] and scores0[i] > thr] if exhausted else [])
    return order + rest, scores0, thr


# --------------------------------------------------------------- the driver
@dataclass
class CalibrationRun:
    """Everything one calibration produced: the consistency check and each method's estimate."""

    points_W: np.ndarray
    points_0: np.ndarray
    theta: np.ndarray | None
    model: ProjectorModel
    consistency: ConsistencyReport
    estimates: dict
    sigma: float | None
    primary: str
    consistency_prefit: ConsistencyReport | None = None
    input_warnings: list = field(default_factory=list)
    joint_noise: tuple | None = None  # encoder noise std (pan, tilt), rad

    @property
    def best(self) -> ExtrinsicEstimate:
        return self.estimates[self.primary]

    @property
    def warnings(self) -> list:
        return list(self.input_warnings) + list(self.consistency.warnings) + [w for w in self.best.warnings]

    def calibrated_model(self, method: str | None = None) -> ProjectorModel:
        """The projector model with the estimated extrinsics (and h / offsets when estimated)."""
        est = self.estimates[method or self.primary]
        m = self.model.with_(R_0_W=est.R_0_W, t_0_W=est.t_0_W)
        if "h" in est.extra:
            m = m.with_(d1=m.H - est.extra["h"], offsets=tuple(est.extra["offsets"]))
        return m


#: Default bound on the estimated tilt zero offset (rad); ``tilt_offset_limit`` in the input changes it.
TILT_OFFSET_LIMIT = math.radians(5.0)


def _tilt_span(model: ProjectorModel, th, p0) -> tuple[float, float]:
    """Smallest and largest actual tilt (rad) of the calibration spots."""
    if th is not None:
        a2 = np.abs(th[:, 1] + model.offsets[1])
    else:
        a2 = np.arctan2(np.hypot(p0[:, 0], p0[:, 1]), model.h)
    return float(a2.min()), float(a2.max())


def _bound_violations(est: ExtrinsicEstimate, model: ProjectorModel, free, tilt_offset_limit: float) -> dict:
    """Estimated parameters outside their physical bounds: ``{name: text}``.

    ``h = H - d1 <= H`` (d1 >= 0: the tilt axis is not above the ceiling
    reference of ``{0}``), ``h > 0``, ``|tilt_offset| <= tilt_offset_limit``.
    """
    out = {}
    if "h" in free:
        h = est.extra["h"]
        if h > model.H:
            out["h"] = f"h = {h:.4g} m above H = {model.H:.4g} m (d1 = {model.H - h:+.4g} m < 0)"
        elif h <= 0:
            out["h"] = f"h = {h:.4g} m <= 0 (the tilt axis below the floor)"
    if "tilt_offset" in free:
        o = est.extra["offsets"][1]
        if abs(o) > tilt_offset_limit:
            out["tilt_offset"] = (f"tilt offset {math.degrees(o):+.3g} deg beyond +-{math.degrees(tilt_offset_limit):g} "
                                  f"deg (tilt_offset_limit)")
    return out


#: Plausible ceiling heights H (m) of a projector room; a slip check that moves H outside is no explanation.
H_PLAUSIBLE = (0.5, 50.0)
#: The slip checks fit at most this many points (evenly spaced): a unit slip shows in any of them.
SLIP_SAMPLE = 2000


def _slip_checks(pw, th, p0_given, model: ProjectorModel, sigma, joint_noise, *, accept: bool,
                 source: str | None):
    """Judge the input's physical scales; name the likely slip (robocal.plausibility).

    Figure of merit: the median floor residual (mm, in the world points' unit
    as read) of a fit that allows for the nominal model's own error: yaw, t,
    ``h`` and the tilt offset free (seed eqs. 1, 6); a rigid fit when the
    ``{0}`` points are given directly. It counts as no fit (inf) when ``H``
    leaves :data:`H_PLAUSIBLE`, when the spots' and world points' spreads
    differ by more than 2x, when the fitted ``h`` leaves ``(0, 1.5 H]`` or
    the tilt offset +-10 deg, or when it exceeds 5 % of the world points' own
    spread (a slip that shrinks them shrinks their residual too). Plausible: a figure of at most 10x the stated
    noise at the largest tilt (5 % of the points' spread without stated noise).

    A unit slip on one side (world points, H, the joint angles), swapped world
    columns (a mirror image, which no rotation fits) or swapped angle columns
    leave it far above that; each slip is undone on its own and the fit redone.
    When the scales agree and no slip explains a poor fit, this returns None:
    the consistency check and the outlier test report it. With ``{0}`` points
    given directly their z is tied to ``H`` (checked before), so a scale slip
    is named on the world points. At most :data:`SLIP_SAMPLE` points are used.
    """
    from robocal.plausibility import Slip, check_slips, try_slips

    n = pw.shape[0]
    idx = np.arange(n) if n <= SLIP_SAMPLE else np.linspace(0, n - 1, SLIP_SAMPLE).round().astype(int)
    pw_s = pw[idx]
    th_s = None if th is None else th[idx]
    p0_s = None if p0_given is None else p0_given[idx]

    def merit(w, m=model, t=th_s, p0=None):
        if not H_PLAUSIBLE[0] <= m.H <= H_PLAUSIBLE[1]:
            return math.inf
        p = (_spots(m, t) if t is not None else p0_s) if p0 is None else p0
        if not 0.5 < spread_ratio(w, p) < 2.0:
            return math.inf
        if t is None:
            fit = rigid_fit(p, w)
            r = (p @ fit.R.T + fit.t - w)[:, :2]
        else:
            est = nonlinear(w, theta=t, model=m, estimate=("h", "tilt_offset"), x0=closed_form(w, p))
            h, o2 = est.extra["h"], est.extra["offsets"][1]
            if not (0.0 < h <= 1.5 * m.H and abs(o2) <= math.radians(10.0)):
                return math.inf
            r = est.residuals
        med = float(np.median(np.linalg.norm(r, axis=1)))
        # a slip that shrinks the world points shrinks their residual too: a fit is one only against its own spread
        sp = float(np.sqrt(np.mean(np.sum((w[:, :2] - w[:, :2].mean(0)) ** 2, axis=1))))
        return 1e3 * med if med <= 0.05 * sp else math.inf

    p0 = _spots(model, th_s) if th_s is not None else p0_s
    spread = float(np.sqrt(np.mean(np.sum((pw_s[:, :2] - pw_s[:, :2].mean(0)) ** 2, axis=1))))
    ratio = spread_ratio(pw_s, p0)
    if sigma:
        jt = 0.0 if joint_noise is None else float(joint_noise[1])
        tmax = _tilt_span(model, th_s, p0)[1]
        limit = 10e3 * math.hypot(sigma, model.h * jt / math.cos(min(tmax, 1.5)) ** 2)
    else:
        limit = 0.05e3 * spread
    try:
        base = merit(pw_s)
    except RobocalError:
        base = math.inf
    if not math.isfinite(base):  # no fit as given: the message quotes the rigid fit's residual (always finite)
        fit = rigid_fit(p0, pw_s)
        r = (p0 @ fit.R.T + fit.t - pw_s)[:, :2]
        base = max(1e3 * float(np.median(np.linalg.norm(r, axis=1))), 1.01 * limit)
    if base <= limit:
        return None
    slips = []
    for f, unit_big, unit_small in ((1e3, "mm", "m"), (1e2, "cm", "m"), (1e1, "mm", "cm")):
        slips.append(Slip(f"world_{unit_big}_as_{unit_small}",
                          f"`points.world` looks like {unit_big} declared as {unit_small} ({f:g}x too large)",
                          f"with /{f:g}", lambda f=f: merit(pw_s / f)))
        slips.append(Slip(f"world_{unit_small}_as_{unit_big}",
                          f"`points.world` looks like {unit_small} declared as {unit_big} ({f:g}x too small)",
                          f"with x{f:g}", lambda f=f: merit(pw_s * f)))
        if th is not None:
            slips.append(Slip(f"H_{unit_big}_as_{unit_small}",
                              f"`projector.H` (and d1) look like {unit_big} declared as {unit_small} ({f:g}x too large)",
                              f"with /{f:g}", lambda f=f: merit(pw_s, m=model.with_(H=model.H / f, d1=model.d1 / f,
                                                                                      d2=model.d2 / f))))
            slips.append(Slip(f"H_{unit_small}_as_{unit_big}",
                              f"`projector.H` (and d1) look like {unit_small} declared as {unit_big} ({f:g}x too small)",
                              f"with x{f:g}", lambda f=f: merit(pw_s, m=model.with_(H=model.H * f, d1=model.d1 * f,
                                                                                      d2=model.d2 * f))))
    slips.append(Slip("world_xy_swapped", "`points.world` x and y look swapped (a mirror image: no rotation fits)",
                      "with x and y swapped back", lambda: merit(pw_s[:, [1, 0, 2]])))
    if th is not None:
        d = math.degrees(1.0)
        slips.append(Slip("angles_rad_as_deg", "`points.joint_angles` look like rad declared as deg",
                          "read as rad", lambda: merit(pw_s, t=th_s * d)))
        slips.append(Slip("angles_deg_as_rad", "`points.joint_angles` look like deg declared as rad",
                          "read as deg", lambda: merit(pw_s, t=th_s / d)))
        slips.append(Slip("angles_swapped", "`points.joint_angles` columns look swapped (tilt, pan instead of pan, tilt)",
                          "with the columns swapped back", lambda: merit(pw_s, t=th_s[:, ::-1])))
    h_ok = H_PLAUSIBLE[0] <= model.H <= H_PLAUSIBLE[1]
    trial = None
    if 0.5 < ratio < 2.0 and h_ok:
        trial = try_slips(slips, base, threshold=limit)
        if trial.best is None:
            # the scales agree: a poor fit is the consistency check's and outlier test's to report
            return None
    reason = (f"projector.H = {model.H:.4g} m is outside the plausible {H_PLAUSIBLE[0]:g}-{H_PLAUSIBLE[1]:g} m"
              if not h_ok else
              f"the floor points do not fit the projector's spots: distances in {{0}} are {ratio:.3g} times those "
              f"in {{W}}, median residual {base:.3g} mm (plausible: <= {limit:.3g} mm)")
    # (a trial already made is judged as it is: each of its figures was a refit)
    return check_slips(what="median residual", residual=base, unit="mm", plausible=False, reason=reason,
                       slips=slips, accept=accept, source=source, threshold=limit, trial=trial)


def calibrate(points_W, *, theta=None, points_0=None, model: ProjectorModel | None = None,
              methods=METHODS, estimate=(), sigma: float | None = None, strict: bool = False,
              seed_alpha: float = 0.5, seed_order=None, joint_noise=None,
              tilt_offset_limit: float = TILT_OFFSET_LIMIT, accept_implausible: bool = False,
              source: str | None = None) -> CalibrationRun:
    """Run the consistency check and the chosen solvers on one data set.

    Parameters
    ----------
    points_W : array_like, shape (N, 2) or (N, 3)
        Measured world floor points (m).
    theta : array_like, shape (N, 2), optional
        Joint angles (rad) that put the spot on each point (then ``model`` is needed).
    points_0 : array_like, shape (N, 3), optional
        The spots in ``{0}``, when given directly (as in the seed's §3).
    model : ProjectorModel, optional
    methods : sequence of {'seed', 'closed_form', 'nonlinear'}
    estimate : extra parameters for the nonlinear solver, see :func:`nonlinear`
    sigma : float, optional
        World measurement noise (m). When given, every standard deviation uses
        it as known (absolute sigma); without it the covariances are scaled by
        the residual variance (needs N > number of parameters / 2).
    joint_noise : (float, float), optional
        Encoder noise std (pan, tilt) in rad; needs ``sigma``. Each point's floor
        covariance is then :func:`floor_covariance`, used by the consistency
        check, the closed form's std and the nonlinear fit's weights, std and
        outlier test.
    tilt_offset_limit : float
        Physical bound (rad) on an estimated tilt zero offset.
    seed_alpha, seed_order
        Step factor and point order of :func:`seed_method`.
    strict : bool
        Raise :class:`~robocal.errors.InconsistentDataError` when the distance
        check fails or an estimate leaves its physical bounds, and
        :class:`~robocal.rigs.projector.model.UnreachablePointError` for spots
        beyond the tilt limit, instead of warning (``inconsistent_data``,
        ``parameter_held``, ``near_singularity``).
    accept_implausible : bool
        Go on when the input's scales are implausible (a likely unit slip or
        swapped columns, :func:`robocal.plausibility.check_slips`) with an
        ``implausible_input`` warning, instead of raising
        :class:`~robocal.errors.ImplausibleInputError`.
    source : str, optional
        Input file, named in errors.

    Physical bounds: an estimated ``h`` above ``H`` (d1 < 0) or at/below 0, or
    a tilt offset beyond ``tilt_offset_limit``, is not returned: the parameter is
    held at its nominal value, the fit redone, and a ``parameter_held`` warning
    says why, with the tilt span of the points (``h`` and the tilt offset are
    told apart only by points at different tilts).

    Returns
    -------
    CalibrationRun
        ``primary`` is the nonlinear estimate when run, else the closed form, else the seed's.
    """
    methods = tuple(methods)
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise InputError(f"methods must be a non-empty subset of {', '.join(METHODS)}, got {list(methods)}")
    if theta is not None:
        if model is None:
            raise InputError("calibrate: joint angles need a projector model (H, d1)")
        th = check_array(theta, "theta", shape=("N", 2))
        if th.ndim != 2:
            raise ShapeError(f"theta must have shape (N, 2), got {tuple(th.shape)}")
        p0 = _spots(model, th)
    elif points_0 is not None:
        th = None
        p0 = check_array(points_0, "points_0")
        if p0.ndim != 2 or p0.shape[-1] != 3:
            raise ShapeError(f"points_0 must have shape (N, 3), got {tuple(p0.shape)}")
        H = float(-np.mean(p0[:, 2]))
        if model is None:
            if not H > 0:
                raise InputError(f"points_0: the floor must be below the projector (z_0 = -H < 0), got mean z {-H:g} m")
            model = ProjectorModel(H=H)
        if np.abs(p0[:, 2] + model.H).max() > 1e-6 * max(1.0, model.H):
            raise InputError(f"points_0: every z must equal -H = {-model.H:g} m (the floor in {{0}}), got "
                             f"{p0[:, 2].tolist()[:10]}")
    else:
        raise InputError("calibrate: give joint angles (theta) or projector-frame points (points_0)")
    jn = None
    if joint_noise is not None:
        jn = check_array(joint_noise, "joint_noise", shape=(2,))
        if np.any(jn < 0):
            raise InputError(f"joint_noise must be >= 0 (rad), got {jn.tolist()}")
        if not np.any(jn > 0):
            jn = None
        elif not sigma:
            raise InputError("joint_noise needs noise (the world measurement sigma) too: together they make each "
                             "point's floor covariance")
    if not 0 < tilt_offset_limit < math.pi / 2:
        raise InputError(f"tilt_offset_limit must be in (0, 90) deg, got {math.degrees(tilt_offset_limit):g} deg")
    from robocal.resources import require_memory

    require_memory(CAL_BYTES_PER_POINT * len(p0), f"calibrating {len(p0)} points", source=source)
    pw, p0 = check_correspondences(points_W, p0, unit_check=False)
    if np.abs(pw[:, 2]).max() > 1e-9:
        raise InputError("points_W: world points must lie on the floor (z_W = 0)")
    input_warnings = []
    slip = _slip_checks(pw, th, p0 if th is None else None, model, sigma, jn, accept=accept_implausible,
                        source=source)
    if slip is not None:
        input_warnings.append(slip)
    reach = beyond_tilt_limit(model, p0, "joint_angles" if th is not None else "points_0")
    if reach is not None:
        if strict:
            raise UnreachablePointError(reach.message)
        input_warnings.append(reach)
    estimate = tuple(estimate)
    if estimate and "nonlinear" not in methods:
        raise InputError(f"estimate: {list(estimate)} is estimated only by the 'nonlinear' method, which is not among "
                         f"methods {list(methods)}: add it or drop estimate")
    hint = ("H - d1 or the tilt offset is probably wrong (estimate: [h, tilt_offset] with the nonlinear method)"
            if th is not None else "H or the units of the {0} points are probably wrong")
    th_cov = None
    if jn is not None:
        th_cov = th if th is not None else model.ik(p0, check_reach=False, on_nadir="ignore")

    def cov0(m):  # joint-noise covariance of the spots in {0} (no world part: the check adds it per pair)
        return None if jn is None else floor_covariance(m, th_cov, 0.0, joint_noise=jn)

    cons = distance_consistency(pw, p0, sigma=sigma, scale_hint=hint, cov_0=cov0(model))
    refine_model = th is not None and any(e in ("h", "tilt_offset") for e in estimate) and "nonlinear" in methods
    # With h or the tilt offset unknown, the nominal f(theta) carries a model error that the
    # distances show too; the check is then repeated with the refined model before judging.
    if strict and not cons.consistent and not refine_model:
        raise InconsistentDataError(cons.warnings[0].message)
    ests = {}
    if "seed" in methods:
        ests["seed"] = seed_method(pw, p0, alpha=seed_alpha, order=seed_order)
    if "closed_form" in methods or "nonlinear" in methods:
        cf = closed_form(pw, p0, sigma=sigma)
        if jn is not None:  # the sandwich covariance under the per-point noise
            cf = closed_form(pw, p0, sigma=sigma, cov=floor_covariance(model, th_cov, cf.yaw, sigma=sigma,
                                                                       joint_noise=jn))
        ests["closed_form"] = cf
    held = {}
    if "nonlinear" in methods:
        # A stated noise is the measurement sigma: with few points (N = 3, h and the tilt offset free
        # leaves 1 dof) the residual-scaled covariance is far too small, so the stated sigma is used as is.
        kw = dict(theta=th, points_0=None if th is not None else p0, model=model, estimate=estimate, sigma=sigma,
                  x0=ests["closed_form"], absolute_sigma=sigma is not None, joint_noise=jn)
        nl = free_fit = nonlinear(pw, **kw)
        for _ in range(2):  # hold what leaves its bounds, refit, check what is still free
            out = _bound_violations(nl, model, [e for e in estimate if e not in held], tilt_offset_limit)
            if not out:
                break
            held.update(out)
            nl = nonlinear(pw, hold=tuple(held), **kw)
        if held:
            lo, hi = _tilt_span(model, th, p0)
            corr = _h_tilt_correlation(free_fit)  # the fit before anything was held
            why = (f"the points span {math.degrees(lo):.1f}-{math.degrees(hi):.1f} deg of tilt "
                   f"({math.degrees(hi - lo):.1f} deg" + (f", correlation of h and the tilt offset {corr:+.3f}"
                                                          if corr is not None else "")
                   + "): h and the tilt offset cannot be told apart; add points nearer and farther from the nadir")
            msg = (f"{'; '.join(held.values())}: {why}; held at nominal "
                   + ", ".join(f"h = {model.h:.4g} m" if k == "h" else f"tilt offset {math.degrees(model.offsets[1]):g} deg"
                               for k in held)
                   + " and the rest refitted (their std take the held value as exact)")
            if strict:
                raise InconsistentDataError(msg, source=source)
            nl.warnings.insert(0, Diagnostic("parameter_held", msg, params=tuple(held)))
            nl.extra["held"] = dict(held)
        ests["nonlinear"] = nl
    if "closed_form" not in methods:
        ests.pop("closed_form", None)
    prefit = cons
    if refine_model and not cons.consistent:
        nl = ests["nonlinear"]
        refined = model.with_(d1=model.H - nl.extra["h"], offsets=tuple(nl.extra["offsets"]))
        cons = distance_consistency(pw, _spots(refined, th), sigma=sigma, scale_hint=hint, cov_0=cov0(refined))
        if strict and not cons.consistent:
            raise InconsistentDataError(cons.warnings[0].message)
    primary = "nonlinear" if "nonlinear" in ests else ("closed_form" if "closed_form" in ests else "seed")
    run = CalibrationRun(pw, p0, th, model, cons, ests, sigma, primary)
    run.consistency_prefit = prefit
    run.input_warnings = input_warnings
    run.joint_noise = None if jn is None else (float(jn[0]), float(jn[1]))
    return run


def _h_tilt_correlation(est: ExtrinsicEstimate) -> float | None:
    lsq = est.extra.get("lsq")
    if lsq is None or lsq.corr is None or "h" not in lsq.free_labels or "tilt_offset" not in lsq.free_labels:
        return None
    i, j = lsq.free_labels.index("h"), lsq.free_labels.index("tilt_offset")
    c = float(np.asarray(lsq.corr)[i, j])
    return c if math.isfinite(c) else None


def rotation_error(R_est, R_true) -> np.ndarray:
    """Angle (rad) of ``R_est R_true^T``."""
    return rotation_angle(np.asarray(R_est) @ np.swapaxes(np.asarray(R_true), -1, -2))
