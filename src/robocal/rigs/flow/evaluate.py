"""Trajectory accuracy in the field's usual terms, and the seed's Fig. 4 plot.

- **ATE** (absolute trajectory error; Sturm et al., IROS 2012, TUM RGB-D
  benchmark): align the estimate to the reference with the least-squares
  rigid transform in the plane (Umeyama 1991 in 2D, :func:`align_trajectory`)
  and take the RMS of the position differences.
- **RPE per distance** (relative pose error; Sturm et al. 2012, with
  KITTI's segments of fixed path length, Geiger et al., CVPR 2012): for every
  start ``i`` and every length ``L``, the frame ``j`` where the reference has
  travelled ``L`` further; ``E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)``; report the
  RMS translation of ``E`` divided by ``L`` (m per m, shown in %) and its
  rotation per metre (deg/m). A segment length is used only when the run's
  path is at least twice as long (two independent segments); on a run shorter
  than twice the headline 0.5 m the lengths become fractions (10, 25, 50 %)
  of its path instead, and the result says so (:func:`rpe_lengths`).

Written from these definitions (no evo: it is GPL).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.errors import DegenerateGeometryError, InputError, NotEnoughDataError
from robocal.rigs.flow.model import median

__all__ = ["TrajectoryErrors", "align_trajectory", "ate", "rpe_lengths", "rpe_per_distance", "evaluate_trajectory",
           "plot_trajectories", "RPE_LENGTHS", "RPE_HEADLINE", "RPE_FRACTIONS"]

#: fixed segment lengths of the RPE (m) and the one shown in tables and on stdout
RPE_LENGTHS = (0.25, 0.5, 1.0)
RPE_HEADLINE = 0.5
#: segment lengths as fractions of the path on a short run (the middle one is the headline)
RPE_FRACTIONS = (0.1, 0.25, 0.5)


def _relative(p, c, s, i, j):
    """Relative motions ``P_i^-1 P_j`` of planar poses ``p (N, 3)`` (``c, s``: cos, sin of their headings):
    the translation in frame ``i`` ``(K, 2)`` and the rotation ``(K,)``, rad (not wrapped).

    In closed form, ``R(-theta_i) (t_j - t_i)`` and ``theta_j - theta_i``, instead of products of 3x3
    homogeneous matrices: 6x less time on a 30 s, 400 Hz run and equal to rounding."""
    d = p[j, :2] - p[i, :2]
    ci, si = c[i], s[i]
    return np.stack([ci * d[:, 0] + si * d[:, 1], ci * d[:, 1] - si * d[:, 0]], axis=1), p[j, 2] - p[i, 2]


def align_trajectory(est, ref):
    """Least-squares rigid 2D alignment (SE(2)) of ``est`` onto ``ref``, poses ``(N, 3)``.

    Umeyama's (1991) closed form in the plane, as Sturm et al. (IROS 2012) and
    Zhang & Scaramuzza (IROS 2018) align for the ATE: with the centred
    positions and ``H = sum e_i r_i^T`` (2x2), the rotation is
    ``atan2(H_01 - H_10, H_00 + H_11)`` (the planar Kabsch solution, a proper
    rotation by construction; :func:`robocal.geometry.rigid_fit` in 2D) and the
    translation matches the centroids. It is
    well defined for collinear positions (a straight drive); only when every
    estimated position coincides (no motion) is the rotation free, and the
    first poses are aligned instead.

    Returns
    -------
    aligned : ndarray (N, 3)
    method : str
    """
    from robocal.geometry import rigid_fit  # here: robocal.geometry imports scipy.spatial

    est = np.asarray(est, float)
    ref = np.asarray(ref, float)
    try:
        fit = rigid_fit(est[:, :2], ref[:, :2], rtol=1e-12)
        yaw, R, t = fit.angle, fit.R, fit.t
        method = "umeyama"
    except DegenerateGeometryError:
        yaw = ref[0, 2] - est[0, 2]
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s], [s, c]])
        t = ref[0, :2] - R @ est[0, :2]
        method = "first-pose (the estimate does not move)"
    xy = est[:, :2] @ R.T + t
    return np.concatenate([xy, (est[:, 2:] + yaw)], 1), method


def ate(est, ref):
    """Absolute trajectory error: RMS position error after rigid alignment, m; and the aligned poses."""
    al, method = align_trajectory(est, ref)
    err = np.linalg.norm(al[:, :2] - np.asarray(ref)[:, :2], axis=1)
    return float(np.sqrt(np.mean(err**2))), al, err, method


def rpe_lengths(distance: float, lengths=RPE_LENGTHS, *, headline: float = RPE_HEADLINE,
                fractions=RPE_FRACTIONS):
    """Segment lengths of the RPE for a run whose reference travels ``distance`` m.

    A length ``L`` gives independent segments only ``distance / L`` times: it is
    kept when ``L <= distance / 2`` (at least two). When the ``headline`` length
    does not fit (a run shorter than ``2 * headline``), the lengths become
    ``fractions`` of the path (rounded to 1 mm), the middle one the headline.

    Returns
    -------
    lengths : tuple of float
        Empty when the reference does not move.
    headline : float or None
        The length to show in one-line summaries.
    note : str
        ``""`` for the fixed lengths as given, else what was changed and why.
    """
    distance = float(distance)
    lengths = tuple(float(L) for L in lengths)
    if not np.isfinite(distance) or distance <= 1e-9:
        return (), None, "the reference does not move: no relative pose error per distance"
    if headline <= distance / 2:
        keep = tuple(L for L in lengths if L <= distance / 2)
        dropped = [L for L in lengths if L > distance / 2]
        note = (f"segments of {', '.join(f'{L:g}' for L in dropped)} m left out: the {distance:.2f} m path holds "
                "fewer than two of them") if dropped else ""
        return keep, headline, note
    fr = tuple(round(f * distance, 3) for f in fractions)
    fr = tuple(L for L in fr if L > 0)
    if not fr:
        return (), None, f"the reference travels only {distance * 1e3:.2f} mm: no relative pose error per distance"
    head = fr[len(fr) // 2]
    note = (f"short run ({distance:.3f} m of path < {2 * headline:g} m): RPE segments are "
            f"{', '.join(f'{f * 100:g}' for f in fractions)} % of the path ({', '.join(f'{L:g}' for L in fr)} m) "
            f"instead of {', '.join(f'{L:g}' for L in lengths)} m")
    return fr, head, note


def rpe_per_distance(est, ref, lengths=(0.5, 1.0)):
    """Relative pose error over segments of fixed reference path length.

    Returns
    -------
    dict: length -> {"trans_rmse": m, "trans_per_m": 1, "rot_per_m": rad/m, "n": int}
        ``trans_per_m``/``rot_per_m`` are RMS over all segment starts; ``*_mean``
        (KITTI) and ``*_median`` (Zhang & Scaramuzza 2018) are also given. A
        length longer than the path has no segment: its entry has ``n = 0``,
        NaN values and a ``"note"`` saying so (:func:`rpe_lengths` picks
        lengths that fit).
    """
    est = np.asarray(est, float)
    ref = np.asarray(ref, float)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ref[:, :2], axis=0), axis=1))])
    ce, se, cr, sr = np.cos(est[:, 2]), np.sin(est[:, 2]), np.cos(ref[:, 2]), np.sin(ref[:, 2])
    out = {}
    for L in lengths:
        j = np.searchsorted(s, s + L)
        ok = j < len(s)
        i = np.flatnonzero(ok)
        if i.size == 0:
            out[float(L)] = {"trans_rmse": np.nan, "trans_per_m": np.nan, "rot_per_m": np.nan, "n": 0,
                             "note": f"no segment of {L:g} m: the reference travels {s[-1]:.3f} m"}
            continue
        j = j[ok]
        dq, aq = _relative(ref, cr, sr, i, j)
        dp, ap = _relative(est, ce, se, i, j)
        # E = Q_rel^-1 P_rel: its translation R(-aq) (dp - dq) has the norm of dp - dq; its rotation ap - aq
        te = np.hypot(dp[:, 0] - dq[:, 0], dp[:, 1] - dq[:, 1])
        da = ap - aq
        re = np.abs(np.arctan2(np.sin(da), np.cos(da)))
        seg = s[j] - s[i]
        out[float(L)] = {
            "trans_rmse": float(np.sqrt(np.mean(te**2))),
            "trans_per_m": float(np.sqrt(np.mean((te / seg) ** 2))),
            "rot_per_m": float(np.sqrt(np.mean((re / seg) ** 2))),
            # KITTI averages, Zhang & Scaramuzza report medians: both alongside the RMS
            "trans_per_m_mean": float(np.mean(te / seg)), "trans_per_m_median": median(te / seg),
            "rot_per_m_mean": float(np.mean(re / seg)), "rot_per_m_median": median(re / seg),
            "n": int(i.size),
        }
    return out


@dataclass
class TrajectoryErrors:
    """ATE and RPE of one estimated trajectory against the reference."""

    ate_rmse: float
    final_error: float
    heading_error_final: float
    rpe: dict
    aligned: np.ndarray
    align_method: str
    distance: float
    rpe_headline: float | None = None
    rpe_note: str = ""

    def headline_rpe(self) -> dict:
        """The RPE entry of the headline length (NaN values and ``n = 0`` when there is none)."""
        empty = {"trans_per_m": np.nan, "rot_per_m": np.nan, "trans_rmse": np.nan, "n": 0}
        return self.rpe.get(self.rpe_headline, empty) if self.rpe_headline is not None else empty

    def rpe_label(self) -> str:
        """``"RPE@0.5m"``; on a short run the length chosen from its path."""
        return "RPE" if self.rpe_headline is None else f"RPE@{self.rpe_headline:g}m"

    def to_dict(self) -> dict:
        return {"ate_rmse_m": self.ate_rmse, "final_position_error_m": self.final_error,
                "final_heading_error_rad": self.heading_error_final, "distance_m": self.distance,
                "rpe": {str(k): v for k, v in self.rpe.items()}, "rpe_headline_m": self.rpe_headline,
                "rpe_note": self.rpe_note, "align_method": self.align_method}

    @classmethod
    def from_dict(cls, d: dict) -> "TrajectoryErrors":
        """The errors as :meth:`to_dict` wrote them (a result file's; ``aligned`` is not stored: empty)."""
        def num(v):
            return np.nan if v is None else v

        rpe = {float(k): {n: num(x) for n, x in v.items()} for k, v in (d.get("rpe") or {}).items()}
        head = d.get("rpe_headline_m")
        return cls(num(d["ate_rmse_m"]), num(d["final_position_error_m"]), num(d["final_heading_error_rad"]), rpe,
                   np.empty((0, 3)), d.get("align_method", ""), num(d["distance_m"]),
                   None if head is None else float(head), d.get("rpe_note") or "")


def evaluate_trajectory(est, ref, *, lengths=RPE_LENGTHS) -> TrajectoryErrors:
    """ATE (after alignment), RPE per distance and the raw end-point error of ``est`` vs ``ref`` (both (N, 3)).

    The RPE segment lengths are ``lengths`` (m) where the reference path holds at
    least two of each; on a short run they are fractions of its path
    (:func:`rpe_lengths`; ``rpe_note`` says what was done).
    """
    from robocal.geometry import wrap_angle  # here: robocal.geometry imports scipy.spatial

    est = np.asarray(est, float)
    ref = np.asarray(ref, float)
    if est.shape != ref.shape or est.ndim != 2 or est.shape[1] != 3:
        raise InputError(f"trajectories must both have shape (N, 3), got {est.shape} and {ref.shape}")
    if len(est) < 3:
        raise NotEnoughDataError(f"need at least 3 poses to evaluate a trajectory, got {len(est)}")
    a, al, _, method = ate(est, ref)
    dist = float(np.sum(np.linalg.norm(np.diff(ref[:, :2], axis=0), axis=1)))
    fe = float(np.linalg.norm(est[-1, :2] - ref[-1, :2]))
    he = float(wrap_angle(est[-1, 2] - ref[-1, 2]))
    lengths = sorted(float(L) for L in lengths)
    if not lengths or not all(np.isfinite(L) and L > 0 for L in lengths):
        raise InputError(f"RPE segment lengths must be > 0 m, got {lengths}")
    head = RPE_HEADLINE if RPE_HEADLINE in lengths else lengths[len(lengths) // 2]
    use, head, note = rpe_lengths(dist, lengths, headline=head)
    return TrajectoryErrors(a, fe, he, rpe_per_distance(est, ref, use), al, method, dist, head, note)


def plot_trajectories(curves: dict, *, ax=None, title: str = "trajectories"):
    """Plot named ``(N, 3)`` trajectories (the seed's Fig. 4); returns the axes."""
    from robocal.report import new_figure

    if ax is None:
        _, ax = new_figure(size=(6.0, 5.0))
    styles = {"true": dict(color="k", lw=2.0), "reference": dict(color="k", lw=2.0)}
    for name, p in curves.items():
        p = np.asarray(p)
        ax.plot(p[:, 0], p[:, 1], label=name, **styles.get(name, dict(lw=1.2)))
        ax.plot(p[-1, 0], p[-1, 1], "o", ms=4, color=ax.lines[-1].get_color())
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("X [m]")
    ax.set_ylabel("Y [m]")
    ax.set_title(title)
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    return ax
