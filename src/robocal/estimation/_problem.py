"""Least-squares problems over named parameter blocks.

A :class:`Problem` holds named parameter blocks (arrays of any shape, each
element free, fixed, or tied to another element) and one or more residual
terms. Residual functions receive a ``dict`` of full block arrays, so they are
written in the model's own variables and never see the free-parameter vector
that the solver works with.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from robocal.errors import InputError, ShapeError
from robocal.estimation._evaluate import Evaluator
from robocal.estimation._layout import _Layout
from robocal.validation import check_array

__all__ = ["Problem", "LeastSquaresProblem", "BlockInfo", "JacobianCheck"]


@dataclass(frozen=True)
class BlockInfo:
    """A read-only view of one parameter block.

    Attributes
    ----------
    name : str
    shape : tuple of int
        Shape of the block's array as the residual functions see it.
    offset : int
        Index of the block's first element in the full (all-blocks) vector.
    x0 : ndarray, shape (size,)
        Initial (or fixed) values, flattened in C order.
    fixed : ndarray of bool, shape (size,)
    labels : tuple of str
        One name per element, unique across the problem.
    units : tuple of str or None
    scale : ndarray, shape (size,), or None
        Characteristic size of each element (the solver's ``x_scale``).
    lower, upper : ndarray, shape (size,)
        Bounds (``-inf`` / ``inf`` when absent).
    """

    name: str
    shape: tuple[int, ...]
    offset: int
    x0: np.ndarray
    fixed: np.ndarray
    labels: tuple[str, ...]
    units: tuple[str | None, ...]
    scale: np.ndarray | None
    lower: np.ndarray
    upper: np.ndarray

    @property
    def size(self) -> int:
        return int(self.x0.size)


@dataclass
class _Term:
    name: str
    fun: Callable
    jacobian: Callable | None
    blocks: tuple[str, ...] | None
    residual_dim: int | None
    sigma: np.ndarray | None
    jac_sparsity: object | None


def _checked_floats(x, name: str) -> np.ndarray:
    """``check_array(x, name)``; a finite float64 ndarray is returned as it is without the generic checks (the
    text and boolean scans are for lists; issue 16: a small problem's set-up is mostly such checks)."""
    if type(x) is np.ndarray and x.dtype == np.float64 and np.isfinite(x).all():
        return x
    return check_array(x, name)


def _per_element(value, size: int, shape: tuple, name: str, what: str, *, default: float) -> np.ndarray:
    if value is None:
        return np.full(size, default, dtype=float)
    arr = check_array(value, f"{what} of block '{name}'", finite=False)
    if arr.ndim == 0:
        return np.full(size, float(arr))
    if arr.size != size or (arr.shape != shape and arr.ndim != 1):
        raise ShapeError(f"{what} of block '{name}' must be a scalar or have shape {shape}, got {arr.shape}")
    if np.any(np.isnan(arr)):
        raise InputError(f"{what} of block '{name}' contains NaN")
    return arr.reshape(-1).astype(float)


def _default_labels(name: str, shape: tuple) -> list[str]:
    if shape == ():
        return [name]
    if len(shape) == 1:
        return [f"{name}[{i}]" for i in range(shape[0])]
    return [f"{name}[{','.join(map(str, idx))}]" for idx in np.ndindex(*shape)]


class Problem:
    """A nonlinear least-squares problem over named parameter blocks.

    Parameters
    ----------
    residuals : callable, optional
        ``residuals(params) -> ndarray``: ``params`` maps each block name to
        its full array (fixed and tied elements included); the return value is
        flat ``(m,)`` or ``(n_obs, dim)``. Shorthand for :meth:`add_residuals`.
    jacobian : callable, optional
        Analytic Jacobian of ``residuals``, see :meth:`add_residuals`.
    residual_dim : int, optional
        Residual components per observation (2 for image points). Inferred
        from a 2-D return value.
    sigma : array_like, optional
        Noise standard deviation of each residual, see :meth:`add_residuals`.
    jac_sparsity : array_like or sparse, optional
        Sparsity of the Jacobian, see :meth:`add_residuals`.
    name : str
        Name of this residual term (used in reports).

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0, 1, 20); y = 2.0 * t + 1.0
    >>> p = Problem(lambda q: q["line"][0] * t + q["line"][1] - y)
    >>> p = p.add_block("line", [0.0, 0.0], labels=["slope", "intercept"])
    """

    def __init__(self, residuals: Callable | None = None, *, jacobian: Callable | None = None,
                 residual_dim: int | None = None, sigma=None, jac_sparsity=None, name: str = "residuals"):
        self._blocks: dict[str, BlockInfo] = {}
        self._label_index: dict[str, int] = {}
        self._ties: dict[str, tuple[str, float]] = {}
        self._terms: list[_Term] = []
        if residuals is not None:
            self.add_residuals(residuals, name=name, jacobian=jacobian, residual_dim=residual_dim,
                               sigma=sigma, jac_sparsity=jac_sparsity)

    # ----------------------------------------------------------------- blocks
    def add_block(self, name: str, x0, *, fixed=False, labels: Sequence[str] | None = None,
                  unit: str | Sequence[str | None] | None = None, scale=None, lower=None,
                  upper=None) -> "Problem":
        """Add a parameter block; returns the problem so calls can be chained.

        Parameters
        ----------
        name : str
            Key of the block in the ``params`` dict.
        x0 : array_like, any shape
            Initial value (the value kept, for fixed elements). Must be finite.
        fixed : bool or array_like of bool, shape of ``x0``
            Elements held at ``x0``.
        labels : sequence of str, optional
            Per-element names, default ``'name[i]'`` (``'name'`` for a scalar).
        unit : str or sequence of str, optional
            Unit(s) shown in the summary (values are SI: m, rad).
        scale : float or array_like, optional
            Typical magnitude of each element; passed to the solver as
            ``x_scale`` so that steps are balanced across units.
        lower, upper : float or array_like, optional
            Bounds (not with ``method='lm'``). ``x0`` must lie inside them.
        """
        if not isinstance(name, str) or not name:
            raise InputError(f"block name must be a non-empty string, got {name!r}")
        if name in self._blocks:
            raise InputError(f"block '{name}' already exists")
        x = _checked_floats(x0, f"x0 of block '{name}'")
        shape = tuple(x.shape)
        size = x.size
        if size == 0:
            raise ShapeError(f"x0 of block '{name}' must have at least one element, got shape {shape}")
        fixed_arr = np.asarray(fixed)
        if fixed_arr.dtype != bool:
            raise InputError(f"fixed of block '{name}' must be bool or a bool mask, got dtype {fixed_arr.dtype}")
        if fixed_arr.ndim == 0:
            fixed_arr = np.full(size, bool(fixed_arr))
        elif fixed_arr.shape != shape and not (fixed_arr.ndim == 1 and fixed_arr.size == size):
            raise ShapeError(f"fixed mask of block '{name}' must have shape {shape}, got {fixed_arr.shape}")
        labs = list(labels) if labels is not None else _default_labels(name, shape)
        if len(labs) != size or not all(isinstance(s, str) and s for s in labs):
            raise ShapeError(f"labels of block '{name}' must be {size} non-empty strings, got {labels!r}")
        dup = [s for s in labs if s in self._label_index] + [s for i, s in enumerate(labs) if s in labs[:i]]
        if dup:
            raise InputError(f"parameter label '{dup[0]}' is used twice (labels must be unique)")
        if unit is None or isinstance(unit, str):
            units = (unit,) * size
        else:
            units = tuple(unit)
            if len(units) != size:
                raise ShapeError(f"unit of block '{name}' must be a string or {size} strings, got {len(units)}")
        sc = None
        if scale is not None:
            sc = _per_element(scale, size, shape, name, "scale", default=1.0)
            if not np.all(np.isfinite(sc) & (sc > 0)):
                raise InputError(f"scale of block '{name}' must be finite and > 0, got {sc.tolist()}")
        lo = _per_element(lower, size, shape, name, "lower", default=-np.inf)
        hi = _per_element(upper, size, shape, name, "upper", default=np.inf)
        flat = x.reshape(-1).copy()
        # no bounds given: x0 is finite (checked above), so inside (-inf, inf); no comparison needed
        outside = (flat < lo) | (flat > hi) if lower is not None or upper is not None else None
        if outside is not None and np.any(outside):
            k = int(np.flatnonzero(outside)[0])
            raise InputError(f"x0 of '{labs[k]}' = {flat[k]!r} is outside its bounds [{lo[k]}, {hi[k]}]")
        offset = len(self._label_index)
        for i, s in enumerate(labs):
            self._label_index[s] = offset + i
        self._blocks[name] = BlockInfo(name, shape, offset, flat, fixed_arr.reshape(-1).copy(), tuple(labs),
                                       units, sc, lo, hi)
        return self

    def set_fixed(self, name: str, fixed=True) -> "Problem":
        """Change the fixed mask of block ``name`` (bool or mask of its shape)."""
        b = self._block(name)
        mask = np.asarray(fixed)
        if mask.dtype != bool:
            raise InputError(f"fixed of block '{name}' must be bool or a bool mask, got dtype {mask.dtype}")
        mask = np.full(b.size, bool(mask)) if mask.ndim == 0 else mask
        if mask.size != b.size:
            raise ShapeError(f"fixed mask of block '{name}' must have shape {b.shape}, got {mask.shape}")
        self._blocks[name] = replace(b, fixed=mask.reshape(-1).copy())
        return self

    def set_x0(self, name: str, x0) -> "Problem":
        """Replace the initial (or fixed) values of block ``name``."""
        b = self._block(name)
        x = check_array(x0, f"x0 of block '{name}'")
        if x.size != b.size or (x.shape != b.shape and x.ndim != 1):
            raise ShapeError(f"x0 of block '{name}' must have shape {b.shape}, got {x.shape}")
        flat = x.reshape(-1).copy()
        if np.any((flat < b.lower) | (flat > b.upper)):
            raise InputError(f"x0 of block '{name}' is outside its bounds")
        self._blocks[name] = replace(b, x0=flat)
        return self

    def tie(self, target: str, source: str, *, factor: float = 1.0) -> "Problem":
        """Make element ``target`` equal ``factor * source`` (labels).

        The target is no longer a free parameter; its ``x0`` and bounds are
        ignored. Use it when one motor drives two joints (factor 1) or a
        mirrored pair (factor -1). Chains of ties are followed.
        """
        for lab in (target, source):
            if lab not in self._label_index:
                raise InputError(f"unknown parameter label '{lab}' (known: {', '.join(self.labels[:8])}, ...)")
        if target == source:
            raise InputError(f"cannot tie '{target}' to itself")
        if target in self._ties:
            raise InputError(f"'{target}' is already tied to '{self._ties[target][0]}'")
        factor = float(factor)
        if not np.isfinite(factor):
            raise InputError(f"tie factor must be finite, got {factor}")
        seen, cur = {target}, source
        while cur in self._ties:
            cur = self._ties[cur][0]
            if cur in seen:
                raise InputError(f"tying '{target}' to '{source}' would make a cycle")
            seen.add(cur)
        self._ties[target] = (source, factor)
        return self

    # ------------------------------------------------------------- residuals
    def add_residuals(self, fun: Callable, *, name: str | None = None, blocks: Sequence[str] | None = None,
                      jacobian: Callable | None = None, residual_dim: int | None = None, sigma=None,
                      jac_sparsity=None) -> "Problem":
        """Add a residual term; all terms are stacked into one residual vector.

        Parameters
        ----------
        fun : callable
            ``fun(params) -> ndarray``, flat ``(m,)`` or ``(n_obs, dim)``;
            ``params`` maps every block name to its full array. A flat
            vector with ``residual_dim = d`` is read as ``(m // d, d)`` in C
            order (``[x0, y0, x1, y1, ...]``).
        name : str, optional
            Name in reports (default ``'residuals'``, then ``'term<k>'``).
        blocks : sequence of str, optional
            The blocks this term depends on (default: all). Gives the
            Jacobian's block sparsity (used for large problems) and the column
            order of a full-matrix ``jacobian``.
        jacobian : callable, optional
            ``jacobian(params)`` returning either a dict ``{block: array}``
            with arrays of shape ``(m, block_size)`` (or ``(n_obs, dim,
            *block_shape)``; blocks left out are zero; scipy sparse allowed),
            or one matrix ``(m, sum of the term's block sizes)`` over the
            term's blocks in order. Derivatives are with respect to every
            element, fixed ones included; they are dropped/folded as needed.
        residual_dim : int, optional
            Components per observation (inferred from a 2-D ``fun`` output).
        sigma : array_like, optional
            Noise standard deviation: scalar, ``(dim,)``, ``(n_obs, 1)``,
            ``(n_obs, dim)`` or ``(m,)``. Residuals are divided by it.
        jac_sparsity : array_like or sparse, shape (m, n_term_elements), optional
            Element-level structure (nonzero = may be nonzero) over the term's
            blocks in order; finer than the block structure.
        """
        if not callable(fun):
            raise InputError(f"residual function must be callable, got {type(fun).__name__}")
        if jacobian is not None and not callable(jacobian):
            raise InputError(f"jacobian must be callable, got {type(jacobian).__name__}")
        if blocks is not None:
            blocks = tuple(blocks)
            if not blocks or not all(isinstance(b, str) for b in blocks):
                raise InputError(f"blocks must be a non-empty sequence of block names, got {blocks!r}")
        if name is None:
            name = "residuals" if not self._terms else f"term{len(self._terms)}"
        if any(t.name == name for t in self._terms):
            raise InputError(f"residual term '{name}' already exists")
        if residual_dim is not None and (int(residual_dim) != residual_dim or residual_dim < 1):
            raise InputError(f"residual_dim must be a positive integer, got {residual_dim!r}")
        if sigma is not None:
            sigma = _checked_floats(sigma, f"sigma of term '{name}'")
            if np.any(sigma <= 0):
                raise InputError(f"sigma of term '{name}' must be > 0, got min {sigma.min()!r}")
        self._terms.append(_Term(name, fun, jacobian, None if blocks is None else tuple(blocks),
                                 None if residual_dim is None else int(residual_dim), sigma, jac_sparsity))
        return self

    # ------------------------------------------------------------ inspection
    def _block(self, name: str) -> BlockInfo:
        if name not in self._blocks:
            raise InputError(f"unknown block '{name}' (blocks: {', '.join(self._blocks) or 'none'})")
        return self._blocks[name]

    @property
    def blocks(self) -> Mapping[str, BlockInfo]:
        """Blocks by name, in the order they were added."""
        return dict(self._blocks)

    @property
    def labels(self) -> list[str]:
        """Labels of all elements, in block order."""
        return list(self._label_index)

    @property
    def ties(self) -> dict[str, tuple[str, float]]:
        """``{target: (source, factor)}`` as given to :meth:`tie`."""
        return dict(self._ties)

    @property
    def free_labels(self) -> list[str]:
        """Labels of the free parameters, in solver order."""
        return [self.labels[k] for k in self._layout().free_full]

    @property
    def n_free(self) -> int:
        return len(self._layout().free_full)

    def initial_params(self) -> dict[str, np.ndarray]:
        """The ``params`` dict at the initial values (ties applied)."""
        return self.params_from_free(self.x0_free)

    @property
    def x0_free(self) -> np.ndarray:
        """Initial values of the free parameters."""
        lay = self._layout()
        return lay.x0_full[lay.free_full].copy()

    def params_from_free(self, x) -> dict[str, np.ndarray]:
        """Full block arrays from a free-parameter vector."""
        lay = self._layout()
        x = check_array(x, "x", shape=(len(lay.free_full),))
        if x.ndim != 1:
            raise ShapeError(f"x must have shape ({len(lay.free_full)},), got {x.shape}")
        return lay.split(lay.full_from_free(x))

    def free_from_params(self, params: Mapping[str, object]) -> np.ndarray:
        """Free-parameter vector from a ``params`` dict (missing blocks: x0)."""
        lay = self._layout()
        full = lay.x0_full.copy()
        for name, val in params.items():
            b = self._block(name)
            v = check_array(val, f"params['{name}']")
            if v.size != b.size:
                raise ShapeError(f"params['{name}'] must have shape {b.shape}, got {v.shape}")
            full[b.offset:b.offset + b.size] = v.reshape(-1)
        return full[lay.free_full].copy()

    def residuals_at(self, params: Mapping[str, object] | None = None, *, weighted: bool = False) -> np.ndarray:
        """Stacked residuals ``(m,)`` at ``params`` (default: initial values).

        ``weighted=True`` divides by ``sigma``.
        """
        ev = self.evaluator()
        x = self.x0_free if params is None else self.free_from_params(params)
        f = ev.weighted(x)
        return f if weighted else f * ev.sigma

    def jacobian_at(self, params: Mapping[str, object] | None = None, *, jac: str | None = None,
                    weighted: bool = True, sparse: bool = False):
        """Jacobian ``(m, n_free)`` of the (weighted) residuals w.r.t. the free
        parameters, e.g. to compute a Cramér–Rao bound at the true values."""
        ev = self.evaluator(jac=jac, sparse=sparse)
        x = self.x0_free if params is None else self.free_from_params(params)
        J = ev.jacobian(x)
        if weighted:
            return J
        return (sp.diags_array(ev.sigma) @ J) if sp.issparse(J) else J * ev.sigma[:, None]

    def check_jacobian(self, params: Mapping[str, object] | None = None, *, method: str = "3-point"
                       ) -> "JacobianCheck":
        """Compare the analytic Jacobian with finite differences at ``params``.

        Returns the largest absolute difference (in weighted-residual units per
        unit parameter), the same relative to the largest entry of its column,
        and where it occurs. Central differences are accurate to about 1e-8
        relative, so a relative error above ~1e-5 is a bug in the Jacobian.
        """
        Ja = np.asarray(self.jacobian_at(params, jac="analytic"))
        Jn = np.asarray(self.jacobian_at(params, jac=method))
        diff = np.abs(Ja - Jn)
        col = np.maximum(np.max(np.abs(Jn), axis=0), np.finfo(float).tiny)
        rel = diff / col
        i, j = np.unravel_index(int(np.argmax(rel)), rel.shape) if rel.size else (0, 0)
        return JacobianCheck(float(diff.max(initial=0.0)), float(rel.max(initial=0.0)), int(i),
                             self.free_labels[j] if rel.size else "")

    # --------------------------------------------------------------- compile
    def _layout(self) -> _Layout:
        return _Layout(self)

    def evaluator(self, *, jac: str | None = None, sparse: bool = False, diff_step=None) -> Evaluator:
        """Compile the problem into an :class:`Evaluator` on the free vector.

        Evaluates the residuals once at the initial values to learn and check
        their size, shape and noise weights.
        """
        if not self._blocks:
            raise InputError("the problem has no parameter blocks (use add_block)")
        if not self._terms:
            raise InputError("the problem has no residuals (pass residuals= or use add_residuals)")
        for t in self._terms:
            for b in t.blocks or ():
                self._block(b)
        return Evaluator(self._layout(), list(self._terms), jac=jac, sparse=sparse, diff_step=diff_step)


LeastSquaresProblem = Problem


@dataclass(frozen=True)
class JacobianCheck:
    """Result of :meth:`Problem.check_jacobian`.

    Attributes
    ----------
    max_abs_error : float
    max_rel_error : float
        Relative to the largest finite-difference entry of the same column.
    worst_row : int
        Residual row of the largest relative error.
    worst_label : str
        Parameter (column) of the largest relative error.
    """

    max_abs_error: float
    max_rel_error: float
    worst_row: int
    worst_label: str
