"""The projector's singular set (seed 000, after eq. 10): tolerances, the warning and the reach error.

``theta2 = 0``: the beam at the nadir, the pan angle undefined; ``theta2 = pi/2``: the beam horizontal,
the spot at infinity. Shared by :mod:`.model` (forward kinematics, rates) and :mod:`.ik` (inverse
kinematics, reach); every name here is also importable from :mod:`.model`.
"""

from __future__ import annotations

import numpy as np

from robocal.errors import InputError

__all__ = ["NADIR_TOL", "HORIZON_TOL", "NEAR_NADIR_WARN", "NearSingularityWarning", "UnreachablePointError"]

#: Below this tilt (rad) the beam is "at the nadir": the pan angle is undetermined.
NADIR_TOL = 1e-9
#: Beam directions with cos(tilt) below this never reach the floor (horizon).
HORIZON_TOL = 1e-9
#: :meth:`ProjectorModel.joint_rates` warns below this tilt (rad): the pan rate needed to move the spot at
#: speed ``v`` is ``v / (h tan(tilt))``, over ``1000 v / h`` here (e.g. 100 rad/s for 0.3 m/s at h = 2.8 m).
NEAR_NADIR_WARN = 1e-3


class NearSingularityWarning(UserWarning):
    """A configuration at or near the singular set (``theta2 -> 0`` or ``pi/2``)."""


class UnreachablePointError(InputError):
    """A floor point lies outside the projector's reachable disc (tilt limit)."""


#: the fast paths' dtype test (``a.dtype is F8``: one pointer comparison)
F8 = np.dtype(np.float64)


def frozen_scalar(v: float) -> np.ndarray:
    """A read-only 0-d float64 array for a per-model constant of the fast paths (issue 16).

    As a NumPy operand it gives the same IEEE result as the float, at ~0.25 us less per call than a Python
    float (which NumPy converts on every call); read-only because every call shares it.
    """
    a = np.array(float(v))
    a.setflags(write=False)
    return a


def first_index(mask) -> tuple:
    idx = np.argwhere(np.asarray(mask))
    return tuple(int(i) for i in idx[0]) if idx.size else ()


def at_index(mask) -> str:
    """' at index (i, j)' for the first True of an array mask; '' for a scalar (no index to name)."""
    return f" at index {first_index(mask)}" if np.ndim(mask) else ""


def indices(mask) -> list[int]:
    m = np.asarray(mask)
    return [int(i) for i in np.flatnonzero(m.reshape(-1))] if m.ndim else ([0] if m else [])
