"""Checks of the calibration data before any solver (seed 000, §2.2): correspondences, distances, reach.

Paired floor points ``^W P_i`` (world) and ``^0 P_i`` (projector frame) must be
a rigid correspondence: :func:`check_correspondences` refuses wrong shapes,
too few, duplicated or collinear points; :func:`distance_consistency`
compares the pairwise distances (a rigid transform preserves them) and names
the points that break them; :func:`beyond_tilt_limit` names spots aimed
beyond the tilt limit (seed §2.1).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import DegenerateGeometryError, NotEnoughDataError, ShapeError, UnitError
from robocal.estimation import OUTLIER_FAMILY_P
from robocal.rigs.projector.model import NearSingularityWarning, ProjectorModel
from robocal.validation import check_array

__all__ = ["check_correspondences", "spread_ratio", "ConsistencyReport", "distance_consistency",
           "beyond_tilt_limit", "CAL_BYTES_PER_POINT", "LARGE_N", "ALL_PAIRS_MAX", "N_ANCHORS", "CONSISTENCY_ALPHA"]


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
#: Family-wise false-alarm rate of the pairwise check when the noise is stated (Bonferroni over the pairs):
#: the core's outlier default.
CONSISTENCY_ALPHA = OUTLIER_FAMILY_P


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
    pair), else ``rel_tol`` of the distance. Default ``n_sigma``:
    :func:`robocal.estimation.outlier_sigma` of the pairs, the two-sided
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
    from robocal.estimation import outlier_sigma
    from robocal.progress import progress

    pw, p0 = check_correspondences(points_W, points_0, unit_check=False)
    n = pw.shape[0]
    n_pairs = n * (n - 1) // 2 if n <= ALL_PAIRS_MAX else sum(len(i) for i, _ in _pair_index(n))
    if sigma and n_sigma is None:  # the core's multiplicity-corrected threshold, over the pairs
        n_sigma = outlier_sigma(n_pairs, alpha)
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



def _tilt_span(model: ProjectorModel, th, p0) -> tuple[float, float]:
    """Smallest and largest actual tilt (rad) of the calibration spots."""
    if th is not None:
        a2 = np.abs(th[:, 1] + model.offsets[1])
    else:
        a2 = np.arctan2(np.hypot(p0[:, 0], p0[:, 1]), model.h)
    return float(a2.min()), float(a2.max())


