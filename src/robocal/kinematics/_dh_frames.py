"""Link frames and twist columns of a :class:`~robocal.kinematics.DHChain` on column arrays (issue 16).

A frame ``T_world_i = T_base @ A_1 @ ... @ A_i`` is carried as the four columns of its top three rows,
each (3, N) over N configurations (or a constant (3, 1)). A link multiplies them by its constant part
(modified: ``Rx(alpha) Tx(a)`` before the motion, standard: ``Tx(a) Rx(alpha)`` after it; elementwise,
zero and unit entries skipped) and by its motion ``Z(theta, d) = Rz(theta) Tz(d)`` in closed form,
``[c0, c1, c2, c3] @ Z = [c c0 + s c1, c c1 - s c0, c2, c3 + d c2]``. The same product as the (N, 4, 4)
stacks of link matrices and batched ``@`` it replaces, to round-off, at a fraction of the cost.

Twists follow :mod:`robocal.kinematics._common`: an elementary screw fixed in a frame ``F`` with local
direction ``v`` through the local point ``r`` has, in the world, direction ``u = R_F v`` and point
``c = R_F r + t_F``; its column is ``[u x (p - c); u]`` (revolute) or ``[u; 0]`` (prismatic), ``p`` the
tool origin. Local directions and points are constants, so ``u`` and ``c`` are sums of frame columns.
"""

from __future__ import annotations

import math

import numpy as np

from robocal.kinematics._common import origin_screws, xyz_rpy_from_transform

__all__: list[str] = []


def _frames_plan(chain):
    """Per-link constants, built once per chain: (kind, joint index, theta0, d0, K before, K after)."""
    plan = chain.__dict__.get("_frames_plan_cache")
    if plan is not None:
        return plan
    from robocal.kinematics._dh import _dh_matrices

    steps, j = [], 0
    for lk in chain.links:
        C = _dh_matrices(lk.alpha, lk.a, 0.0, 0.0, chain.convention)
        K = None if np.array_equal(C, np.eye(4)) else C.tolist()
        idx = None
        if lk.joint != "fixed":
            idx, j = j, j + 1
        steps.append((lk.joint, idx, lk.theta, lk.d) + ((K, None) if chain.convention == "modified" else (None, K)))
    base = chain.T_base[:3]
    plan = (tuple(steps), [base[:, k:k + 1] for k in range(4)])
    chain.__dict__["_frames_plan_cache"] = plan
    return plan


def frame_columns(chain, qf) -> list:
    """Columns ``[c0, c1, c2, c3]`` of the top rows of every frame ``T_world_i``, i = 0..n_links.

    ``qf`` is validated and flat, (N, dof), or None for a chain without joints. Each column is (3, N) or
    a constant (3, 1).
    """
    from robocal.kinematics._dh import _times_constant, _z_motion

    steps, cols = _frames_plan(chain)
    frames = [cols]
    for kind, j, theta, d, K_pre, K_post in steps:
        if K_pre is not None:
            cols = _times_constant(cols, K_pre)
        if kind == "revolute":
            theta = qf[:, j] + theta
            c, s = np.cos(theta), np.sin(theta)
        else:
            if kind == "prismatic":
                d = qf[:, j] + d
            # a constant angle; Rz(0) moves nothing
            c, s = (math.cos(theta), math.sin(theta)) if theta != 0.0 else (None, None)
        cols = _z_motion(cols, c, s, None if isinstance(d, float) and d == 0.0 else d)  # a new list: frames keep theirs
        if K_post is not None:
            cols = _times_constant(cols, K_post)
        frames.append(cols)
    return frames


def stack_frames(frames: list, n: int) -> np.ndarray:
    """(N, len(frames), 4, 4) from :func:`frame_columns` (constant columns broadcast over N)."""
    out = np.empty((n, len(frames), 4, 4))
    out[:, :, 3, :3] = 0.0
    out[:, :, 3, 3] = 1.0
    for i, cols in enumerate(frames):
        for k in range(4):
            out[:, i, :3, k] = cols[k].T
    return out


def _point(cols, r) -> np.ndarray:
    """``R r + t`` of a frame's columns for a constant local point ``r`` (3,), (3, N) or (3, 1)."""
    acc = cols[3]
    for j in range(3):
        if r[j] != 0.0:
            acc = acc + cols[j] * r[j]
    return acc


def _direction(cols, v) -> np.ndarray:
    """``R v`` for a constant local direction ``v`` (3,); a unit axis is the column itself."""
    acc = None
    for j in range(3):
        if v[j] == 0.0:
            continue
        t = cols[j] if v[j] == 1.0 else cols[j] * v[j]
        acc = t if acc is None else acc + t
    return np.zeros((3, 1)) if acc is None else acc


def tool_origin(chain, last) -> np.ndarray:
    """Tool origin in the world (3, N) from the last link frame's columns."""
    T_tool = chain.T_tool
    return _point(last, T_tool[:3, 3])


def origin_local_screws(T) -> list:
    """(local direction, local point, revolute) of the six xyz/rpy parameters of a constant origin ``T``,
    in the frame the origin is attached to (:func:`~robocal.kinematics._common.origin_screws` of the
    identity)."""
    return [(L[:3, :3] @ ax, L[:3, 3], rev) for L, ax, rev in origin_screws(np.eye(4), xyz_rpy_from_transform(T))]


def twist_columns(screws, p: np.ndarray, n: int) -> np.ndarray:
    """(N, 6, len(screws)) twist columns ``[u x (p - c); u]`` / ``[u; 0]`` of screws ``(frame columns,
    local direction, local point, revolute)``, ``p`` the tool origin (3, N)."""
    J = np.empty((n, 6, len(screws)))
    for m, (cols, v, r, revolute) in enumerate(screws):
        u = _direction(cols, v)
        if revolute:
            w = p - _point(cols, r)
            for row, (a, b) in enumerate(((1, 2), (2, 0), (0, 1))):
                np.subtract(u[a] * w[b], u[b] * w[a], out=J[:, row, m])
            J[:, 3:, m] = u.T
        else:
            J[:, :3, m] = u.T
            J[:, 3:, m] = 0.0
    return J
