"""A jackknife std of the hand-eye X beside the refinement's first-order one (issue 13, "honesty on real data").

The first-order std (``s^2 (J^T J)^-1``) holds when the residuals are independent, alike and the model
right; on real data a few poses often carry most of the information or most of the error. The jackknife
re-estimates X with each pose left out in turn and takes the spread of those estimates (Efron & Stein,
Ann. Stat. 9(3), 1981; Efron & Tibshirani, *An Introduction to the Bootstrap*, 1993, ch. 11):

    std_jack^2 = (g - 1) / g * sum_k (theta_k - mean theta)^2

over ``g`` replicates. Up to :data:`MAX_DELETE_ONE` poses: **delete-one-pose**, each replicate refined
by two Gauss-Newton steps from the full estimate with its own residuals and the full data's Jacobian less
the left-out pose's rows (a replicate's optimum lies O(1/n) of a std away, where the Jacobian differs by
that much: it slows the iteration, not its fixed point; at 20 poses the std matches a full re-solve of
every replicate to 0.1 %, ``tests/handeye/test_handeye_jackknife.py``). Beyond: **delete-a-group** (Kott,
"The delete-a-group jackknife", J. Official Statistics 17(4), 2001): the poses in file order cut into
:data:`GROUPS` contiguous groups (neighbours in a stream share their errors: a group keeps them
together), one Gauss-Newton step each (a group is 1/50 of more than 100 poses: its estimate moves by a
fraction of a std, where one step leaves an error far below the jackknife's own sampling error).

The problem is :func:`robocal.handeye.calibrate_hand_eye`'s: the closure ``G[i] X T_cam_target[i] = Y``
in X and Y (rotation as a left rotation vector, rad; translation, m), rotation and translation residuals
weighted by their RMS and, with ``pose_sigmas``, each pose by its relative std (or, with ``whitening``,
each pose's residual whitened by its view's covariance, :mod:`robocal.handeye.weighted`). ``theta`` is
X's 6-vector (rx, ry, rz, tx, ty, tz) relative to the full estimate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MAX_DELETE_ONE", "GROUPS", "Jackknife", "jackknife_hand_eye"]

#: Delete-one-pose up to this many poses; beyond, delete-a-group.
MAX_DELETE_ONE = 100
#: The number of contiguous groups of the delete-a-group jackknife.
GROUPS = 50
#: Finite-difference step of the Jacobian (rad, m): well above rounding of O(1) poses, far below any std.
_STEP = 1e-7


@dataclass(frozen=True)
class Jackknife:
    """The jackknife std of X (6,: rad x3, m x3, as the first-order ``std``), which kind (``"delete-one"`` or
    ``"delete-a-group"``), the number of replicates and the poses left out per replicate."""

    std: np.ndarray
    kind: str
    replicates: int
    group_size: int

    def to_dict(self) -> dict:
        return {"std": [float(v) for v in self.std], "kind": self.kind, "replicates": int(self.replicates),
                "poses_per_replicate": int(self.group_size)}


def _pose_weights(Tc, pose_sigmas):
    """Per-pose relative weights (N, 6) as :func:`~robocal.handeye.calibrate_hand_eye` gives them."""
    w = np.ones((len(Tc), 6))
    if pose_sigmas is not None:
        ps = np.asarray(pose_sigmas, float)
        s_rot = ps[:, 0]
        s_t = np.hypot(ps[:, 1], np.linalg.norm(Tc[:, :3, 3], axis=1) * ps[:, 0])
        w[:, :3] = (np.median(s_rot) / s_rot)[:, None]
        w[:, 3:] = (np.median(s_t) / s_t)[:, None]
    return w


def _exp(v):
    """Rodrigues' rotation matrices (..., 3, 3) of rotation vectors (..., 3) (the perturbations: < 0.1 rad)."""
    th = np.linalg.norm(v, axis=-1)[..., None, None]
    K = np.zeros(v.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    K = K - np.swapaxes(K, -1, -2)
    small = th < 1e-6
    a = np.where(small, 1.0, np.sin(th) / np.where(small, 1.0, th))
    b = np.where(small, 0.5, (1 - np.cos(th)) / np.where(small, 1.0, th) ** 2)
    return np.eye(3) + a * K + b * (K @ K)


def _log(R):
    """Rotation vectors (..., 3) of rotations (..., 3, 3) well below a half turn (closure residuals: the
    plausibility check refuses a set whose residuals reach 0.1 rad)."""
    c = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1) / 2, -1, 1)
    th = np.arccos(c)
    s = np.sin(th)
    f = np.where(th < 1e-6, 0.5 + th ** 2 / 12, th / (2 * np.where(th < 1e-6, 1.0, s)))
    return f[..., None] * np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0],
                                    R[..., 1, 0] - R[..., 0, 1]], axis=-1)


def _perturbed(T, d):
    """``T`` (4, 4) moved by ``d`` (R, 6): rotation ``Exp(d[:3]) R``, translation ``t + d[3:]`` -> (R, 4, 4)."""
    out = np.broadcast_to(T, d.shape[:-1] + (4, 4)).copy()
    out[..., :3, :3] = _exp(d[..., :3]) @ T[:3, :3]
    out[..., :3, 3] = T[:3, 3] + d[..., 3:]
    return out


