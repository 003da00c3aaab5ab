"""Solve a :class:`~robocal.estimation.Problem` with ``scipy.optimize.least_squares``.

SciPy does the optimisation (MINPACK Levenberg–Marquardt, trust-region
reflective, dogbox). This module adds what it does not keep: the cost at each
accepted iterate, a covariance that stays meaningful when the problem is rank
deficient, parameters named in every warning, and outliers by observation.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy import special
from scipy.optimize import least_squares, leastsq

from robocal.diagnostics import Diagnostic
from robocal.errors import InputError, NotEnoughDataError, RobocalError
from robocal.estimation._identifiability import _analyze_checked
from robocal.estimation._problem import Problem
from robocal.estimation._result import STATUS_MESSAGES, LSQResult, outlier_threshold
from robocal.estimation._result import outlier_sigma as bonferroni_sigma

__all__ = ["solve", "Iteration", "robust_cost", "loss_derivatives", "METHODS", "LOSSES"]

METHODS = ("trf", "dogbox", "lm")
LOSSES = ("linear", "soft_l1", "huber", "cauchy", "arctan")


def _rho(z: np.ndarray, loss: str) -> tuple[np.ndarray, np.ndarray]:
    """Loss ``rho(z)`` and ``rho'(z)`` on ``z = (r / f_scale)^2`` (SciPy's definitions)."""
    if loss == "linear":
        return z, np.ones_like(z)
    if loss == "soft_l1":
        t = np.sqrt(1.0 + z)
        return 2.0 * (t - 1.0), 1.0 / t
    if loss == "huber":
        big = z > 1.0
        sq = np.sqrt(np.where(big, z, 1.0))
        return np.where(big, 2.0 * sq - 1.0, z), np.where(big, 1.0 / sq, 1.0)
    if loss == "cauchy":
        return np.log1p(z), 1.0 / (1.0 + z)
    if loss == "arctan":
        return np.arctan(z), 1.0 / (1.0 + z**2)
    raise InputError(f"loss must be one of {', '.join(LOSSES)}, got {loss!r}")


def loss_derivatives(z: np.ndarray, loss: str) -> tuple[np.ndarray, np.ndarray]:
    """``rho'(z)`` and ``rho''(z)`` of SciPy's losses on ``z = (r / f_scale)^2``.

    For a solver of one's own on a robust cost: the gradient is ``J^T rho' f`` and SciPy's
    trust-region methods use ``J^T (rho' + 2 z rho'') J`` as the Gauss-Newton matrix.
    """
    z = np.asarray(z, dtype=float)
    _, r1 = _rho(z, loss)
    if loss == "soft_l1":
        r2 = -0.5 * r1**3
    elif loss == "huber":
        r2 = np.where(z > 1.0, -0.5 * r1**3, 0.0)
    elif loss == "cauchy":
        r2 = -(r1**2)
    elif loss == "arctan":
        r2 = -2.0 * z * r1**2
    else:  # linear
        r2 = np.zeros_like(z)
    return r1, r2


def robust_cost(f: np.ndarray, loss: str = "linear", f_scale: float = 1.0) -> float:
    """``0.5 * f_scale^2 * sum(rho((f / f_scale)^2))``, the cost ``least_squares`` minimises."""
    f = np.asarray(f)
    if loss == "linear":  # the common case, at every iterate: no rho arrays
        return float(0.5 * np.dot(f, f)) if f.ndim == 1 else float(0.5 * np.sum(f**2))
    rho, _ = _rho((f / f_scale) ** 2, loss)
    return float(0.5 * f_scale**2 * np.sum(rho))


@dataclass(frozen=True)
class Iteration:
    """What a ``callback`` receives at each accepted iterate.

    Attributes
    ----------
    iteration : int
        0 for the initial point, then 1, 2, ... per accepted step.
    cost : float
    x : ndarray, shape (n,)
        Free parameters.
    params : dict of str to ndarray
        All blocks.
    """

    iteration: int
    cost: float
    x: np.ndarray
    params: dict


class _Stop(Exception):
    pass


class _Tracker:
    """Wraps the residual and Jacobian functions given to the solver.

    Every method asks for the Jacobian exactly once per accepted iterate (the
    start point and after each successful step) and always at a point whose
    residuals it has just evaluated. So the cost at each accepted iterate is
    read from the cache of recent residual evaluations when the Jacobian is
    requested; trial points that the solver rejects never reach the Jacobian
    and never enter the history. A second request at the point of the last
    Jacobian (SciPy's wrappers probe the start point before MINPACK does, and
    ask again at MINPACK's last point) returns that Jacobian: no evaluation,
    no second history entry. Residuals asked for again at a point in the cache
    (the start point, evaluated when the problem was compiled) are not
    evaluated again either.
    """

    def __init__(self, ev, loss, f_scale, callback, bar):
        self.ev, self.loss, self.f_scale = ev, loss, f_scale
        self.callback, self.bar = callback, bar
        self.cache: list[tuple[bytes, np.ndarray]] = []
        self.history: list[float] = []
        self.last_x = self.last_f = self.last_J = None
        self.last_key = None

    def seed(self, x, f):
        """Residuals ``f`` already evaluated at ``x`` (counted as the solver's evaluation there)."""
        self.cache.append((np.ascontiguousarray(x, dtype=float).tobytes(), f))
        self.ev.n_fun += 1

    def lookup(self, x, key=None):
        # keyed by the bytes of x: np.array_equal over the cache cost more than a small problem's residuals
        if key is None:
            key = np.ascontiguousarray(x, dtype=float).tobytes()
        for kk, f in reversed(self.cache):
            if kk == key:
                return f
        return None

    def fun(self, x):
        key = np.ascontiguousarray(x, dtype=float).tobytes()
        f = self.lookup(x, key)
        if f is None:
            f = self.ev.weighted(x)
            self.cache = self.cache[-3:] + [(key, f)]
        # a copy: SciPy 1.11/1.12 scale the returned residuals in place for a robust loss, which
        # corrupted the cached ones (robust residual variance off by 1e12 at the lowest pins)
        return f.copy()

    def jac(self, x, *args, **kwargs):
        key = np.ascontiguousarray(x, dtype=float).tobytes()
        if self.last_J is not None and key == self.last_key:
            return self.last_J.copy()
        f = self.lookup(x, key)
        if f is None:
            self.fun(x)
            f = self.lookup(x, key)
        cost = robust_cost(f, self.loss, self.f_scale)
        self.history.append(cost)
        self.last_x, self.last_f, self.last_J = np.array(x, copy=True), f, None
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix(cost=f"{cost:.6g}")
        if self.callback is not None:
            info = Iteration(len(self.history) - 1, cost, self.last_x.copy(), self.ev.params(self.last_x))
            if self.callback(info) is True:
                raise _Stop
        self.last_J = self.ev.jacobian(x, f0=f)
        self.last_key = key
        return self.last_J.copy()  # SciPy 1.11/1.12 scale it in place too (see fun)


@functools.lru_cache(maxsize=256)
def _clip_constants(n_sigma: float, dim: int) -> tuple[float, float]:
    """The clipping threshold ``t`` (chi-square(dim) quantile of the ``n_sigma`` tail) and the truncation
    factor ``F_{d+2}(t) / F_d(t)`` (chi2.cdf, without scipy.stats); cached: every solve asks for the same few."""
    t = outlier_threshold(n_sigma, dim)
    return t, float(special.chdtr(dim + 2, t) / special.chdtr(dim, t))


def _clipped_variance(q, dims, m, rank, n_sigma, max_iter=20, unique=None) -> float:
    """Residual variance by iterative n-sigma clipping of whole observations.

    Starts from ``sum(q) / (m - rank)`` and re-estimates from the observations
    inside the threshold until the inlier set stops changing. The truncation
    is corrected exactly for Gaussian noise: for ``q ~ s^2 chi2_d`` cut at
    ``t``, ``E[q | q < t s^2] = s^2 d F_{d+2}(t) / F_d(t)``. The plain
    estimate would let a gross outlier inflate the yardstick and hide itself;
    the median absolute deviation is robust but too noisy for small samples.
    """
    dof_factor = m / max(m - rank, 1)
    s2 = float(q.sum()) / max(m - rank, 1)
    if s2 <= 0:
        return 0.0
    udims, which = np.unique(dims, return_inverse=True) if unique is None else unique
    tc = np.array([_clip_constants(float(n_sigma), int(d)) for d in udims.tolist()])
    # one observation size: the constants as scalars (the same products, without gathering them per row)
    one = len(tc) == 1
    t, c = (float(tc[0, 0]), float(tc[0, 1])) if one else (tc[which, 0], tc[which, 1])
    inl = None
    for _ in range(max_iter):
        new = q <= t * s2
        if inl is not None and (new == inl).all():
            break
        inl = new
        if not inl.any():
            break
        s2 = float(q[inl].sum() / (dims[inl] * (c if one else c[inl])).sum()) * dof_factor
        if s2 <= 0:
            return 0.0
    return s2


#: MINPACK's ``info`` -> ``least_squares``'s status, and its messages (scipy.optimize._lsq.least_squares's
#: FROM_MINPACK_TO_COMMON and TERMINATION_MESSAGES, the same since SciPy 0.17): the direct MINPACK path
#: reports what ``least_squares(method='lm')`` would.
_FROM_MINPACK = {0: -1, 1: 2, 2: 3, 3: 4, 4: 1, 5: 0}
_LSQ_MESSAGES = {
    -1: "Improper input parameters status returned from `leastsq`",
    0: "The maximum number of function evaluations is exceeded.",
    1: "`gtol` termination condition is satisfied.",
    2: "`ftol` termination condition is satisfied.",
    3: "`xtol` termination condition is satisfied.",
    4: "Both `ftol` and `xtol` termination conditions are satisfied.",
}
_EPS = np.finfo(float).eps


def _minpack_diag(x_scale, n: int, ftol, xtol, gtol, verbose):
    """MINPACK's ``diag`` for ``x_scale`` (None for ``'jac'``), or False when ``least_squares`` must take the
    call: verbose output, a tolerance below machine epsilon, an invalid ``x_scale`` (it words the warnings
    and errors)."""
    if verbose or min(ftol, xtol, gtol) < _EPS:
        return False
    if isinstance(x_scale, str):
        return None if x_scale == "jac" else False
    try:
        xs = np.asarray(x_scale, dtype=float)
    except (TypeError, ValueError):
        return False
    if xs.ndim > 1 or (xs.ndim == 1 and xs.shape != (n,)) or not np.all(np.isfinite(xs) & (xs > 0)):
        return False
    return 1.0 / np.broadcast_to(xs, (n,))


def _probe_lmder():
    """SciPy's private ``_minpack._lmder`` (MINPACK's lmder as :func:`scipy.optimize.leastsq` calls it), or
    None when it is missing or does not solve a one-parameter probe as expected (then ``leastsq`` takes
    every call). Like the finite-difference engine (``_evaluate.py``), private on purpose: ``leastsq``'s
    Python layer around it — argument probes that :class:`_Tracker`'s checked shapes make redundant, its
    message table and, with ``full_output``, a covariance from MINPACK's QR that :func:`_analyse` does not
    use — cost ~0.1 ms a call, a tenth of a 15-pose hand-eye refinement (issue 16)."""
    try:
        from scipy.optimize._minpack import _lmder

        x, info = _lmder(lambda x: np.array([x[0] - 2.0, 2.0 - x[0]]), lambda x: np.array([[1.0], [-1.0]]),
                         np.zeros(1), (), 0, 0, 1e-8, 1e-8, 1e-8, 100, 100.0, None)
        return _lmder if 1 <= int(info) <= 4 and abs(float(x[0]) - 2.0) < 1e-12 else None
    except Exception:  # noqa: BLE001 - any failure of the probe means: use the public leastsq
        return None


_lmder = _probe_lmder()


def _minpack_lm(tr, x0, diag, ftol, xtol, gtol, max_nfev):
    """Levenberg-Marquardt by MINPACK's ``lmder`` through :func:`scipy.optimize.leastsq`.

    The very call ``least_squares(method='lm')`` makes (same tolerances, step bound factor 100, ``diag =
    1 / x_scale`` or column norms for ``'jac'``, budget ``100 n``), so the same iterates and answer, without
    its wrappers: since SciPy 1.15 it builds a ``VectorFunction``, evaluates the residuals and the Jacobian
    at the start point before MINPACK does and once more at the end, ~1 ms of a 90 x 12 problem's ~1.5 ms
    (issue 16). ``leastsq`` probes the start point once (served from :class:`_Tracker`'s caches); where
    SciPy's ``_lmder`` is usable (:func:`_probe_lmder`) it is called without ``leastsq``'s Python layer.
    """
    if _lmder is not None and leastsq is not None:
        # lmder works on x in place: a copy, so that x0 (the caller's) stays the start point
        x, ier = _lmder(tr.fun, tr.jac, np.array(x0, dtype=float), (), 0, 0, ftol, xtol, gtol, int(max_nfev),
                        100.0, diag)
    else:
        x, _, _, _, ier = leastsq(tr.fun, x0, Dfun=tr.jac, full_output=True, ftol=ftol, xtol=xtol, gtol=gtol,
                                  maxfev=int(max_nfev), factor=100.0, diag=diag)
    status = _FROM_MINPACK.get(int(ier), -1)   # 6-8 (tolerances below epsilon) cannot occur: see _minpack_diag
    return x, status, _LSQ_MESSAGES[status]


def _check_options(method, loss, f_scale, outlier_sigma, rank_tol):
    if method not in METHODS:
        raise InputError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if loss not in LOSSES:
        raise InputError(f"loss must be one of {', '.join(LOSSES)}, got {loss!r}")
    for name, v in (("f_scale", f_scale), ("outlier_sigma", outlier_sigma), ("rank_tol", rank_tol)):
        if name == "outlier_sigma" and v is None:
            continue
        if not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v > 0):
            raise InputError(f"{name} must be a finite number > 0, got {v!r}")


def solve(
    problem: Problem,
    *,
    method: str = "trf",
    loss: str = "linear",
    f_scale: float = 1.0,
    jac: str | None = None,
    x_scale=None,
    max_nfev: int | None = None,
    ftol: float = 1e-8,
    xtol: float = 1e-8,
    gtol: float = 1e-8,
    diff_step=None,
    sparse: bool | None = None,
    absolute_sigma: bool = False,
    outlier_sigma: float | None = None,
    rank_tol: float = 1e-6,
    weak_vif: float = 1e4,
    verbose: int = 0,
    callback: Callable[[Iteration], bool | None] | None = None,
    progress: bool = False,
) -> LSQResult:
    """Solve a least-squares problem and analyse the solution.

    Parameters
    ----------
    problem : Problem
    method : {'trf', 'dogbox', 'lm'}
        ``'lm'`` is MINPACK's Levenberg–Marquardt (no bounds, linear loss,
        dense only, ``m >= n``); ``'trf'``/``'dogbox'`` take bounds, robust
        losses and sparse Jacobians.
    loss : {'linear', 'soft_l1', 'huber', 'cauchy', 'arctan'}
        Robust loss on the weighted residuals; ``f_scale`` is the residual
        size (in units of sigma) where it starts to bite.
    f_scale : float
    jac : {'analytic', '2-point', '3-point'}, optional
        Default: analytic if every term has a Jacobian, else '2-point'.
    x_scale : float, array_like or 'jac', optional
        Default: the blocks' ``scale`` (1 where absent); ``'jac'`` for 'lm'.
    max_nfev : int, optional
        Budget of solver residual evaluations (finite-difference evaluations
        not counted); SciPy's default ``100 n``.
    ftol, xtol, gtol : float
        SciPy's termination tolerances.
    diff_step : float or array_like, optional
        Relative finite-difference step.
    sparse : bool, optional
        Use a sparse Jacobian (and SciPy's LSMR trust-region solver). Default:
        when the block structure is < 20 % dense, n >= 50 and the method is
        not 'lm'.
    absolute_sigma : bool
        True: the problem's ``sigma`` is the true noise, the covariance is
        ``(J^T J)^+`` unscaled. False: it is only relative, and the covariance
        is scaled by the residual variance ``s^2``: ``2 cost / (m - rank)``
        for the linear loss; for a robust loss the clipped estimate described
        under ``outlier_sigma`` (the outliers the loss discounted must not
        inflate the inliers' noise level).
    outlier_sigma : float, optional
        Observations beyond this many sigma are named in an ``outliers``
        warning. Default: :func:`outlier_sigma` of the number of
        observations (Bonferroni, 1 % chance of any false alarm in a clean
        calibration; the one default of every rig). The sigma is the known
        noise with ``absolute_sigma``, else the residual std re-estimated with
        iterative clipping at ``outlier_sigma`` (3 sigma by default), so that
        gross outliers do not inflate it. An observation
        with ``d`` components is tested on its squared norm against the
        chi-square(d) quantile of the same tail probability.
    rank_tol, weak_vif : float
        See :func:`analyze_jacobian`.
    verbose : int
        Passed to ``least_squares``.
    callback : callable, optional
        ``callback(Iteration)`` at each accepted iterate; return True to stop
        (status -2, ``not_converged`` warning).
    progress : bool
        Show a tqdm progress line with the cost.

    Returns
    -------
    LSQResult

    Notes
    -----
    Cost history: ``least_squares`` does not expose it (its ``callback`` is
    SciPy >= 1.16 and not for 'lm'), so the residual and Jacobian functions
    handed to it are wrapped. Every method requests the Jacobian exactly once
    per accepted iterate, right after evaluating the residuals there; the cost
    of those residuals is recorded at that moment. Rejected trial points and
    finite-difference evaluations never enter the history.
    ``cost_history[0]`` is the initial cost, ``cost_history[-1] == cost``
    and ``iterations == len(cost_history) - 1``.

    Covariance: from the Jacobian of the weighted residuals at the solution,
    each row scaled by ``sqrt(rho'(z))`` for a robust loss (the weights of the
    equivalent reweighted least-squares problem), via
    :func:`analyze_jacobian`: parameters in the null space get no std.
    """
    if not isinstance(problem, Problem):
        raise InputError(f"problem must be a robocal.estimation.Problem, got {type(problem).__name__}")
    _check_options(method, loss, f_scale, outlier_sigma, rank_tol)
    if absolute_sigma and all(t.sigma is None for t in problem._terms):
        raise InputError("absolute_sigma=True needs the noise: give sigma= to the residual terms")
    ev = problem.evaluator(jac=jac, diff_step=diff_step)
    lay = ev.layout
    m, n = ev.m, ev.n
    if n == 0:
        raise InputError("the problem has no free parameters (everything is fixed or tied)")
    if sparse is None:
        sparse = method != "lm" and ev.density < 0.2 and n >= 50
    if method == "lm":
        if sparse:
            raise InputError("method='lm' cannot use a sparse Jacobian; use method='trf'")
        if loss != "linear":
            raise InputError(f"method='lm' supports only loss='linear', got {loss!r}; use method='trf'")
        if np.any(np.isfinite(lay.lower)) or np.any(np.isfinite(lay.upper)):
            raise InputError("method='lm' does not take bounds; use method='trf' or remove lower/upper")
        if m < n:
            raise NotEnoughDataError(f"method='lm' needs at least as many residuals as free parameters: "
                                     f"m = {m} < n = {n}")
    ev.sparse = bool(sparse)
    if x_scale is None:
        x_scale = lay.scale if lay.scale is not None else ("jac" if method == "lm" else 1.0)

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(desc="least squares", unit="it", leave=False, disable=None)  # None: off when stderr is no terminal
    tr = _Tracker(ev, loss, f_scale, callback, bar)
    x0 = lay.x0_full[lay.free_full]
    tr.seed(x0, ev.f0)
    # 'lm' goes to MINPACK directly (the call least_squares makes, without its wrappers: see _minpack_lm)
    diag = _minpack_diag(x_scale, n, ftol, xtol, gtol, verbose) if method == "lm" and (
        max_nfev is None or max_nfev > 0) else False
    status, message, x = None, None, None
    try:
        if diag is not False:
            x, status, message = _minpack_lm(tr, x0, diag, ftol, xtol, gtol, 100 * n if max_nfev is None
                                             else max_nfev)
        else:
            res = least_squares(tr.fun, x0, jac=tr.jac, method=method, loss=loss, f_scale=f_scale,
                                x_scale=x_scale, bounds=(lay.lower, lay.upper), ftol=ftol, xtol=xtol, gtol=gtol,
                                max_nfev=max_nfev, verbose=verbose)
            x, status, message = res.x, int(res.status), str(res.message)
    except _Stop:
        x, status, message = tr.last_x, -2, STATUS_MESSAGES[-2]
    except RobocalError:
        raise
    except ValueError as exc:
        raise InputError(f"scipy.optimize.least_squares rejected the problem: {exc}") from None
    finally:
        if bar is not None:
            bar.close()

    f = tr.lookup(x)
    if f is None:
        f = ev.weighted(x)
    same = tr.last_x is not None and np.array_equal(tr.last_x, x)
    if not same:
        # MINPACK may stop after a step at which it never asked for the
        # Jacobian; record that final accepted point too.
        tr.history.append(robust_cost(f, loss, f_scale))
    J = tr.last_J if same and tr.last_J is not None else ev.jacobian(x, f0=f)
    return _analyse(problem, ev, x, f, J, tr.history, status, message, method=method, loss=loss,
                    f_scale=f_scale, absolute_sigma=absolute_sigma, outlier_sigma=outlier_sigma,
                    rank_tol=rank_tol, weak_vif=weak_vif)


def _analyse(problem, ev, x, f, J, history, status, message, *, method, loss, f_scale, absolute_sigma,
             outlier_sigma, rank_tol, weak_vif) -> LSQResult:
    lay = ev.layout
    m = ev.m
    labels = lay.labels
    free_labels = lay.free_labels
    if loss == "linear":
        J_eff = J                                       # unit weights: the Jacobian as it is
    else:
        _, w = _rho((f / f_scale) ** 2, loss)
        sw = np.sqrt(w)
        J_eff = sp.csc_array(sp.diags_array(sw) @ J) if sp.issparse(J) else J * sw[:, None]
    # the evaluator checked J's shape and finiteness as it built it
    ident = _analyze_checked(sp.csc_array(J_eff) if sp.issparse(J_eff) else np.asarray(J_eff, dtype=float),
                             free_labels, rank_tol=rank_tol, weak_vif=weak_vif)
    dof = m - ident.rank
    warnings: list[Diagnostic] = []

    # A scale the outliers themselves do not inflate, for naming outliers and
    # (with a robust loss) for the covariance.
    if len(ev.term_info) == 1:       # one term: no per-term pieces to stack (issue 16: small problems)
        info0 = ev.term_info[0]
        fo = f.reshape(info0.n_obs, info0.dim)
        q = (fo * fo).sum(axis=1)                     # np.sum's own reduction, without its wrapper
        dims = np.full(info0.n_obs, info0.dim)
        unique = (np.array([info0.dim]), np.zeros(info0.n_obs, dtype=np.intp))
    else:
        q = np.concatenate([np.sum(f[i.rows].reshape(i.n_obs, i.dim) ** 2, axis=1) for i in ev.term_info])
        dims = np.concatenate([np.full(i.n_obs, i.dim) for i in ev.term_info])
        unique = np.unique(dims, return_inverse=True)
    # Clipping estimates the noise level (3 sigma keeps ~99.7 % of clean data);
    # naming outliers is a test over every observation, so its default threshold
    # grows with their number (see outlier_sigma).
    clip_sigma = 3.0 if outlier_sigma is None else outlier_sigma
    if outlier_sigma is None:
        outlier_sigma = bonferroni_sigma(ev.n_obs)
    clipped = _clipped_variance(q, dims, m, ident.rank, clip_sigma, unique=unique) if dof > 0 else float("nan")
    if absolute_sigma:
        s2 = 1.0
    elif dof <= 0:
        s2 = float("nan")
        warnings.append(Diagnostic(
            "weakly_determined",
            f"no redundancy (m - rank = {dof}): the residual variance, and so every standard deviation, "
            "cannot be estimated; give sigma and absolute_sigma=True, or add observations",
            params=tuple(free_labels)))
    elif loss == "linear":
        s2 = float((f * f).sum() / dof)
    else:
        # the robust loss has (mostly) removed the outliers from the fit; their
        # residuals must not set the noise level of the inliers either
        s2 = clipped
    ident = ident.with_variance(s2)
    s = np.sqrt(s2) if np.isfinite(s2) and s2 > 0 else 1.0

    if status <= 0:
        warnings.insert(0, Diagnostic(
            "not_converged",
            f"the solver stopped before convergence ({message}) after {len(history) - 1} iterations; "
            "the estimate and its uncertainty are not reliable"))
    warnings.extend(ident.diagnostics())

    scale2 = 1.0 if absolute_sigma else (clipped if np.isfinite(clipped) else s**2)
    # scale2 is finite (the clipped variance, else s^2 with s = 1 where s2 is not a positive number)
    scores = np.where(q > 0, q / scale2, 0.0) if scale2 > 0 else np.where(q > 0, np.inf, 0.0)
    # one chi2 quantile per distinct observation size, not per observation
    # (scipy's ppf costs ~0.3 ms a call: seconds on a few thousand observations)
    udims, which = unique
    thr = np.array([outlier_threshold(outlier_sigma, int(d)) for d in udims.tolist()])[which]
    outliers = np.flatnonzero(scores > thr).tolist()
    scale = float(np.sqrt(scale2))
    rms_term, rms_comp = {}, {}
    raw = f * ev.sigma
    raw2 = raw * raw
    # sums / counts: np.mean's own arithmetic (add.reduce, then a division) without its wrapper (issue 16)
    for info in ev.term_info:
        rr = raw2[info.rows].reshape(info.n_obs, info.dim)
        rms_term[info.name] = math.sqrt(float(rr.sum()) / rr.size)
        rms_comp[info.name] = np.sqrt(rr.sum(axis=0) / info.n_obs)
    if outliers:
        parts = []
        for info in ev.term_info:
            local = [i - info.obs_start for i in outliers if info.obs_start <= i < info.obs_start + info.n_obs]
            if local:
                shown = ", ".join(map(str, local[:20])) + (", ..." if len(local) > 20 else "")
                parts.append(f"term '{info.name}' observations [{shown}]" if len(ev.term_info) > 1
                             else f"observations [{shown}]")
        warnings.append(Diagnostic(
            "outliers",
            f"{len(outliers)} of {ev.n_obs} observations ({100.0 * len(outliers) / ev.n_obs:.1f} %) lie beyond "
            f"{outlier_sigma:g} sigma (sigma = {scale:.4g} in units of the weighted residuals): "
            + "; ".join(parts)
            + (" (numbered within each term; `indices` holds the global observation numbers)"
               if len(ev.term_info) > 1 else ""),
            indices=tuple(outliers)))

    std = {lab: (float(v) if math.isfinite(v) else None) for lab, v in zip(free_labels, ident.std.tolist())}
    tied = {}
    for kt, (kr, factor) in lay.tied.items():
        tied[labels[kt]] = (labels[kr], factor)
        if labels[kr] in std:
            sr = std[labels[kr]]
            std[labels[kt]] = None if sr is None else abs(factor) * sr
        else:
            std[labels[kt]] = 0.0
    fixed_labels = [lab for b in lay.blocks if b.fixed.any() for lab, fx in zip(b.labels, b.fixed.tolist()) if fx]

    return LSQResult(
        params=ev.params(x), x=np.array(x, dtype=float), free_labels=free_labels, labels=list(labels),
        fixed_labels=fixed_labels, tied=tied, units=dict(lay.units), cost=robust_cost(f, loss, f_scale),
        cost_history=np.array(history), residuals=raw, weighted_residuals=f.copy(),
        normalized_residuals=f / s, terms=list(ev.term_info), rms=math.sqrt(float(raw2.sum()) / raw2.size),
        rms_per_term=rms_term, rms_per_component=rms_comp, residual_variance=s2, dof=int(dof),
        cov=ident.cov, std=std, corr=ident.corr, correlations=ident.correlations,
        unidentifiable=list(ident.unidentifiable), weakly_determined=list(ident.weakly_determined),
        rank=ident.rank, condition_number=ident.condition_number, singular_values=ident.singular_values,
        observation_scores=scores, outlier_sigma=float(outlier_sigma), outliers=np.array(outliers, dtype=int),
        nfev=ev.n_fun, njev=ev.n_jac, iterations=len(history) - 1, status=status,
        message=message or STATUS_MESSAGES.get(status, ""), success=status > 0, method=method, loss=loss,
        f_scale=float(f_scale), jac_method=ev.jac_mode, absolute_sigma=bool(absolute_sigma),
        warnings=warnings, jac=J)
