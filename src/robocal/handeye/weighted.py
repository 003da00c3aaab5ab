"""AX = XB refined with each camera pose's full covariance (issue 13: "carries that covariance into X's").

A target's pose from one image is anisotropic: the rotation about the optical axis and the lateral
translation are far better determined than the tilts and the depth (0.3 px corners on a 7 x 5 board at
0.4 m: ~1 vs ~8 mrad). :func:`~robocal.handeye.calibrate_hand_eye` weights each pose by one rotation
and one translation std (``pose_sigmas``), which keeps the estimate consistent but leaves its
first-order covariance wrong by direction (200 simulated sets: the error of one rotation component 1.5x
its std, another 0.7x; NEES / 6 = 1.20). Here each pose's closure residual is whitened by its own
covariance instead:

* the sensor pose ``T_cam_target[i]`` with covariance ``C_i`` over (OpenCV rotation vector, translation),
  i.e. ``Exp(rvec + d)`` = ``Exp(J_l(rvec) d) Exp(rvec)`` (:func:`robocal.geometry.so3_left_jacobian`);
* the closure ``G[i] X T_cam_target[i] = Y`` then moves by ``R_GX (J_l d_r)`` in rotation and ``R_GX d_t``
  in translation, ``R_GX`` the rotation of ``G[i] X`` (the robot poses taken as exact: their error, if
  any, is left to the residuals' common scale);
* residual ``i`` is multiplied by ``S_i^-1/2`` (``diag(w^-1/2) V^T`` of ``S_i = V diag(w) V^T``), ``S_i``
  that covariance at the start's X; the noise scale is still estimated from the residuals
  (``robocal.estimation``: ``s^2 (J^T J)^-1``).

The X and Y parameterisation, the residual and the solver are :func:`~robocal.handeye.calibrate_hand_eye`'s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["CovarianceRefinement", "closure_whitening", "refine_with_pose_covariances"]


@dataclass
class CovarianceRefinement:
    """X and Y refined on whitened closures: ``cov`` (6, 6) of X (left rotation vector, rad; translation,
    m), ``std`` by label, ``residuals`` (N, 6) unwhitened (rad, m), ``whitening`` (N, 6, 6), the solver's
    ``lsq`` and its ``warnings`` (outliers named by pose)."""

    X: np.ndarray
    Y: np.ndarray
    cov: np.ndarray
    std: dict
    residuals: np.ndarray
    whitening: np.ndarray
    lsq: object = None
    warnings: list = field(default_factory=list)


def closure_whitening(G, X, T_cam_target, cov_rvec_t) -> np.ndarray:
    """``W_i`` (N, 6, 6) with ``W_i^T W_i = S_i^-1``: the whitening of each pose's closure residual (module
    docstring).

    ``G`` (N, 4, 4) the robot poses as the closure takes them, ``X`` (4, 4), ``cov_rvec_t`` (N, 6, 6) over
    the OpenCV rotation vector of ``R_cam_target`` (rad) and ``t_cam_target`` (m).
    """
    from robocal.geometry import rotvec_from_matrix, so3_left_jacobian

    Tc = np.asarray(T_cam_target, float)
    C = np.asarray(cov_rvec_t, float)
    A = np.zeros(C.shape)
    A[:, :3, :3] = so3_left_jacobian(rotvec_from_matrix(Tc[:, :3, :3]))
    A[:, 3:, 3:] = np.eye(3)
    R = (np.asarray(G, float) @ np.asarray(X, float))[:, :3, :3]
    B = np.zeros(C.shape)
    B[:, :3, :3], B[:, 3:, 3:] = R, R
    M = B @ A
    S = M @ C @ np.swapaxes(M, -1, -2)
    S = 0.5 * (S + np.swapaxes(S, -1, -2))
    # S^-1/2 by eigen-decomposition, eigenvalues floored at 1e-12 of each view's largest: a view whose pose
    # is (nearly) undetermined along a direction gets ~no weight there instead of a failed Cholesky
    w, V = np.linalg.eigh(S)
    w = np.maximum(w, 1e-12 * w[:, -1:])
    return np.swapaxes(V / np.sqrt(w)[:, None, :], -1, -2)


def refine_with_pose_covariances(G, T_cam_target, cov_rvec_t, X0, Y0, *, times=None):
    """X and Y by least squares on the whitened closures -> :class:`CovarianceRefinement`.

    ``G``: the robot poses as the closure takes them (``T_base_gripper``, or its inverse eye-to-hand);
    ``cov_rvec_t`` (N, 6, 6) as :func:`closure_whitening`; ``X0``, ``Y0``: the start (a refined X);
    ``times`` only name poses in warnings.
    """
    from robocal.estimation import Problem, solve
    from robocal.handeye.motions import _LABELS, _perturbed, _pose_residual, name_outliers

    G, Tc = np.asarray(G, float), np.asarray(T_cam_target, float)
    X0, Y0 = np.asarray(X0, float), np.asarray(Y0, float)
    W = closure_whitening(G, X0, Tc, cov_rvec_t)

    def fun(p):
        X, Y = _perturbed(X0, p["X"]), _perturbed(Y0, p["Y"])
        return np.einsum("nab,nb->na", W, _pose_residual(G @ X @ Tc, Y[None]))

    prob = Problem()
    prob.add_block("X", np.r_[0, 0, 0, X0[:3, 3]], labels=[f"X.{k}" for k in _LABELS],
                   unit=["rad"] * 3 + ["m"] * 3)
    prob.add_block("Y", np.r_[0, 0, 0, Y0[:3, 3]], labels=[f"Y.{k}" for k in _LABELS],
                   unit=["rad"] * 3 + ["m"] * 3)
    prob.add_residuals(fun, name="closure", residual_dim=6)
    res = solve(prob, method="lm")
    X, Y = _perturbed(X0, res.params["X"]), _perturbed(Y0, res.params["Y"])
    idx = [res.free_labels.index(f"X.{k}") for k in _LABELS]
    r = _pose_residual(G @ X @ Tc, Y[None])
    warnings = name_outliers(res.warnings, times, what="T_base_gripper X T_cam_target = Y (whitened by the "
                                                       "view's covariance)")
    std = {k: res.std.get(f"X.{k}") for k in _LABELS}
    return CovarianceRefinement(X, Y, np.asarray(res.cov)[np.ix_(idx, idx)], std, r, W, res, warnings)
