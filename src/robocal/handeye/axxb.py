"""Closed-form AX = XB solvers: Tsai-Lenz, Park-Martin, Horaud-Dornaika, Andreff, Daniilidis.

``A_i X = X B_i`` for paired relative motions (:func:`.motions.relative_motions`);
rotation first (each method its own parametrisation), then the translation by
linear least squares with a rank check, except Daniilidis (dual quaternions,
both together).

References: R. Tsai, R. Lenz, IEEE T-RA 5(3), 1989. F. Park, B. Martin, IEEE
T-RA 10(5), 1994. R. Horaud, F. Dornaika, IJRR 14(3), 1995. N. Andreff,
R. Horaud, B. Espiau, 3DIM 1999. K. Daniilidis, IJRR 18(3), 1999.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack as _lapack

from robocal.errors import DegenerateGeometryError, InputError, NotEnoughDataError, ShapeError
from robocal.geometry import matrix_from_quaternion, project_to_rotation, skew
from robocal.handeye._lie import _I3, log_so3, skew3
from robocal.handeye.motions import (MIN_AXIS_SPREAD, MIN_ROTATION, MotionCheck, _check_poses, _eigh3,
                                                       check_motions)

__all__ = ["AXXB_METHODS", "solve_ax_xb"]

AXXB_METHODS = ("tsai", "park", "horaud", "andreff", "daniilidis")


def _quat_from_rotvec(v):
    """Scalar-first quaternions from rotation vectors, *without* sign canonicalisation."""
    th = np.linalg.norm(v, axis=-1)
    k = v / np.maximum(th, 1e-300)[..., None]
    return np.concatenate([np.cos(th / 2)[..., None], np.sin(th / 2)[..., None] * k], axis=-1)


def _aligned_rotvecs(RA, RB, rotvecs=None):
    """Rotation vectors of A and B whose axes correspond (alpha_i ~ R_X beta_i).

    Near a half-turn the axis sign of a rotation vector is arbitrary, so A's
    and B's may disagree; every closed form below then breaks. A first Park
    estimate from the motions below 0.8 pi fixes each sign: where
    ``alpha . R0 beta < 0`` beta is replaced by the same rotation written as
    ``(theta - 2 pi) k``.
    """
    if rotvecs is None:
        alpha = log_so3(RA)                      # SciPy's log map costs more than the closed form here
        beta = log_so3(RB)
    else:
        alpha, beta = rotvecs[0], rotvecs[1].copy()     # the caller's (the motion check's) log maps
    th = _norms(beta)
    safe = th < 0.8 * np.pi
    use = safe if safe.sum() >= 2 else np.ones_like(safe)
    R0 = _rot_park(alpha[use], beta[use])
    flip = np.einsum("ij,ij->i", alpha @ R0, beta) < 0        # alpha_i . R0 beta_i
    if flip.any():
        beta[flip] = beta[flip] * ((th[flip] - 2 * np.pi) / np.maximum(th[flip], 1e-300))[:, None]
    return alpha, beta


def _rot_tsai(alpha, beta):
    """Tsai-Lenz: modified Rodrigues vectors P = 2 sin(theta/2) k; skew(Pa+Pb) P' = Pb - Pa.

    Least squares through the 3 x 3 normal matrix ``sum [s]x^T [s]x = sum(|s|^2) I - S^T S`` (``s = Pa + Pb``)
    and ``sum [s]x^T d = sum d x s`` (``d = Pb - Pa``) rather than ``lstsq`` on the 3M x 3 stack: the
    same solution (the motion check has ensured two axes at least, so the 3 x 3 matrix is well conditioned:
    the spread is >= 2 deg), ~8 NumPy calls instead of an SVD of 3M rows (issue 16).
    """
    ta, tb = _norms(alpha), _norms(beta)
    Pa = alpha * (2 * np.sin(ta / 2) / np.maximum(ta, 1e-300))[:, None]
    Pb = beta * (2 * np.sin(tb / 2) / np.maximum(tb, 1e-300))[:, None]
    S, d = Pa + Pb, Pb - Pa
    N = _I3 * np.einsum("ij,ij->", S, S) - S.T @ S
    D = d.T @ S                                   # sum d s^T: its antisymmetric part is sum d x s
    # LAPACK's dgesv (numpy.linalg.solve's wrapper costs 4x a 3 x 3 solve); info > 0: exactly singular
    # (parallel axes, which the motion check refuses first)
    _, _, Pp, info = _lapack.dgesv(N, np.array([D[1, 2] - D[2, 1], D[2, 0] - D[0, 2], D[0, 1] - D[1, 0]]))
    if info != 0:
        Pp, *_ = np.linalg.lstsq(skew3(S).reshape(-1, 3), d.reshape(-1), rcond=None)
    Px = 2 * Pp / np.sqrt(1 + Pp @ Pp)
    n2 = Px @ Px
    return (1 - n2 / 2) * _I3 + 0.5 * (np.outer(Px, Px) + np.sqrt(4 - n2) * skew3(Px))


def _norms(v):
    """Row norms of (M, 3) vectors (``np.linalg.norm(v, axis=-1)`` without its per-call overhead)."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def _nearest_rotation(M):
    """:func:`robocal.geometry.project_to_rotation` of one finite 3 x 3 matrix, without its validation.

    LAPACK's dgesdd through scipy.linalg.lapack (numpy.linalg's wrapper costs more than a 3 x 3 SVD) and
    the determinant of ``U V^T`` as the product of its factors' (+-1 each), numpy's SVD where LAPACK fails.
    """
    U, _, Vt, info = _lapack.dgesdd(M)
    if info != 0:
        U, _, Vt = np.linalg.svd(M)
    if _det3(U) * _det3(Vt) < 0:
        U[:, -1] = -U[:, -1]
    return U @ Vt