def _residuals(G, Tc, X, Y, d, w):
    """Weighted closure residuals (R, N, 6) of R perturbations ``d`` (R, 12) of X then Y on all N poses:
    rotation vector of ``R_closure R_Y^T`` (rad) and ``t_closure - t_Y`` (m), as the refinement's, times the
    weight matrices ``w`` (..., N, 6, 6)."""
    Xd, Yd = _perturbed(X, d[:, :6]), _perturbed(Y, d[:, 6:])
    C = G[None] @ Xd[:, None] @ Tc[None]
    Ry = Yd[:, None, :3, :3]
    r = np.concatenate([_log(C[..., :3, :3] @ np.swapaxes(Ry, -1, -2)), C[..., :3, 3] - Yd[:, None, :3, 3]], axis=-1)
    return np.einsum("...nab,...nb->...na", w, r)


def _jacobian(G, Tc, X, Y, d, w):
    """Forward differences of :func:`_residuals`: ``J`` (R, N, 6, 12) and ``r`` (R, N, 6)."""
    r0 = _residuals(G, Tc, X, Y, d, w)
    J = np.empty(r0.shape + (12,))
    for k in range(12):
        dk = d.copy()
        dk[:, k] += _STEP
        J[..., k] = (_residuals(G, Tc, X, Y, dk, w) - r0) / _STEP
    return J, r0


def jackknife_hand_eye(G, T_cam_target, X, Y, *, pose_sigmas=None, whitening=None,
                       max_delete_one: int = MAX_DELETE_ONE, groups: int = GROUPS) -> Jackknife:
    """The jackknife std of ``X`` (module docstring).

    Parameters
    ----------
    G : (N, 4, 4)
        The robot poses as the closure takes them: ``T_base_gripper`` (eye-in-hand) or its inverse
        (eye-to-hand), metres.
    T_cam_target : (N, 4, 4)
    X, Y : (4, 4)
        The full-data estimate (:attr:`HandEyeResult.X`, ``.Y``).
    pose_sigmas : (N, 2), optional
        As :func:`~robocal.handeye.calibrate_hand_eye`'s.
    whitening : (N, 6, 6), optional
        Each pose's residual whitening (:func:`robocal.handeye.weighted.closure_whitening`), for an X refined
        with the views' full covariances; replaces the weights above.
    """
    G, Tc = np.asarray(G, float), np.asarray(T_cam_target, float)
    X, Y = np.asarray(X, float), np.asarray(Y, float)
    n = len(Tc)
    if whitening is not None:
        w = np.asarray(whitening, float)
    else:
        w = _pose_weights(Tc, pose_sigmas)
        r = _residuals(G, Tc, X, Y, np.zeros((1, 12)), np.einsum("na,ab->nab", w, np.eye(6))[None])[0]
        # rotation and translation weighted by their RMS, as the refinement does (the jackknife needs the
        # same relative weighting, not the same scale)
        sig = np.r_[[max(np.sqrt(np.mean(r[:, :3] ** 2)), 1e-12)] * 3,
                    [max(np.sqrt(np.mean(r[:, 3:] ** 2)), 1e-15)] * 3]
        w = np.einsum("na,ab->nab", w / sig, np.eye(6))     # diagonal weights as (N, 6, 6) matrices
    if n <= max_delete_one:
        kind, size = "delete-one", 1
        masks = ~np.eye(n, dtype=bool)
        steps = 2
    else:
        kind = "delete-a-group"
        g = min(groups, n)
        edges = np.linspace(0, n, g + 1).round().astype(int)
        masks = np.ones((g, n), bool)
        for k in range(g):
            masks[k, edges[k]:edges[k + 1]] = False
        size = int(np.max(np.diff(edges)))
        steps = 1
    J, r = _jacobian(G, Tc, X, Y, np.zeros((1, 12)), w[None])
    J, r = J[0], r[0]
    Hi = np.einsum("nai,naj->nij", J, J)
    H = Hi.sum(0)
    # the full data's own optimum under these weights (the refinement's weights came from the closed form's
    # RMS: a shift common to every replicate, which the spread below does not see, removed all the same)
    full = -np.linalg.solve(H, np.einsum("nai,na->i", J, r))
    # Gauss-Newton on each replicate with the full data's Jacobian (a replicate's optimum is O(1/n) std
    # away: its Jacobian differs by that much, which slows the iteration, not its fixed point) and the
    # replicate's exact residuals
    Hk = H - np.einsum("rn,nij->rij", (~masks).astype(float), Hi)
    thetas = np.repeat(full[None], len(masks), axis=0)
    if steps == 1:
        gi = np.einsum("nai,na->ni", J, _residuals(G, Tc, X, Y, full[None], w[None])[0])
        thetas -= np.linalg.solve(Hk, (masks.astype(float) @ gi)[..., None])[..., 0]
    else:
        for lo in range(0, len(masks), 25):         # 25 replicates at a time: 25 x N x 6 residuals
            sl = slice(lo, lo + 25)
            for _ in range(steps):
                rk = _residuals(G, Tc, X, Y, thetas[sl], w[None]) * masks[sl, :, None]   # left-out pose: 0
                thetas[sl] -= np.linalg.solve(Hk[sl], np.einsum("nai,rna->ri", J, rk)[..., None])[..., 0]
    g = len(masks)
    dev = thetas[:, :6] - thetas[:, :6].mean(axis=0)
    std = np.sqrt((g - 1) / g * np.sum(dev ** 2, axis=0))
    return Jackknife(std, kind, g, size)
