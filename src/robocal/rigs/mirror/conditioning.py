"""A pose's conditioning told in words (issue 14): "rotation about z_c (the camera's optical axis) is determined
to 6 deg", from its covariance and, with the solver's record, the weakest combination of the whole problem.

Split from :mod:`robocal.rigs.mirror.markerless`, which re-exports :func:`conditioning`.
"""

from __future__ import annotations

import numpy as np

from robocal.estimation import LSQResult

__all__ = ["conditioning"]


_CAMERA_AXES = {"x_c (the camera's right)": [1, 0, 0], "y_c (the camera's down)": [0, 1, 0],
                "z_c (the camera's optical axis)": [0, 0, 1]}
_ROBOT_AXES = {"x_r (forward)": [1, 0, 0], "y_r (left)": [0, 1, 0], "z_r (up)": [0, 0, 1]}


def _named(v, axes: dict, frame: str) -> str:
    v = np.asarray(v, dtype=float) / np.linalg.norm(v)
    best = max(axes, key=lambda a: abs(v @ axes[a]))
    if abs(v @ axes[best]) >= np.cos(np.radians(25.0)):
        return best
    return f"[{v[0]:+.2f}, {v[1]:+.2f}, {v[2]:+.2f}] in {frame}"


def conditioning(cov, T_r_c, lsq: LSQResult | None = None) -> dict:
    """The pose's weakest directions in words, from its 6 x 6 covariance (rotvec left [rad], t [m]).

    Returns ``{"condition_number", "rotation_text", "translation_text",
    "weakest_parameters", "text"}``: e.g. "rotation about z_c (the camera's
    optical axis) is determined to 6.1 deg (1 sigma)". The rotation's axis
    is the covariance's principal direction, in the camera frame (a left,
    robot-side rotation vector ``w`` is ``R_rc^T w`` there); the translation's
    in the robot frame. With ``lsq``: its condition number (column-scaled
    Jacobian) and the parameters that dominate the smallest singular
    direction of the whole problem (planes included).
    """
    cov = np.asarray(cov, dtype=float)
    R_rc = np.asarray(T_r_c, dtype=float)[:3, :3]
    out: dict = {}
    if np.all(np.isfinite(cov)):
        w, V = np.linalg.eigh(cov[:3, :3])
        axis_c = R_rc.T @ V[:, -1]
        out["rotation_text"] = (f"rotation about {_named(axis_c, _CAMERA_AXES, 'the camera frame')} is determined "
                                f"to {np.degrees(np.sqrt(max(w[-1], 0))):.2g} deg (1 sigma; best axis "
                                f"{np.degrees(np.sqrt(max(w[0], 0))):.2g} deg)")
        w, V = np.linalg.eigh(cov[3:, 3:])
        out["translation_text"] = (f"position along {_named(V[:, -1], _ROBOT_AXES, 'the robot frame')} is "
                                   f"determined to {np.sqrt(max(w[-1], 0)) * 1e3:.3g} mm (best direction "
                                   f"{np.sqrt(max(w[0], 0)) * 1e3:.3g} mm)")
    else:
        out["rotation_text"] = out["translation_text"] = "not determined (singular covariance)"
    text = f"{out['rotation_text']}; {out['translation_text']}"
    if lsq is not None:
        out["condition_number"] = float(lsq.condition_number)
        J = lsq.jac.toarray() if hasattr(lsq.jac, "toarray") else np.asarray(lsq.jac) if lsq.jac is not None else None
        if J is not None and J.size:
            Js = J / np.where(np.linalg.norm(J, axis=0) > 0, np.linalg.norm(J, axis=0), 1.0)
            v = np.linalg.svd(Js)[2][-1]
            top = np.argsort(-np.abs(v))[:3]
            out["weakest_parameters"] = [[lsq.free_labels[i], float(v[i])] for i in top]
            names = ", ".join(f"{lsq.free_labels[i]} ({v[i]:+.2f})" for i in top if abs(v[i]) > 0.2)
            text += (f"; condition number {lsq.condition_number:.3g} (column-scaled Jacobian), weakest "
                     f"combination mostly {names}")
    out["text"] = text
    return out
