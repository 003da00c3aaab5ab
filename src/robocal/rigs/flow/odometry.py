"""Robot motion from several flow sensors: the seed's A u = b, robustly (Li, Guan and Chu 2017, eqs. 6–12).

For each frame interval ``k`` every valid sensor ``i`` gives its metric ground
displacement ``dS_i`` in its own frame at the *end* of the interval (block
matching follows the ground point under the lens at the start into the new
frame). In the robot frame at the middle of the interval it is

    b_i = scale_i R(phi_i + dtheta/2) dS_i
        = [[1, 0, -R_i sin psi_i], [0, 1, R_i cos psi_i]] u = A_i u,

``u = (dx, dy, dtheta)`` the body twist of the step (the seed's eq. 9 with
``theta = 0``: solving in the robot frame and then rotating by the heading
gives the same ``u`` as the seed's world-frame form). The half-step rotation
``dtheta/2`` (and the chord-to-arc factor ``sinc(dtheta/2)``) account for the
sensor turning during the interval, found by fixed-point passes (``A`` does
not depend on them); with them the twists integrate exactly. Two or more sensors make it
(over)determined; it is solved by weighted least squares with weights from
each sensor's per-frame quality, a sensor that disagrees with the others
beyond its noise (chi-square test) is dropped, and the twist covariance is
``(A^T W A)^-1``. Poses follow by exact SE(2) integration (eq. 12 is its
first-order form, available as ``method="euler"``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import InputError, NotEnoughDataError
from robocal.rigs.flow.model import SensorArray, integrate_twists, median, se2_exp

__all__ = ["SensorSteps", "Odometry", "fuse_steps", "dead_reckon", "flow_sigma", "final_pose_covariance",
           "CHI2_RATIO_WARN"]

#: A median chi-square ratio (see :func:`dead_reckon`) above this means the flow noise is
#: understated (by more than 1.7x) or the array geometry is off: on the rendered loop with
#: the true array it is 0.34 (equiangular, sigma 0.06 px), 2.6 for half-pixel flow weighted
#: with 0.06 px, 1.8 with the nominal array (mounting errors of 6-9 mm and 2-3 deg).
CHI2_RATIO_WARN = 3.0



@functools.lru_cache(maxsize=256)
def _chi2_isf_int(k: int, p: float) -> float:
    """The chi-square quantile with ``k`` (integer >= 1) degrees of freedom exceeded with probability
    ``p`` (SciPy's ``chdtri(k, p)``): bisection on the closed-form survival function of integer
    degrees of freedom (Abramowitz and Stegun 26.4.4-5), to the last bit of the double interval.

    Here and not SciPy's: ``scipy.special`` costs 0.4-0.6 s to import, more than the whole fixed cost
    a ``robocal flow odometry`` call may have (issue 16), and the fusion needs only integer ``k``.
    """
    def sf(x: float) -> float:
        if k % 2 == 0:
            term = total = 1.0
            for i in range(1, k // 2):
                term *= 0.5 * x / i
                total += term
            return math.exp(-0.5 * x) * total
        total = math.erfc(math.sqrt(0.5 * x))
        if k > 1:
            term = math.sqrt(2.0 * x / math.pi) * math.exp(-0.5 * x)
            total += term
            for i in range(1, (k - 1) // 2):
                term *= x / (2 * i + 1)
                total += term
        return total

    lo, hi = 0.0, float(max(k, 1))
    while sf(hi) > p:
        lo, hi = hi, 2.0 * hi
    while True:
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            return hi
        if sf(mid) > p:
            lo = mid
        else:
            hi = mid


def chi2_isf(dof, p: float) -> np.ndarray:
    """:func:`_chi2_isf_int` of each integer ``dof`` (array_like), as ``scipy.special.chdtri(dof, p)``."""
    d = np.asarray(dof)
    if not 0.0 < p < 1.0 or (d.size and (d.min() < 1 or np.any(d != np.rint(d)))):
        raise InputError(f"chi2_isf: needs integer degrees of freedom >= 1 and 0 < p < 1, got {dof!r}, {p!r}")
    u, inv = np.unique(d.astype(np.int64), return_inverse=True)
    return np.array([_chi2_isf_int(int(k), float(p)) for k in u])[inv].reshape(d.shape)


@dataclass
class SensorSteps:
    """Per-interval displacements of every sensor, the fusion's input.

    Attributes
    ----------
    t : ndarray, shape (K+1,)
        Frame times, s (strictly increasing).
    disp : ndarray, shape (n, K, 2)
        Metric displacement in each sensor's frame, m (NaN where not valid).
    valid : ndarray of bool, shape (n, K)
    sigma : ndarray, shape (n, K)
        Standard deviation of each displacement component, m.
    quality : ndarray, shape (n, K)
        0..255.
    reasons : list of dict, optional
        Per sensor, ``{reason: count}`` of the frames without a valid flow
        (the kernel's "low texture" / "ambiguous" / "poor match", or a flow
        log's "quality 0 in the log" / "no record" / "dropped interval").
    warnings : list of Diagnostic
        Found while reading the input (dropped stretches, ...); passed on by
        :func:`dead_reckon`.
    kernel : KernelTrace, optional
        Raw flow, pixel scale and a sample of the frames when the steps come
        from frames (:func:`robocal.rigs.flow.log.steps_from_frames`): what the
        calibration's kernel-bias model needs (:mod:`robocal.rigs.flow.kernel_bias`).
    height : ndarray, shape (n, K), optional
        The logged distance to the floor, m (NaN where a sensor has no record): what
        the plausibility check (:mod:`robocal.rigs.flow.plausibility`) judges.
    """

    t: np.ndarray
    disp: np.ndarray
    valid: np.ndarray
    sigma: np.ndarray
    quality: np.ndarray
    reasons: list | None = None
    warnings: list = field(default_factory=list)
    kernel: object = None
    height: np.ndarray | None = None

    def __post_init__(self):
        t = np.asarray(self.t, float)
        if t.ndim != 1 or t.size < 2:
            raise InputError(f"t must be a 1-D array of at least 2 frame times, got shape {t.shape}")
        d = np.diff(t)
        if np.any(~(d > 0)):
            k = int(np.flatnonzero(~(d > 0))[0])
            raise InputError(f"timestamps must increase strictly: t[{k + 1}] = {t[k + 1]:.6f} s follows t[{k}] = {t[k]:.6f} s")
        n, K = self.valid.shape
        if self.disp.shape != (n, K, 2) or K != t.size - 1:
            raise InputError(f"disp must have shape (n, {t.size - 1}, 2), got {self.disp.shape}")
        self.t = t

    @property
    def dt(self) -> np.ndarray:
        return np.diff(self.t)


def flow_sigma(n_used, height, focal_px, *, sigma_px: float = 0.06, n_blocks: int = 25):
    """Displacement standard deviation (m) of a frame's flow from its block count.

    ``sigma_px`` is the per-frame flow error with all blocks in use (measured
    on real-photo frames: about 0.06 px for the equiangular fit, see
    docs/rigs/flow.md); fewer blocks average less: ``sigma_px sqrt(n_blocks /
    n_used)``. Converted to metres by ``h / f`` (eq. 5).
    """
    n = np.maximum(np.asarray(n_used, float), 1.0)
    return sigma_px * np.sqrt(n_blocks / n) * np.asarray(height, float) / float(focal_px)


@dataclass
class Odometry:
    """Dead-reckoning result.

    Attributes
    ----------
    t : ndarray, shape (K+1,)
    poses : ndarray, shape (K+1, 3)
        ``(X, Y, theta)`` in the world frame (the first pose is ``pose0``).
    twists : ndarray, shape (K, 3)
        Body twist of each step ``(dx, dy, dtheta)``.
    twist_cov : ndarray, shape (K, 3, 3)
        Covariance of each twist (NaN for bridged steps).
    velocity : ndarray, shape (K, 3)
        ``(vx, vy, omega)`` in the robot frame, m/s, m/s, rad/s.
    velocity_std : ndarray, shape (K, 3)
    used : ndarray of bool, shape (n, K)
        Which sensors entered each step.
    rejected : ndarray of bool, shape (n, K)
        Valid sensors dropped as outliers.
    bridged : ndarray of bool, shape (K,)
        Steps with fewer than 2 usable sensors (the previous twist was held).
    chi2 : ndarray, shape (K,)
        Normalised residual sum of squares of each step (NaN without redundancy).
    warnings : list of Diagnostic
    frames : dict
        ``invalid_frames`` (per sensor) and ``invalid_by_reason`` (per sensor, reason -> count).
    chi2_ratio : float
        Median over redundant steps of ``chi2`` divided by the median of its
        chi-square distribution: about 1 when the stated flow noise is right.
    method : str
        How the twists were integrated (``"exact"`` or ``"euler"``).
    """

    t: np.ndarray
    poses: np.ndarray
    twists: np.ndarray
    twist_cov: np.ndarray
    velocity: np.ndarray
    velocity_std: np.ndarray
    used: np.ndarray
    rejected: np.ndarray
    bridged: np.ndarray
    chi2: np.ndarray
    warnings: list = field(default_factory=list)
    chi2_ratio: float = float("nan")
    frames: dict = field(default_factory=dict)
    method: str = "exact"

    def summary(self) -> dict:
        return {
            **self.frames,
            "chi2_median_ratio": self.chi2_ratio,
            "steps": int(len(self.twists)),
            "bridged_steps": int(self.bridged.sum()),
            "sensor_rejections": self.rejected.sum(axis=1).tolist(),
            "distance_m": float(np.sum(np.linalg.norm(np.diff(self.poses[:, :2], axis=0), axis=1))),
        }


def _solve_weighted(A, b, w):
    """Batched weighted least squares. A (n,2,3) common, b (K,n,2), w (K,n) -> u (K,3), N^-1 (K,3,3), rss (K,)."""
    AtA = np.einsum("nij,nil->njl", A, A)                      # (n, 3, 3), once
    N = np.einsum("kn,njl->kjl", w, AtA)
    rhs = np.einsum("kn,nij,kni->kj", w, A, b, optimize=True)
    # an explicit 3x3 inverse (adjugate): one vectorised pass, singular steps -> NaN
    c00 = N[:, 1, 1] * N[:, 2, 2] - N[:, 1, 2] * N[:, 2, 1]
    c01 = N[:, 0, 2] * N[:, 2, 1] - N[:, 0, 1] * N[:, 2, 2]
    c02 = N[:, 0, 1] * N[:, 1, 2] - N[:, 0, 2] * N[:, 1, 1]
    c10 = N[:, 1, 2] * N[:, 2, 0] - N[:, 1, 0] * N[:, 2, 2]
    c11 = N[:, 0, 0] * N[:, 2, 2] - N[:, 0, 2] * N[:, 2, 0]
    c12 = N[:, 0, 2] * N[:, 1, 0] - N[:, 0, 0] * N[:, 1, 2]
    c20 = N[:, 1, 0] * N[:, 2, 1] - N[:, 1, 1] * N[:, 2, 0]
    c21 = N[:, 0, 1] * N[:, 2, 0] - N[:, 0, 0] * N[:, 2, 1]
    c22 = N[:, 0, 0] * N[:, 1, 1] - N[:, 0, 1] * N[:, 1, 0]
    det = N[:, 0, 0] * c00 + N[:, 0, 1] * c10 + N[:, 0, 2] * c20
    scale = np.abs(N).max(axis=(1, 2)) ** 3
    ok = np.abs(det) > 1e-12 * np.maximum(scale, 1e-300)
    inv_det = np.where(ok, 1.0 / np.where(ok, det, 1.0), np.nan)
    Ninv = np.stack([np.stack([c00, c01, c02], -1), np.stack([c10, c11, c12], -1), np.stack([c20, c21, c22], -1)], -2)
    Ninv = Ninv * inv_det[:, None, None]
    u = np.einsum("kij,kj->ki", Ninv, rhs)
    r = b - np.einsum("nij,kj->kni", A, u)
    rss = np.sum(w * np.sum(r**2, axis=2), axis=1)
    return u, Ninv, rss, r


def fuse_steps(steps: SensorSteps, array: SensorArray, *, robust: bool = True, outlier_p: float = 1e-3,
               half_step: bool = True, return_raw_chi2: bool = False):
    """Solve the seed's ``A u = b`` for every step (weighted, outlier-robust).

    Parameters
    ----------
    steps : SensorSteps
    array : SensorArray
        Sensor placement (at least 2 sensors).
    robust : bool
        Drop, one at a time, the sensor with the largest normalised residual
        while the step's chi-square exceeds its ``1 - outlier_p`` quantile
        and at least 3 sensors remain (2 sensors leave 1 redundant equation:
        a disagreement can be seen but not blamed).
    half_step : bool
        Rotate each displacement by half the step's rotation (see module doc).

    return_raw_chi2 : bool
        Also return each step's chi-square and its degrees of freedom with all
        valid sensors, before any outlier rejection (rejection removes the
        largest ones and would hide an understated noise).

    Returns
    -------
    twists (K, 3), cov (K, 3, 3), used (n, K), rejected (n, K), bridged (K,), chi2 (K,)
    [, raw_chi2 (K,), raw_dof (K,)]
    """
    n, K = steps.valid.shape
    if n != array.n:
        raise InputError(f"the log has {n} sensors but the array describes {array.n}")
    A = array.design_matrix().reshape(array.n, 2, 3)
    valid = steps.valid & np.all(np.isfinite(steps.disp), axis=2) & (steps.sigma > 0)
    d = np.where(valid[..., None], steps.disp, 0.0) * array.scale[:, None, None]
    sig = np.where(valid, steps.sigma * array.scale[:, None], 1.0)
    w0 = np.where(valid, 1.0 / sig**2, 0.0).T                 # (K, n)
    used = valid.T.copy()                                      # (K, n)

    dx, dy = d[:, :, 0].T, d[:, :, 1].T                       # (K, n)

    def build_b(dtheta, rows=slice(None)):
        ang = array.phi[None, :] + (0.5 * dtheta[:, None] if half_step else 0.0)
        # R(ang) d written out: the same products and sums as the batched 2x2 product (rot2), 7x faster
        c, s = np.cos(ang), np.sin(ang)
        x, y = dx[rows], dy[rows]
        b = np.stack([c * x - s * y, s * x + c * y], axis=-1)
        if half_step:
            # a constant twist moves a point along an arc: its chord, seen from the middle of
            # the step, is the twist shortened by sinc(dtheta/2)
            h = 0.5 * dtheta
            b = b / np.where(np.abs(h) > 1e-8, np.sin(h) / np.where(h == 0, 1.0, h), 1.0)[:, None, None]
        return b

    enough = used.sum(axis=1) >= 2
    dth = np.zeros(K)
    for _ in range(3):
        b = build_b(dth)
        u, Ninv, rss, r = _solve_weighted(A, b, np.where(used, w0, 0.0))
        dth = np.where(enough, np.nan_to_num(u[:, 2]), 0.0)
    raw_dof = 2 * used.sum(axis=1) - 3
    raw_chi2 = np.where(raw_dof > 0, rss, np.nan)
    rejected = np.zeros_like(used)
    if robust:
        for _ in range(max(0, n - 2)):
            m = used.sum(axis=1)
            dof = 2 * m - 3
            redundant = m >= 3
            thr = np.where(redundant, chi2_isf(np.maximum(dof, 1), outlier_p), np.inf)
            bad = redundant & (rss > thr)
            if not np.any(bad):
                break
            score = np.where(used, w0 * np.sum(r**2, axis=2), -np.inf)
            worst = np.argmax(score, axis=1)
            idx = np.flatnonzero(bad)
            used[idx, worst[idx]] = False
            rejected[idx, worst[idx]] = True
            # only the steps that lost a sensor are solved again (each step's least squares is its own; a
            # 30 s log drops a sensor in ~3 % of its steps): without it, then with the half-step rotation of
            # the cleaned twist
            w_i = np.where(used[idx], w0[idx], 0.0)
            u_i = _solve_weighted(A, build_b(dth[idx], idx), w_i)[0]
            dth[idx] = np.where(used[idx].sum(axis=1) >= 2, np.nan_to_num(u_i[:, 2]), 0.0)
            u[idx], Ninv[idx], rss[idx], r[idx] = _solve_weighted(A, build_b(dth[idx], idx), w_i)
    m = used.sum(axis=1)
    # a step whose sensors all sit at one point (two valid sensors of a rank-3 array may) has
    # a singular normal matrix: it is bridged like a step without sensors, never NaN
    singular = ~np.all(np.isfinite(u), axis=1)
    bridged = (m < 2) | singular
    chi2 = np.where(m >= 2, rss, np.nan)
    chi2 = np.where(2 * m - 3 > 0, chi2, np.nan)
    # steps without two sensors hold the last good twist (constant-velocity bridge)
    if np.any(bridged):
        good = np.flatnonzero(~bridged)
        if good.size == 0:
            raise NotEnoughDataError("no interval has two valid sensors: the log cannot give a trajectory")
        fill = np.maximum.accumulate(np.where(~bridged, np.arange(K), -1))
        fill = np.where(fill < 0, good[0], fill)
        # hold the velocity, not the displacement: a bridged interval may be longer (a dropped record)
        dt = steps.dt
        u = u[fill] * (dt / dt[fill])[:, None]
        Ninv = np.where(bridged[:, None, None], np.nan, Ninv)
    if return_raw_chi2:
        return u, Ninv, used.T, rejected.T, bridged, chi2, raw_chi2, raw_dof
    return u, Ninv, used.T, rejected.T, bridged, chi2


def dead_reckon(steps: SensorSteps, array: SensorArray, *, pose0=(0.0, 0.0, 0.0), method: str = "exact",
                robust: bool = True) -> Odometry:
    """Trajectory of the robot from its flow sensors (Li, Guan and Chu 2017, eqs. 9–12).

    Parameters
    ----------
    steps : SensorSteps
    array : SensorArray
    pose0 : (X, Y, theta)
    method : {"exact", "euler"}
        Pose integration (see :func:`robocal.rigs.flow.model.integrate_twists`).
    robust : bool
        Outlier-robust fusion (see :func:`fuse_steps`).
    """
    if method not in ("exact", "euler"):
        raise InputError(f"method must be 'exact' or 'euler', got {method!r}")
    u, cov, used, rejected, bridged, chi2, raw_chi2, dof = fuse_steps(steps, array, robust=robust, return_raw_chi2=True)
    if not np.all(np.isfinite(u)):  # pragma: no cover - fuse_steps bridges singular steps
        raise NotEnoughDataError("the array gave no finite twist for some steps")
    poses = integrate_twists(u, pose0, method=method)
    dt = steps.dt
    vel = u / dt[:, None]
    vstd = np.sqrt(np.abs(np.diagonal(cov, axis1=1, axis2=2))) / dt[:, None]
    warnings = []
    # consistency of the stated flow noise: each redundant step's chi-square over the median of
    # its chi-square distribution (about 1 when sigma is right; 0.3-0.4 with the kernel's own
    # sigma_px on rendered drives, which is conservative); far above 1, the noise is understated
    # and the covariance and the outlier test are wrong with it
    red = (dof > 0) & np.isfinite(raw_chi2)
    chi2_ratio = median(raw_chi2[red] / chi2_isf(dof[red], 0.5)) if red.sum() >= 10 else float("nan")
    if chi2_ratio > CHI2_RATIO_WARN:
        warnings.append(Diagnostic("inconsistent_data", f"the sensors disagree {np.sqrt(chi2_ratio):.1f}x more than their "
                                   f"stated noise (median chi-square ratio {chi2_ratio:.2f}, expected <= 1): the flow "
                                   "sigma is too small for this log (set camera: sigma_px in run.yaml) or the array "
                                   "geometry is off (calibrate it); the covariance is too small and the outlier test "
                                   "drops good sensors"))
    if bridged.any():
        idx = np.flatnonzero(bridged)
        warnings.append(Diagnostic("low_quality", f"{idx.size} of {len(u)} intervals had fewer than 2 valid sensors "
                                   "(or only sensors at one point); the previous velocity was held", indices=tuple(int(i) for i in idx[:200])))
    warnings = list(steps.warnings) + warnings
    for i in range(array.n):
        inval = ~steps.valid[i]
        # any excluded frame is reported, with its reasons: a sensor that loses a few percent of
        # its frames in one place (a texture gap) loses motion there even if the rest is fine
        if inval.any():
            why = (steps.reasons[i] if steps.reasons is not None else {}) or {"invalid": int(inval.sum())}
            text = ", ".join(f"{r} {c}" for r, c in sorted(why.items(), key=lambda x: -x[1]))
            warnings.append(Diagnostic("low_quality", f"sensor {array.names[i]}: {inval.sum()} of {len(inval)} frames "
                                       f"({100 * inval.mean():.1f} %) without a valid flow ({text}); left out of the "
                                       "fusion there", params=(array.names[i],),
                                       indices=tuple(int(k) for k in np.flatnonzero(inval)[:200])))
        if rejected[i].sum() > 0:
            idx = np.flatnonzero(rejected[i])
            warnings.append(Diagnostic("outliers", f"sensor {array.names[i]} disagreed with the others in {idx.size} "
                                       "intervals and was left out there", params=(array.names[i],),
                                       indices=tuple(int(k) for k in idx[:200])))
    inv = ~steps.valid
    frames = {"invalid_frames": {nm: int(inv[i].sum()) for i, nm in enumerate(array.names)},
              "invalid_by_reason": {nm: dict(steps.reasons[i]) if steps.reasons is not None else
                                    ({"invalid": int(inv[i].sum())} if inv[i].any() else {})
                                    for i, nm in enumerate(array.names)}}
    return Odometry(frames=frames, t=steps.t, poses=poses, twists=u, twist_cov=cov, velocity=vel, velocity_std=vstd, used=used,
                    rejected=rejected, bridged=bridged, chi2=chi2, warnings=warnings, chi2_ratio=chi2_ratio,
                    method=method)


def final_pose_covariance(poses, twists, twist_cov, *, method: str = "exact") -> np.ndarray:
    """Covariance (3, 3) of the last pose ``(X, Y, theta)`` of :func:`integrate_twists`, first order.

    Each step's twist error (``twist_cov``, independent between steps) moves
    every later pose: its translation part by ``R(theta_k)`` times it, its
    rotation part rotates the rest of the path about the step's end point
    (the standard SE(2) dead-reckoning propagation, e.g. Thrun, Burgard and
    Fox, *Probabilistic Robotics*, MIT Press 2005, sec. 5.4). ``"exact"``
    integration goes through the Jacobian of :func:`se2_exp` (central
    differences). Under the fusion's white-noise model: the flow kernel's
    time-correlated bias (see :mod:`robocal.rigs.flow.calibrate`) is not in
    it. NaN when a step has no covariance (a bridged step, held at the last
    velocity: its error is not modelled).
    """
    p = np.asarray(poses, float)
    u = np.asarray(twists, float)
    C = np.asarray(twist_cov, float)
    K = u.shape[0]
    if method == "exact":
        h = 1e-7
        J_exp = np.empty((K, 3, 3))
        for j in range(3):
            e = np.zeros(3)
            e[j] = h
            J_exp[:, :, j] = (se2_exp(u + e) - se2_exp(u - e)) / (2 * h)
        C = J_exp @ C @ np.swapaxes(J_exp, 1, 2)
    c, s = np.cos(p[:-1, 2]), np.sin(p[:-1, 2])
    G = np.zeros((K, 3, 3))
    G[:, 0, 0], G[:, 0, 1], G[:, 1, 0], G[:, 1, 1] = c, -s, s, c
    G[:, 0, 2] = -(p[-1, 1] - p[1:, 1])
    G[:, 1, 2] = p[-1, 0] - p[1:, 0]
    G[:, 2, 2] = 1.0
    # sum_k G_k C_k G_k^T: the batched product, then one contraction over k and the inner index (BLAS),
    # 3x less time than the three-operand einsum
    return np.tensordot(G @ C, G, axes=([0, 2], [0, 2]))
