"""Agreement between the images of a multi-placement calibration: planar choice by consensus,
single-image estimates against the joint one, and outliers named by image and point.
"""

from __future__ import annotations

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.geometry import rotvec_from_matrix
from robocal.rigs.mirror.joint import _Layout, predicted_covariance
from robocal.rigs.mirror.model import householder_compose, patent_compose
from robocal.rigs.mirror.observation import check_observation
from robocal.rigs.mirror.single import SingleImageResult, _single_warnings

__all__ = []


def _consensus_choice(singles, camera, rectangle, body_points_r, obs_list, sigma_px=None):
    """With several images, re-decide undecided planar choices by agreement of T_r_c.

    The reference camera position is the median over the images whose choice
    was decisive. With none decisive, it is the median of the undecided picks
    themselves: that can still repair a minority of wrong picks, but it is no
    independent evidence, so the switched choices stay ``decisive=False``.
    The residuals and warnings of a switched image are those of the new pose.
    """
    decided = [s for s in singles if s.choice.decisive]
    if len(singles) < 2 or len(decided) == len(singles):
        return singles
    ref = decided if decided else singles
    t_ref = np.median(np.stack([s.T_r_c[:3, 3] for s in ref]), axis=0)
    out = []
    for s, o in zip(singles, obs_list):
        if s.choice.decisive or len(s.choice.T_r_c) < 2:
            out.append(s)
            continue
        dist = np.linalg.norm(s.choice.T_r_c[:, :3, 3] - t_ref, axis=1)
        k = int(np.argmin(dist))
        c = s.choice
        c.chosen = k
        c.decisive = bool(decided) and bool(dist[1 - k] > 2 * dist[k])
        whose = "the decisive images'" if decided else "the median"
        c.reason = (f"ambiguous alone; pose {k} agrees with {whose} camera position "
                    f"({dist[k] * 1e3:.3g} vs {dist[1 - k] * 1e3:.3g} mm)")
        T_c_m = c.T_c_m[k]
        steps = patent_compose(T_c_m, s.steps.T_c_ri)
        _, b_uv, _, P_seen = check_observation(o, body_points_r, rectangle)
        warnings = _single_warnings(P_seen, body_points_r, steps, s.body_residuals, sigma_px, c, o.name,
                                    camera=camera, body_uv=b_uv, rectangle=rectangle)
        m_res = s.marker_residuals if c.marker_residuals is None else c.marker_residuals[k]
        out.append(SingleImageResult(steps, householder_compose(T_c_m, s.steps.T_c_ri), c, m_res,
                                     s.body_residuals, s.sigma_px, warnings))
    return out


def _consistency_warnings(camera, rectangle, P_all, singles, obs_list, T_r_c, sigma_px):
    """Flag images whose own estimate disagrees with the joint one beyond its predicted covariance."""
    from scipy import special  # chi2.isf = chdtri, without scipy.stats' 0.5 s import

    limit = float(special.chdtri(6, 1e-3))
    bad = []
    for k, (s, o) in enumerate(zip(singles, obs_list)):
        sig = sigma_px if sigma_px is not None else s.sigma_px
        C = predicted_covariance(camera, rectangle, P_all, s.T_r_c, s.T_c_m, [o], sig)
        e = np.concatenate([rotvec_from_matrix(s.T_r_c[:3, :3] @ T_r_c[:3, :3].T), s.T_r_c[:3, 3] - T_r_c[:3, 3]])
        if e @ np.linalg.solve(C, e) > limit:
            bad.append(k)
    if not bad:
        return []
    return [Diagnostic("inconsistent_data", f"single-image estimates of images {bad} disagree with the joint "
                       "estimate beyond their predicted covariance (p < 0.001): did the camera move on the body, "
                       "or are some correspondences wrong?", params=("T_r_c",), indices=tuple(bad))]


def _name_outliers(w: Diagnostic, layout: _Layout, obs_list) -> Diagnostic:
    """Rewrite the solver's ``outliers`` warning from flat observation indices to (image, point).

    The solver numbers the observations of all images in one sequence (markers
    of every image, then body points of every image); a user needs the image
    name and the marker letter or the ``body_points`` row.
    """
    if w.code != "outliers" or not w.indices:
        return w
    n_m = 4 * layout.K
    starts = np.cumsum([0] + [len(i) for i in layout.ids])
    named = []
    for g in w.indices:
        if g < n_m:
            named.append(f"{obs_list[g // 4].name}: marker {'ABCD'[g % 4]}")
        else:
            j = g - n_m
            k = int(np.searchsorted(starts, j, side="right") - 1)
            named.append(f"{obs_list[k].name}: body point {int(layout.ids[k][j - starts[k]])}")
    head = w.message.split(":")[0]
    shown = "; ".join(named[:12]) + ("; ..." if len(named) > 12 else "")
    return Diagnostic("outliers", f"{head}: {shown}", params=w.params, indices=w.indices)