def _det3(A) -> float:
    """Determinant of a 3 x 3 matrix (Python floats: the sign of an orthogonal factor)."""
    (a, b, c), (d, e, f), (g, h, i) = A.tolist()
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


def _rot_park(alpha, beta):
    """Park-Martin: M = sum beta_i alpha_i^T, R = (M^T M)^-1/2 M^T (log-map Procrustes).

    ``(M^T M)^-1/2 M^T`` is the orthogonal polar factor of ``M^T = sum alpha_i beta_i^T``: the nearest
    rotation to it, one 3 x 3 SVD (it also stays a rotation when M is rank deficient).
    """
    return _nearest_rotation(alpha.T @ beta)


def _qleft(q):
    w, x, y, z = q
    return np.array([[w, -x, -y, -z], [x, w, -z, y], [y, z, w, -x], [z, -y, x, w]])


def _qright(q):
    w, x, y, z = q
    return np.array([[w, -x, -y, -z], [x, w, z, -y], [y, -z, w, x], [z, y, -x, w]])


def _qleft_n(q):
    """:func:`_qleft` of each row of q (n, 4): (n, 4, 4)."""
    return np.moveaxis(_qleft(np.moveaxis(q, -1, 0)), (0, 1), (-2, -1))


def _qright_n(q):
    return np.moveaxis(_qright(np.moveaxis(q, -1, 0)), (0, 1), (-2, -1))


def _matrix_from_wxyz(q):
    return matrix_from_quaternion(np.r_[q[1:], q[0]])


def _rot_horaud(alpha, beta):
    """Horaud-Dornaika: q_A q_X = q_X q_B, smallest eigenvector of sum (L(q_A) - R(q_B))^T (...)."""
    Mi = _qleft_n(_quat_from_rotvec(alpha)) - _qright_n(_quat_from_rotvec(beta))
    S = np.einsum("nki,nkj->ij", Mi, Mi)           # sum Mi^T Mi: 4 x 4 whatever the number of motions
    return _matrix_from_wxyz(np.linalg.eigh(S)[1][:, 0])


