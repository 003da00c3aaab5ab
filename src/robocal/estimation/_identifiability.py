"""Covariance and identifiability of a least-squares estimate from its Jacobian.

The analysis works on the *column-scaled* Jacobian ``J D^-1`` (each column
divided by its norm) so that parameters in different units (metres, radians,
pixels) are compared fairly: a singular value of the scaled matrix that is tiny
relative to the largest means a direction in parameter space that the data do
not see, whatever the units.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.linalg import lapack as _lapack

from robocal.diagnostics import Diagnostic
from robocal.errors import ShapeError
from robocal.validation import check_array

__all__ = ["Identifiability", "analyze_jacobian"]


@dataclass(frozen=True)
class Identifiability:
    """What a Jacobian says about the parameters it was taken with respect to.

    Attributes
    ----------
    labels : tuple of str, length n
        Parameter names, in column order.
    cov : ndarray, shape (n, n)
        Covariance, ``residual_variance * (J^T J)^+`` with the pseudo-inverse
        restricted to the identifiable subspace. Rows and columns of
        unidentifiable parameters are NaN: no number is given for them.
    std : ndarray, shape (n,)
        Square root of the diagonal of ``cov`` (NaN where unidentifiable).
    corr : ndarray, shape (n, n)
        Correlation matrix (NaN where unidentifiable).
    rank : int
        Numerical rank of the column-scaled Jacobian.
    singular_values : ndarray, shape (n,)
        Singular values of the column-scaled Jacobian, descending.
    condition_number : float
        Largest over smallest scaled singular value (``inf`` if rank deficient
        to machine precision).
    unidentifiable : tuple of str
        Parameters with a sizeable component in the null space.
    null_space : ndarray, shape (n, n - rank)
        Null-space basis in scaled coordinates (unit columns).
    vif : ndarray, shape (n,)
        Variance inflation factor of each parameter: how many times its
        variance exceeds the variance it would have if it were the only
        unknown (``1 / (1 - R_j^2)``). NaN where unidentifiable.
    weakly_determined : tuple of str
        Identifiable parameters whose ``vif`` exceeds the threshold.
    correlations : list of (str, str, float)
        Strongest pairwise correlations, by decreasing absolute value.
    residual_variance : float
        The factor ``cov`` was scaled by.
    """

    labels: tuple[str, ...]
    cov: np.ndarray
    std: np.ndarray
    corr: np.ndarray
    rank: int
    singular_values: np.ndarray
    condition_number: float
    unidentifiable: tuple[str, ...]
    null_space: np.ndarray
    vif: np.ndarray
    weakly_determined: tuple[str, ...]
    correlations: list = field(default_factory=list)
    residual_variance: float = 1.0
    weak_vif: float = 1e4

    def with_variance(self, residual_variance: float) -> "Identifiability":
        """Return a copy whose covariance is scaled to ``residual_variance``."""
        k = float(residual_variance) / self.residual_variance if self.residual_variance else np.nan
        # a shallow copy with three fields set: dataclasses.replace re-runs __init__ over every field, a
        # tenth of a small problem's analysis (issue 16)
        new = object.__new__(Identifiability)
        new.__dict__.update(self.__dict__)
        object.__setattr__(new, "cov", self.cov * k)
        object.__setattr__(new, "std", self.std * np.sqrt(k))
        object.__setattr__(new, "residual_variance", float(residual_variance))
        return new

    def null_directions(self, *, min_component: float = 0.1, max_vectors: int = 3) -> list[str]:
        """Human-readable null-space directions, e.g. ``'+0.71 a -0.71 b'``.

        Each direction's sign makes its largest component positive; among
        components equal to within rounding (an exact +-0.7071 pair is common)
        the first in label order, so the text does not flip with rounding.
        """
        out = []
        for v in self.null_space.T[:max_vectors]:
            a = np.abs(v)
            lead = int(np.flatnonzero(a >= a.max() * (1.0 - 1e-9))[0])
            v = v * np.sign(v[lead])
            terms = [f"{c:+.2f} {self.labels[j]}" for j, c in enumerate(v) if abs(c) >= min_component]
            out.append(" ".join(terms))
        return out

    def diagnostics(self) -> list[Diagnostic]:
        """``rank_deficient`` and ``weakly_determined`` warnings, if any."""
        out = []
        n = len(self.labels)
        if self.unidentifiable:
            dirs = "; ".join(f"({d})" for d in self.null_directions())
            out.append(
                Diagnostic(
                    "rank_deficient",
                    f"Jacobian rank {self.rank} < {n} parameters: the data do not determine "
                    f"{', '.join(self.unidentifiable)} (no value or std is reported for them); "
                    f"unobservable directions (column-scaled): {dirs}",
                    params=self.unidentifiable,
                )
            )
        if self.weakly_determined:
            vifs = ", ".join(
                f"{lab} ({self.vif[self.labels.index(lab)]:.3g})" for lab in self.weakly_determined
            )
            out.append(
                Diagnostic(
                    "weakly_determined",
                    f"parameters nearly confounded with others (variance inflation > {self.weak_vif:.3g}): "
                    f"{vifs}; condition number {self.condition_number:.3g}",
                    params=self.weakly_determined,
                )
            )
        return out


@functools.lru_cache(maxsize=64)
def _triu(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(n, 1)``, cached (read-only): every solve of one problem size asks for the same."""
    iu, ju = np.triu_indices(n, 1)
    iu.flags.writeable = ju.flags.writeable = False
    return iu, ju


