"""The record a least-squares solve returns: estimate, uncertainty, residuals, diagnostics."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, fields

import numpy as np
import scipy.sparse as sp
from scipy import special

from robocal.diagnostics import Diagnostic
from robocal.errors import InputError
from robocal.estimation._evaluate import TermInfo

__all__ = ["LSQResult", "STATUS_MESSAGES", "outlier_threshold", "outlier_sigma", "OUTLIER_FAMILY_P"]

#: Meaning of ``LSQResult.status`` (SciPy's codes plus -2 for a callback stop).
STATUS_MESSAGES = {
    -2: "stopped by the callback",
    -1: "improper input parameters status returned from MINPACK",
    0: "the maximum number of function evaluations is exceeded",
    1: "gtol termination condition is satisfied",
    2: "ftol termination condition is satisfied",
    3: "xtol termination condition is satisfied",
    4: "both ftol and xtol termination conditions are satisfied",
}

SAMPLING_NOTE = ("Standard deviations are the sampling error caused by residual noise under the model; "
                 "they do not include model error.")


#: Family-wise false-alarm probability of the outlier test over all observations of one calibration.
OUTLIER_FAMILY_P = 0.01


def outlier_sigma(n_obs: int, family_p: float = OUTLIER_FAMILY_P) -> float:
    """The outlier threshold [sigma] of a calibration with ``n_obs`` observations (Bonferroni).

    A fixed 3 sigma (two-sided tail 0.27 %) names on average 0.6 of 216 clean
    observations, 2.7 of 1000; testing each at ``family_p / n_obs`` keeps the
    chance of any false alarm in a clean calibration at ``family_p`` (216
    observations: 4.07 sigma; 1000: 4.42 sigma). Never below 3 sigma. This is
    the one default of every rig (:func:`robocal.estimation.solve` with
    ``outlier_sigma=None``).
    """
    if not (0.0 < family_p < 1.0):
        raise ValueError(f"family_p must be in (0, 1), got {family_p}")
    return _outlier_sigma(max(int(n_obs), 1), float(family_p))


@functools.lru_cache(maxsize=256)
def _outlier_sigma(n_obs: int, family_p: float) -> float:
    # cached: a calibration's solves ask for the same few sizes (issue 16: ~5 us a call on small problems)
    return max(3.0, float(np.sqrt(2.0) * special.erfcinv(family_p / n_obs)))


def outlier_threshold(n_sigma: float, dim: int) -> float:
    """Chi-square (``dim`` dof) quantile with the two-sided Gaussian tail of ``n_sigma``."""
    return _threshold(float(n_sigma), int(dim))


@functools.lru_cache(maxsize=256)
def _threshold(n_sigma: float, dim: int) -> float:
    # scipy.special, not scipy.stats: the same functions (norm.sf = erfc/2, chi2.isf =
    # chdtri) without the 0.5 s import of scipy.stats on every CLI start; cached: every solve asks for
    # the same few (n_sigma, dim) pairs, at ~10 us a pair
    tail = special.erfc(n_sigma / np.sqrt(2.0))
    return float(special.chdtri(dim, tail))


def _json(x):
    """Convert numpy values to JSON types: NaN -> None, +-inf -> 'inf' / '-inf'."""
    if isinstance(x, dict):
        return {str(k): _json(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json(v) for v in x]
    if isinstance(x, np.ndarray):
        return _json(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer, int)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        x = float(x)
        if math.isnan(x):
            return None
        if math.isinf(x):
            return "inf" if x > 0 else "-inf"
        return x
    return x


def _unjson(x):
    if isinstance(x, list):
        return [_unjson(v) for v in x]
    if x is None:
        return np.nan
    if x == "inf":
        return np.inf
    if x == "-inf":
        return -np.inf
    return x


def _farr(x) -> np.ndarray:
    return np.asarray(_unjson(x), dtype=float)


@dataclass
class LSQResult:
    """Outcome of :func:`robocal.estimation.solve`.

    Attributes
    ----------
    params : dict of str to ndarray
        Every block at the solution (fixed and tied elements included).
    x : ndarray, shape (n,)
        Free parameters, in the order of ``free_labels``.
    free_labels, labels, fixed_labels : list of str
    tied : dict
        ``{target: (root source, factor)}``.
    units : dict of str to str or None
    cost : float
        ``0.5 * sum(rho((r_w / f_scale)^2)) * f_scale^2`` at the solution
        (``0.5 * sum(r_w^2)`` for the linear loss), ``r_w = r / sigma``.
    cost_history : ndarray
        Cost at the start and after each accepted step (see :func:`solve`).
    residuals, weighted_residuals, normalized_residuals : ndarray, shape (m,)
        Raw ``r``, ``r / sigma`` and ``r / (sigma * s)`` with ``s^2`` the
        residual variance (``s = 1`` for ``absolute_sigma``).
    terms : list of TermInfo
        Where each residual term sits; see :meth:`obs_residuals`.
    rms : float
        RMS of the raw residuals (all terms).
    rms_per_term : dict of str to float
    rms_per_component : dict of str to ndarray, shape (dim,)
        E.g. ``[rms_x, rms_y]`` for image residuals.
    residual_variance : float
        ``s^2 = sum(r_w^2) / (m - rank)`` for the linear loss, a clipped
        (outlier-free) estimate for robust losses, 1 for ``absolute_sigma``.
    dof : int
        ``m - rank``.
    cov : ndarray, shape (n, n)
        Covariance of ``x`` (NaN rows/columns for unidentifiable parameters).
    std : dict of str to float or None
        Standard deviation of each free (and tied) parameter; ``None`` when
        the data do not determine it.
    corr : ndarray, shape (n, n)
    correlations : list of (str, str, float)
        Strongest correlations first.
    unidentifiable, weakly_determined : list of str
    rank : int
    condition_number : float
        Of the column-scaled Jacobian.
    singular_values : ndarray
        Of the column-scaled Jacobian.
    observation_scores : ndarray, shape (n_obs,)
        ``||r_w,i||^2 / s_c^2`` per observation, ``s_c`` the residual std re-estimated with outlier clipping (1 with ``absolute_sigma``).
    outlier_sigma : float
        An observation is an outlier when its score exceeds
        :meth:`outlier_threshold` for its dimension: the chi-square quantile
        with the same tail probability as ``outlier_sigma`` for a Gaussian
        (``outlier_sigma^2`` for one component).
    outliers : ndarray of int
        Global observation indices of the outliers.
    nfev, njev : int
        Residual evaluations (finite-difference ones included) and Jacobian
        evaluations.
    iterations : int
        Accepted steps, ``len(cost_history) - 1``.
    status, message, success
        As SciPy's, see :data:`STATUS_MESSAGES`.
    method, loss, f_scale, jac_method, absolute_sigma
        The options used.
    warnings : list of Diagnostic
    jac : ndarray or sparse, shape (m, n), optional
        Weighted Jacobian at the solution (not serialised by default).
    """

    params: dict
    x: np.ndarray
    free_labels: list
    labels: list
    fixed_labels: list
    tied: dict
    units: dict
    cost: float
    cost_history: np.ndarray
    residuals: np.ndarray
    weighted_residuals: np.ndarray
    normalized_residuals: np.ndarray
    terms: list
    rms: float
    rms_per_term: dict
    rms_per_component: dict
    residual_variance: float
    dof: int
    cov: np.ndarray
    std: dict
    corr: np.ndarray
    correlations: list
    unidentifiable: list
    weakly_determined: list
    rank: int
    condition_number: float
    singular_values: np.ndarray
    observation_scores: np.ndarray
    outlier_sigma: float
    outliers: np.ndarray
    nfev: int
    njev: int
    iterations: int
    status: int
    message: str
    success: bool
    method: str
    loss: str
    f_scale: float
    jac_method: str
    absolute_sigma: bool
    warnings: list = field(default_factory=list)
    jac: object = None

    # ------------------------------------------------------------- queries
    @property
    def std_array(self) -> np.ndarray:
        """Standard deviations of ``x`` (NaN where unidentifiable)."""
        return np.array([np.nan if self.std[k] is None else self.std[k] for k in self.free_labels])

    def value(self, label: str) -> float | None:
        """Estimated value of one element, or None if it is not identifiable."""
        if label not in self.labels:
            raise InputError(f"unknown parameter label '{label}'")
        root = self.tied.get(label, (label, 1.0))[0]
        if root in self.unidentifiable:
            return None
        flat = np.concatenate([np.ravel(v) for v in self.params.values()])
        return float(flat[self.labels.index(label)])

    def block_std(self, name: str) -> np.ndarray:
        """Std of every element of block ``name``, in its shape (0 for fixed,
        NaN for unidentifiable elements)."""
        if name not in self.params:
            raise InputError(f"unknown block '{name}' (blocks: {', '.join(self.params)})")
        offset = 0
        for k, v in self.params.items():
            if k == name:
                break
            offset += np.size(v)
        shape = np.shape(self.params[name])
        labs = self.labels[offset:offset + int(np.prod(shape, dtype=int))]
        out = [0.0 if lab in self.fixed_labels else (np.nan if self.std.get(lab) is None else self.std[lab])
               for lab in labs]
        return np.array(out, dtype=float).reshape(shape)

    def _term(self, term: str | None) -> TermInfo:
        if term is None:
            if len(self.terms) != 1:
                raise InputError(f"several residual terms ({', '.join(t.name for t in self.terms)}): name one")
            return self.terms[0]
        for t in self.terms:
            if t.name == term:
                return t
        raise InputError(f"unknown residual term '{term}' (terms: {', '.join(t.name for t in self.terms)})")

    def obs_residuals(self, term: str | None = None, *, kind: str = "raw") -> np.ndarray:
        """Residuals of one term as ``(n_obs, dim)``; ``kind`` is ``'raw'``,
        ``'weighted'`` or ``'normalized'``."""
        src = {"raw": self.residuals, "weighted": self.weighted_residuals,
               "normalized": self.normalized_residuals}.get(kind)
        if src is None:
            raise InputError(f"kind must be 'raw', 'weighted' or 'normalized', got {kind!r}")
        t = self._term(term)
        return src[t.rows].reshape(t.n_obs, t.dim)

    def locate_observation(self, index: int) -> tuple[str, int]:
        """``(term name, index within the term)`` of a global observation index."""
        for t in self.terms:
            if t.obs_start <= index < t.obs_start + t.n_obs:
                return t.name, int(index - t.obs_start)
        raise InputError(f"observation index {index} out of range [0, {self.terms[-1].obs_start + self.terms[-1].n_obs})")

    def worst_observations(self, k: int = 10) -> list[tuple[int, str, int, float]]:
        """The ``k`` largest observation scores: ``(index, term, local index, score)``."""
        order = np.argsort(-self.observation_scores, kind="stable")[:k]
        return [(int(i), *self.locate_observation(int(i)), float(self.observation_scores[i])) for i in order]

    def outlier_threshold(self, dim: int = 1) -> float:
        """Score threshold for an observation with ``dim`` components."""
        return outlier_threshold(self.outlier_sigma, dim)

    def warning_codes(self) -> list[str]:
        return [w.code for w in self.warnings]

    # ------------------------------------------------------ serialisation
    def to_dict(self, *, include_jacobian: bool = False) -> dict:
        """A JSON-serialisable dict (NaN -> None, inf -> 'inf').

        Includes a ``parameters`` table in which unidentifiable elements have
        ``value: None`` (the raw ``params`` keep the solver's numbers so the
        result can be reloaded and evaluated).
        """
        d = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "jac":
                if include_jacobian and v is not None:
                    d["jac"] = _json(v.toarray() if sp.issparse(v) else v)
                continue
            if f.name == "terms":
                v = [t.to_dict() for t in v]
            elif f.name == "warnings":
                v = [w.to_dict() for w in v]
            elif f.name == "tied":
                v = {k: [s, fac] for k, (s, fac) in v.items()}
            elif f.name == "correlations":
                v = [[a, b, c] for a, b, c in v]
            d[f.name] = _json(v)
        d["parameters"] = _json(self.parameter_table())
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "LSQResult":
        """Rebuild a result written by :meth:`to_dict`."""
        try:
            kw = dict(
                params={k: _farr(v) for k, v in d["params"].items()},
                x=_farr(d["x"]),
                free_labels=list(d["free_labels"]),
                labels=list(d["labels"]),
                fixed_labels=list(d["fixed_labels"]),
                tied={k: (v[0], float(v[1])) for k, v in d["tied"].items()},
                units=dict(d["units"]),
                terms=[TermInfo(**t) for t in d["terms"]],
                rms_per_term={k: float(_unjson(v)) for k, v in d["rms_per_term"].items()},
                rms_per_component={k: _farr(v) for k, v in d["rms_per_component"].items()},
                std={k: (None if v is None else float(v)) for k, v in d["std"].items()},
                correlations=[(a, b, float(c)) for a, b, c in d["correlations"]],
                unidentifiable=list(d["unidentifiable"]),
                weakly_determined=list(d["weakly_determined"]),
                outliers=np.asarray(d["outliers"], dtype=int),
                warnings=[Diagnostic.from_dict(w) for w in d["warnings"]],
                jac=_farr(d["jac"]) if "jac" in d else None,
            )
            for name in ("cost_history", "residuals", "weighted_residuals", "normalized_residuals", "cov",
                         "corr", "singular_values", "observation_scores"):
                kw[name] = _farr(d[name])
            for name in ("cost", "rms", "residual_variance", "condition_number", "outlier_sigma",
                         "f_scale"):
                kw[name] = float(_unjson(d[name]))
            for name in ("dof", "rank", "nfev", "njev", "iterations", "status"):
                kw[name] = int(d[name])
            for name in ("message", "method", "loss", "jac_method"):
                kw[name] = str(d[name])
            kw["success"] = bool(d["success"])
            kw["absolute_sigma"] = bool(d["absolute_sigma"])
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise InputError(f"not a least-squares result record ({type(exc).__name__}: {exc})") from None
        return cls(**kw)

    # -------------------------------------------------------------- report
    def parameter_table(self) -> list[dict]:
        """One row per element: label, status (free/fixed/tied/unidentifiable),
        value (None if unidentifiable), std, unit."""
        flat = np.concatenate([np.ravel(v) for v in self.params.values()])
        rows = []
        for k, lab in enumerate(self.labels):
            root, factor = self.tied.get(lab, (lab, 1.0))
            if lab in self.fixed_labels:
                status = "fixed"
            elif root in self.unidentifiable:
                status = "unidentifiable"
            elif lab in self.tied:
                status = "tied"
            else:
                status = "free"
            rows.append(dict(
                label=lab,
                status=status,
                value=None if status == "unidentifiable" else float(flat[k]),
                std=0.0 if status == "fixed" else self.std.get(lab),
                unit=self.units.get(lab),
                tied_to=root if lab in self.tied else None,
                factor=factor if lab in self.tied else None,
            ))
        return rows

    def summary(self, *, n_correlations: int = 5) -> str:
        """A plain-text report: status, fit statistics, parameter table, warnings."""
        state = "converged" if self.success else "NOT converged"
        lines = [
            f"least squares ({self.method}, loss={self.loss}, jac={self.jac_method}): {state} - {self.message}",
            f"  {self.iterations} iterations, {self.nfev} residual and {self.njev} Jacobian evaluations; "
            f"cost {self.cost_history[0]:.6g} -> {self.cost:.6g}",
        ]
        m = self.residuals.size
        for t in self.terms:
            comp = self.rms_per_component[t.name]
            comp_txt = f" (per component: {', '.join(f'{c:.4g}' for c in comp)})" if comp.size > 1 else ""
            lines.append(f"  term '{t.name}': {t.n_obs} observations x {t.dim}, RMS {self.rms_per_term[t.name]:.4g}"
                         f"{comp_txt}")
        lines.append(f"  m = {m} residuals, n = {len(self.free_labels)} free parameters, rank {self.rank}, "
                     f"condition number {self.condition_number:.3g} (column-scaled), "
                     f"residual std {math.sqrt(self.residual_variance):.4g}"
                     + (" (noise given, absolute_sigma)" if self.absolute_sigma else ""))
        w = max([len("parameter")] + [len(r["label"]) for r in self.parameter_table()])
        lines.append(f"  {'parameter':<{w}}  {'value':>14}  {'std':>12}  unit")
        for r in self.parameter_table():
            unit = r["unit"] or ""
            if r["status"] == "unidentifiable":
                lines.append(f"  {r['label']:<{w}}  {'-':>14}  {'-':>12}  {unit}  not identifiable")
                continue
            std = "fixed" if r["status"] == "fixed" else ("-" if r["std"] is None else f"{r['std']:.4g}")
            note = f"  = {r['factor']:g} * {r['tied_to']}" if r["status"] == "tied" else ""
            lines.append(f"  {r['label']:<{w}}  {r['value']:>14.8g}  {std:>12}  {unit}{note}")
        if self.correlations and n_correlations:
            txt = ", ".join(f"{a}/{b} {c:+.3f}" for a, b, c in self.correlations[:n_correlations])
            lines.append(f"  strongest correlations: {txt}")
        if self.warnings:
            lines.append("  warnings:")
            lines.extend(f"    {w}" for w in self.warnings)
        lines.append("  " + SAMPLING_NOTE)
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()