def _rot_andreff(RA, RB):
    """Andreff: (R_A (x) I - I (x) R_B^T) vec(R_X) = 0 (row-major vec), null vector -> SO(3)."""
    I3 = np.eye(3)
    K = np.einsum("nac,bd->nabcd", RA, I3) - np.einsum("ac,ndb->nabcd", I3, RB)   # kron(R_A, I) - kron(I, R_B^T)
    K = K.reshape(len(RA), 9, 9)
    # normal equations (9 x 9) rather than an SVD of the 9M x 9 stack: memory independent of M
    v = np.linalg.eigh(np.einsum("nki,nkj->ij", K, K))[1][:, 0]
    Rx = v.reshape(3, 3)
    Rx *= np.sign(np.linalg.det(Rx)) / abs(np.linalg.det(Rx)) ** (1 / 3)
    return project_to_rotation(Rx)


def _translation(RA, tA, RB_tB_rot, Rx):
    """(R_A - I) t_X = R_X t_B - t_A stacked, least squares with a rank check.

    Solved on the 3 x 3 normal matrix whose eigen-decomposition the rank check needs anyway (its
    eigenvalues are the squared singular values of the stack): ``t = V diag(1/w) V^T M^T rhs``.
    """
    tB = RB_tB_rot
    M = RA - _I3                                                  # (M, 3, 3) blocks of the stack
    u = tB @ Rx.T - tA                                            # (M, 3) right-hand sides
    w, V = _eigh3(np.einsum("nki,nkj->ij", M, M))
    if np.sqrt(max(w[0], 0.0)) < 1e-6 * np.sqrt(w[-1]):
        v = V[:, 0]
        raise DegenerateGeometryError(
            f"the translation of X along {np.round(v, 3).tolist()} is undetermined (rotation axes parallel)")
    return V @ ((np.einsum("nki,nk->i", M, u) @ V) / w)


def _daniilidis(A, B, rotvecs=None):
    """Daniilidis: dual quaternions, SVD of the 6M x 8 system, two-vector null-space combination."""
    alpha, beta = _aligned_rotvecs(A[:, :3, :3], B[:, :3, :3], rotvecs)

    def dual(T, rv):
        q = _quat_from_rotvec(rv)
        t = np.concatenate([np.zeros((len(T), 1)), T[:, :3, 3]], axis=1)
        return q, 0.5 * np.einsum("nij,nj->ni", _qleft_n(t), q)

    qa, qda = dual(A, alpha)
    qb, qdb = dual(B, beta)
    S = np.zeros((len(A), 6, 8))
    S[:, :3, 0] = qa[:, 1:] - qb[:, 1:]
    S[:, :3, 1:4] = skew(qa[:, 1:] + qb[:, 1:])
    S[:, 3:, 0] = qda[:, 1:] - qdb[:, 1:]
    S[:, 3:, 1:4] = skew(qda[:, 1:] + qdb[:, 1:])
    S[:, 3:, 4] = qa[:, 1:] - qb[:, 1:]
    S[:, 3:, 5:8] = skew(qa[:, 1:] + qb[:, 1:])
    # the right singular vectors of the 6M x 8 stack from its 8 x 8 normal matrix (economy, memory O(1) in
    # M); its two smallest eigenvectors span the null space as the SVD's last two rows do
    Vt = np.linalg.eigh(np.einsum("nki,nkj->ij", S, S))[1][:, ::-1].T
    u1, v1 = Vt[-2, :4], Vt[-2, 4:]
    u2, v2 = Vt[-1, :4], Vt[-1, 4:]
    a_, b_, c_ = u1 @ v1, u1 @ v2 + u2 @ v1, u2 @ v2
    if abs(a_) < 1e-14:
        roots = np.array([-c_ / b_]) if abs(b_) > 1e-14 else np.array([0.0])
    else:
        disc = b_ * b_ - 4 * a_ * c_
        if disc < 0:
            disc = 0.0  # noise only: the exact system has real roots
        roots = (-b_ + np.array([1.0, -1.0]) * np.sqrt(disc)) / (2 * a_)
    vals = roots**2 * (u1 @ u1) + 2 * roots * (u1 @ u2) + u2 @ u2
    k = int(np.argmax(vals))
    l2 = 1 / np.sqrt(vals[k])
    l1 = roots[k] * l2
    q = l1 * u1 + l2 * u2
    qd = l1 * v1 + l2 * v2
    R = _matrix_from_wxyz(q)
    qc = q * np.array([1, -1, -1, -1])
    t = 2 * (_qleft(qd) @ qc)[1:]
    return R, t


