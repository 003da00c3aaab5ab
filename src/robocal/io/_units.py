"""Units in input files.

Files state their units explicitly (``unit: mm`` beside a value, or a
``units:`` mapping); everything is converted to SI (metres, radians,
seconds) on load. An unknown unit or one of the wrong kind is an error,
never a silent guess.
"""

from __future__ import annotations

import numpy as np

from robocal.errors import UnitError

__all__ = ["UNITS", "to_si", "from_si", "unit_kind"]

#: unit -> (kind, factor to SI)
UNITS: dict[str, tuple[str, float]] = {
    "m": ("length", 1.0),
    "cm": ("length", 1e-2),
    "mm": ("length", 1e-3),
    "um": ("length", 1e-6),
    "rad": ("angle", 1.0),
    "deg": ("angle", np.pi / 180.0),
    "s": ("time", 1.0),
    "ms": ("time", 1e-3),
    "us": ("time", 1e-6),
    "Hz": ("frequency", 1.0),
    "px": ("pixel", 1.0),
    "m/s": ("speed", 1.0),
    "mm/s": ("speed", 1e-3),
    "rad/s": ("angular_rate", 1.0),
    "deg/s": ("angular_rate", np.pi / 180.0),
    "1": ("dimensionless", 1.0),
}


def unit_kind(unit: str) -> str:
    """Kind of a unit (``"length"``, ``"angle"``, ...); raises :class:`UnitError` if unknown."""
    try:
        return UNITS[unit][0]
    except (KeyError, TypeError):
        known = ", ".join(sorted(UNITS))
        raise UnitError(f"unknown unit {unit!r} (known: {known})") from None


def to_si(value, unit: str, kind: str | None = None, *, name: str = "value") -> np.ndarray:
    """Convert ``value`` given in ``unit`` to SI, checking the unit's kind.

    Parameters
    ----------
    value : array_like
    unit : str
        One of :data:`UNITS`.
    kind : str, optional
        Expected kind (``"length"``, ``"angle"``, ...).
    name : str
        Used in error messages.
    """
    got = unit_kind(unit)
    if kind is not None and got != kind:
        raise UnitError(f"{name} needs a unit of {kind}, got {unit!r} ({got})")
    return np.asarray(value, dtype=float) * UNITS[unit][1]


def from_si(value, unit: str) -> np.ndarray:
    """Convert an SI value to ``unit``."""
    unit_kind(unit)
    return np.asarray(value, dtype=float) / UNITS[unit][1]
