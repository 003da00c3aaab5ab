"""Evaluation of a compiled :class:`~robocal.estimation.Problem` on the free vector.

Every residual and Jacobian the user functions return is checked here
(shape, size, finiteness) so that a wrong shape or a NaN is reported with the
term and observation it came from, and never reaches the solver.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import scipy
import scipy.sparse as sp

from robocal.errors import InputError, NonFiniteError, ShapeError

# SciPy's finite-difference engine (the one least_squares itself uses, with
# bound handling, one-sided steps at bounds and column grouping for sparse
# Jacobians). It is *private* API, kept here on purpose: we call it ourselves so
# that every Jacobian evaluation passes through one place, which is how the cost
# of each accepted iterate is recorded for every method (see _solve.py), and a
# hand-written copy of its bounds and grouping logic would be more code to get
# wrong than the risk it removes. Its signature has been stable since SciPy 0.17.
# The import is guarded: if a SciPy release moves or changes it, analytic
# Jacobians keep working and asking for finite differences raises an ImportError
# that says what is missing and what to do (tests/estimation/test_estimation_numdiff.py
# checks the names and keywords used here against the installed SciPy).
_NUMDIFF_KEYWORDS = ("method", "rel_step", "f0", "bounds", "sparsity")
try:
    from scipy.optimize._numdiff import approx_derivative, group_columns
except ImportError as _exc:  # pragma: no cover - depends on the installed SciPy
    approx_derivative = group_columns = None
    _NUMDIFF_PROBLEM: str | None = f"cannot import it ({_exc})"
else:
    _missing_kw = [k for k in _NUMDIFF_KEYWORDS if k not in inspect.signature(approx_derivative).parameters]
    _NUMDIFF_PROBLEM = f"its signature lacks the keyword(s) {', '.join(_missing_kw)}" if _missing_kw else None


def _require_numdiff(jac: str) -> None:
    """Raise a clear ImportError if SciPy's private finite-difference engine is unusable."""
    if _NUMDIFF_PROBLEM is not None:
        raise ImportError(
            f"jac={jac!r} (finite differences) uses scipy.optimize._numdiff.approx_derivative, a private "
            f"SciPy function, and with SciPy {scipy.__version__} {_NUMDIFF_PROBLEM}. Give every residual "
            f"term an analytic jacobian (jac='analytic'), or install a SciPy robocal is tested with "
            f"(see pyproject.toml)."
        )

__all__ = ["Evaluator", "TermInfo", "JAC_METHODS"]

JAC_METHODS = ("analytic", "2-point", "3-point")


@dataclass(frozen=True)
class TermInfo:
    """Where one residual term sits in the stacked residual vector.

    Attributes
    ----------
    name : str
    row_start : int
        First row of the term in the stacked residual vector.
    size : int
        Number of residuals ``m_t = n_obs * dim``.
    dim : int
        Components per observation.
    n_obs : int
        Number of observations.
    obs_start : int
        Global index of the term's first observation (terms are numbered
        consecutively).
    """

    name: str
    row_start: int
    size: int
    dim: int
    n_obs: int
    obs_start: int

    @property
    def rows(self) -> slice:
        return slice(self.row_start, self.row_start + self.size)

    def to_dict(self) -> dict:
        return dict(name=self.name, row_start=self.row_start, size=self.size, dim=self.dim,
                    n_obs=self.n_obs, obs_start=self.obs_start)


def _describe(params: Mapping[str, np.ndarray], limit: int = 300) -> str:
    txt = ", ".join(f"{k}={np.array2string(np.asarray(v), precision=4, threshold=6)}" for k, v in params.items())
    return txt if len(txt) <= limit else txt[:limit] + " ..."


