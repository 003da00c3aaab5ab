"""Checking an estimate against a simulated truth: the NEES test every rig's demo and tests use.

A rig whose uncertainty is honest gives errors ``e = x_hat - x_true`` whose
normalized estimation error squared ``NEES = e^T C^-1 e`` follows a
chi-square distribution with ``n`` degrees of freedom (Bar-Shalom, Li and
Kirubarajan, *Estimation with Applications to Tracking and Navigation*,
Wiley 2001, sec. 5.4.2). One test over all parameters replaces per-parameter
``|z| < 3.5`` or ``< 4`` rules, which neither account for the number of
parameters nor for their correlations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from robocal.errors import InputError

__all__ = ["TruthCheck", "truth_check", "TRUTH_ALPHA"]

#: Chance that a correct estimate with honest uncertainty fails the check.
TRUTH_ALPHA = 1e-3


@dataclass(frozen=True)
class TruthCheck:
    """Outcome of :func:`truth_check`.

    Attributes
    ----------
    nees : float
        ``e^T C^-1 e`` over the parameters with a finite standard deviation.
    dof : int
        Parameters in the test (the rank of their covariance).
    threshold : float
        Chi-square(dof) quantile at ``1 - alpha``.
    p_value : float
        Chance of a NEES at least this large when the uncertainty is honest.
    passed : bool
        ``nees <= threshold``.
    z : dict of str to float
        Per-parameter ``e_i / std_i`` (NaN where the std is not finite), for
        naming the parameter that failed.
    alpha : float
    """

    nees: float
    dof: int
    threshold: float
    p_value: float
    passed: bool
    z: dict
    alpha: float = TRUTH_ALPHA

    @property
    def worst(self) -> tuple[str, float] | None:
        """The parameter with the largest ``|z|`` (None when no parameter has a std)."""
        finite = {k: v for k, v in self.z.items() if np.isfinite(v)}
        if not finite:
            return None
        k = max(finite, key=lambda n: abs(finite[n]))
        return k, finite[k]

    def to_dict(self) -> dict:
        return {"nees": self.nees, "dof": self.dof, "threshold": self.threshold, "p_value": self.p_value,
                "passed": self.passed, "alpha": self.alpha,
                "z": {k: (float(v) if np.isfinite(v) else None) for k, v in self.z.items()}}

    def __str__(self) -> str:
        w = self.worst
        worst = f"; largest |z| {abs(w[1]):.2f} ({w[0]})" if w else ""
        verdict = "consistent with" if self.passed else "NOT consistent with"
        return (f"NEES {self.nees:.2f} over {self.dof} parameters (limit {self.threshold:.1f} at "
                f"p = {self.alpha:g}, p-value {self.p_value:.3g}): errors {verdict} the reported uncertainty{worst}")


def truth_check(error, cov, *, names=None, alpha: float = TRUTH_ALPHA) -> TruthCheck:
    """Test estimation errors against their covariance by NEES (chi-square, ``alpha`` false-alarm rate).

    Parameters
    ----------
    error : (n,) array_like
        ``estimate - truth`` in the parameters' units (rotation errors as
        rotation vectors on the side the covariance uses).
    cov : (n, n) or (n,) array_like
        Covariance of the estimate, or its standard deviations (taken as
        uncorrelated). Parameters whose variance is not finite or not
        positive (not identifiable, fixed) are left out of the test.
    names : sequence of str, optional
        Parameter names for ``z`` (default ``"0"``, ``"1"``, ...).
    alpha : float
        False-alarm probability of the check for a correct estimate.

    Returns
    -------
    TruthCheck
    """
    e = np.asarray(error, dtype=float).reshape(-1)
    C = np.asarray(cov, dtype=float)
    if C.ndim == 1:
        C = np.diag(C**2)
    n = e.size
    if C.shape != (n, n):
        raise InputError(f"cov: expected shape ({n}, {n}) or ({n},) for {n} errors, got {np.shape(cov)}")
    if not (0.0 < alpha < 1.0):
        raise InputError(f"alpha: expected a probability in (0, 1), got {alpha}")
    names = [str(i) for i in range(n)] if names is None else [str(k) for k in names]
    if len(names) != n:
        raise InputError(f"names: expected {n} names, got {len(names)}")
    var = np.diag(C)
    keep = np.isfinite(var) & (var > 0) & np.isfinite(e)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where(keep, e / np.sqrt(np.where(keep, var, 1.0)), np.nan)
    Ck = C[np.ix_(keep, keep)]
    ek = e[keep]
    if ek.size == 0:
        return TruthCheck(0.0, 0, 0.0, 1.0, True, dict(zip(names, z)), alpha)
    # pseudo-inverse on the covariance's range: a rank-deficient block (a gauge
    # freedom the covariance carries as exact correlation) loses its null directions
    w, V = np.linalg.eigh((Ck + Ck.T) / 2)
    good = w > w.max() * 1e-12
    proj = V[:, good].T @ ek
    nees = float(np.sum(proj**2 / w[good]))
    dof = int(good.sum())
    threshold = float(special.chdtri(dof, alpha))
    p_value = float(special.chdtrc(dof, nees))
    return TruthCheck(nees, dof, threshold, p_value, bool(nees <= threshold), dict(zip(names, z)), alpha)
