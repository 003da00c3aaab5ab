"""The least-squares problem of the humanoid calibration (seed 001, eqs. 6-8): parameters, noise model, gauge.

* :func:`resolve_parameters` -- the free parameters from a set name or a list;
* :func:`noise_weights` -- per-view noise covariance (corner noise plus joint
  quantisation moving a view's corners together) and its whitening;
* :func:`corner_noise` -- the corner noise measured where joint errors cannot reach;
* :func:`choose_gauge` -- one parameter per null-space direction to hold;
* :func:`build_problem` -- one residual term per view over the kept corners.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from robocal.errors import InputError
from robocal.estimation import Problem
from robocal.rigs.humanoid.model import CAMERA_PARAMS, HumanoidModel
from robocal.rigs.humanoid.simulate import HumanoidDataset

__all__ = ["PARAMETER_SETS", "resolve_parameters", "noise_weights", "corner_noise", "choose_gauge",
           "build_problem", "present_corners", "valid_views"]

#: Named parameter sets (``--params``): see :func:`resolve_parameters`.
PARAMETER_SETS = {
    "seed": "the seed's Table 1: camera roll/pitch/yaw, the 12 leg joint offsets, board yaw/x/y per foot (21)",
    "seed+camera_xy": "the seed's set plus the camera x/y shift (23)",
    "legs": "leg joint offsets only (12)",
    "all": "every parameter: head and leg joints, camera roll/pitch/yaw/x/y, boards",
}


def resolve_parameters(model: HumanoidModel, spec: str | Sequence[str] = "seed") -> list[str]:
    """Labels of the free parameters from a set name, a comma list or a sequence.

    Names: a set of :data:`PARAMETER_SETS`, a joint name, ``camera.roll`` ...
    ``camera.y``, ``board.left.yaw`` ..., or the groups ``camera``,
    ``camera_rotation``, ``boards``, ``legs``, ``head``; comma-separated.
    """
    if isinstance(spec, str):
        items = [s.strip() for s in spec.split(",") if s.strip()]
    else:
        items = list(spec)
    labels = model.parameter_labels()
    groups = {
        "seed": model.seed_parameters(),
        "seed+camera_xy": model.seed_parameters() + ["camera.x", "camera.y"],
        "legs": list(model.leg_joints),
        "head": list(model.head_joints),
        "camera": [f"camera.{p}" for p in CAMERA_PARAMS],
        "camera_rotation": ["camera.roll", "camera.pitch", "camera.yaw"],
        "boards": [lab for lab in labels if lab.startswith("board.")],
        "all": labels,
    }
    out: list[str] = []
    for it in items:
        add = groups.get(it, [it])
        for lab in add:
            if lab not in labels:
                hint = (" (the camera's z shift is not observable in this set-up, seed 001)"
                         if lab == "camera.z" else "")
                raise InputError(f"unknown calibration parameter {lab!r}{hint}; known: sets {list(groups)} or "
                                 f"labels {labels}")
            if lab not in out:
                out.append(lab)
    if not out:
        raise InputError("no calibration parameter selected")
    return [lab for lab in labels if lab in out]


def valid_views(data: HumanoidDataset) -> np.ndarray:
    """Views (V,) bool with at least one corner (a corner is present when both coordinates are finite)."""
    return present_corners(data).any(axis=1)


def present_corners(data: HumanoidDataset) -> np.ndarray:
    """Corners (V, N) bool that are present (finite): NaN marks a corner removed at detection."""
    if data.corners is None:
        raise InputError("the data set has no corners (detect them first)")
    return np.all(np.isfinite(data.corners), axis=2)


def noise_weights(model: HumanoidModel, data: HumanoidDataset, x, *, corner_sigma: float,
                  joint_sigma: float) -> np.ndarray:
    """Per-view whitening matrices ``W_v`` (V, 2N, 2N) with ``W_v^T W_v = Sigma_v^-1``.

    ``Sigma_v = corner_sigma^2 I + joint_sigma^2 J_theta J_theta^T``: corner
    noise plus the joint readings' error (quantisation to 0.1 deg is a uniform
    error of std ``0.1 deg / sqrt(12)``), which moves all corners of a view
    together. ``J_theta`` equals the offset Jacobian (an offset adds to the
    reading), evaluated at ``x``, over the joints whose reading changes
    between views: a joint that stays still (the head) has one constant
    reading error, a bias the camera rotation absorbs, not noise.
    """
    V, N = data.corners.shape[:2]
    n = len(model.joint_names)
    moving = np.ptp(data.theta, axis=0) > 0
    if joint_sigma > 0 and np.any(moving):
        _, J = model.project(data.theta, data.feet, x, jacobian=True, check=False)
        Jt = J[..., :n][..., moving].reshape(V, 2 * N, int(moving.sum()))
        S = corner_sigma ** 2 * np.eye(2 * N) + joint_sigma ** 2 * Jt @ Jt.transpose(0, 2, 1)
    else:
        S = np.broadcast_to(corner_sigma ** 2 * np.eye(2 * N), (V, 2 * N, 2 * N))
    L = np.linalg.cholesky(S)
    return np.linalg.inv(L), S


def corner_noise(model: HumanoidModel, data: HumanoidDataset, x, keep=None) -> float:
    """Corner noise [px] from the residual part no joint-reading error can explain.

    Per view, the residual is projected onto the orthogonal complement of the
    columns of ``d uv / d theta``; ``sigma^2 = sum ||P r||^2 / sum (2N - rank)``.
    ``keep`` (V, N) bool, optional: only these corners count (rejected outliers left out); missing
    (NaN) corners never do.
    """
    V, N = data.corners.shape[:2]
    n = len(model.joint_names)
    uv, J = model.project(data.theta, data.feet, x, jacobian=True, check=False)
    r = (uv - data.corners).reshape(V, 2 * N)
    Jt = J[..., :n].reshape(V, 2 * N, n)
    present = present_corners(data)
    rows = np.repeat(present if keep is None else np.asarray(keep, bool) & present, 2, axis=1)
    ss, dof = 0.0, 0
    for v in range(V):
        if not rows[v].any():
            continue
        U, sv, _ = np.linalg.svd(Jt[v][rows[v]], full_matrices=False)
        k = int(np.sum(sv > 1e-9 * max(sv.max(), 1e-300)))
        Uk = U[:, :k]
        rv = r[v][rows[v]]
        e = rv - Uk @ (Uk.T @ rv)
        ss += float(e @ e)
        dof += int(rows[v].sum()) - k
    return float(np.sqrt(ss / max(dof, 1)))


def choose_gauge(pre) -> list[str]:
    """One parameter per null-space direction to hold fixed (the gauge), from an
    :class:`~robocal.estimation.Identifiability` of the selected problem.

    Pivoted QR on the transposed null-space basis ``N^T`` (k x n, column-scaled coordinates)
    picks the k parameters with the largest independent null-space components, so that fixing
    them removes every null direction and the k x k block of ``N`` stays well conditioned.
    Among near-equal components a parameter outside the seed's usual set (HeadYaw, HeadPitch,
    camera.x, camera.y) is preferred, as its value is the least interesting one.
    """
    import scipy.linalg

    N = np.asarray(pre.null_space)
    k = N.shape[1] if N.ndim == 2 else 0
    if k == 0:
        return []
    prefer = np.array([1.2 if lab in ("HeadYaw", "HeadPitch", "camera.x", "camera.y") else 1.0
                       for lab in pre.labels])
    _, _, piv = scipy.linalg.qr(N.T * prefer, pivoting=True, mode="economic")
    return [pre.labels[j] for j in sorted(piv[:k])]


def build_problem(model: HumanoidModel, data: HumanoidDataset, free: Sequence[str], *, tie: bool = False,
                  x0=None, analytic: bool = True, corner_sigma: float = 0.3,
                  joint_sigma: float = 0.0, keep=None) -> tuple[Problem, np.ndarray]:
    """The least-squares problem over one block ``p`` (all parameters, unselected ones fixed at ``x0``).

    One residual term per view (named by the view), holding ``uv_pred - uv_meas`` [px] of its
    kept corners only, whitened by the inverse Cholesky factor of their block of the view's
    noise covariance :func:`noise_weights` (the marginal of the noise model; in units of the
    assumed noise, with ``joint_sigma = 0`` simply divided by ``corner_sigma``): one observation
    of dimension ``2 K_v`` per view, as the whitening mixes the corners of a view (corner
    outliers are tested separately on the raw residuals, see :func:`calibrate`). ``keep`` (V, N)
    bool, optional: corners to use (default: the present ones, see :func:`present_corners`); a view
    without any is left out. So the residual count ``m``, the degrees of freedom and the
    residual variance count only the corners used. ``tie`` ties the RHipYawPitch offset to
    LHipYawPitch (one motor) when the tree does not already do so. Returns the problem and the
    per-view noise covariances (V, 2N, 2N) [px^2] of all corners.
    """
    labels = model.parameter_labels()
    x0 = np.zeros(len(labels)) if x0 is None else np.asarray(x0, dtype=float)
    fixed = np.array([lab not in free for lab in labels])
    theta, feet = data.theta, np.asarray(data.feet)
    V, N = data.corners.shape[:2]
    keep = present_corners(data) if keep is None else np.asarray(keep, bool) & present_corners(data)
    W_all, S = noise_weights(model, data, x0, corner_sigma=corner_sigma, joint_sigma=joint_sigma)
    meas = data.corners.reshape(V, 2 * N)
    P = len(labels)
    # model.project evaluates every view at once: the per-view terms share one evaluation per parameter
    # vector (the solver calls all terms with the same one)
    cache: dict = {}

    def projected(p, jacobian=False):
        key = p.tobytes()
        if cache.get("key") != key or (jacobian and cache["J"] is None):
            out = model.project(theta, feet, p, jacobian=jacobian, check=False)
            uv, J = out if jacobian else (out, None)
            cache.update(key=key, uv=uv, J=J)
        return cache["uv"], cache["J"]

    units = model.parameter_units()
    scale = np.where(np.array(units) == "m", 1e-3, np.radians(0.5))
    prob = Problem().add_block("p", x0, fixed=fixed, labels=labels, unit=units, scale=scale)
    names = data.names if len(set(data.names)) == V else [f"view{v:03d}" for v in range(V)]
    for v in range(V):
        rows = np.flatnonzero(np.repeat(keep[v], 2))
        if not rows.size:
            continue
        W = W_all[v] if rows.size == 2 * N else np.linalg.inv(np.linalg.cholesky(S[v][np.ix_(rows, rows)]))

        def fun(p, v=v, rows=rows, W=W):
            uv, _ = projected(p["p"])
            return W @ (uv[v].reshape(2 * N)[rows] - meas[v, rows])

        def jac(p, v=v, rows=rows, W=W):
            _, J = projected(p["p"], jacobian=True)
            return {"p": W @ J[v].reshape(2 * N, P)[rows]}

        prob.add_residuals(fun, name=str(names[v]), jacobian=jac if analytic else None, residual_dim=rows.size)
    if tie and not model.tied and "RHipYawPitch" in labels and "LHipYawPitch" in labels:
        if ("RHipYawPitch" in free) != ("LHipYawPitch" in free):
            raise InputError("tie needs both LHipYawPitch and RHipYawPitch among the free parameters")
        if "RHipYawPitch" in free:
            prob.tie("RHipYawPitch", "LHipYawPitch")
    return prob, S