def _svd_of(Js) -> tuple[np.ndarray, np.ndarray]:
    """Singular values (descending) and right singular vectors (columns)."""
    if sp.issparse(Js):
        # A large sparse Jacobian: the normal matrix is small (n x n) even when
        # J is tall. Squaring the condition number is acceptable here because
        # the rank tolerance is far above the precision this costs.
        JtJ = (Js.T @ Js).toarray()
        w, V = np.linalg.eigh(JtJ)
        order = np.argsort(w)[::-1]
        return np.sqrt(np.clip(w[order], 0.0, None)), V[:, order]
    m, n = Js.shape
    # with fewer rows than columns the trailing right singular vectors are
    # needed too: they span the part of the null space the thin SVD omits
    if m > 2 * n:
        # Tall Jacobian (many observations, few parameters): J = Q R keeps the
        # singular values and right vectors (R^T R = J^T J) and the SVD of the
        # n x n factor is cheap; 1.3-7x faster than the SVD of J on 3k-100k rows.
        # LAPACK's dgeqrf / dgesdd called through scipy.linalg.lapack: numpy.linalg's wrappers cost more than
        # the factorisations of a small problem (90 x 12: ~40 % of them, issue 16); numpy's path where
        # LAPACK reports a failure (it raises numpy's error)
        qr, _, _, info = _lapack.dgeqrf(Js)
        if info == 0:
            _, s, Vt, info = _lapack.dgesdd(np.triu(qr[:n]))
            if info == 0:
                return s, Vt.T
        _, s, Vt = np.linalg.svd(np.linalg.qr(Js, mode="r"))
        return s, Vt.T
    _, s, Vt = np.linalg.svd(Js, full_matrices=m < n)
    if m < n:
        s = np.concatenate([s, np.zeros(n - m)])
    return s, Vt.T


def analyze_jacobian(
    J,
    labels: Sequence[str] | None = None,
    *,
    residual_variance: float = 1.0,
    rank_tol: float = 1e-6,
    null_tol: float = 0.1,
    weak_vif: float = 1e4,
    n_correlations: int = 10,
) -> Identifiability:
    """Covariance, rank and identifiability from a (weighted) Jacobian.

    Parameters
    ----------
    J : array_like or scipy sparse, shape (m, n)
        Jacobian of the *weighted* residuals (each residual divided by its
        noise standard deviation, if known) with respect to the n parameters.
    labels : sequence of str, length n, optional
        Parameter names (default ``'p[j]'``).
    residual_variance : float
        Variance of the weighted residuals, ``s^2``: 1 when the weights are
        the true noise, else an estimate such as ``2 cost / (m - rank)``.
    rank_tol : float
        A scaled singular value below ``rank_tol`` times the largest counts as
        zero. The default 1e-6 stays above the ~1e-8 relative error of a
        forward-difference Jacobian.
    null_tol : float
        A parameter is unidentifiable if its unit vector has a component of at
        least ``null_tol`` (squared: 1 %) in the null space.
    weak_vif : float
        Variance inflation factor above which an identifiable parameter is
        reported as weakly determined (1e4: its std is 100 times what it
        would be if it were the only unknown).
    n_correlations : int
        How many of the strongest pairwise correlations to keep.

    Returns
    -------
    Identifiability

    Notes
    -----
    With ``J D^-1 = U S V^T`` (``D`` the column norms), the covariance is
    ``s^2 D^-1 V_r S_r^-2 V_r^T D^-1`` over the ``r`` singular values above
    tolerance. For a parameter orthogonal to the null space this equals the
    variance of its (estimable) least-squares estimate; for the others it
    would depend on an arbitrary choice and is reported as NaN.
    """
    if sp.issparse(J):
        Jm = sp.csc_array(J, dtype=float)
        if Jm.ndim != 2:
            raise ShapeError(f"J must have shape (m, n), got {Jm.shape}")
    else:
        Jm = check_array(J, "J")
        if Jm.ndim != 2:
            raise ShapeError(f"J must have shape (m, n), got {tuple(Jm.shape)}")
    return _analyze_checked(Jm, labels, residual_variance=residual_variance, rank_tol=rank_tol, null_tol=null_tol,
                            weak_vif=weak_vif, n_correlations=n_correlations)


