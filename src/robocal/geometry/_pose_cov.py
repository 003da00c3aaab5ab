"""A rigid pose with its 6x6 covariance: inverse, composition and error to a truth, to first order.

The covariance is over ``d = (rx, ry, rz, tx, ty, tz)``: a small rotation
vector (rad) and a translation offset (m, in the parent frame), the parameters
every estimator of robocal perturbs and the order of the stds in a result
(``docs/results.md``). The rotation side is named (``docs/conventions.md``):

* ``"left"`` (world / parent side, the default): ``R = Exp(d_r) R_hat``,
* ``"right"`` (body / child side): ``R = R_hat Exp(d_r)``,

and in both ``t = t_hat + d_t``. These are :meth:`CalibrationResult.add_pose`'s
``rotation_std`` sides, so :meth:`PoseWithCovariance.add_to` writes a pose the
way :meth:`CalibrationResult.pose` reads it back. Propagation is linear
(first order: J. Sola, J. Deray, D. Atchuthan, "A micro Lie theory for state
estimation in robotics", arXiv:1812.01537, 2018, sec. 4-5, with the
translation kept additive as above). Everything is vectorised over leading
dimensions: ``T`` (..., 4, 4), ``cov`` (..., 6, 6).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from robocal.geometry._se3 import invert_transform
from robocal.geometry._so3 import rotation_angle, rotvec_from_matrix, skew
from robocal.validation import check_array, check_transform

__all__ = ["PoseWithCovariance", "PoseError", "POSE_PARAMS"]

#: Names of the six perturbation parameters, the order of ``cov`` (rad, rad, rad, m, m, m).
POSE_PARAMS = ("rx", "ry", "rz", "tx", "ty", "tz")
_SIDES = ("left", "right")


class PoseError(NamedTuple):
    """Error of an estimate against a truth (:meth:`PoseWithCovariance.error_to`), shapes over the leading dims.

    ``rotation``: angle (rad, in [0, pi]) of the rotation error; ``translation``: ``|t_est - t_true|`` (m);
    ``vector`` (..., 6): ``(rotation vector, t_est - t_true)`` on the pose's side, the coordinates of its
    covariance (what :func:`robocal.estimation.truth_check` takes).
    """

    rotation: np.ndarray | float
    translation: np.ndarray | float
    vector: np.ndarray


def _t(M):
    return np.swapaxes(M, -1, -2)


def _block(a, b, c, d):
    """``[[a, b], [c, d]]`` of (..., 3, 3) blocks -> (..., 6, 6)."""
    return np.concatenate([np.concatenate([a, b], -1), np.concatenate([c, d], -1)], -2)


def _sandwich(G, cov):
    return G @ cov @ _t(G)


@dataclass(frozen=True, eq=False)
class PoseWithCovariance:
    """A pose ``T`` (..., 4, 4), metres, with the covariance ``cov`` (..., 6, 6) of ``(rx, ry, rz, tx, ty, tz)``.

    Parameters
    ----------
    T : array_like, shape (..., 4, 4)
        ``T_parent_child`` (``docs/conventions.md``).
    cov : array_like, shape (..., 6, 6), optional
        Covariance of the rotation vector (rad) and translation (m), module docstring; ``None`` for a pose
        without one (every std is then ``None``). NaN marks what the data did not determine.
    side : {"left", "right"}
        Side of the rotation perturbation (module docstring).
    """

    T: np.ndarray
    cov: np.ndarray | None = None
    side: str = "left"

    def __post_init__(self):
        T = check_array(self.T, "T", shape=(4, 4), finite=False)
        # NaN marks an undetermined translation component (a rank-deficient fit): allowed, not in the rotation
        check_transform(np.concatenate([T[..., :3], np.nan_to_num(T[..., 3:], nan=0.0)], -1), "T", atol=1e-5)
        if self.side not in _SIDES:
            raise ValueError(f"side must be 'left' or 'right', got {self.side!r}")
        object.__setattr__(self, "T", T)
        if self.cov is not None:
            cov = check_array(self.cov, "cov", shape=(6, 6), finite=False)
            if cov.shape[:-2] != T.shape[:-2]:
                raise ValueError(f"cov has leading shape {cov.shape[:-2]} but T has {T.shape[:-2]}: one 6x6 "
                                 "covariance per pose")
            object.__setattr__(self, "cov", cov)

    # ------------------------------------------------------------------------- parts
    @property
    def R(self) -> np.ndarray:
        """Rotation block (..., 3, 3)."""
        return self.T[..., :3, :3]

    @property
    def t(self) -> np.ndarray:
        """Translation (..., 3), m."""
        return self.T[..., :3, 3]

    @property
    def std(self) -> np.ndarray | None:
        """Standard deviations (..., 6) of ``(rx, ry, rz, tx, ty, tz)`` (rad, m), or None without a covariance."""
        if self.cov is None:
            return None
        return np.sqrt(np.maximum(np.diagonal(self.cov, axis1=-2, axis2=-1), 0.0))

    @property
    def std_rotation(self) -> np.ndarray | None:
        """Std (..., 3) of the rotation vector on :attr:`side` (rad), or None."""
        s = self.std
        return None if s is None else s[..., :3]

    @property
    def std_translation(self) -> np.ndarray | None:
        """Std (..., 3) of the translation (m), or None."""
        s = self.std
        return None if s is None else s[..., 3:]

    # ------------------------------------------------------------------------- side
    def to_side(self, side: str) -> "PoseWithCovariance":
        """The same pose with its covariance on the other rotation side.

        ``R Exp(d_right) = Exp(R d_right) R``, so ``d_left = R d_right``; the translation part is unchanged.
        """
        if side not in _SIDES:
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        if side == self.side or self.cov is None:
            return PoseWithCovariance(self.T, self.cov, side)
        R = self.R if side == "left" else _t(self.R)
        z, eye = np.zeros_like(R), np.broadcast_to(np.eye(3), R.shape)
        return PoseWithCovariance(self.T, _sandwich(_block(R, z, z, eye), self.cov), side)

    # ------------------------------------------------------------------------- algebra
    def inverse(self) -> "PoseWithCovariance":
        """``T^-1`` and its covariance (first order), on the same side.

        Left: ``d r_inv = -R^T d r``, ``d t_inv = -R^T [t]x d r - R^T d t``. Right: ``d r_inv = -R d r``,
        ``d t_inv = [t_inv]x d r - R^T d t`` with ``t_inv = -R^T t``.
        """
        Ti = invert_transform(self.T)
        if self.cov is None:
            return PoseWithCovariance(Ti, None, self.side)
        R, t = self.R, self.t
        Rt = _t(R)
        z = np.zeros_like(R)
        if self.side == "left":
            G = _block(-Rt, z, -Rt @ skew(t), -Rt)
        else:
            G = _block(-R, z, skew(Ti[..., :3, 3]), -Rt)
        return PoseWithCovariance(Ti, _sandwich(G, self.cov), self.side)

    def compose(self, other: "PoseWithCovariance") -> "PoseWithCovariance":
        """``self @ other`` (``T_a_b`` then ``T_b_c`` -> ``T_a_c``), the two poses' errors independent.

        Left side: ``d r = d r1 + R1 d r2``, ``d t = d t1 - [R1 t2]x d r1 + R1 d t2`` (a correlated pair
        needs its joint covariance: compose the Jacobians yourself). The result is on ``self``'s side; a
        pose without covariance counts as exact.
        """
        if not isinstance(other, PoseWithCovariance):
            other = PoseWithCovariance(other)
        side = self.side
        a, b = self.to_side("left"), other.to_side("left")
        T = a.T @ b.T
        if a.cov is None and b.cov is None:
            return PoseWithCovariance(T, None, side)
        R1 = a.R
        lead = T.shape[:-2]
        z = np.zeros(lead + (3, 3))
        eye = np.broadcast_to(np.eye(3), lead + (3, 3))
        R1 = np.broadcast_to(R1, lead + (3, 3))
        cov = np.zeros(lead + (6, 6))
        if a.cov is not None:
            G1 = _block(eye, z, -skew(np.einsum("...ij,...j->...i", R1, np.broadcast_to(b.t, lead + (3,)))), eye)
            cov = cov + _sandwich(G1, np.broadcast_to(a.cov, lead + (6, 6)))
        if b.cov is not None:
            cov = cov + _sandwich(_block(R1, z, z, R1), np.broadcast_to(b.cov, lead + (6, 6)))
        return PoseWithCovariance(T, cov, "left").to_side(side)

    __matmul__ = compose

    # ------------------------------------------------------------------------- truth, result
    def error_to(self, T_true) -> PoseError:
        """Error of this estimate against ``T_true`` (..., 4, 4), on this pose's side.

        Left: rotation vector of ``R_est R_true^T``; right: of ``R_true^T R_est``; translation
        ``t_est - t_true`` (m) on both. The angle is :func:`~robocal.geometry.rotation_angle` of the same
        matrix (robust near 0 and pi). Scalars for a single pose.
        """
        T_true = check_transform(T_true, "T_true", atol=1e-5)
        Rt = T_true[..., :3, :3]
        dR = self.R @ _t(Rt) if self.side == "left" else _t(Rt) @ self.R
        dt = self.t - T_true[..., :3, 3]
        ang, dist = rotation_angle(dR), np.linalg.norm(dt, axis=-1)
        if np.ndim(ang) == 0:
            ang, dist = float(ang), float(dist)
        return PoseError(ang, dist, np.concatenate([rotvec_from_matrix(dR), dt], axis=-1))

    def add_to(self, result, name: str, *, parent: str | None = None, child: str | None = None):
        """Write this (single) pose into a :class:`~robocal.io.CalibrationResult` under ``name``.

        :meth:`~robocal.io.CalibrationResult.add_pose` with the stds of :attr:`cov` (NaN written as
        undetermined) and ``rotation_std`` = :attr:`side`; the correlations are not written. Returns
        ``result``.
        """
        if self.T.shape != (4, 4):
            raise ValueError(f"add_to writes one pose, got shape {self.T.shape}")
        sr, st = self.std_rotation, self.std_translation
        return result.add_pose(name, self.T, std_rotation=sr, std_translation=st, parent=parent, child=child,
                               rotation_std=self.side)

    @classmethod
    def from_result(cls, result, name: str) -> "PoseWithCovariance":
        """The pose ``name`` of a result (:meth:`~robocal.io.CalibrationResult.pose`) with a diagonal
        covariance from its stds (a result keeps no correlations; NaN where undetermined; no covariance when
        the result has no std for the pose)."""
        p = result.pose(name)
        if p.std_rotation is None and p.std_translation is None:
            return cls(p.T, None, p.rotation_std)
        nan3 = np.full(3, np.nan)
        s = np.r_[nan3 if p.std_rotation is None else p.std_rotation,
                  nan3 if p.std_translation is None else p.std_translation]
        return cls(p.T, np.diag(s ** 2), p.rotation_std)
