"""Serial chains from Denavit-Hartenberg tables, standard or modified (Craig).

Per link ``i`` the table holds ``alpha, a, theta, d`` and the link transform is

* modified (Craig, proximal): ``A_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)``
  -- row ``i`` stores Craig's ``alpha_{i-1}, a_{i-1}``, as seed 000's Table 1 does;
* standard (distal): ``A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``.

A revolute joint adds its variable to ``theta``, a prismatic one to ``d``; the
table value is then the joint's zero offset, which calibration estimates along
with the other D-H values. A ``fixed`` row (seed 000's end-effector row ``E``)
has no variable. ``T_world_tool = T_base @ A_1 @ ... @ A_n @ T_tool``.

SciPy and OpenCV have no D-H kinematics, hence the hand-written products here;
they are closed-form and vectorised over any leading batch of configurations.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from robocal.errors import InputError, ShapeError
from robocal.kinematics._common import (
    ORIGIN_PARAM_SUFFIXES,
    check_limits,
    check_q,
    check_scalar,
    normalise_joint_type,
    optional_transform,
    transform_from_xyz_rpy,
    xyz_rpy_from_transform,
)
from robocal.validation import check_array

__all__ = ["DHLink", "DHChain"]

_CONVENTIONS = ("modified", "standard")
_EX = np.array([1.0, 0.0, 0.0])
_EZ = np.array([0.0, 0.0, 1.0])
_EYE34 = np.eye(4)[:3]
_EYE34_ZERO = (False, False, False, True)


def _combine(terms):
    """``sum(u * x)`` over (u, x, u_is_zero) terms, skipping zero ``u`` or ``x`` and unit ``x``: (3, 1) columns
    times scalars or (N,) arrays."""
    acc = None
    for u, x, zero in terms:
        if zero or (isinstance(x, float) and x == 0.0):
            continue
        t = u if (isinstance(x, float) and x == 1.0) else u * x
        acc = t if acc is None else acc + t
    return np.zeros((3, 1)) if acc is None else acc


def _z_motion(cols: list, c, s, d) -> list:
    """Columns of ``M @ Rz(theta) Tz(d)``, a D-H link's joint motion, for the columns ``[c0, c1, c2, c3]`` of
    the top rows of ``M``: ``[c c0 + s c1, c c1 - s c0, c2, c3 + d c2]`` (one formula for :meth:`DHChain._fk_columns`
    and :func:`._dh_frames.frame_columns`).

    ``c, s``: cos and sin of theta, (N,) arrays or floats; None: no rotation. ``d``: (N,) or a float; None: no
    translation. The callers skip the zero motions (Rz(0), Tz(0)): nothing is multiplied by 1 or added 0.
    """
    c0, c1, c2, c3 = cols
    if c is not None:
        c0, c1 = c0 * c + c1 * s, c1 * c - c0 * s
    return [c0, c1, c2, c3 if d is None else c3 + c2 * d]


def _times_constant(cols: list, K: list, want=(0, 1, 2, 3)) -> list:
    """Columns of ``M @ K`` for the columns of top rows ``M`` (each (3, N) or (3, 1)) and a constant ``K``
    (4, 4, as nested lists: no NumPy scalar per entry).

    Column k is ``sum_j M_j K[j, k]`` (plus ``M_3`` for k = 3: K's last row is (0, 0, 0, 1)); exact zeros
    and ones in K are not multiplied. Elementwise on contiguous columns, no BLAS call (a threaded BLAS on
    a tall (3 N, 4) product was 20x slower than one thread on a loaded machine).
    """
    out = []
    for k in range(4):
        if k not in want:
            out.append(None)
            continue
        acc = None
        for j in range(3):
            w = K[j][k]
            if w == 0.0:
                continue
            t = cols[j] if w == 1.0 else cols[j] * w
            acc = t if acc is None else acc + t
        if k == 3:
            acc = cols[3] if acc is None else acc + cols[3]
        out.append(np.zeros((3, 1)) if acc is None else acc)
    return out


def _constant_or_none(K):
    """``None`` for no constant (or the identity: not multiplied), else ``(K, K as lists, zero columns of
    its top rows)``."""
    if K is None or np.array_equal(K, np.eye(4)):
        return None
    return K, K.tolist(), tuple(not np.any(K[:3, k]) for k in range(4))


@dataclass(frozen=True)
class DHLink:
    """One row of a D-H table.

    Parameters
    ----------
    alpha, a, theta, d : float
        Twist (rad), length (m), angle (rad) and offset (m). In the modified
        convention ``alpha`` and ``a`` are Craig's ``alpha_{i-1}, a_{i-1}``.
        For a revolute joint ``theta`` is the joint's zero offset, for a
        prismatic joint ``d`` is.
    joint : {'revolute', 'prismatic', 'fixed'}
        Also accepted: ``'R'``, ``'P'``, ``'F'`` (any case).
    name : str, optional
        Joint name (default ``joint<i>``, 1-based).
    limits : (float, float), optional
        Lower and upper joint-variable limits (rad or m).
    """

    alpha: float
    a: float
    theta: float
    d: float
    joint: str = "revolute"
    name: str | None = None
    limits: tuple[float, float] | None = field(default=None)

    def __post_init__(self):
        for key in ("alpha", "a", "theta", "d"):
            object.__setattr__(self, key, check_scalar(getattr(self, key), f"DHLink.{key}"))
        kind = normalise_joint_type(self.joint, "DHLink.joint")
        if kind == "continuous":
            kind = "revolute"
        object.__setattr__(self, "joint", kind)
        object.__setattr__(self, "limits", check_limits(self.limits, "DHLink.limits"))
        if kind == "fixed" and self.limits is not None:
            raise InputError("DHLink.limits must be None for a fixed link")


def _dh_matrices(alpha: float, a: float, theta, d, convention: str) -> np.ndarray:
    """Closed-form link transforms, ``theta`` and ``d`` broadcast over (...)."""
    theta, d = np.broadcast_arrays(np.asarray(theta, float), np.asarray(d, float))
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    A = np.zeros(theta.shape + (4, 4))
    if convention == "modified":
        A[..., 0, 0] = ct
        A[..., 0, 1] = -st
        A[..., 0, 3] = a
        A[..., 1, 0] = st * ca
        A[..., 1, 1] = ct * ca
        A[..., 1, 2] = -sa
        A[..., 1, 3] = -sa * d
        A[..., 2, 0] = st * sa
        A[..., 2, 1] = ct * sa
        A[..., 2, 2] = ca
        A[..., 2, 3] = ca * d
    else:
        A[..., 0, 0] = ct
        A[..., 0, 1] = -st * ca
        A[..., 0, 2] = st * sa
        A[..., 0, 3] = a * ct
        A[..., 1, 0] = st
        A[..., 1, 1] = ct * ca
        A[..., 1, 2] = -ct * sa
        A[..., 1, 3] = a * st
        A[..., 2, 1] = sa
        A[..., 2, 2] = ca
        A[..., 2, 3] = d
    A[..., 3, 3] = 1.0
    return A


class DHChain:
    """A serial chain from a D-H table (see module docstring for the conventions).

    Parameters
    ----------
    links : sequence of DHLink
    convention : {'modified', 'standard'}, keyword-only
        D-H convention of the table (default ``'modified'``, Craig's proximal
        form); keyword-only so a call reads ``DHChain(links, convention="standard")``.
    T_base : array_like, shape (4, 4), optional, keyword-only
        ``T_world_0``: pose of the chain's frame 0 in the world (base) frame.
    T_tool : array_like, shape (4, 4), optional, keyword-only
        ``T_n_tool``: tool frame in the last link frame.
    base_params, tool_params : bool, keyword-only
        Add ``T_base`` / ``T_tool`` as six calibration parameters each
        (``x, y, z, roll, pitch, yaw`` with URDF's ``Trans(xyz) Rz Ry Rx``)
        to :attr:`params`.

    Notes
    -----
    Joint values ``q`` have shape ``(..., dof)``: one value per non-fixed
    link, in table order. Every method is vectorised over the leading axes.

    References
    ----------
    Seed 000, Table 1 and eq. (5) (modified convention); J. J. Craig,
    *Introduction to Robotics*, ch. 3.
    """

    def __init__(
        self,
        links: Sequence[DHLink],
        *,
        convention: str = "modified",
        T_base=None,
        T_tool=None,
        base_params: bool = False,
        tool_params: bool = False,
    ):
        links = tuple(links)
        if not all(isinstance(lk, DHLink) for lk in links):
            raise InputError("links must be DHLink objects (use DHChain.from_table for a numeric table)")
        if not links:
            raise InputError("a DHChain needs at least one link, got 0")
        if convention not in _CONVENTIONS:
            raise InputError(f"convention must be 'modified' or 'standard', got {convention!r}")
        self._links = links
        self._convention = convention
        self._T_base = optional_transform(T_base, "T_base")
        self._T_tool = optional_transform(T_tool, "T_tool")
        self._base_params = bool(base_params)
        self._tool_params = bool(tool_params)
        self._joint_links = tuple(i for i, lk in enumerate(links) if lk.joint != "fixed")
        self._plan = None  # fk's folded constants, built on the first call (_fk_plan)
        names = self.joint_names
        if len(set(names)) != len(names):
            raise InputError(f"joint names must be unique, got {list(names)}")

    @classmethod
    def from_table(
        cls,
        rows,
        *,
        convention: str = "modified",
        joint_types: str | Sequence[str] | None = None,
        names: Sequence[str] | None = None,
        limits: Sequence | None = None,
        T_base=None,
        T_tool=None,
        base_params: bool = False,
        tool_params: bool = False,
    ) -> "DHChain":
        """Build a chain from a numeric table.

        Parameters
        ----------
        rows : array_like, shape (n, 4)
            ``[alpha, a, theta, d]`` per link (rad, m).
        joint_types : str or sequence of str, optional
            One type per row, e.g. ``"RRF"`` or ``["revolute", "prismatic"]``;
            all revolute by default.
        names, limits : sequences of length n, optional
            Per-row joint names and ``(lower, upper)`` limits (``None`` for none).
        """
        table = check_array(rows, "rows", shape=("n", 4))
        if table.ndim != 2:
            raise ShapeError(f"rows must have shape (n, 4), got {table.shape}")
        n = table.shape[0]
        types = ["revolute"] * n if joint_types is None else list(joint_types)
        for label, seq in (("joint_types", types), ("names", names), ("limits", limits)):
            if seq is not None and len(seq) != n:
                raise ShapeError(f"{label} must have {n} entries (one per row), got {len(seq)}")
        links = [
            DHLink(*table[i], joint=types[i], name=None if names is None else names[i],
                   limits=None if limits is None else limits[i])
            for i in range(n)
        ]
        return cls(links, convention=convention, T_base=T_base, T_tool=T_tool, base_params=base_params,
                   tool_params=tool_params)

    # -- description -------------------------------------------------------------------
    @property
    def links(self) -> tuple[DHLink, ...]:
        return self._links

    @property
    def convention(self) -> str:
        return self._convention

    @property
    def T_base(self) -> np.ndarray:
        """``T_world_0`` (4, 4); identity when not given."""
        return np.eye(4) if self._T_base is None else self._T_base.copy()

    @property
    def T_tool(self) -> np.ndarray:
        """``T_n_tool`` (4, 4); identity when not given."""
        return np.eye(4) if self._T_tool is None else self._T_tool.copy()

    @property
    def n_links(self) -> int:
        return len(self._links)

    @property
    def dof(self) -> int:
        """Number of joint variables (non-fixed links)."""
        return len(self._joint_links)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(self._links[i].name or f"joint{i + 1}" for i in self._joint_links)

    @property
    def joint_types(self) -> tuple[str, ...]:
        return tuple(self._links[i].joint for i in self._joint_links)

    @property
    def table(self) -> np.ndarray:
        """``[alpha, a, theta, d]`` per link, shape (n_links, 4)."""
        return np.array([[lk.alpha, lk.a, lk.theta, lk.d] for lk in self._links])

    @property
    def joint_offsets(self) -> np.ndarray:
        """Zero offset of each joint (theta for revolute, d for prismatic), shape (dof,)."""
        return np.array([self._links[i].theta if self._links[i].joint == "revolute" else self._links[i].d
                         for i in self._joint_links])

    @property
    def joint_offset_names(self) -> tuple[str, ...]:
        """Names in :attr:`param_names` of the joint zero offsets, in joint order."""
        return tuple(f"{'theta' if self._links[i].joint == 'revolute' else 'd'}_{i + 1}" for i in self._joint_links)

    @property
    def param_names(self) -> tuple[str, ...]:
        """``alpha_i, a_i, theta_i, d_i`` per table row ``i`` (1-based), then base/tool.

        Names index the table row, so in the modified convention ``alpha_1``
        is Craig's ``alpha_0``.
        """
        names = [f"{p}_{i + 1}" for i in range(self.n_links) for p in ("alpha", "a", "theta", "d")]
        if self._base_params:
            names += [f"base_{s}" for s in ORIGIN_PARAM_SUFFIXES]
        if self._tool_params:
            names += [f"tool_{s}" for s in ORIGIN_PARAM_SUFFIXES]
        return tuple(names)

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    @property
    def params(self) -> np.ndarray:
        """Calibration parameter vector in :attr:`param_names` order (rad, m)."""
        parts = [self.table.reshape(-1)]
        if self._base_params:
            parts.append(xyz_rpy_from_transform(self.T_base))
        if self._tool_params:
            parts.append(xyz_rpy_from_transform(self.T_tool))
        return np.concatenate(parts)

    def with_params(self, params) -> "DHChain":
        """A copy of the chain with the parameter vector replaced (same names, limits, flags)."""
        p = check_array(params, "params", shape=(self.n_params,))
        if p.ndim != 1:
            raise ShapeError(f"params must have shape ({self.n_params},), got {p.shape}")
        m = 4 * self.n_links
        links = [
            DHLink(*p[4 * i: 4 * i + 4], joint=lk.joint, name=lk.name, limits=lk.limits)
            for i, lk in enumerate(self._links)
        ]
        T_base, T_tool = self._T_base, self._T_tool
        if self._base_params:
            T_base = transform_from_xyz_rpy(p[m:m + 3], p[m + 3:m + 6])
            m += 6
        if self._tool_params:
            T_tool = transform_from_xyz_rpy(p[m:m + 3], p[m + 3:m + 6])
        return DHChain(links, convention=self._convention, T_base=T_base, T_tool=T_tool,
                       base_params=self._base_params, tool_params=self._tool_params)

    def __repr__(self) -> str:
        return f"DHChain({self.n_links} links, dof={self.dof}, convention={self._convention!r})"

    # -- kinematics -----------------------------------------------------------------------
    def check_q(self, q) -> np.ndarray:
        """Validate joint values: finite, shape ``(..., dof)``; returns float64."""
        return check_q(q, self.joint_names)

    def within_limits(self, q) -> np.ndarray:
        """Boolean (...): every joint value within its limits (joints without limits pass)."""
        q = self.check_q(q)
        ok = np.ones(q.shape[:-1], dtype=bool)
        for j, i in enumerate(self._joint_links):
            lim = self._links[i].limits
            if lim is not None:
                ok &= (q[..., j] >= lim[0]) & (q[..., j] <= lim[1])
        return ok

    def link_transform(self, index: int, q=0.0) -> np.ndarray:
        """``A_(index+1)``: the transform of link ``index`` (0-based), shape (..., 4, 4).

        ``q`` is that link's own joint value (rad or m; ignored for a fixed
        link), broadcast over leading dimensions; negative ``index`` counts
        from the tool end. Row ``index`` of the table in this chain's
        convention (seed 000 eq. 5 for the modified one).
        """
        if not isinstance(index, (int, np.integer)) or not -self.n_links <= index < self.n_links:
            raise InputError(f"link index must be an integer in [-{self.n_links}, {self.n_links}), got {index!r}")
        lk = self._links[index]
        q = np.asarray(check_array(q, "q"), dtype=float)
        theta, d = lk.theta, lk.d
        if lk.joint == "revolute":
            theta = theta + q
        elif lk.joint == "prismatic":
            d = d + q
        return _dh_matrices(lk.alpha, lk.a, theta, d, self._convention)

    def fk_all(self, q) -> np.ndarray:
        """All link frames ``T_world_i``, i = 0..n_links, shape (..., n_links + 1, 4, 4).

        Frame 0 is ``T_base``; frame ``i`` is ``T_base @ A_1 @ ... @ A_i``.
        ``T_tool`` is not applied (``fk(q) == fk_all(q)[..., -1, :, :] @ T_tool``). Computed on column
        arrays, each link's motion in closed form (:mod:`._dh_frames`), not as 4x4 stacks.
        """
        from robocal.kinematics._dh_frames import frame_columns, stack_frames

        q = self.check_q(q)
        n = int(np.prod(q.shape[:-1], dtype=np.int64))
        frames = frame_columns(self, q.reshape(n, q.shape[-1]) if q.shape[-1] else None)
        return stack_frames(frames, n).reshape(q.shape[:-1] + (self.n_links + 1, 4, 4))

    def fk(self, q) -> np.ndarray:
        """Tool pose ``T_world_tool`` (..., 4, 4) for joint values ``q`` (..., dof)."""
        return self._fk_unchecked(self.check_q(q))

    def _fk_unchecked(self, q: np.ndarray) -> np.ndarray:
        """:meth:`fk` for ``q`` already validated (float64, finite, (..., dof))."""
        cols = self._fk_columns(q)
        out = np.empty(q.shape[:-1] + (4, 4))
        flat = out.reshape(-1, 4, 4)
        for k in range(4):
            flat[:, :3, k] = cols[k].T
        flat[:, 3, :] = (0.0, 0.0, 0.0, 1.0)
        return out

    def _fk_plan(self):
        """Per-chain constants of :meth:`_fk_columns`, built once: the constant factors between joint motions.

        Each joint link splits into a constant part and its motion ``Z(theta, d) = Rz(theta) Tz(d)``:
        modified ``A = [Rx(alpha) Tx(a)] Z``, standard ``A = Z [Tx(a) Rx(alpha)]``. Constants between
        two motions (base, fixed links, those parts, tool) are multiplied once here, so a call multiplies
        the batch only by one 4x4 constant per joint and applies ``Z`` to two columns in closed form.
        """
        if self._plan is not None:
            return self._plan
        K = self._T_base
        steps = []
        for i, lk in enumerate(self._links):
            if lk.joint == "fixed":
                A = _dh_matrices(lk.alpha, lk.a, lk.theta, lk.d, self._convention)
                K = A if K is None else K @ A
                continue
            C = _dh_matrices(lk.alpha, lk.a, 0.0, 0.0, self._convention)
            if self._convention == "modified":
                K = C if K is None else K @ C
            steps.append((_constant_or_none(K), len(steps), i))
            K = C if self._convention == "standard" else None
        if self._T_tool is not None:
            K = self._T_tool if K is None else K @ self._T_tool
        # entries: (K, K as lists, zero columns) or None; K is the constant before the motion of link i
        self._plan = (tuple(steps), _constant_or_none(K))
        return self._plan

    def _fk_columns(self, q: np.ndarray, want=(0, 1, 2, 3)) -> list:
        """The four columns of the top three rows of :meth:`fk`, each (3, N) or a constant (3, 1).

        ``q`` is validated, (..., dof), flattened to N configurations. ``want``: the columns the caller
        reads (the others of the last constant product are skipped, None). Same product as
        ``T_base @ A_1 @ ... @ A_n @ T_tool`` with the constants folded (:meth:`_fk_plan`) and each motion
        applied in closed form, ``[c0, c1, c2, c3] @ Z(theta, d) = [c c0 + s c1, c c1 - s c0, c2, c3 + d c2]``,
        on contiguous columns: a few elementwise terms per joint instead of a (..., 4, 4) stack per link
        and batched 4x4 products (issue 16); zero and unit factors are not multiplied. Equal to the
        product to round-off.
        """
        steps, K_end = self._fk_plan()
        qf = q.reshape(-1, q.shape[-1]) if q.shape[-1] else None  # None: no joint (the loop does not run)
        cols = None
        for K, j, i in steps:
            lk = self._links[i]
            revolute = lk.joint == "revolute"
            theta, d = (qf[:, j] + lk.theta, lk.d) if revolute else (lk.theta, qf[:, j] + lk.d)
            c, s = np.cos(theta), np.sin(theta)
            if cols is None:  # first motion: the constant before it times Z
                B, zero = (_EYE34, _EYE34_ZERO) if K is None else (K[0][:3], K[2])
                u0, u1, u2, u3 = (B[:, k:k + 1] for k in range(4))
                cols = [_combine(((u0, c, zero[0]), (u1, s, zero[1]))),
                        _combine(((u1, c, zero[1]), (-u0, s, zero[0]))), u2,
                        _combine(((u3, 1.0, zero[3]), (u2, d, zero[2])))]
                continue
            if K is not None:
                cols = _times_constant(cols, K[1])
            cols = _z_motion(cols, c, s, None if revolute and lk.d == 0.0 else d)  # Tz(0) moves nothing
        if cols is None:  # no joint: a constant pose
            B = _EYE34 if K_end is None else K_end[0][:3]
            return [B[:, k:k + 1] for k in range(4)]
        return cols if K_end is None else _times_constant(cols, K_end[1], want)

    def _screws(self, q, params: bool):
        """Tool origin (3, N), the batch size N and the screws (frame columns, local direction, local point,
        revolute) of the joints (``params=False``) or of :attr:`params` (:mod:`._dh_frames`)."""
        from robocal.kinematics._dh_frames import frame_columns, origin_local_screws, tool_origin

        q = self.check_q(q)
        n = int(np.prod(q.shape[:-1], dtype=np.int64))
        frames = frame_columns(self, q.reshape(n, q.shape[-1]) if q.shape[-1] else None)
        zero, modified = np.zeros(3), self._convention == "modified"
        screws = []
        for i, lk in enumerate(self._links):
            # modified: alpha, a about/along x of frame i-1, theta, d about/along z of frame i; standard: swapped
            fx, fz = (frames[i], frames[i + 1]) if modified else (frames[i + 1], frames[i])
            link = [(fx, _EX, zero, True), (fx, _EX, zero, False), (fz, _EZ, zero, True), (fz, _EZ, zero, False)]
            if params:
                screws += link
            elif lk.joint != "fixed":
                screws.append(link[2] if lk.joint == "revolute" else link[3])
        if params and self._base_params:
            base = [np.eye(4)[:3, k:k + 1] for k in range(4)]
            screws += [(base, v, r, rev) for v, r, rev in origin_local_screws(self.T_base)]
        if params and self._tool_params:
            screws += [(frames[-1], v, r, rev) for v, r, rev in origin_local_screws(self.T_tool)]
        return tool_origin(self, frames[-1]), n, q.shape[:-1], screws

    def jacobian(self, q) -> np.ndarray:
        """Geometric Jacobian of the tool origin in the world frame, shape (..., 6, dof).

        Rows ``[v; w]``: ``v = d t_world_tool / dq``, ``w`` with
        ``dR_world_tool/dq_j @ R^T = [w_j]_x``, both in the world (base) frame.
        """
        from robocal.kinematics._dh_frames import twist_columns

        p, n, batch, screws = self._screws(q, params=False)
        return twist_columns(screws, p, n).reshape(batch + (6, len(screws)))

    def param_jacobian(self, q) -> np.ndarray:
        """Derivative of the tool pose w.r.t. :attr:`params`, shape (..., 6, n_params).

        Each column is the world-frame twist ``[d t; delta rotation]`` of
        ``T_world_tool`` (same convention as :meth:`jacobian`). Exact
        (analytic), for least-squares calibration of the table, base and tool.
        """
        from robocal.kinematics._dh_frames import twist_columns

        p, n, batch, screws = self._screws(q, params=True)
        return twist_columns(screws, p, n).reshape(batch + (6, len(screws)))

    # -- conversion -------------------------------------------------------------------------
    def to_tree(self, *, name: str = "dh_chain"):
        """The same chain as a :class:`~robocal.kinematics.KinematicTree`.

        Links: ``base`` (world) -> ``link0`` (via fixed joint ``base_joint`` =
        ``T_base``) -> ``link1`` ... ``link<n>`` (the D-H frames) -> ``tool``
        (fixed joint ``tool_joint`` = ``T_tool``). Joint axes are z; each
        joint's D-H zero offset becomes the tree joint's ``offset``. The
        standard convention needs one extra fixed joint ``<joint>_fixed`` per
        link (its constant part comes after the motion).
        """
        from robocal.kinematics._joint import Joint
        from robocal.kinematics._tree import KinematicTree

        joints = [Joint("base_joint", "base", "link0", self.T_base, type="fixed")]
        for i, lk in enumerate(self._links):
            parent, child = f"link{i}", f"link{i + 1}"
            jname = lk.name or f"joint{i + 1}"
            # The table value of the joint variable becomes the tree joint's offset.
            th, d, off = {
                "revolute": (0.0, lk.d, lk.theta),
                "prismatic": (lk.theta, 0.0, lk.d),
                "fixed": (lk.theta, lk.d, 0.0),
            }[lk.joint]
            if self._convention == "modified":
                origin = _dh_matrices(lk.alpha, lk.a, th, d, "modified")
                joints.append(Joint(jname, parent, child, origin, _EZ, lk.joint, lk.limits, off))
                continue
            if lk.joint == "fixed":
                joints.append(Joint(jname, parent, child, _dh_matrices(lk.alpha, lk.a, lk.theta, lk.d, "standard"),
                                    _EZ, "fixed"))
                continue
            # Standard: Rz(theta + q) Tz(d + q) first, then the constant Tx(a) Rx(alpha).
            mid = f"{jname}_frame"
            origin = _dh_matrices(0.0, 0.0, th, d, "standard")
            joints.append(Joint(jname, parent, mid, origin, _EZ, lk.joint, lk.limits, off))
            joints.append(Joint(f"{jname}_fixed", mid, child, _dh_matrices(lk.alpha, lk.a, 0.0, 0.0, "standard"),
                                _EZ, "fixed"))
        joints.append(Joint("tool_joint", f"link{self.n_links}", "tool", self.T_tool, type="fixed"))
        return KinematicTree(joints, name=name)
