"""Rigid transforms as 4x4 homogeneous matrices, batched over leading axes.

``T_a_b`` maps points from frame b into frame a: ``p_a = T_a_b @ p_b``, so
``T_a_b @ T_b_c == T_a_c`` reads right (see ``docs/conventions.md``).
"""

from __future__ import annotations

import numpy as np

from robocal._deprecation import deprecated_alias
from robocal.geometry._so3 import (
    _tail,
    matrix_from_quaternion,
    matrix_from_rotvec,
    quaternion_from_matrix,
    rotvec_from_matrix,
)
from robocal.validation import check_array

__all__ = [
    "transform_from",
    "transform_from_translation",
    "rotation_from_transform",
    "translation_from_transform",
    "rotation_of",
    "translation_of",
    "invert_transform",
    "compose",
    "apply_transform",
    "apply_rotation",
    "transform_from_pq",
    "pq_from_transform",
    "transform_from_rotvec",
    "rotvec_translation_from_transform",
    "translation_transform",
]


def transform_from(R, t) -> np.ndarray:
    """Homogeneous transform from rotation ``(..., 3, 3)`` and translation ``(..., 3)``."""
    R = _tail(R, (3, 3), "R")
    t = _tail(t, (3,), "t")
    lead = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    T = np.zeros(lead + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def transform_from_translation(t) -> np.ndarray:
    """Pure translation, (..., 3) -> (..., 4, 4)."""
    t = np.asarray(t, dtype=float)
    return transform_from(np.broadcast_to(np.eye(3), t.shape[:-1] + (3, 3)), t)


def rotation_from_transform(T) -> np.ndarray:
    """Rotation block ``T[..., :3, :3]``."""
    return np.asarray(T)[..., :3, :3]


def translation_from_transform(T) -> np.ndarray:
    """Translation ``T[..., :3, 3]``."""
    return np.asarray(T)[..., :3, 3]


translation_transform = deprecated_alias(transform_from_translation, "translation_transform")
rotation_of = deprecated_alias(rotation_from_transform, "rotation_of")
translation_of = deprecated_alias(translation_from_transform, "translation_of")


def invert_transform(T) -> np.ndarray:
    """Inverse of a rigid transform, exact (uses R^T, not a general inverse)."""
    T = _tail(T, (4, 4), "T")
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    return transform_from(Rt, -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3]))


def compose(*Ts) -> np.ndarray:
    """Compose transforms left to right: ``compose(T_a_b, T_b_c) == T_a_c``."""
    out = _tail(Ts[0], (4, 4), "transform 0")
    for k, T in enumerate(Ts[1:], 1):
        out = out @ _tail(T, (4, 4), f"transform {k}")
    return out


def apply_transform(T, points) -> np.ndarray:
    """Transform points: ``T (..., 4, 4)`` applied to ``points (..., 3)``, broadcasting."""
    T = _tail(T, (4, 4), "T")
    p = _tail(points, (3,), "points")
    return np.einsum("...ij,...j->...i", T[..., :3, :3], p) + T[..., :3, 3]


def apply_rotation(R, vectors) -> np.ndarray:
    """Rotate vectors: ``R (..., 3, 3)`` applied to ``vectors (..., 3)``, broadcasting."""
    return np.einsum("...ij,...j->...i", _tail(R, (3, 3), "R"), _tail(vectors, (3,), "vectors"))


def transform_from_pq(pq) -> np.ndarray:
    """Transform from position + scalar-last quaternion ``(x, y, z, qx, qy, qz, qw)``."""
    pq = check_array(pq, "pq", shape=(7,))
    return transform_from(matrix_from_quaternion(pq[..., 3:]), pq[..., :3])


def pq_from_transform(T) -> np.ndarray:
    """Position + scalar-last quaternion ``(x, y, z, qx, qy, qz, qw)`` with qw >= 0."""
    T = check_array(T, "T", shape=(4, 4))
    return np.concatenate([T[..., :3, 3], quaternion_from_matrix(T[..., :3, :3])], axis=-1)


def transform_from_rotvec(rotvec, t) -> np.ndarray:
    """Transform from a rotation vector (rad) and a translation."""
    return transform_from(matrix_from_rotvec(rotvec), t)


def rotvec_translation_from_transform(T) -> tuple[np.ndarray, np.ndarray]:
    """Split a transform into (rotation vector, translation)."""
    T = np.asarray(T, dtype=float)
    return rotvec_from_matrix(T[..., :3, :3]), T[..., :3, 3].copy()
