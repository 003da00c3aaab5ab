"""Plane reflections (Householder), as needed by the mirror rig (seed 002).

A plane is ``{x : n . x = d}`` with unit normal ``n``. Reflection maps
``x -> x - 2 (n . x - d) n``; its linear part ``H = I - 2 n n^T`` has
det = -1, so it turns right-handed frames into left-handed ones.
"""

from __future__ import annotations

import numpy as np

from robocal._deprecation import deprecated_alias
from robocal.errors import DegenerateGeometryError
from robocal.validation import check_array

__all__ = ["householder_from_normal", "reflection_from_plane", "householder_matrix", "reflection_transform",
           "reflect_points", "reflect_frame"]


def _unit_normal(n) -> np.ndarray:
    n = check_array(n, "normal", shape=(3,))
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        raise DegenerateGeometryError("plane normal has zero length")
    return n / norm


def householder_from_normal(n) -> np.ndarray:
    """``H = I - 2 n n^T`` for a (batch of) normal(s) ``(..., 3)`` (normalised here)."""
    n = _unit_normal(n)
    return np.eye(3) - 2.0 * n[..., :, None] * n[..., None, :]


def reflection_from_plane(n, d) -> np.ndarray:
    """4x4 affine reflection in the plane ``n . x = d`` (det of the 3x3 block = -1)."""
    n = _unit_normal(n)
    d = np.asarray(d, dtype=float)
    H = householder_from_normal(n)
    T = np.zeros(np.broadcast_shapes(n.shape[:-1], d.shape) + (4, 4))
    T[..., :3, :3] = H
    T[..., :3, 3] = 2.0 * d[..., None] * n
    T[..., 3, 3] = 1.0
    return T


householder_matrix = deprecated_alias(householder_from_normal, "householder_matrix")
reflection_transform = deprecated_alias(reflection_from_plane, "reflection_transform")


def reflect_points(points, n, d) -> np.ndarray:
    """Mirror images of ``points (..., 3)`` in the plane ``n . x = d``."""
    n = _unit_normal(n)
    p = check_array(points, "points", shape=(3,))
    dist = np.sum(p * n, axis=-1) - np.asarray(d, dtype=float)
    return p - 2.0 * dist[..., None] * n


def reflect_frame(T, n, d, *, flip_axis: int = 0) -> np.ndarray:
    """Mirror image of a right-handed frame, kept right-handed.

    The mirror image of a frame is left-handed; negating axis ``flip_axis``
    of the image makes it right-handed again (seed 002's frame ``ri`` negates
    x). Returns ``reflection_from_plane(n, d) @ T @ diag(F, 1)`` with
    ``F = I`` except ``F[flip_axis, flip_axis] = -1``.
    """
    F = np.eye(4)
    F[flip_axis, flip_axis] = -1.0
    return reflection_from_plane(n, d) @ np.asarray(T, dtype=float) @ F
