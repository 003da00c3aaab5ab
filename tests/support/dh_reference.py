"""The D-H chain as products of full 4x4 link matrices: the reference the faster kinematics paths are
tested against (tests/kinematics; on the test path: tests/support)."""

import numpy as np

from robocal.kinematics._dh import _dh_matrices


def stacked_frames(chain, q):
    """``[T_base, T_base A_1(q), ..., T_base A_1 ... A_n]`` (without the tool), each broadcast to ``q``'s batch."""
    T, j, frames = np.broadcast_to(chain.T_base, q.shape[:-1] + (4, 4)), 0, []
    frames.append(T)
    for lk in chain.links:
        theta, d = lk.theta, lk.d
        if lk.joint != "fixed":
            theta, d = (theta + q[..., j], d) if lk.joint == "revolute" else (theta, d + q[..., j])
            j += 1
        T = T @ _dh_matrices(lk.alpha, lk.a, theta, d, chain.convention)
        frames.append(T)
    return [np.broadcast_to(F, q.shape[:-1] + (4, 4)) for F in frames]