class Evaluator:
    """Weighted residuals and their Jacobian as functions of the free vector.

    Built by :meth:`Problem.evaluator`. ``weighted(x)`` returns the stacked
    residuals divided by ``sigma``; ``jacobian(x)`` their Jacobian w.r.t. the
    free parameters (dense, or CSR when ``sparse``).
    """

    def __init__(self, layout, terms, *, jac: str | None = None, sparse: bool = False, diff_step=None):
        self.layout = layout
        self.terms = terms
        missing = [t.name for t in terms if t.jacobian is None]
        if jac is None:
            jac = "2-point" if missing else "analytic"
        if jac not in JAC_METHODS:
            raise InputError(f"jac must be one of {', '.join(JAC_METHODS)}, got {jac!r}")
        if jac == "analytic" and missing:
            raise InputError(f"jac='analytic' but residual term(s) {', '.join(missing)} have no jacobian")
        if jac != "analytic":
            _require_numdiff(jac)
        self.jac_mode = jac
        self.sparse = bool(sparse)
        self.diff_step = diff_step
        self.n_fun = 0
        self.n_jac = 0
        self.stage = "at the initial values"
        self._blocks = {b.name: b for b in layout.blocks}

        x0 = layout.x0_full[layout.free_full]
        params = layout.split(layout.full_from_free(x0))
        infos, sigmas, self._cols, f0 = [], [], [], []
        row = obs = 0
        for t in terms:
            r = self._term_residuals(t, params, None)
            f0.append(r.reshape(-1))
            n_obs, dim = r.shape
            info = TermInfo(t.name, row, r.size, dim, n_obs, obs)
            infos.append(info)
            sigmas.append(self._sigma(t, info))
            if t.blocks is None:                   # every block in order: every element
                self._cols.append(np.arange(layout.n_full))
            else:
                self._cols.append(np.concatenate([np.arange(self._blocks[n].offset, self._blocks[n].offset
                                                            + self._blocks[n].size) for n in t.blocks]))
            row += r.size
            obs += n_obs
        self.term_info: list[TermInfo] = infos
        self.m = row
        self.n_obs = obs
        self.sigma = np.concatenate(sigmas)
        #: weighted residuals at the initial values (evaluated here to learn their shape): the solver's first
        #: evaluation, so :func:`~robocal.estimation.solve` does not repeat it
        self.f0 = np.concatenate(f0) / self.sigma
        self.n = len(layout.free_full)
        structured = any(t.blocks is not None or t.jac_sparsity is not None for t in terms)
        # a single dense term needs no structure (and building an all-ones
        # m x n pattern for it would only cost memory)
        self.structure = self._structure() if structured else None
        density = self.structure.nnz / max(1, self.m * self.n) if structured else 1.0
        # column grouping only pays when the structure has zeros to exploit
        self._fd_sparsity = None
        if jac != "analytic" and density < 0.5:
            self._fd_sparsity = (self.structure, group_columns(self.structure))
        self.density = density
        # one term over every block in order, no ties: its Jacobian is the full one as it is (no zero-filled
        # assembly, no fold; issue 16: a small problem's evaluation is mostly that overhead)
        self._single = (len(terms) == 1 and not layout.tied
                        and (terms[0].blocks is None or list(terms[0].blocks) == list(self._blocks)))
        self.stage = "during the solve"

    # ----------------------------------------------------------- residuals
    def _term_residuals(self, t, params, info: TermInfo | None) -> np.ndarray:
        out = t.fun(params)
        try:
            r = np.asarray(out, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InputError(f"residual term '{t.name}' returned a non-numeric value ({exc})") from None
        if r.ndim == 0:
            r = r.reshape(1)
        if r.ndim == 2:
            if t.residual_dim is not None and r.shape[1] != t.residual_dim:
                raise ShapeError(f"residual term '{t.name}' must return shape (n_obs, {t.residual_dim}), "
                                 f"got {r.shape}")
        elif r.ndim == 1:
            dim = t.residual_dim or 1
            if r.size % dim:
                raise ShapeError(f"residual term '{t.name}' returned {r.size} residuals, not a multiple of "
                                 f"residual_dim = {dim}")
            r = r.reshape(-1, dim)
        else:
            raise ShapeError(f"residual term '{t.name}' must return shape (m,) or (n_obs, dim), got {r.shape}")
        if r.size == 0:
            raise ShapeError(f"residual term '{t.name}' returned no residuals")
        if info is not None and r.shape != (info.n_obs, info.dim):
            raise ShapeError(f"residual term '{t.name}' returned shape {r.shape} {self.stage} but "
                             f"{(info.n_obs, info.dim)} at the initial values; the number of residuals must not "
                             "change")
        if not np.all(np.isfinite(r)):
            i, c = (int(v) for v in np.argwhere(~np.isfinite(r))[0])
            raise NonFiniteError(f"residual term '{t.name}' returned NaN or infinity {self.stage} at observation "
                                 f"{i} (component {c}); parameters: {_describe(params)}")
        return r

    def _sigma(self, t, info: TermInfo) -> np.ndarray:
        if t.sigma is None:
            return np.ones(info.size)
        s = t.sigma
        shape = (info.n_obs, info.dim)
        if s.ndim == 1 and s.size == info.size:
            s = s.reshape(shape)
        try:
            out = np.empty(shape)              # broadcast by assignment: np.broadcast_to's wrapper costs more
            out[...] = s
            return out.reshape(-1)
        except ValueError:
            raise ShapeError(f"sigma of term '{t.name}' must be a scalar or have shape ({info.dim},), "
                             f"({info.n_obs}, 1), {shape} or ({info.size},), got {s.shape}") from None

    def params(self, x: np.ndarray) -> dict[str, np.ndarray]:
        return self.layout.split(self.layout.full_from_free(x))

    def weighted(self, x: np.ndarray) -> np.ndarray:
        """Stacked residuals divided by sigma, shape (m,)."""
        self.n_fun += 1
        params = self.params(x)
        if len(self.terms) == 1:
            return self._term_residuals(self.terms[0], params, self.term_info[0]).reshape(-1) / self.sigma
        parts = [self._term_residuals(t, params, info).reshape(-1) for t, info in zip(self.terms, self.term_info)]
        return np.concatenate(parts) / self.sigma

    # ------------------------------------------------------------ jacobian
    def _structure(self):
        rows, cols = [], []
        for t, info, tcols in zip(self.terms, self.term_info, self._cols):
            if t.jac_sparsity is not None:
                S = sp.coo_array(t.jac_sparsity)
                if S.shape != (info.size, tcols.size):
                    raise ShapeError(f"jac_sparsity of term '{t.name}' must have shape ({info.size}, "
                                     f"{tcols.size}), got {S.shape}")
                nz = S.data != 0
                rows.append(S.row[nz] + info.row_start)
                cols.append(tcols[S.col[nz]])
            else:
                rr, cc = np.meshgrid(np.arange(info.size) + info.row_start, tcols, indexing="ij")
                rows.append(rr.ravel())
                cols.append(cc.ravel())
        r, c = np.concatenate(rows), np.concatenate(cols)
        S_full = sp.csr_array((np.ones(r.size), (r, c)), shape=(self.m, self.layout.n_full))
        S = sp.csc_array(S_full @ abs(self.layout.M))
        S.data[:] = 1.0
        S.eliminate_zeros()
        return S

    def _term_block(self, t, info: TermInfo, val, ncols: int, what: str):
        if sp.issparse(val):
            if val.shape != (info.size, ncols):
                raise ShapeError(f"jacobian of term '{t.name}' {what} must have shape ({info.size}, {ncols}), "
                                 f"got {val.shape}")
            return sp.coo_array(val, dtype=float)
        try:
            a = np.asarray(val, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InputError(f"jacobian of term '{t.name}' {what} is not numeric ({exc})") from None
        ok = a.size == info.size * ncols and a.ndim >= 2 and (
            a.shape[0] == info.size or (a.shape[0] == info.n_obs and a.shape[1] == info.dim))
        if not ok:
            raise ShapeError(f"jacobian of term '{t.name}' {what} must have shape ({info.size}, {ncols}) or "
                             f"({info.n_obs}, {info.dim}, {ncols}), got {a.shape}")
        return a.reshape(info.size, ncols)

    def _analytic(self, x: np.ndarray):
        params = self.params(x)
        N = self.layout.n_full
        if self._single and not self.sparse:
            t, info = self.terms[0], self.term_info[0]
            out = t.jacobian(params)
            if not isinstance(out, Mapping) and not sp.issparse(out):
                J = self._term_block(t, info, out, N, "(full matrix over its blocks)") / self.sigma[:, None]
                if not np.isfinite(J).all():
                    # the general path below words the error (term, residual, parameter)
                    return self._analytic_general(params, N, t, out)
                return J if self.layout._all_free else J[:, self.layout.free_full]
            return self._analytic_general(params, N, t, out)
        return self._analytic_general(params, N)

    def _analytic_general(self, params, N, first=None, first_out=None):
        dense = None if self.sparse else np.zeros((self.m, N))
        rows, cols, data = [], [], []

        def put(info, block, colidx):
            r0 = info.row_start
            if sp.issparse(block):
                if dense is not None:
                    dense[r0:r0 + info.size, colidx] = block.toarray()
                else:
                    rows.append(block.row + r0)
                    cols.append(colidx[block.col])
                    data.append(block.data)
            elif dense is not None:
                dense[r0:r0 + info.size, colidx] = block
            else:
                rr, cc = np.nonzero(block)
                rows.append(rr + r0)
                cols.append(colidx[cc])
                data.append(block[rr, cc])

        for t, info, tcols in zip(self.terms, self.term_info, self._cols):
            out = first_out if t is first else t.jacobian(params)
            if isinstance(out, Mapping):
                for name, val in out.items():
                    b = self._blocks.get(name)
                    if b is None or (t.blocks is not None and name not in t.blocks):
                        raise InputError(f"jacobian of term '{t.name}' has an entry for '{name}', which is not "
                                         f"one of its blocks ({', '.join(t.blocks or self._blocks)})")
                    blk = self._term_block(t, info, val, b.size, f"for block '{name}'")
                    put(info, blk, np.arange(b.offset, b.offset + b.size))
            else:
                blk = self._term_block(t, info, out, tcols.size, "(full matrix over its blocks)")
                put(info, blk, tcols)
        if dense is not None:
            J_full = dense
            bad = ~np.isfinite(J_full)
        else:
            J_full = sp.csr_array((np.concatenate(data) if data else np.zeros(0),
                                   (np.concatenate(rows) if rows else np.zeros(0, int),
                                    np.concatenate(cols) if cols else np.zeros(0, int))), shape=(self.m, N))
            J_full.sum_duplicates()
            bad = None if np.all(np.isfinite(J_full.data)) else ~np.isfinite(J_full.toarray())
        if bad is not None and np.any(bad):
            r, c = (int(v) for v in np.argwhere(bad)[0])
            term = next(i for i in self.term_info if i.row_start <= r < i.row_start + i.size)
            raise NonFiniteError(f"jacobian of term '{term.name}' is NaN or infinite {self.stage} at residual "
                                 f"{r - term.row_start}, parameter '{self.layout.labels[c]}'")
        if dense is not None:
            J_full /= self.sigma[:, None]
        else:
            J_full = sp.csr_array(sp.diags_array(1.0 / self.sigma) @ J_full)
        return self.layout.fold_columns(J_full)

    def jacobian(self, x: np.ndarray, f0: np.ndarray | None = None):
        """Jacobian of :meth:`weighted` w.r.t. the free vector, shape (m, n)."""
        self.n_jac += 1
        if self.jac_mode == "analytic":
            J = self._analytic(x)
        else:
            J = approx_derivative(self.weighted, x, method=self.jac_mode, f0=f0, rel_step=self.diff_step,
                                  bounds=(self.layout.lower, self.layout.upper), sparsity=self._fd_sparsity)
        if sp.issparse(J):
            return sp.csr_array(J) if self.sparse else J.toarray()
        return sp.csr_array(J) if self.sparse else np.asarray(J)
