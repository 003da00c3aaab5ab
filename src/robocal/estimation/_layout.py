"""Mapping between all parameter elements and the solver's free vector."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from robocal.errors import InputError

__all__: list[str] = []


class _Layout:
    """Map between the full element vector and the free vector.

    ``full = M @ x_free + c``: ``M`` (N x n_free) picks free elements and adds
    tied ones with their factor; ``c`` holds the fixed values (and factor times
    a fixed root for elements tied to a fixed element).
    """

    def __init__(self, problem):
        blocks = list(problem._blocks.values())
        self.blocks = blocks
        self.labels = problem.labels
        n = len(self.labels)
        self.n_full = n
        self.x0_full = np.concatenate([b.x0 for b in blocks]) if blocks else np.zeros(0)
        fixed = np.concatenate([b.fixed for b in blocks]) if blocks else np.zeros(0, bool)
        lo = np.concatenate([b.lower for b in blocks]) if blocks else np.zeros(0)
        hi = np.concatenate([b.upper for b in blocks]) if blocks else np.zeros(0)
        idx = problem._label_index
        tied_full = {idx[t] for t in problem._ties}
        for t in problem._ties:
            k = idx[t]
            if fixed[k]:
                raise InputError(f"'{t}' is both fixed and tied; use one or the other")
        if tied_full or fixed.any():
            self.free_full = np.array([k for k in range(n) if not fixed[k] and k not in tied_full], dtype=int)
        else:                                       # the common case, without a Python loop over elements
            self.free_full = np.arange(n)
        free_pos = {k: i for i, k in enumerate(self.free_full.tolist())}
        rows = list(self.free_full)
        cols = list(range(len(self.free_full)))
        vals = [1.0] * len(self.free_full)
        self.c = np.where(fixed, self.x0_full, 0.0)
        self.tied: dict[int, tuple[int, float]] = {}
        for t in problem._ties:
            root, factor = t, 1.0
            while root in problem._ties:
                src, f = problem._ties[root]
                factor *= f
                root = src
            kt, kr = idx[t], idx[root]
            self.tied[kt] = (kr, factor)
            if fixed[kr]:
                self.c[kt] = factor * self.x0_full[kr]
            else:
                rows.append(kt)
                cols.append(free_pos[kr])
                vals.append(factor)
        self._M_triplets = (vals, rows, cols)
        self._M = None
        # the same map as index arrays: the solver calls full_from_free at every evaluation, and a sparse
        # product costs ~0.15 ms a call, more than a small problem's residuals
        self._tied_to = np.array([k for k in self.tied if self.tied[k][0] in free_pos], dtype=int)
        self._tied_from = np.array([free_pos[self.tied[k][0]] for k in self._tied_to], dtype=int)
        self._tied_factor = np.array([self.tied[k][1] for k in self._tied_to], dtype=float)
        self.free_pos = free_pos
        self._all_free = len(self.free_full) == n and not self.tied
        self.lower = lo[self.free_full]
        self.upper = hi[self.free_full]
        if all(b.scale is None for b in blocks):
            self.scale = None
        else:
            scales = [b.scale if b.scale is not None else np.full(b.size, np.nan) for b in blocks]
            sc = np.concatenate(scales)[self.free_full]
            self.scale = None if np.all(np.isnan(sc)) else np.where(np.isnan(sc), 1.0, sc)
        self.units = {lab: u for b in blocks for lab, u in zip(b.labels, b.units)}

    @property
    def free_labels(self) -> list[str]:
        return [self.labels[k] for k in self.free_full]

    @property
    def M(self):
        """``full = M @ x_free + c`` as a sparse (N, n_free) matrix (built on first use)."""
        if self._M is None:
            vals, rows, cols = self._M_triplets
            self._M = sp.csc_array((vals, (rows, cols)), shape=(self.n_full, len(self.free_full)))
        return self._M

    def full_from_free(self, x: np.ndarray) -> np.ndarray:
        if self._all_free:                          # nothing fixed or tied: the free vector is the full one
            return np.array(x, dtype=float)
        x = np.asarray(x, dtype=float)
        full = self.c.copy()
        full[self.free_full] = x
        if self._tied_to.size:
            full[self._tied_to] += self._tied_factor * x[self._tied_from]
        return full

    def split(self, full: np.ndarray) -> dict[str, np.ndarray]:
        return {b.name: full[b.offset:b.offset + b.size].reshape(b.shape).copy() for b in self.blocks}

    def fold_columns(self, J_full):
        """Jacobian over all elements -> Jacobian over the free vector."""
        if sp.issparse(J_full):
            return sp.csr_array(sp.csr_array(J_full) @ self.M)
        J = J_full[:, self.free_full]
        for kt, (kr, factor) in self.tied.items():
            if kr in self.free_pos:
                J[:, self.free_pos[kr]] += factor * J_full[:, kt]
        return J
