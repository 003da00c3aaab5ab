"""Shared fixtures for the kinematics tests: finite-difference twists, a NAO-class URDF."""

from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data"


def _unskew(S):
    return 0.5 * np.stack([S[..., 2, 1] - S[..., 1, 2], S[..., 0, 2] - S[..., 2, 0], S[..., 1, 0] - S[..., 0, 1]], -1)


def fd_twists(pose, x, h=1e-6):
    """Central-difference twist columns ``[d t; w]`` (6, len(x)) of ``pose(x) -> (4, 4)``.

    ``w`` comes from ``dR/dx @ R^T = [w]_x``, the convention of the analytic Jacobians.
    Truncation error is O(h^2) ~ 1e-12 and rounding ~ 1e-16 / h ~ 1e-10.
    """
    x = np.asarray(x, dtype=float)
    R0 = pose(x)[:3, :3]
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        dT = (pose(x + e) - pose(x - e)) / (2 * h)
        cols.append(np.concatenate([dT[:3, 3], _unskew(dT[:3, :3] @ R0.T)]))
    return np.stack(cols, axis=-1)


@pytest.fixture
def fd():
    return fd_twists


@pytest.fixture(scope="session")
def nao_path():
    return DATA / "nao_legs_head.urdf"
