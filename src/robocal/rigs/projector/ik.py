"""Inverse kinematics of the ceiling projector (seed 000, eq. 8) and the reach checks.

Frames and units as in :mod:`.model` (``{0}`` the projector base, ``{W}`` the world; m, rad). The
methods here are those of :class:`~robocal.rigs.projector.model.ProjectorModel` (a mixin: the model's
fields ``H``, ``d1``, ``offsets``, ``tilt_limit`` and extrinsics are read from ``self``).
"""

from __future__ import annotations

import math
import warnings
from functools import cached_property

import numpy as np

from robocal.errors import InputError, SingularConfigurationError
from robocal.geometry import wrap_angle
from robocal.kinematics._common import finite_fast as _finite
from robocal.rigs.projector.singular import (
    F8 as _F8,
    NADIR_TOL,
    NearSingularityWarning,
    UnreachablePointError,
    first_index as _first,
    frozen_scalar as _scalar,
    indices as _indices,
)
from robocal.validation import check_array

__all__: list[str] = []


class InverseKinematics:
    """:meth:`ik`, :meth:`ik_world`, :meth:`reachable` of :class:`~robocal.rigs.projector.model.ProjectorModel`."""

    def ik(self, points, *, theta1_at_nadir: float = 0.0, on_nadir: str = "warn", check_reach: bool = True,
           floor_tol: float = 1e-6) -> np.ndarray:
        """Joint angles that put the spot on floor points given in ``{0}``, seed eq. (8).

        ``theta1 = atan2(x, y)``, ``theta2 = atan(sqrt(x^2 + y^2) / (H - d1))``,
        minus the zero offsets; ``theta1`` wrapped to ``(-pi, pi]``.

        Parameters
        ----------
        points : array_like, shape (..., 3) or (..., 2)
            Floor points in ``{0}`` (m). With 3 columns, ``z`` must be ``-H``.
        theta1_at_nadir : float
            Pan command (rad) returned at the nadir, where eq. (8) leaves it undefined.
        on_nadir : {'warn', 'raise', 'ignore'}
            At the nadir: emit :class:`NearSingularityWarning`, raise
            :class:`~robocal.errors.SingularConfigurationError`, or stay silent.
        check_reach : bool
            Raise :class:`UnreachablePointError` for points beyond the tilt limit.
        floor_tol : float
            Tolerance (m) on ``z = -H``.

        Returns
        -------
        ndarray, shape (..., 2)
        """
        if on_nadir not in ("warn", "raise", "ignore"):
            raise InputError(f"on_nadir must be 'warn', 'raise' or 'ignore', got {on_nadir!r}")
        out = self._ik_fast(points, check_reach, floor_tol)
        if out is not None:
            return out
        # something to name (non-finite, off the floor, nadir, out of reach) or not a float64 array:
        # the per-element checks
        xy = self._floor_xy(points, "points", floor_tol)
        r = np.hypot(xy[..., 0], xy[..., 1])
        a2 = np.arctan2(r, self.h)
        if check_reach:
            self._require_reachable(a2, r, "points")
        nadir = r <= NADIR_TOL * self.h
        a1 = np.where(nadir, theta1_at_nadir + self.offsets[0], np.arctan2(xy[..., 0], xy[..., 1]))
        if np.any(nadir):
            msg = (f"ik: point(s) {_indices(nadir)[:10]} are at the nadir (theta2 = 0): the pan angle is undefined, "
                   f"theta1 = {theta1_at_nadir:g} rad used")
            if on_nadir == "raise":
                raise SingularConfigurationError(msg)
            if on_nadir == "warn":
                warnings.warn(msg, NearSingularityWarning, stacklevel=2)
            elif on_nadir != "ignore":
                raise InputError(f"on_nadir must be 'warn', 'raise' or 'ignore', got {on_nadir!r}")
        out = np.empty(xy.shape[:-1] + (2,))
        out[..., 0] = wrap_angle(a1 - self.offsets[0])
        out[..., 1] = a2 - self.offsets[1]
        return out

    def _ik_fast(self, points, check_reach: bool, floor_tol: float) -> np.ndarray | None:
        """:meth:`ik` for the common case, or None when a check could fail (the caller then names it).

        The checks are reductions on arrays eq. (8) computes anyway: z within ``floor_tol`` of ``-H``
        (min and max), no point at the nadir (min of the tilt), every tilt within the limit (max of the
        tilt; with ``check_reach=False`` below pi/2, which an infinite coordinate reaches); a NaN fails
        every comparison. The pan is wrapped to ``(-pi, pi]`` by one shift of 2 pi where the offset pushed it
        out (atan2 is in ``[-pi, pi]``), not by a modulo over all points. Issue 16.
        """
        p = points
        if not (type(p) is np.ndarray and p.dtype is _F8 and p.ndim and p.size and p.shape[-1] in (2, 3)):
            return None
        H, h, r_nadir, r_reach, o1, o2, wrap_up, wrap_down = self._ik_constants
        f = p if p.ndim == 2 else p.reshape(-1, p.shape[-1])
        x, y = f[:, 0], f[:, 1]
        if f.shape[1] == 3:
            # bounds rounded inwards: never looser than |z + H| <= floor_tol (exact near -H, Sterbenz);
            # argmin / argmax inline (see lo_hi)
            z = f[:, 2]
            if not (z[z.argmin()] >= math.nextafter(-H - floor_tol, math.inf)
                    and z[z.argmax()] <= math.nextafter(-H + floor_tol, -math.inf)):
                return None
        r = np.hypot(x, y)
        # the min and max of r decide the nadir (r > NADIR_TOL h) and the reach (r <= h tan(tilt_limit), so the
        # tilt atan(r / h) is within the limit to round-off, well inside its 1e-12 rad margin); a NaN fails
        # every comparison, an infinite coordinate the upper one
        if not (r[r.argmin()] > r_nadir and r[r.argmax()] < (r_reach if check_reach else math.inf)):
            return None  # (r_nadir is inf when |o1| >= pi: the one-shift wrap below would not do)
        out = np.empty(p.shape[:-1] + (2,))
        o = out if out.ndim == 2 else out.reshape(-1, 2)
        a1, a2 = o[:, 0], o[:, 1]
        # outputs positional (the out= keyword costs ~0.1 us a call), h, o1, o2 0-d arrays (see frozen_scalar)
        np.arctan2(x, y, a1)
        np.arctan(np.divide(r, h, r), a2)  # atan(r / h): equal to atan2(r, h) to round-off, 1.8x faster
        if o1:  # per column: one broadcast call on (N, 2) runs an inner loop of 2 values, 10x slower at 10^4
            a1 -= o1
        if o2:
            a2 -= o2
        # the pan is atan2 - o1 in [-pi - |o1|, pi + |o1|]: one shift of 2 pi where it left (-pi, pi]
        # (atan2(-0.0, y < 0) = -pi included), not a modulo over all points
        if wrap_up and a1[a1.argmin()] <= -math.pi:
            np.add(a1, 2 * math.pi, out=a1, where=a1 <= -math.pi)
        if wrap_down and a1[a1.argmax()] > math.pi:
            np.subtract(a1, 2 * math.pi, out=a1, where=a1 > math.pi)
        return out

    @cached_property
    def _ik_constants(self) -> tuple:
        """``(H, h, NADIR_TOL h, h tan(tilt_limit), o1, o2, o1 >= 0, o1 < 0)`` for :meth:`_ik_fast`, once per
        (frozen) model; the nadir radius is inf when ``|o1| >= pi`` (the fast path's pan wrap assumes less).
        ``h, o1, o2`` are read-only 0-d arrays (:func:`~.singular.frozen_scalar`), the pan wrap's two tests
        on ``o1`` bools (on a 0-d array each would be a ufunc call)."""
        h = self.H - self.d1
        o1, o2 = self.offsets
        return (self.H, _scalar(h), NADIR_TOL * h if abs(o1) < math.pi else math.inf, h * math.tan(self.tilt_limit),
                _scalar(o1), _scalar(o2), o1 >= 0, o1 < 0)

    def _floor_xy(self, points, name: str, floor_tol: float) -> np.ndarray:
        p = check_array(points, name)
        if p.ndim < 1 or p.shape[-1] not in (2, 3):
            raise InputError(f"{name} must have shape (..., 2) or (..., 3), got {tuple(p.shape)}")
        if p.shape[-1] == 3:
            dz = np.abs(p[..., 2] + self.H)
            if np.any(dz > floor_tol):
                k = _first(dz > floor_tol)
                raise InputError(f"{name}: point {k} has z = {float(p[k + (2,)]):.6g} m but the floor is z_0 = -H = "
                                 f"{-self.H:.6g} m (wrong units or wrong H?)")
            p = p[..., :2]
        return p

    def _require_reachable(self, a2, r, name: str) -> None:
        bad = a2 > self.tilt_limit + 1e-12
        if np.any(bad):
            idx = _indices(bad)
            raise UnreachablePointError(
                f"{name}: point(s) {idx[:10]}{' ...' if len(idx) > 10 else ''} are outside the reachable floor "
                f"(distance {float(np.max(r[bad])):.4g} m from the nadir, limit {self.floor_radius:.4g} m at tilt "
                f"{math.degrees(self.tilt_limit):g} deg)")

    def reachable(self, points, *, floor_tol: float = 1e-6) -> np.ndarray:
        """Boolean (...): floor points in ``{0}`` within the tilt limit."""
        xy = self._floor_xy(points, "points", floor_tol)
        return np.hypot(xy[..., 0], xy[..., 1]) <= self.floor_radius * (1 + 1e-12)

    def ik_world(self, points_W, **kw) -> np.ndarray:
        """Joint angles (..., 2) for world floor points (seed eqs. 1 and 8)."""
        p = points_W
        if (type(p) is np.ndarray and p.dtype is _F8 and p.ndim and p.shape[-1] in (2, 3)
                and p.size and _finite(p)):
            # checked here so a NaN is named as points_W (one call, see _finite); ^0P = R ^WP + t,
            # a floor point (z_W = 0) through the first two columns of R only
            p0 = p @ self.R_0_W[:, :p.shape[-1]].T
            p0 += self.t_0_W
        else:
            p0 = self.to_projector(points_W)
        return self.ik(p0, floor_tol=kw.pop("floor_tol", 1e-6 + 1e-6 * self.H), **kw)
