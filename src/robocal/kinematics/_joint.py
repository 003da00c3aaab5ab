"""Joints of a kinematic tree: :class:`Joint` and :class:`Mimic` (see ``_tree`` for the model).

A joint maps its child link into its parent link,
``T_parent_child = origin @ Motion(axis, q + offset)``; the geometry lives
here, the bookkeeping of joint values and paths in :mod:`._tree`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from robocal.errors import InputError, ShapeError
from robocal.kinematics._common import check_limits, check_scalar, joint_motion, normalise_joint_type
from robocal.validation import check_array, check_transform

__all__ = ["Mimic", "Joint"]


@dataclass(frozen=True)
class Mimic:
    """``value = multiplier * value(joint) + offset`` (URDF ``<mimic>``)."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0

    def __post_init__(self):
        if not isinstance(self.joint, str) or not self.joint:
            raise InputError(f"Mimic.joint must be a joint name, got {self.joint!r}")
        object.__setattr__(self, "multiplier", check_scalar(self.multiplier, "Mimic.multiplier"))
        object.__setattr__(self, "offset", check_scalar(self.offset, "Mimic.offset"))


def _readonly(arr: np.ndarray) -> np.ndarray:
    arr = np.array(arr, dtype=float)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Joint:
    """A joint from link ``parent`` to link ``child``.

    Parameters
    ----------
    name, parent, child : str
    origin : array_like, shape (4, 4), optional
        ``T_parent_joint``: joint frame in the parent link frame (identity).
    axis : array_like, shape (3,)
        Joint axis in the joint frame, normalised here (default z; URDF's
        default x is applied by the URDF loader).
    type : {'revolute', 'continuous', 'prismatic', 'fixed'}
    limits : (float, float), optional
        Limits of the joint *variable* ``q`` (rad or m), not of ``q + offset``.
    offset : float
        Zero offset added to the variable (rad or m).
    mimic : Mimic or (joint, multiplier, offset), optional
        Follow another joint instead of having a variable.
    """

    name: str
    parent: str
    child: str
    origin: np.ndarray | None = None
    axis: np.ndarray | Sequence[float] = (0.0, 0.0, 1.0)
    type: str = "revolute"
    limits: tuple[float, float] | None = None
    offset: float = 0.0
    mimic: Mimic | None = None

    def __post_init__(self):
        for key in ("name", "parent", "child"):
            val = getattr(self, key)
            if not isinstance(val, str) or not val:
                raise InputError(f"Joint.{key} must be a non-empty string, got {val!r}")
        if self.parent == self.child:
            raise InputError(f"joint {self.name!r}: parent and child are the same link {self.parent!r}")
        origin = np.eye(4) if self.origin is None else check_transform(self.origin, f"joint {self.name!r} origin")
        if origin.shape != (4, 4):
            raise ShapeError(f"joint {self.name!r} origin must have shape (4, 4), got {origin.shape}")
        object.__setattr__(self, "origin", _readonly(origin))
        kind = normalise_joint_type(self.type, f"joint {self.name!r} type")
        object.__setattr__(self, "type", kind)
        axis = check_array(self.axis, f"joint {self.name!r} axis", shape=(3,))
        norm = float(np.linalg.norm(axis)) if axis.ndim == 1 else 0.0
        if axis.ndim != 1 or norm < 1e-12:
            raise InputError(f"joint {self.name!r} axis must be a non-zero 3-vector, got {axis.tolist()}")
        object.__setattr__(self, "axis", _readonly(axis / norm))
        object.__setattr__(self, "limits", check_limits(self.limits, f"joint {self.name!r} limits"))
        object.__setattr__(self, "offset", check_scalar(self.offset, f"joint {self.name!r} offset"))
        mimic = self.mimic
        if mimic is not None and not isinstance(mimic, Mimic):
            mimic = Mimic(*mimic) if isinstance(mimic, (tuple, list)) else Mimic(mimic)
        object.__setattr__(self, "mimic", mimic)
        if kind == "fixed" and (self.offset != 0.0 or mimic is not None or self.limits is not None):
            raise InputError(f"fixed joint {self.name!r} cannot have an offset, limits or mimic")
        if mimic is not None and mimic.joint == self.name:
            raise InputError(f"joint {self.name!r} cannot mimic itself")

    @property
    def movable(self) -> bool:
        return self.type != "fixed"

    def transform(self, q=0.0) -> np.ndarray:
        """``T_parent_child`` (..., 4, 4) for variable ``q`` (...); the offset is added here."""
        if not self.movable:
            return self.origin.copy()
        q = check_array(q, f"q[{self.name!r}]")
        return self._transform_value(q + self.offset)

    def _transform_value(self, value: np.ndarray) -> np.ndarray:
        """``origin @ Motion(value)`` where ``value`` already includes the offset."""
        if not self.movable:
            return self.origin
        return self.origin @ joint_motion(self.type, self.axis, value)
