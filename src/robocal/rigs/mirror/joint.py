"""The joint problem over K mirror images: ``T_r_c`` and every mirror pose ``T_c_m_k`` (beyond the patent).

One nonlinear least-squares problem on the reprojection error of the
markers and of the reflected body points (:func:`residual_model`, analytic
Jacobians), its first-order covariance (:func:`predicted_covariance`), and
the two-component noise model of the ArUco path
(:func:`_two_component_covariance`). For one image the joint problem splits
into the two PnPs of the patent's method (``T_c_ri`` is a re-parametrisation
of ``T_c_r`` for a fixed mirror), so its covariance is the first-order
covariance of the single-image estimate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.camera import CameraModel, MarkerRectangle
from robocal.errors import InputError
from robocal.estimation import Problem
from robocal.geometry import matrix_from_rotvec, skew, so3_left_jacobian, transform_from
from robocal.rigs.mirror.model import mirror_plane
from robocal.rigs.mirror.observation import check_observation

__all__ = ["residual_model", "predicted_covariance"]


@dataclass
class _Layout:
    K: int
    ids: list
    P: list
    marker_uv: np.ndarray
    body_uv: list
    marker_scale: np.ndarray  # (K,) marker noise relative to the body points'
    marker_cov: list = None  # per image: (4, 2, 2) relative marker covariance or None
    body_cov: list = None  # per image: (N_k // 4, 8, 8) relative covariance of each tag's corners, or None

    @property
    def correlated(self) -> bool:
        """True when some image gives a body or marker covariance (the residuals are whitened)."""
        return any(c is not None for c in (self.marker_cov or []) + (self.body_cov or []))

    def whitening(self):
        """``(W_markers (8K, 8K), W_body (2 sum N, 2 sum N))``: ``W^T W = C^-1`` of the relative covariances."""
        from scipy.linalg import block_diag, cholesky, solve_triangular

        def w(C):
            L = cholesky(C, lower=True)
            return solve_triangular(L, np.eye(len(C)), lower=True)

        wm, wb = [], []
        for k in range(self.K):
            s2 = float(self.marker_scale[k]) ** 2
            mc = self.marker_cov[k] if self.marker_cov[k] is not None else np.broadcast_to(np.eye(2), (4, 2, 2))
            wm += [w(s2 * C) for C in mc]
            n = len(self.ids[k])
            if self.body_cov[k] is None:
                wb.append(np.eye(2 * n))
            else:
                wb += [w(C) for C in self.body_cov[k]]
        return block_diag(*wm), block_diag(*wb)


def residual_model(camera: CameraModel, rectangle: MarkerRectangle, layout: _Layout, R_rc_ref, R_cm_ref):
    """Residual functions of the joint problem and their analytic Jacobians.

    Parameters ``params`` hold ``rot_rc (3,)``, ``t_rc (3,)``, ``rot_cm (K, 3)``,
    ``t_cm (K, 3)``: rotations as left perturbations of the reference
    rotations, ``R = exp(rot) R_ref``. Residual = projected - observed [px].

    Returns
    -------
    markers, body : callable
        ``(4K, 2)`` and ``(sum N_k, 2)`` residuals.
    markers_jac, body_jac : callable
        ``{block: (m, block size)}`` derivatives.
    poses : callable
        ``params -> (T_r_c (4, 4), T_c_m (K, 4, 4))``.
    """
    A = rectangle.object_points()
    K = layout.K

    def poses(p):
        R_rc = matrix_from_rotvec(p["rot_rc"]) @ R_rc_ref
        T_r_c = transform_from(R_rc, p["t_rc"])
        R_cm = matrix_from_rotvec(p["rot_cm"]) @ R_cm_ref
        T_c_m = transform_from(R_cm, p["t_cm"])
        return T_r_c, T_c_m

    def _markers(p, want_jac):
        _, T_c_m = poses(p)
        Ra = np.einsum("kij,nj->kni", T_c_m[:, :3, :3], A)  # (K, 4, 3)
        pc = Ra + T_c_m[:, None, :3, 3]
        if not want_jac:
            return (camera.project(pc, check=False) - layout.marker_uv).reshape(-1, 2)
        _, Jp = camera.project_jacobian(pc, check=False)  # (K, 4, 2, 3)
        Jl = so3_left_jacobian(p["rot_cm"])  # (K, 3, 3)
        dR = -skew(Ra) @ Jl[:, None]  # (K, 4, 3, 3)
        Jrot = np.zeros((K, 4, 2, K, 3))
        Jt = np.zeros((K, 4, 2, K, 3))
        for k in range(K):
            Jrot[k, :, :, k] = Jp[k] @ dR[k]
            Jt[k, :, :, k] = Jp[k]
        m = 8 * K
        return {"rot_cm": Jrot.reshape(m, 3 * K), "t_cm": Jt.reshape(m, 3 * K)}

    def _body(p, want_jac):
        T_r_c, T_c_m = poses(p)
        R_rc, t_rc = T_r_c[:3, :3], T_r_c[:3, 3]
        n, d = mirror_plane(T_c_m)
        out, jac = [], {"rot_rc": [], "t_rc": [], "rot_cm": [], "t_cm": []}
        Jl_rc = so3_left_jacobian(p["rot_rc"])
        Jl_cm = so3_left_jacobian(p["rot_cm"])
        for k in range(K):
            q = layout.P[k] - t_rc
            pc = q @ R_rc  # R_rc^T q
            s = pc @ n[k] - d[k]
            H = np.eye(3) - 2.0 * np.outer(n[k], n[k])
            pv = pc - 2.0 * s[:, None] * n[k]
            if not want_jac:
                out.append(camera.project(pv, check=False) - layout.body_uv[k])
                continue
            _, Jp = camera.project_jacobian(pv, check=False)  # (N, 2, 3)
            N = pc.shape[0]
            dpc_drot = R_rc.T @ skew(q) @ Jl_rc  # (N, 3, 3)
            dpc_dt = -R_rc.T
            jac["rot_rc"].append(Jp @ (H @ dpc_drot))
            jac["t_rc"].append(Jp @ (H @ dpc_dt))
            t_cm = T_c_m[k, :3, 3]
            dpv_dn = -2.0 * (s[:, None, None] * np.eye(3) + n[k][None, :, None] * (pc - t_cm)[:, None, :])
            dn_drot = -skew(n[k]) @ Jl_cm[k]
            jr = np.zeros((N, 2, K, 3))
            jt = np.zeros((N, 2, K, 3))
            jr[:, :, k] = Jp @ (dpv_dn @ dn_drot)
            jt[:, :, k] = Jp @ (2.0 * np.outer(n[k], n[k]))
            jac["rot_cm"].append(jr.reshape(N, 2, 3 * K))
            jac["t_cm"].append(jt.reshape(N, 2, 3 * K))
        if not want_jac:
            return np.concatenate(out, axis=0)
        return {b: np.concatenate(v, axis=0).reshape(-1, v[0].shape[-1]) for b, v in jac.items()}

    return (lambda p: _markers(p, False), lambda p: _body(p, False),
            lambda p: _markers(p, True), lambda p: _body(p, True), poses)


def _labels(K):
    return {
        "rot_rc": ["rot_rc_x", "rot_rc_y", "rot_rc_z"],
        "t_rc": ["t_rc_x", "t_rc_y", "t_rc_z"],
        "rot_cm": [f"rot_cm{k}_{a}" for k in range(K) for a in "xyz"],
        "t_cm": [f"t_cm{k}_{a}" for k in range(K) for a in "xyz"],
    }


def _problem(camera, rectangle, layout, T_r_c0, T_c_m0, sigma_px):
    """``(problem, poses, whitened)``; ``whitened`` (the ArUco path's noise model, for
    :func:`_two_component_covariance`) is None without per-tag covariances."""
    markers, body, mjac, bjac, poses = residual_model(camera, rectangle, layout, T_r_c0[:3, :3], T_c_m0[:, :3, :3])
    lab = _labels(layout.K)
    prob = Problem()
    prob.add_block("rot_rc", np.zeros(3), labels=lab["rot_rc"], unit="rad", scale=1e-3)
    prob.add_block("t_rc", T_r_c0[:3, 3], labels=lab["t_rc"], unit="m", scale=1e-3)
    prob.add_block("rot_cm", np.zeros((layout.K, 3)), labels=lab["rot_cm"], unit="rad", scale=1e-3)
    prob.add_block("t_cm", T_c_m0[:, :3, 3], labels=lab["t_cm"], unit="m", scale=1e-3)
    sig = None if sigma_px is None else float(sigma_px)
    msig = sig
    if layout.correlated:
        # per-tag covariances (ArUco path): whiten each image's marker and body residuals
        Wm, Wb = layout.whitening()

        def wrap(f, W):
            return lambda p: (W @ np.asarray(f(p)).reshape(-1)).reshape(-1, 2)

        def wrap_jac(f, W):
            return lambda p: {b: W @ J for b, J in f(p).items()}

        markers, mjac = wrap(markers, Wm), wrap_jac(mjac, Wm)
        body, bjac = wrap(body, Wb), wrap_jac(bjac, Wb)
        prob.add_residuals(markers, name="markers", jacobian=mjac, residual_dim=2, sigma=sig)
        prob.add_residuals(body, name="body", jacobian=bjac, residual_dim=2, sigma=sig)
        # second component of the noise model (_two_component_covariance), raw: independent body points;
        # none on tag centres (marker_cov given: their systematic error is 0.004 px against 0.022 px for a
        # body tag's corner on noise-free renders), else marker_sigma_scale^2
        v_m = np.concatenate([np.full(8, 0.0 if layout.marker_cov[k] is not None else layout.marker_scale[k] ** 2)
                              for k in range(layout.K)])
        return prob, poses, (markers, body, (Wm * v_m) @ Wm.T, Wb @ Wb.T)
    if np.any(layout.marker_scale != 1.0):  # relative weights (absolute only with sigma_px)
        sig = 1.0 if sig is None else sig
        msig = sig * np.repeat(layout.marker_scale, 4)[:, None]
    prob.add_residuals(markers, name="markers", jacobian=mjac, residual_dim=2, sigma=msig)
    prob.add_residuals(body, name="body", jacobian=bjac, residual_dim=2, sigma=sig)
    return prob, poses, None


def _layout(obs_list, body_points_r, rectangle):
    checked = [check_observation(o, body_points_r, rectangle) for o in obs_list]
    return _Layout(
        K=len(checked),
        ids=[c[2] for c in checked],
        P=[c[3] for c in checked],
        marker_uv=np.stack([c[0] for c in checked]),
        body_uv=[c[1] for c in checked],
        marker_scale=np.array([float(o.marker_sigma_scale) for o in obs_list]),
        marker_cov=[o.marker_cov for o in obs_list],
        body_cov=[_checked_body_cov(o, len(c[2])) for o, c in zip(obs_list, checked)],
    )


def _checked_body_cov(obs, n_body: int):
    c = obs.body_cov
    if c is not None and 4 * len(c) != n_body:
        raise InputError(f"{obs.name}: body_cov has {len(c)} tag blocks (8 x 8, four body points each) but there "
                         f"are {n_body} body points; expected {n_body / 4:g}")
    return c


def _two_component_covariance(prob, whitened, res) -> tuple[np.ndarray, np.ndarray]:
    """Covariance of the whitened fit with the noise split into the modelled part and an iid part.

    The body-corner errors of the ArUco path are the edge-fit noise, whose
    per-tag structure the whitening models (``C_fit``, scale ``s1^2``), plus
    a systematic part from the rendering/edge localisation (0.022 px RMS at
    blur 0.6 on noise-free renders, against 0.014 px of noise at grey noise
    2) that is dominated by the lines' *offsets*, which ``C_fit`` says are
    the precise part: scaling ``C_fit`` by the residual variance then
    over-states the std 2x. Model ``C = s1^2 C_fit + s2^2 C_iid`` (``C_iid``:
    independent body corners, ``I``; nothing on tag centres, whose
    systematic error is 0.003 px: a common offset of a tag's four sides
    does not move its centre; plain markers ``marker_sigma_scale^2 I``) and
    estimate both variances from the whitened residuals ``r`` (MINQUE moments, ``M`` the residual projector): ``r^T r`` and
    ``r^T V2 r`` against their expectations ``tr(M V_j)``, ``tr(V2 M V_j M)``.
    The estimate is the whitened fit's; its covariance the sandwich
    ``(J^T J)^-1 J^T C J (J^T J)^-1`` in whitened units. Returns ``(cov
    (6 + 6K, 6 + 6K), (s1^2, s2^2))``.

    Limits: from one image the two variances are estimated with few
    effective degrees of freedom (on noise drawn from this very model with
    equal parts: ~55 % relative sd of ``s1^2`` per image, unbiased), so
    error / std has heavier tails than a Gaussian (RMS 1.3 on that model,
    1.1 with the edge-fit part alone); when the moments give a negative
    variance the single-component (whitened-only) covariance is used, which
    is conservative (RMS 0.6 when the independent part dominates).
    """
    markers, body, V2_m, V2_b = whitened
    J = np.asarray(prob.jacobian_at(res.params, jac="analytic"))
    r = np.concatenate([np.ravel(markers(res.params)), np.ravel(body(res.params))])
    m = len(r)
    n_m = len(V2_m)
    V2 = np.zeros((m, m))
    V2[:n_m, :n_m] = V2_m
    V2[n_m:, n_m:] = V2_b
    A = np.linalg.inv(J.T @ J)
    M = np.eye(m) - J @ A @ J.T
    MV2M = M @ V2 @ M
    E = np.array([[np.trace(M), np.trace(MV2M)], [np.trace(V2 @ M @ M), np.trace(V2 @ MV2M)]])
    q = np.array([r @ r, r @ V2 @ r])
    s = np.linalg.solve(E, q)
    if not np.all(s >= 0):
        # the components are not separated: the modelled part alone, scaled by the residual variance
        # (conservative: it charges the whole residual to the edge-fit structure, markers included)
        s = np.array([q[0] / E[0, 0], 0.0])
    C = s[0] * np.eye(m) + s[1] * V2
    return A @ (J.T @ C @ J) @ A, s


def predicted_covariance(camera: CameraModel, rectangle: MarkerRectangle, body_points_r, T_r_c, T_c_m,
                         obs_list, sigma_px: float, *, full: bool = False) -> np.ndarray:
    """First-order covariance of ``(rot_rc [rad], t_rc [m])`` (6, 6) for K images at given poses.

    ``sigma_px^2 (J^T J)^-1`` of the joint problem, marginal over the mirror
    poses, with the analytic Jacobian at ``(T_r_c, T_c_m)`` — e.g. the
    simulated truth, for the Monte Carlo comparison. Only the observation
    layout (which points are seen) is taken from ``obs_list``. For K = 1 it is
    the first-order covariance of the patent's single-image estimate.
    With ``full=True`` the whole ``(6 + 6K, 6 + 6K)`` matrix is returned, in
    the order ``rot_rc, t_rc, rot_cm (K x 3), t_cm (K x 3)``.
    """
    T_r_c = np.asarray(T_r_c, dtype=float)
    T_c_m = np.asarray(T_c_m, dtype=float).reshape(-1, 4, 4)
    layout = _layout(obs_list, body_points_r, rectangle)
    prob, _, _ = _problem(camera, rectangle, layout, T_r_c, T_c_m, sigma_px)
    J = np.asarray(prob.jacobian_at(None, jac="analytic"))
    cov = np.linalg.inv(J.T @ J)  # residuals are already divided by sigma_px
    return cov if full else cov[:6, :6]
