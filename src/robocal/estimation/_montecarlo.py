"""Monte Carlo accuracy studies and the Cramér–Rao bound.

Correctness of a calibration is shown on simulations with known truth: run the
estimator over many noisy draws, measure bias and RMSE, and compare them with
(a) the Cramér–Rao bound of the same design, the best any unbiased estimator
can do, and (b) the standard deviations the estimator itself reports.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from robocal.errors import ConvergenceError, DegenerateGeometryError, InputError, RobocalError, ShapeError
from robocal.estimation._identifiability import analyze_jacobian
from robocal.estimation._result import _json
from robocal.validation import check_array

__all__ = ["monte_carlo", "MonteCarloResult", "check_coverage", "CoverageResult", "fisher_bound", "executor_workers",
           "default_batch_size"]


def fisher_bound(J, sigma=1.0, *, labels: Sequence[str] | None = None) -> np.ndarray:
    """Cramér–Rao bound ``(J^T Sigma^-1 J)^-1`` for Gaussian noise.

    Parameters
    ----------
    J : array_like or sparse, shape (m, n)
        Jacobian of the *unweighted* model residuals (or of the measurement
        model) w.r.t. the parameters, at the true values.
    sigma : float or array_like, shape (m,)
        Noise standard deviation of each residual.
    labels : sequence of str, optional
        Parameter names for the error message.

    Returns
    -------
    ndarray, shape (n, n)
        The bound on the covariance of any unbiased estimator; for a scalar
        ``sigma`` it is ``sigma^2 (J^T J)^-1``. For a nonlinear model this is
        the bound of the locally linearised model.

    Raises
    ------
    DegenerateGeometryError
        If ``J`` is rank deficient: some parameters have no finite bound.
    """
    if sp.issparse(J):
        Jd = sp.csr_array(J, dtype=float).toarray()
    else:
        Jd = check_array(J, "J")
    if Jd.ndim != 2:
        raise ShapeError(f"J must have shape (m, n), got {Jd.shape}")
    s = check_array(sigma, "sigma")
    if np.any(s <= 0):
        raise InputError(f"sigma must be > 0, got min {s.min()!r}")
    if s.ndim == 1 and s.size != Jd.shape[0]:
        raise ShapeError(f"sigma must be a scalar or have shape ({Jd.shape[0]},), got {s.shape}")
    if s.ndim > 1:
        raise ShapeError(f"sigma must be a scalar or have shape ({Jd.shape[0]},), got {s.shape}")
    Jw = Jd / (s[:, None] if s.ndim == 1 else s)
    ident = analyze_jacobian(Jw, labels)
    if ident.rank < Jw.shape[1]:
        raise DegenerateGeometryError(
            f"the Fisher information is singular (rank {ident.rank} < {Jw.shape[1]}): no finite Cramér–Rao "
            f"bound for {', '.join(ident.unidentifiable) or 'some parameters'}")
    _, sv, Vt = np.linalg.svd(Jw, full_matrices=False)
    return (Vt.T / sv**2) @ Vt


@dataclass
class CoverageResult:
    """How well reported standard deviations describe the actual errors.

    Attributes
    ----------
    n : int
        Trials used.
    n_sigma : float
    fraction_within : ndarray, shape (k,)
        Fraction of trials with ``|error| <= n_sigma * predicted_std``.
    fraction_within_all : float
        Same, pooled over all parameters.
    expected_fraction : float
        What Gaussian errors give, ``erf(n_sigma / sqrt 2)`` (0.9973 for 3).
    spread_ratio : ndarray, shape (k,)
        Monte Carlo spread over predicted spread:
        ``std(errors) / sqrt(mean(predicted_std^2))``; 1 when the reported
        uncertainty is right.
    spread_ratio_se : float
        Its standard error from the number of trials,
        ``1 / sqrt(2 (n - 1))`` (of a sample standard deviation).
    z_std : ndarray, shape (k,)
        Std of the standardised errors ``error / predicted_std``.
    """

    n: int
    n_sigma: float
    fraction_within: np.ndarray
    fraction_within_all: float
    expected_fraction: float
    spread_ratio: np.ndarray
    spread_ratio_se: float
    z_std: np.ndarray

    def consistent(self, rel_tol: float = 0.2) -> bool:
        """True if every spread ratio is within ``rel_tol`` of 1."""
        return bool(np.all(np.abs(self.spread_ratio - 1.0) <= rel_tol))

    def to_dict(self) -> dict:
        return _json(dict(n=self.n, n_sigma=self.n_sigma, fraction_within=self.fraction_within,
                          fraction_within_all=self.fraction_within_all, expected_fraction=self.expected_fraction,
                          spread_ratio=self.spread_ratio, spread_ratio_se=self.spread_ratio_se, z_std=self.z_std))


def check_coverage(errors, predicted_std, *, n_sigma: float = 3.0) -> CoverageResult:
    """Compare Monte Carlo errors with the standard deviations an estimator reported.

    Parameters
    ----------
    errors : array_like, shape (n, k)
        Estimate minus truth, one row per trial.
    predicted_std : array_like, shape (k,) or (n, k)
        Reported std (per trial, or one for all). NaN entries (parameters
        reported as unidentifiable) are left out.
    n_sigma : float
        Width of the coverage interval.
    """
    e = check_array(errors, "errors")
    if e.ndim == 1:
        e = e[:, None]
    if e.ndim != 2 or e.shape[0] < 2:
        raise ShapeError(f"errors must have shape (n >= 2, k), got {e.shape}")
    p = check_array(predicted_std, "predicted_std", finite=False)
    n, k = e.shape
    if p.ndim == 2 and p.shape == e.shape:
        pass
    elif p.ndim <= 1 and p.size in (1, k):
        p = np.broadcast_to(p.reshape(-1), e.shape)
    elif p.ndim == 1 and k == 1 and p.size == n:
        p = p[:, None]
    else:
        raise ShapeError(f"predicted_std must have shape ({k},) or {e.shape}, got {p.shape}")
    if np.any(p <= 0) or np.any(np.isinf(p)):
        raise InputError("predicted_std must be finite and > 0 (NaN marks an unidentifiable parameter)")
    ok = np.isfinite(p)
    cnt = ok.sum(axis=0)

    def col_std(a):
        # std over the finite entries of each column (NaN for < 2 entries)
        a = np.where(ok, a, 0.0)
        mean = a.sum(axis=0) / cnt
        return np.sqrt((((a - mean) ** 2) * ok).sum(axis=0) / (cnt - 1))

    with np.errstate(invalid="ignore", divide="ignore"):
        pp = np.where(ok, p, 1.0)
        z = e / pp
        within = ok & (np.abs(z) <= n_sigma)
        frac = within.sum(axis=0) / cnt
        spread = col_std(e) / np.sqrt((np.where(ok, pp, 0.0) ** 2).sum(axis=0) / cnt)
        z_std = col_std(z)
    return CoverageResult(
        n=n, n_sigma=float(n_sigma), fraction_within=frac,
        fraction_within_all=float(within.sum() / max(1, int(ok.sum()))),
        expected_fraction=math.erf(n_sigma / math.sqrt(2.0)), spread_ratio=spread,
        spread_ratio_se=1.0 / math.sqrt(2.0 * (n - 1)), z_std=z_std)


@dataclass
class MonteCarloResult:
    """Accuracy of an estimator over simulated trials.

    Attributes
    ----------
    errors : ndarray, shape (n_ok, k)
        One row per successful trial.
    labels : list of str or None
    bias : ndarray, shape (k,)
        Mean error.
    bias_se : ndarray, shape (k,)
        Standard error of the bias, ``std / sqrt(n)``: a bias is significant
        when it is several times this.
    std : ndarray, shape (k,)
        Spread of the errors (ddof = 1).
    rmse : ndarray, shape (k,)
    mean_sq_norm : float
        Mean squared norm of the error vector.
    bound_std : ndarray, shape (k,) or None
        ``sqrt(diag(bound))`` for the Cramér–Rao bound given.
    ratio_to_bound : ndarray, shape (k,) or None
        ``rmse / bound_std``: 1 is efficient; above 1 is the price paid.
    ratio_total : float or None
        ``sqrt(mean_sq_norm / trace(bound))``.
    predicted_std : ndarray, shape (n_ok, k) or None
        Std reported by the estimator in each trial, when it returned one.
    coverage : CoverageResult or None
        :func:`check_coverage` of the errors against ``predicted_std``.
    n_trials : int
    failures : list of (int, str)
        Trials whose estimator raised a RobocalError, with the message.
    """

    errors: np.ndarray
    labels: list | None
    bias: np.ndarray
    bias_se: np.ndarray
    std: np.ndarray
    rmse: np.ndarray
    mean_sq_norm: float
    bound_std: np.ndarray | None
    ratio_to_bound: np.ndarray | None
    ratio_total: float | None
    predicted_std: np.ndarray | None
    coverage: CoverageResult | None
    n_trials: int
    failures: list = field(default_factory=list)

    @property
    def n_failed(self) -> int:
        return len(self.failures)

    def to_dict(self, *, include_errors: bool = False) -> dict:
        d = dict(labels=self.labels, bias=self.bias, bias_se=self.bias_se, std=self.std, rmse=self.rmse,
                 mean_sq_norm=self.mean_sq_norm, bound_std=self.bound_std, ratio_to_bound=self.ratio_to_bound,
                 ratio_total=self.ratio_total, n_trials=self.n_trials, n_failed=self.n_failed,
                 failures=[[i, msg] for i, msg in self.failures],
                 coverage=None if self.coverage is None else self.coverage.to_dict())
        if include_errors:
            d["errors"] = self.errors
            d["predicted_std"] = self.predicted_std
        return _json(d)

    def summary(self) -> str:
        k = self.errors.shape[1]
        labels = self.labels or [f"p[{j}]" for j in range(k)]
        w = max(9, *(len(s) for s in labels))
        head = f"  {'parameter':<{w}}  {'bias':>11}  {'bias_se':>10}  {'rmse':>10}"
        head += f"  {'CRB std':>10}  {'rmse/CRB':>8}" if self.bound_std is not None else ""
        head += f"  {'MC/pred':>7}" if self.coverage is not None else ""
        lines = [f"Monte Carlo: {self.errors.shape[0]} of {self.n_trials} trials succeeded", head]
        for j in range(k):
            row = f"  {labels[j]:<{w}}  {self.bias[j]:>11.4g}  {self.bias_se[j]:>10.3g}  {self.rmse[j]:>10.4g}"
            if self.bound_std is not None:
                row += f"  {self.bound_std[j]:>10.4g}  {self.ratio_to_bound[j]:>8.3f}"
            if self.coverage is not None:
                row += f"  {self.coverage.spread_ratio[j]:>7.3f}"
            lines.append(row)
        if self.ratio_total is not None:
            lines.append(f"  overall rmse / CRB: {self.ratio_total:.3f}")
        if self.coverage is not None:
            c = self.coverage
            lines.append(f"  within {c.n_sigma:g} reported sigma: {100 * c.fraction_within_all:.1f} % "
                         f"(Gaussian: {100 * c.expected_fraction:.1f} %); ratio standard error "
                         f"{c.spread_ratio_se:.3f}")
        return "\n".join(lines)


def _bound_std(bound, k: int) -> tuple[np.ndarray, float]:
    b = check_array(bound, "bound")
    if b.shape == (k, k):
        d = np.diag(b)
        if np.any(d <= 0):
            raise InputError("bound covariance must have a positive diagonal")
        return np.sqrt(d), float(np.trace(b))
    if b.shape == (k,):
        if np.any(b <= 0):
            raise InputError("bound std must be > 0")
        return b.copy(), float(np.sum(b**2))
    raise ShapeError(f"bound must be a covariance ({k}, {k}) or a std vector ({k},), got {b.shape}")


def _trial_seeds(rng: np.random.Generator, n: int) -> tuple[type, list]:
    """The bit generator's type and one ``SeedSequence`` child per trial: what ``rng.spawn(n)`` would build.

    Shipping seed sequences (a few hundred bytes each) instead of generators
    lets any process rebuild trial ``i``'s generator exactly; the children are
    the same as ``rng.spawn``'s, so a serial run draws what it drew before.
    """
    bitgen = rng.bit_generator
    seq = getattr(bitgen, "seed_seq", None) or bitgen._seed_seq  # public since NumPy 1.25
    return type(bitgen), seq.spawn(int(n))


def _run_trials(simulate, estimate, error, bitgen_type, seeds, first: int) -> list:
    """Trials ``first, first + 1, ...``: one task's work, run where the executor puts it.

    Returns per trial ``(error, reported std)`` or the failure message (a
    :class:`RobocalError` the estimator raised); anything else propagates.
    Shapes are checked by the caller, in trial order, so that a message names
    the same trial whatever the number of workers.
    """
    out = []
    for j, seq in enumerate(seeds):
        i = first + j
        data, truth = simulate(np.random.Generator(bitgen_type(seq)))
        try:
            res = estimate(data)
        except RobocalError as exc:
            out.append(str(exc))
            continue
        pred = None
        if hasattr(res, "x") and hasattr(res, "std_array"):
            est, pred = res.x, res.std_array
        elif isinstance(res, tuple) and len(res) == 2:
            est, pred = res
        else:
            est = res
        est = check_array(est, f"estimate of trial {i}", finite=False)
        e = np.atleast_1d(error(est, truth) if error is not None else est - check_array(truth, "truth"))
        e = check_array(e, f"error of trial {i}", finite=False).reshape(-1)
        if pred is not None:
            pred = check_array(pred, f"reported std of trial {i}", finite=False).reshape(-1)
        out.append((e, pred))
    return out


def _submit(executor, fn, *args):
    # Dask's Client hashes a task's arguments to name it unless told the call is impure;
    # concurrent.futures executors take no such keyword
    if type(executor).__module__.split(".")[0] == "distributed":
        return executor.submit(fn, *args, pure=False)
    return executor.submit(fn, *args)


def executor_workers(executor) -> int:
    """How many tasks ``executor`` runs at once (1 for None; a Dask ``Client``: its workers' threads)."""
    if executor is None:
        return 1
    info = getattr(executor, "nthreads", None)
    if callable(info) and type(executor).__module__.split(".")[0] == "distributed":
        return max(1, sum(info().values()))
    return max(1, int(getattr(executor, "_max_workers", 1) or 1))


def default_batch_size(n_tasks: int, workers: int, *, per_worker: int = 4) -> int:
    """Items per task: about ``per_worker`` tasks for each worker (load balance vs per-task overhead).

    With one task per worker the slowest task sets the wall time; with many
    small ones the per-task overhead (~1-5 ms on a local Dask cluster,
    ``bench/bench_batch.py``) dominates cheap trials. Four per worker keeps
    both small for trials of >= ~10 ms.
    """
    return max(1, math.ceil(n_tasks / (per_worker * max(1, workers))))


def monte_carlo(
    simulate: Callable[[np.random.Generator], tuple[object, object]],
    estimate: Callable[[object], object],
    n_trials: int,
    rng: np.random.Generator,
    *,
    error: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    bound=None,
    labels: Sequence[str] | None = None,
    n_sigma: float = 3.0,
    progress: bool = False,
    executor=None,
    workers: int | None = None,
    batch_size: int | None = None,
) -> MonteCarloResult:
    """Run ``estimate`` on ``n_trials`` simulations and measure its accuracy.

    Parameters
    ----------
    simulate : callable
        ``simulate(rng) -> (data, truth)``; all randomness through ``rng``.
    estimate : callable
        ``estimate(data)`` returning the estimate as an array, or an
        :class:`LSQResult` (then ``x`` is the estimate and its reported std
        is kept for a coverage check), or a tuple ``(estimate, std)``.
    n_trials : int
    rng : numpy.random.Generator
        Each trial gets its own child ``SeedSequence`` (those of
        ``rng.spawn``), so trial ``i`` draws the same numbers wherever and in
        whichever order it runs: the result is bit-identical for a serial run
        and for any number of workers.
    error : callable, optional
        ``error(estimate, truth) -> (k,)``; default ``estimate - truth``. Use
        it for rotations (e.g. the rotation vector of ``R_true^T R_est``).
    bound : array_like, shape (k, k) or (k,), optional
        Cramér–Rao bound as a covariance, or as a std vector.
    labels : sequence of str, optional
    n_sigma : float
        Interval of the coverage check.
    progress : bool
        Show a progress bar on a terminal.
    executor : concurrent.futures.Executor-like, optional
        Runs the trials in tasks of ``batch_size`` through
        ``executor.submit(fn, *args) -> future``: a Dask
        ``distributed.Client`` or a ``concurrent.futures`` executor (a
        process pool needs ``simulate``/``estimate`` picklable by ``pickle``:
        module-level functions or ``functools.partial``; Dask's cloudpickle
        also ships closures). Default: serial, in this process.
    workers : int, optional
        Without ``executor``: ``1`` (or None) runs serially; ``N > 1`` starts
        a local Dask cluster of ``N`` worker processes for this call
        (:func:`robocal.batch.open_executor`).
    batch_size : int, optional
        Trials per task (default :func:`default_batch_size`: ~4 tasks per
        worker). It changes the speed, never the result.

    Returns
    -------
    MonteCarloResult

    Raises
    ------
    ConvergenceError
        If every trial failed.
    """
    if not isinstance(rng, np.random.Generator):
        raise InputError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    if int(n_trials) != n_trials or n_trials < 2:
        raise InputError(f"n_trials must be an integer >= 2, got {n_trials!r}")
    if batch_size is not None and (int(batch_size) != batch_size or batch_size < 1):
        raise InputError(f"batch_size must be an integer >= 1, got {batch_size!r}")
    n_trials = int(n_trials)
    if executor is None and workers is not None and int(workers) > 1:
        from robocal.batch._engine import open_executor  # Dask only when asked for

        with open_executor(workers=int(workers), echo=None) as ex:
            return monte_carlo(simulate, estimate, n_trials, rng, error=error, bound=bound, labels=labels,
                               n_sigma=n_sigma, progress=progress, executor=ex, batch_size=batch_size)
    bitgen_type, seeds = _trial_seeds(rng, n_trials)
    from robocal.progress import progress as _progress

    if executor is None:
        outcomes = [_run_trials(simulate, estimate, error, bitgen_type, [s], i)[0]
                    for i, s in enumerate(_progress(seeds, desc="Monte Carlo", total=n_trials, enabled=progress))]
    else:
        size = int(batch_size or default_batch_size(n_trials, executor_workers(executor)))
        futures = [_submit(executor, _run_trials, simulate, estimate, error, bitgen_type, seeds[a:a + size], a)
                   for a in range(0, n_trials, size)]
        outcomes = []
        # collected in submission order: the trials stay in their order, so the statistics
        # are summed in the same order as a serial run's (bit-identical)
        for fut in _progress(futures, desc=f"Monte Carlo ({size} trials a task)", total=len(futures),
                             enabled=progress):
            outcomes.extend(fut.result())
    return _summarise(outcomes, n_trials, bound=bound, labels=labels, n_sigma=n_sigma)


def _summarise(outcomes, n_trials: int, *, bound, labels, n_sigma) -> MonteCarloResult:
    errs, preds, failures = [], [], []
    k = None
    for i, out in enumerate(outcomes):
        if isinstance(out, str):
            failures.append((i, out))
            continue
        e, pred = out
        if k is None:
            k = e.size
        if e.size != k:
            raise ShapeError(f"error of trial {i} has {e.size} elements, the first trial had {k}")
        if not np.all(np.isfinite(e)):
            failures.append((i, "estimate is not finite"))
            continue
        errs.append(e)
        if pred is not None:
            if pred.size != k:
                raise ShapeError(f"reported std of trial {i} has {pred.size} elements, errors have {k}")
            preds.append(pred)
    if not errs:
        raise ConvergenceError(f"all {n_trials} Monte Carlo trials failed; first: {failures[0][1]}")
    E = np.array(errs)
    n = E.shape[0]
    if labels is not None and len(labels) != k:
        raise ShapeError(f"labels must have {k} entries, got {len(labels)}")
    std = E.std(axis=0, ddof=1) if n > 1 else np.full(k, np.nan)
    rmse = np.sqrt(np.mean(E**2, axis=0))
    msn = float(np.mean(np.sum(E**2, axis=1)))
    bstd = ratio = total = None
    if bound is not None:
        bstd, tr = _bound_std(bound, k)
        ratio = rmse / bstd
        total = math.sqrt(msn / tr)
    P = np.array(preds) if len(preds) == n else None
    cov = check_coverage(E, P, n_sigma=n_sigma) if P is not None and n >= 2 else None
    return MonteCarloResult(errors=E, labels=None if labels is None else list(labels), bias=E.mean(axis=0),
                            bias_se=std / math.sqrt(n), std=std, rmse=rmse, mean_sq_norm=msn, bound_std=bstd,
                            ratio_to_bound=ratio, ratio_total=total, predicted_std=P, coverage=cov,
                            n_trials=int(n_trials), failures=failures)
