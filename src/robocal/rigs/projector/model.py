"""Kinematics of a ceiling pan-tilt laser projector (seed 000, §2.1).

Frames
------
``{W}``  world frame fixed to the floor, floor plane ``z_W = 0``.
``{0}``  projector base frame (D-H frame 0); the floor is the plane ``z_0 = -H``.
``{E}``  laser frame; the beam leaves along ``+z_E``.

``^0P = R_0_W ^WP + t_0_W`` (seed eq. 1). Lengths in metres, angles in radians.

The D-H table (seed Table 1) is in the **modified (Craig)** convention::

    link   alpha    a   theta               d
    1      pi       0   -pi/2 + theta1      d1     (R)
    2      -pi/2    0   theta2              0      (R)
    E      pi/2     0   0                   d2     (fixed)

It reproduces seed eq. (5) for ``^0T_E``; :attr:`ProjectorModel.chain` builds it
with :class:`robocal.kinematics.DHChain`. Joint zero offsets ``o1, o2`` are
added to the commanded angles: the mechanism sits at ``theta + offsets``.

Singular set (seed, after eq. 10): ``theta2 = 0`` (beam at the nadir, the pan
angle is undefined and the inverse Jacobian does not exist) and
``theta2 = pi/2`` (beam horizontal, the spot is at infinity). Functions here
refuse with :class:`~robocal.errors.SingularConfigurationError` or warn with
:class:`NearSingularityWarning`; they never return inf or NaN. The singular set's tolerances, warning and
reach error are defined in :mod:`.singular`, the inverse kinematics (eq. 8) and the reach checks in
:mod:`.ik` (methods of :class:`ProjectorModel` all the same); every name is importable from here.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from robocal.errors import InputError, SingularConfigurationError
from robocal.geometry import wrap_angle  # re-exported: part of this module's API
from robocal.kinematics import DHChain
from robocal.kinematics._common import finite_fast as _finite, lo_hi as _lo_hi
from robocal.rigs.projector.ik import InverseKinematics
from robocal.rigs.projector.singular import (  # re-exported: part of this module's API
    F8 as _F8,
    HORIZON_TOL,
    NADIR_TOL,
    NEAR_NADIR_WARN,
    NearSingularityWarning,
    UnreachablePointError,
    at_index as _at,
    first_index as _first,
    frozen_scalar as _scalar,
)
from robocal.validation import check_array, check_rotation_matrix

__all__ = [
    "ProjectorModel",
    "NearSingularityWarning",
    "UnreachablePointError",
    "wrap_angle",
    "NADIR_TOL",
    "HORIZON_TOL",
    "NEAR_NADIR_WARN",
]


@dataclass(frozen=True)
class ProjectorModel(InverseKinematics):
    """A ceiling pan-tilt laser projector and (optionally) its pose in the world.

    Parameters
    ----------
    H : float
        Distance (m) from the origin of ``{0}`` down to the floor (the floor is
        ``z_0 = -H``; seed: "ceiling height").
    d1 : float
        D-H offset (m) of link 1: the intersection of the pan and tilt axes is
        at ``(0, 0, -d1)`` in ``{0}``. Only ``H - d1`` affects the spot.
    d2 : float
        D-H offset (m) of the laser frame along the beam (affects only the beam
        range ``g``, seed eq. 7).
    offsets : (float, float)
        Joint zero offsets (rad): the mechanism is at ``theta + offsets``.
    tilt_limit : float
        Largest usable tilt (rad, < pi/2): the reachable floor is the disc of
        radius ``(H - d1) tan(tilt_limit)`` around the nadir.
    rate_limits : (float, float)
        Joint speed limits (rad/s) used by path planning.
    R_0_W, t_0_W : array_like, optional
        Extrinsics ``^0P = R_0_W ^WP + t_0_W`` (seed eq. 1). Default: ``{W}``
        directly below ``{0}``: ``R = I``, ``t = (0, 0, -H)``.
    name : str
        Label used in reports and multi-projector paths.
    pan_range : (float, float), optional
        Mechanical range (rad) of the *unwrapped* pan command, e.g. ``(-3 pi/2,
        3 pi/2)`` for a head with a cable stop; None: endless pan. Used by path
        planning (a path circling the nadir winds the pan up).
    tilt_min : float
        Lowest *actual* tilt (rad, with its offset) the tilt joint reaches, in
        ``[-tilt_limit, 0]``. 0 (default): the seed's eq. (8) branch only
        (tilt >= 0). Negative: the other IK branch ``(theta1 + pi, -theta2)``
        (same spot, seed eq. 6 is invariant under it) is usable where
        ``-tilt_min`` allows; path planning uses it to follow a line through the
        nadir with constant pan (the tilt goes through zero) instead of flipping
        the pan by pi there.

    References
    ----------
    Seed 000, Table 1 and eqs. (1)-(10).
    """

    H: float
    d1: float = 0.0
    d2: float = 0.0
    offsets: tuple = (0.0, 0.0)
    tilt_limit: float = math.radians(75.0)
    rate_limits: tuple = (math.radians(90.0), math.radians(90.0))
    R_0_W: np.ndarray = field(default=None, repr=False)
    t_0_W: np.ndarray = field(default=None, repr=False)
    name: str = "projector"
    pan_range: tuple | None = None
    tilt_min: float = 0.0

    def __post_init__(self):
        for key in ("H", "d1", "d2", "tilt_limit", "tilt_min"):
            v = float(check_array(getattr(self, key), f"projector.{key}"))
            object.__setattr__(self, key, v)
        if not self.H > 0:
            raise InputError(f"projector.H must be > 0 (m), got {self.H!r}")
        if not self.H - self.d1 > 0:
            raise InputError(f"projector: H - d1 must be > 0 (the tilt axis is above the floor), got "
                             f"H = {self.H:g} m, d1 = {self.d1:g} m")
        if not 0.0 < self.tilt_limit < math.pi / 2:
            raise InputError(f"projector.tilt_limit must be in (0, 90) deg, got {math.degrees(self.tilt_limit):g} deg")
        if not -self.tilt_limit - 1e-12 <= self.tilt_min <= 0.0:
            raise InputError(f"projector.tilt_min must be in [-tilt_limit, 0] = "
                             f"[{-math.degrees(self.tilt_limit):g}, 0] deg, got {math.degrees(self.tilt_min):g} deg")
        off = check_array(self.offsets, "projector.offsets", shape=(2,))
        if off.ndim != 1:
            raise InputError(f"projector.offsets must have shape (2,), got {off.shape}")
        object.__setattr__(self, "offsets", (float(off[0]), float(off[1])))
        rl = check_array(self.rate_limits, "projector.rate_limits", shape=(2,))
        if rl.ndim != 1 or np.any(rl <= 0):
            raise InputError(f"projector.rate_limits must be two values > 0, got "
                             f"[{', '.join(f'{v:.4g}' for v in rl.ravel())}] rad/s = "
                             f"[{', '.join(f'{math.degrees(v):.4g}' for v in rl.ravel())}] deg/s")
        object.__setattr__(self, "rate_limits", (float(rl[0]), float(rl[1])))
        if self.pan_range is not None:
            pr = check_array(self.pan_range, "projector.pan_range", shape=(2,))
            if pr.ndim != 1 or not pr[1] - pr[0] > 0:
                raise InputError(f"projector.pan_range must be (min, max) with max > min, got "
                                 f"[{', '.join(f'{v:.4g}' for v in pr.ravel())}] rad = "
                                 f"[{', '.join(f'{math.degrees(v):.4g}' for v in pr.ravel())}] deg")
            object.__setattr__(self, "pan_range", (float(pr[0]), float(pr[1])))
        R = np.eye(3) if self.R_0_W is None else check_rotation_matrix(self.R_0_W, "projector.R_0_W")
        t = np.array([0.0, 0.0, -self.H]) if self.t_0_W is None else check_array(self.t_0_W, "projector.t_0_W",
                                                                                 shape=(3,))
        if R.shape != (3, 3) or t.shape != (3,):
            raise InputError(f"projector extrinsics must be R (3, 3) and t (3,), got {R.shape} and {t.shape}")
        R = np.array(R, dtype=float)
        t = np.array(t, dtype=float)
        R.setflags(write=False)
        t.setflags(write=False)
        object.__setattr__(self, "R_0_W", R)
        object.__setattr__(self, "t_0_W", t)

    # ------------------------------------------------------------ structure
    @property
    def h(self) -> float:
        """``H - d1`` (m): height of the tilt axis above the floor."""
        return self.H - self.d1

    @property
    def floor_radius(self) -> float:
        """Radius (m) of the reachable floor disc around the nadir."""
        return self.h * math.tan(self.tilt_limit)

    def with_(self, **changes) -> "ProjectorModel":
        """A copy with some fields replaced (``model.with_(H=3.0)``)."""
        return replace(self, **changes)

    @cached_property
    def chain(self) -> DHChain:
        """The modified-D-H chain of seed Table 1 (joint offsets in the ``theta`` column).

        Built once per model (the model is frozen): building it validates the table, which cost more
        than the forward kinematics of a few hundred angle pairs when it was rebuilt per call.
        """
        o1, o2 = self.offsets
        rows = [[np.pi, 0.0, -np.pi / 2 + o1, self.d1], [-np.pi / 2, 0.0, o2, 0.0], [np.pi / 2, 0.0, 0.0, self.d2]]
        return DHChain.from_table(rows, convention="modified", joint_types="RRF", names=["pan", "tilt", "laser"])

    @property
    def T_0_W(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.R_0_W
        T[:3, 3] = self.t_0_W
        return T

    @property
    def origin_world(self) -> np.ndarray:
        """Origin of ``{0}`` in ``{W}`` (m), ``-R^T t``."""
        return -self.R_0_W.T @ self.t_0_W

    @property
    def nadir_world(self) -> np.ndarray:
        """The floor point straight below the tilt axis, in ``{W}`` (m, shape (2,))."""
        return self.to_world(np.array([0.0, 0.0, -self.H]))[:2]

    # ---------------------------------------------------------- validation
    def _theta(self, theta) -> np.ndarray:
        if (type(theta) is np.ndarray and theta.dtype is _F8 and theta.ndim and theta.shape[-1] == 2
                and _finite(theta)):
            return theta  # a float64 array: O(1) checks and one reduction, not an isfinite mask (issue 16)
        return check_array(theta, "theta", shape=(2,))

    def _fast_theta(self, theta):
        """``(theta, a2)`` when ``theta`` needs no per-element check, else None (the caller then checks each).

        The common call: a float64 array, finite, every actual tilt ``a2 = theta2 + o2`` within
        +-``tilt_limit`` (no warning, the beam meets the floor). Decided by :func:`_finite` and the min and
        max of ``a2`` (argmin / argmax, see ``lo_hi``; a NaN fails every comparison). Issue 16.
        """
        if not (type(theta) is np.ndarray and theta.dtype is _F8 and theta.ndim and theta.shape[-1] == 2
                and theta.size):
            return None
        a2 = theta[..., 1] + self.offsets[1]
        lim = self.tilt_limit + 1e-12
        lo, hi = _lo_hi(a2)
        ok = (lo >= -lim and hi <= lim and _finite(theta[..., 0])
              and math.cos(lim) > HORIZON_TOL)  # a limit within 1e-9 of pi/2: the horizon check is needed too
        return (theta, a2) if ok else None

    def _checked_theta(self, theta, what: str) -> np.ndarray:
        """``theta`` validated with the per-element checks: raise at the horizon, warn beyond the tilt limit."""
        theta = self._theta(theta)
        a2 = theta[..., 1] + self.offsets[1]
        self._require_floor_hit(np.cos(a2), what, a2)
        self._warn_beyond_limit(a2, what)
        return theta

    def _angles(self, theta, what: str) -> np.ndarray:
        """Validated ``theta`` (..., 2): the fast decision, else the per-element checks."""
        fast = self._fast_theta(theta)
        return self._checked_theta(theta, what) if fast is None else fast[0]

    def _actual(self, theta: np.ndarray):
        return theta[..., 0] + self.offsets[0], theta[..., 1] + self.offsets[1]

    def _require_floor_hit(self, c2: np.ndarray, what: str, a2=None) -> None:
        bad = c2 <= HORIZON_TOL
        if np.any(bad):
            k = _first(bad)
            where = [f"first at index {k}"] if np.ndim(bad) else []
            if a2 is not None:
                where.append(f"theta2 + offset = {float(np.broadcast_to(a2, bad.shape)[k]):.6g} rad")
            where.append(f"cos(theta2) = {float(c2[k]):.3g}")
            raise SingularConfigurationError(
                f"{what}: tilt theta2 + offset reaches the horizon (theta2 = pi/2) or beyond, the beam never "
                f"meets the floor ({', '.join(where)}); angles are in rad: degrees passed as rad?")

    def _warn_beyond_limit(self, a2: np.ndarray, what: str) -> None:
        """Warn (NearSingularityWarning) where the actual tilt exceeds ``tilt_limit``.

        Between the tilt limit and the horizon the spot exists but runs off as ``h tan(theta2)``
        and its sensitivity to the tilt as ``h / cos^2(theta2)`` (seed eq. 9): 2.8e8 m and 2.8e16 m/rad
        at 1e-8 rad below pi/2 (h = 2.78 m). Refusing there would break callers that probe a margin, so it warns.
        """
        bad = np.abs(a2) > self.tilt_limit + 1e-12
        if np.any(bad):
            k = _first(bad)
            t = float(np.broadcast_to(a2, bad.shape)[k])
            warnings.warn(
                f"{what}: tilt theta2 + offset = {math.degrees(t):.6g} deg{_at(bad)} ({int(np.sum(bad))} "
                f"configuration(s)) is beyond the tilt limit {math.degrees(self.tilt_limit):g} deg, near the horizon "
                f"singularity: spot {self.h * abs(math.tan(t)):.4g} m from the nadir, d spot / d theta2 = "
                f"{self.h / math.cos(t) ** 2:.4g} m/rad", NearSingularityWarning, stacklevel=3)

    # ---------------------------------------------------------- kinematics
    def pose(self, theta) -> np.ndarray:
        """``^0T_E`` (..., 4, 4) from the D-H chain (seed eq. 5)."""
        return self.chain._fk_unchecked(self._theta(theta))  # theta checked: no second validation

    def spot(self, theta) -> np.ndarray:
        """Spot on the floor in ``{0}``, seed eq. (6): ``f(theta)``, shape (..., 3), m.

        ``f = [h s1 s2 / c2, h c1 s2 / c2, -H]`` with ``h = H - d1`` and the
        angles including the zero offsets.

        Raises
        ------
        SingularConfigurationError
            Where the beam is horizontal or points upwards (no floor hit).
        """
        o1, o2, lim, h, z = self._spot_constants
        t = theta
        if type(t) is np.ndarray and t.dtype is _F8 and t.ndim == 2 and t.shape[1] == 2 and t.size and lim:
            # The common call, (N, 2) float64 (issue 16). Every check in four argmin / argmax passes, no
            # per-element mask: every actual tilt within +-limit (its min and max; a NaN is their answer
            # and fails the comparison, so the range also covers NaN / inf), the pan finite (min > -inf,
            # max < inf). Profile at 100 points: a pass + its comparison ~0.3-0.5 us, the alternatives
            # more: `(abs(a2) <= lim).all()` ~2.5 us (`.all()` is a ufunc reduction), `isfinite(sum)` ~1.3 us
            # and a pan over 1e306 rad overflows the sum with a RuntimeWarning. Anything else: the checked
            # path below, whose messages name the element.
            a1 = np.add(t[:, 0], o1)  # o1, o2, h are 0-d arrays: a Python float operand costs ~0.25 us a call
            a2 = np.add(t[:, 1], o2)
            if a2[a2.argmin()] >= -lim and a2[a2.argmax()] <= lim and a1[a1.argmin()] > -math.inf \
                    and a1[a1.argmax()] < math.inf:
                rho = np.tan(a2, a2)  # in place: a2 is ours (positional out=: the keyword costs ~0.1 us)
                rho *= h  # h s2 / c2 as h tan(a2): one transcendental call instead of two (equal to round-off)
                out = np.empty((t.shape[0], 3))
                out.fill(z)  # z = -H; one contiguous fill is cheaper than a strided column write
                np.multiply(rho, np.sin(a1), out[:, 0])  # the products land in the output columns
                np.multiply(rho, np.cos(a1, a1), out[:, 1])
                return out
        elif type(t) is np.ndarray and t.dtype is _F8 and t.ndim and t.shape[-1] == 2 and t.size and lim:
            # other shapes ((2,), (..., 2)): the same decision through lo_hi over the flattened tilts
            a1, a2 = t[..., 0] + o1, t[..., 1] + o2
            lo, hi = _lo_hi(a2)
            if lo >= -lim and hi <= lim and _finite(a1):
                return self._spot_of(a1, a2, h, z)
        theta = self._checked_theta(theta, "spot")
        return self._spot_of(theta[..., 0] + o1, theta[..., 1] + o2, h, z)

    @staticmethod
    def _spot_of(a1, a2, h, z) -> np.ndarray:
        """Seed eq. (6) for checked actual angles ``a1, a2`` (any shape), (..., 3)."""
        rho = np.tan(a2)
        rho *= h
        out = np.empty(np.shape(a2) + (3,))
        out.fill(z)
        np.multiply(rho, np.sin(a1), out=out[..., 0])
        np.multiply(rho, np.cos(a1), out=out[..., 1])
        return out

    @cached_property
    def _spot_constants(self) -> tuple:
        """``(o1, o2, tilt limit + 1e-12 or 0.0, h, -H)`` for :meth:`spot`, once per (frozen) model.

        ``o1, o2, h`` as 0-d float64 arrays (the same IEEE operations as with floats, ~0.25 us less per
        NumPy call). Limit 0.0: within 1e-9 of the horizon, the fast path cannot decide (per-element checks).
        """
        lim = self.tilt_limit + 1e-12
        o1, o2, h = (_scalar(v) for v in (*self.offsets, self.H - self.d1))
        return o1, o2, lim if math.cos(lim) > HORIZON_TOL else 0.0, h, -self.H

    def spot_from_chain(self, theta) -> np.ndarray:
        """The spot as the intersection of the chain's beam ``z_E`` with ``z_0 = -H``.

        Independent of eq. (6) (used to check it); same result and errors as :meth:`spot`.
        """
        fast = self._fast_theta(theta)
        theta = self._theta(theta) if fast is None else fast[0]
        # columns z_E and p of ^0T_E, (3, N) each (theta checked above: no second validation)
        _, _, z, p = self.chain._fk_columns(theta, want=(2, 3))
        if fast is None:
            a2 = theta[..., 1] + self.offsets[1]
            self._require_floor_hit(-z[2].reshape(a2.shape), "spot", a2)  # the chain's own cos(theta2)
            self._warn_beyond_limit(a2, "spot")
        s = (-self.H - p[2]) / z[2]  # p may be a constant (3, 1) column (d2 = 0)
        out = np.empty(theta.shape[:-1] + (3,))
        flat = out.reshape(-1, 3).T  # (3, N) view: the products land in the output
        np.multiply(z, s, out=flat)
        flat += p
        return out

    def beam_range(self, theta) -> np.ndarray:
        """Distance (m) from the laser frame origin to the spot, seed eq. (7): ``h / c2 - d2``."""
        theta = self._angles(theta, "beam_range")
        a2 = theta[..., 1] + self.offsets[1]
        out = self.h / np.cos(a2)
        out -= self.d2
        return out

    # ----------------------------------------------------------- velocity
    def spot_jacobian(self, theta) -> np.ndarray:
        """``d f / d theta``, seed eq. (9), shape (..., 3, 2) (third row zero), m/rad.

        ``J = h / c2 [[c1 s2, s1 / c2], [-s1 s2, c1 / c2], [0, 0]]``.
        """
        theta = self._angles(theta, "spot_jacobian")
        a1, a2 = self._actual(theta)
        c2 = np.cos(a2)
        s1, c1, s2 = np.sin(a1), np.cos(a1), np.sin(a2)
        k = self.h / c2
        J = np.zeros(theta.shape[:-1] + (3, 2))
        J[..., 0, 0] = k * c1 * s2
        J[..., 0, 1] = k * s1 / c2
        J[..., 1, 0] = -k * s1 * s2
        J[..., 1, 1] = k * c1 / c2
        return J

    def joint_rates(self, theta, spot_velocity, *, nadir_tol: float = 1e-6,
                    warn_tol: float = NEAR_NADIR_WARN) -> np.ndarray:
        """Joint rates (rad/s) that move the spot with a given floor velocity (inverse of eq. 9).

        ``theta1' = c2 (c1 vx - s1 vy) / (h s2)``, ``theta2' = c2^2 (s1 vx + c1 vy) / h``.

        Parameters
        ----------
        theta : array_like, shape (..., 2)
        spot_velocity : array_like, shape (..., 2) or (..., 3)
            Spot velocity in ``{0}`` (m/s); a third component must be 0.
        nadir_tol : float
            Tilt (rad) below which the inverse is refused.
        warn_tol : float
            Tilt (rad) below which :class:`NearSingularityWarning` is emitted
            (default :data:`NEAR_NADIR_WARN` = 1e-3 rad: pan rate over ``1000 |v| / h``).
            Beyond the tilt limit it warns too (horizon side).

        Raises
        ------
        SingularConfigurationError
            At (or within ``nadir_tol`` of) the nadir, where ``theta1'`` is unbounded,
            or at the horizon.
        """
        theta = self._theta(theta)
        v = check_array(spot_velocity, "spot_velocity")
        if v.ndim < 1 or v.shape[-1] not in (2, 3):
            raise InputError(f"spot_velocity must have shape (..., 2) or (..., 3), got {tuple(v.shape)}")
        if v.shape[-1] == 3:
            if np.any(np.abs(v[..., 2]) > 1e-9):
                raise InputError("spot_velocity: the spot moves on the floor, its z component must be 0")
            v = v[..., :2]
        a1, a2 = self._actual(theta)
        c2 = np.cos(a2)
        self._require_floor_hit(c2, "joint_rates", a2)
        self._warn_beyond_limit(a2, "joint_rates")
        s2 = np.sin(a2)
        bad = np.abs(s2) < math.sin(nadir_tol)
        if np.any(bad):
            raise SingularConfigurationError(
                f"joint_rates: configuration{_at(bad)} is at the nadir singularity (theta2 = "
                f"{float(np.broadcast_to(a2, bad.shape)[_first(bad)]):.3g} rad): the pan rate needed to move the spot "
                f"is unbounded; keep the path at least {nadir_tol:g} rad of tilt away from the nadir")
        near = np.abs(s2) < math.sin(warn_tol)
        if np.any(near):
            k = _first(near)
            warnings.warn(
                f"joint_rates: configuration{_at(near)} ({int(np.sum(near))} in all) is within {warn_tol:g} rad of the "
                f"nadir singularity (theta2 + offset = {float(np.broadcast_to(a2, near.shape)[k]):.3g} rad): the pan "
                f"rate is v / (h tan(theta2)), over {1 / math.tan(warn_tol):.4g} v / h", NearSingularityWarning,
                stacklevel=2)
        s1, c1 = np.sin(a1), np.cos(a1)
        vx, vy = v[..., 0], v[..., 1]
        out = np.empty(np.broadcast_shapes(theta.shape[:-1], v.shape[:-1]) + (2,))
        out[..., 0] = c2 * (c1 * vx - s1 * vy) / (self.h * s2)
        out[..., 1] = c2 * c2 * (s1 * vx + c1 * vy) / self.h
        return out

    def beam_range_rate(self, theta, theta_dot) -> np.ndarray:
        """Rate (m/s) of the beam range along ``z_E``, seed eq. (10): ``h s2 / c2^2 theta2'``."""
        theta = self._theta(theta)
        td = check_array(theta_dot, "theta_dot", shape=(2,))
        _, a2 = self._actual(theta)
        c2 = np.cos(a2)
        self._require_floor_hit(c2, "beam_range_rate", a2)
        return self.h * np.sin(a2) / (c2 * c2) * td[..., 1]

    def singularity_margin(self, theta) -> np.ndarray:
        """Distance (rad) of the tilt from the singular set ``{0, pi/2}``, shape (...)."""
        theta = self._theta(theta)
        _, a2 = self._actual(theta)
        return np.minimum(np.abs(a2), np.abs(math.pi / 2 - a2))

    # -------------------------------------------------------- world frame
    def to_projector(self, points_W) -> np.ndarray:
        """``^0P = R ^WP + t`` (seed eq. 1); world points (..., 2) on the floor or (..., 3)."""
        p = check_array(points_W, "points_W")
        if p.ndim < 1 or p.shape[-1] not in (2, 3):
            raise InputError(f"points_W must have shape (..., 2) or (..., 3), got {tuple(p.shape)}")
        if p.shape[-1] == 2:
            p = np.concatenate([p, np.zeros(p.shape[:-1] + (1,))], axis=-1)
        return p @ self.R_0_W.T + self.t_0_W

    def to_world(self, points_0) -> np.ndarray:
        """``^WP = R^T (^0P - t)``, shape (..., 3)."""
        p = check_array(points_0, "points_0", shape=(3,))
        return (p - self.t_0_W) @ self.R_0_W

    def spot_world(self, theta) -> np.ndarray:
        """Spot in ``{W}`` (..., 3) for joint angles ``theta``."""
        p = self.spot(theta)  # finite, checked: no second validation
        p -= self.t_0_W
        return p @ self.R_0_W

    def joint_rates_world(self, theta, velocity_W, **kw) -> np.ndarray:
        """Joint rates for a world floor velocity (seed eqs. 2 and 9)."""
        v = check_array(velocity_W, "velocity_W")
        if v.ndim < 1 or v.shape[-1] not in (2, 3):
            raise InputError(f"velocity_W must have shape (..., 2) or (..., 3), got {tuple(v.shape)}")
        if v.shape[-1] == 2:
            v = np.concatenate([v, np.zeros(v.shape[:-1] + (1,))], axis=-1)
        v0 = v @ self.R_0_W.T
        return self.joint_rates(theta, v0[..., :2], **kw)

    # -------------------------------------------------------------- files
    def to_dict(self) -> dict:
        """SI values (m, rad) for result files."""
        return dict(name=self.name, H=self.H, d1=self.d1, d2=self.d2, offsets=list(self.offsets),
                    tilt_limit=self.tilt_limit, rate_limits=list(self.rate_limits),
                    pan_range=None if self.pan_range is None else list(self.pan_range), tilt_min=self.tilt_min,
                    R_0_W=self.R_0_W.tolist(), t_0_W=self.t_0_W.tolist())