def _analyze_checked(Jm, labels=None, *, residual_variance: float = 1.0, rank_tol: float = 1e-6,
                     null_tol: float = 0.1, weak_vif: float = 1e4, n_correlations: int = 10) -> Identifiability:
    """:func:`analyze_jacobian` on a 2-D float ndarray or CSC array known to be finite: the solver's own
    Jacobian, checked by the evaluator as it was built (issue 16: not validated a second time)."""
    if sp.issparse(Jm):
        d = np.sqrt(np.asarray(Jm.multiply(Jm).sum(axis=0)).ravel())
    else:
        d = np.sqrt(np.add.reduce(Jm * Jm, axis=0))       # np.linalg.norm(Jm, axis=0)'s own arithmetic
    m, n = Jm.shape
    labels = tuple(labels) if labels is not None else tuple(f"p[{j}]" for j in range(n))
    if len(labels) != n:
        raise ShapeError(f"labels must have length {n} (columns of J), got {len(labels)}")
    if n == 0:
        empty = np.zeros((0, 0))
        return Identifiability(labels, empty, np.zeros(0), empty, 0, np.zeros(0), 1.0, (), empty,
                               np.zeros(0), (), [], float(residual_variance), weak_vif)

    # a column of zeros is a parameter the residuals do not depend on at all;
    # unit scale keeps it as an exact zero singular direction.
    d_safe = np.where(d > 0, d, 1.0)
    Js = Jm @ sp.diags_array(1.0 / d_safe) if sp.issparse(Jm) else Jm / d_safe
    s, V = _svd_of(Js)
    smax = s[0] if s.size else 0.0
    rank = int(np.count_nonzero(s > rank_tol * smax)) if smax > 0 else 0
    cond = float(smax / s[-1]) if s[-1] > 0 else float("inf")

    Vr, sr = V[:, :rank], s[:rank]
    cov_scaled = (Vr / sr**2) @ Vr.T
    V0 = V[:, rank:]
    leverage = np.einsum("ij,ij->i", V0, V0)
    bad = leverage >= null_tol**2
    cov = residual_variance * cov_scaled / np.outer(d_safe, d_safe)
    vif = cov_scaled.diagonal().copy()
    any_bad = bool(bad.any())
    # (issue 16) the masks and sub-matrix copies only where a parameter is unidentifiable: on a small
    # problem each of these NumPy calls costs as much as the SVD's share of a row
    if any_bad:
        cov[bad, :] = np.nan
        cov[:, bad] = np.nan
        vif[bad] = np.nan
    std = np.sqrt(np.maximum(cov.diagonal(), 0.0))       # NaN stays NaN, as with np.clip
    if any_bad:
        std[bad] = np.nan
        g = np.flatnonzero(~bad)
        covg, stdg = cov[np.ix_(g, g)], std[g]
    else:
        g, covg, stdg = np.arange(n), cov, std
    if stdg.size and 0.0 < stdg.min() and stdg.max() < np.inf:          # NaN fails the first comparison
        cg = np.minimum(np.maximum(covg / np.outer(stdg, stdg), -1.0), 1.0)
    else:
        with np.errstate(invalid="ignore", divide="ignore"):
            cg = covg / np.outer(stdg, stdg)
        # a parameter with zero variance (exact fit) is uncorrelated with the rest
        cg = np.where(np.isfinite(cg), np.clip(cg, -1.0, 1.0), 0.0)
    np.einsum("ii->i", cg)[:] = 1.0               # the diagonal (a view; np.fill_diagonal's checks cost more)
    if any_bad:
        corr = np.full((n, n), np.nan)
        corr[np.ix_(g, g)] = cg
    else:
        corr = cg

    iu, ju = _triu(len(g))
    vals = cg[iu, ju]
    top = np.argsort(-np.abs(vals), kind="stable")[:n_correlations]
    pairs = [(labels[g[iu[k]]], labels[g[ju[k]]], float(vals[k])) for k in top.tolist()]

    weak = tuple(labels[j] for j in np.flatnonzero(~bad & (vif > weak_vif)).tolist())
    return Identifiability(
        labels=labels,
        cov=cov,
        std=std,
        corr=corr,
        rank=rank,
        singular_values=s,
        condition_number=cond,
        unidentifiable=tuple(labels[j] for j in np.flatnonzero(bad).tolist()),
        null_space=V0,
        vif=vif,
        weakly_determined=weak,
        correlations=pairs[:n_correlations],
        residual_variance=float(residual_variance),
        weak_vif=float(weak_vif),
    )