_ROT = {"tsai": _rot_tsai, "park": _rot_park, "horaud": _rot_horaud}


def _check_method(method: str) -> str:
    m = str(method).lower().replace("-", "").replace("_", "")
    alias = {"tsailenz": "tsai", "parkmartin": "park", "horauddornaika": "horaud"}
    m = alias.get(m, m)
    if m not in AXXB_METHODS:
        raise InputError(f"method must be one of {', '.join(AXXB_METHODS)}, got {method!r}")
    return m


def solve_ax_xb(A, B, method: str = "tsai", *, min_rotation: float = MIN_ROTATION,
                min_axis_spread: float = MIN_AXIS_SPREAD, pairs=None, times=None) -> tuple[np.ndarray, MotionCheck]:
    """Closed-form solution of ``A_i X = X B_i``.

    Parameters
    ----------
    A, B : array_like, shape (M, 4, 4)
        Paired relative motions (metres), M >= 2 with non-parallel rotation axes.
    method : {'tsai', 'park', 'horaud', 'andreff', 'daniilidis'}
    pairs, times : optional
        The pose pairs ``(i, j)`` behind the motions and the poses' times (s), so that
        :func:`~robocal.handeye.motions.check_motions` names poses, not motions.

    Returns
    -------
    X : ndarray, shape (4, 4)
    check : MotionCheck
    """
    m = _check_method(method)
    A = _check_poses(A, "A")
    B = _check_poses(B, "B")
    if len(A) != len(B):
        raise ShapeError(f"A has {len(A)} motions but B has {len(B)}: counts must match")
    if len(A) < 2:
        raise NotEnoughDataError(f"AX = XB needs at least 2 motions, got {len(A)}")
    return _solve_checked(A, B, m, min_rotation=min_rotation, min_axis_spread=min_axis_spread, pairs=pairs,
                          times=times)


def _solve_checked(A, B, m: str, *, min_rotation: float = MIN_ROTATION, min_axis_spread: float = MIN_AXIS_SPREAD,
                   pairs=None, times=None) -> tuple[np.ndarray, MotionCheck]:
    """:func:`solve_ax_xb` on motions already known to be rigid (products of validated poses), ``m`` a
    checked method name: the excitation check and the closed form, without validating A and B again."""
    # one log map of A and of B for the motion check and the closed form (issue 16)
    rv = (log_so3(A[:, :3, :3]), log_so3(B[:, :3, :3]))
    chk = check_motions(A, B, min_rotation=min_rotation, min_axis_spread=min_axis_spread, pairs=pairs,
                        times=times, _rotvecs=rv)
    if m == "daniilidis":
        R, t = _daniilidis(A, B, rv)
    else:
        if m == "andreff":
            R = _rot_andreff(A[:, :3, :3], B[:, :3, :3])
        else:
            R = _ROT[m](*_aligned_rotvecs(A[:, :3, :3], B[:, :3, :3], rv))
        t = _translation(A[:, :3, :3], A[:, :3, 3], B[:, :3, 3], R)
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, t
    return X, chk
