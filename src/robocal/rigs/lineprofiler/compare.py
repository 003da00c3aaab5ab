"""Error measures of repeated calibrations (seed 004 §4.3, eqs. 13-15) and the FPDP vs MCT re-run.

``X`` is written as rotation axis ``v`` (unit), angle ``theta`` and translation
``p`` (eqs. 13-15). Over repeated calibrations the mean is the reference (the
seed has no ground truth): ``e_v = |v_i - v_mean|``, ``e_theta = |theta_i -
theta_mean|``, ``e_p = |p_i - p_mean|``. In simulation the error against the
truth is reported as well.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.errors import InputError
from robocal.geometry import rotvec_from_matrix
from robocal.rigs.lineprofiler.fpdp import fpdp_calibrate
from robocal.rigs.lineprofiler.mct import mct_calibrate
from robocal.rigs.lineprofiler.model import LineProfilerRig
from robocal.rigs.lineprofiler.refine import refine_sphere
from robocal.rigs.lineprofiler.simulate import perturbed_chain, simulate_fpdp, simulate_mct

__all__ = ["axis_angle_translation", "repeatability_errors", "ComparisonResult", "run_comparison",
           "plot_comparison"]


def axis_angle_translation(X):
    """Eqs. 13-15: unit axis ``v`` (3,), angle ``theta`` (rad) and translation ``p`` (3,) of ``X`` (4, 4)."""
    rv = rotvec_from_matrix(np.asarray(X, float)[:3, :3])
    theta = float(np.linalg.norm(rv))
    v = rv / theta if theta > 0 else np.array([0.0, 0.0, 1.0])
    return v, theta, np.asarray(X, float)[:3, 3].copy()


def repeatability_errors(Xs, *, components=(0, 1, 2)):
    """``(e_v, e_theta, e_p)`` per calibration against their mean (seed §4.3).

    ``components`` selects the translation components used in ``e_p`` (FPDP on
    a P1R2P3 arm leaves one undetermined: leave it out rather than count a 0).
    """
    vs, ths, ps = zip(*(axis_angle_translation(X) for X in Xs))
    vs, ths, ps = np.array(vs), np.array(ths), np.array(ps)[:, list(components)]
    vm = vs.mean(axis=0)
    vm /= np.linalg.norm(vm)
    return (np.linalg.norm(vs - vm, axis=1), np.abs(ths - ths.mean()), np.linalg.norm(ps - ps.mean(axis=0), axis=1))


@dataclass
class ComparisonResult:
    """FPDP, geometric refinement and MCT over ``n_runs`` simulated experiments."""

    X_true: np.ndarray
    X: dict  # method -> list of (4, 4)
    e_v: dict
    e_theta: dict
    e_p: dict
    err_true_rot: dict  # rad, vs truth
    err_true_t: dict  # m, vs truth (determined components only)
    undetermined: tuple
    components: tuple
    extra: dict = field(default_factory=dict)


def run_comparison(rig: LineProfilerRig, rng: np.random.Generator, *, n_runs: int = 3, n_poses: int = 16,
                   sigma_length: float = 0.3e-3, sigma_angle: float = np.deg2rad(0.1),
                   sigma_q=(0.02e-3, np.deg2rad(0.02), 0.02e-3), progress=None) -> ComparisonResult:
    """Re-run the seed's comparison (3 experiments x 16 poses) in simulation.

    The real arm differs from its model by D-H errors (``sigma_length``,
    ``sigma_angle``, drawn once: the same arm in every run) and each joint
    reading carries encoder/backlash noise ``sigma_q`` (for MCT: P3's, on the
    line and block-scan readings). FPDP moves all joints and uses the whole
    model; MCT moves only R2 and P3 and uses link 3's row.

    Methods (keys of ``X``, ``e_v``, ...): ``"FPDP"`` (linear), ``"refine, q exact"``
    (the geometric refinement taking the joint readings as exact: every
    point an independent observation), ``"FPDP+refine"`` (the refinement
    with the stated joint noise ``sigma_q``: one joint correction per pose,
    errors in variables) and ``"MCT"``. With joint noise the readings'
    errors, shared by all points of a profile, dominate; the "q exact"
    refinement weights the poses by their point count and is then barely
    more repeatable than FPDP in the rotation angle (its ``e_theta`` exceeds
    FPDP's in about a third of the runs), see docs/rigs/lineprofiler.md.
    ``extra["std"]`` holds the std each refinement reports (rad, m).
    """
    if int(n_runs) < 2:
        raise InputError(f"n_runs must be >= 2: the error measures are spreads about the mean of the runs, "
                         f"got {n_runs}")
    true_chain = perturbed_chain(rig.chain, rng, sigma_length=sigma_length, sigma_angle=sigma_angle)
    X = {"FPDP": [], "refine, q exact": [], "FPDP+refine": [], "MCT": []}
    std = {"refine, q exact": [], "FPDP+refine": []}
    sq = np.broadcast_to(np.asarray(sigma_q, float), (rig.chain.dof,))
    und = ()
    runs = range(n_runs) if progress is None else progress(range(n_runs))
    for _ in runs:
        d, tr = simulate_fpdp(rig, rng, n_poses=n_poses, true_chain=true_chain, sigma_q=sigma_q)
        f = fpdp_calibrate(d.q, d.profiles, rig.chain, d.sphere_radius)
        und = f.undetermined
        hold = [k for k in f.undetermined if k.startswith("X.")]
        q_used, prof_used = d.q[f.used], [d.profiles[i] for i in f.used]
        g0 = refine_sphere(q_used, prof_used, rig.chain, d.sphere_radius, f.X, f.Q, hold=hold)
        g = refine_sphere(q_used, prof_used, rig.chain, d.sphere_radius, g0.X, g0.Q,
                          hold=hold, joint_sigma=sq if np.any(sq > 0) else None)
        m, _ = simulate_mct(rig, rng, true_chain=true_chain, sigma_q3=float(sq[-1]))
        mr = mct_calibrate(m, rig.chain, covariance=False)  # repeatability study: spread, not std
        X["FPDP"].append(f.X)
        X["refine, q exact"].append(g0.X)
        X["FPDP+refine"].append(g.X)
        for k, r in (("refine, q exact", g0), ("FPDP+refine", g)):
            std[k].append([np.nan if r.std[lab] is None else r.std[lab] for lab in
                           ("X.rx", "X.ry", "X.rz", "X.tx", "X.ty", "X.tz")])
        X["MCT"].append(mr.X)
    comps = tuple(i for i, k in enumerate(("X.tx", "X.ty", "X.tz")) if k not in und)
    out = ComparisonResult(rig.X.copy(), X, {}, {}, {}, {}, {}, und, comps,
                           extra={"std": {k: np.array(v) for k, v in std.items()}})
    for k, Xs in X.items():
        c = comps if k != "MCT" else (0, 1, 2)
        out.e_v[k], out.e_theta[k], out.e_p[k] = repeatability_errors(Xs, components=c)
        out.err_true_rot[k] = np.array([np.linalg.norm(rotvec_from_matrix(Xi[:3, :3] @ rig.X[:3, :3].T)) for Xi in Xs])
        out.err_true_t[k] = np.array([np.linalg.norm((Xi[:3, 3] - rig.X[:3, 3])[list(c)]) for Xi in Xs])
    return out


def plot_comparison(cmp: ComparisonResult, ax=None):
    """Bar chart of e_v, e_theta (deg) and e_p (mm) per run and method (seed Fig. 5); returns the axes.

    The legend is the figure's, above the panels (it covers no bar)."""
    from robocal.report import new_figure

    if ax is None:
        _, ax = new_figure(1, 3, size=(11, 3.4))
    methods = list(cmp.X)
    n = len(cmp.X[methods[0]])
    w = 0.8 / len(methods)
    for j, meth in enumerate(methods):
        xs = np.arange(n) + j * w
        ax[0].bar(xs, cmp.e_v[meth], w, label=meth)
        ax[1].bar(xs, np.rad2deg(cmp.e_theta[meth]), w, label=meth)
        ax[2].bar(xs, 1e3 * cmp.e_p[meth], w, label=meth)
    for a, t in zip(ax, ("e_v (axis)", "e_theta [deg]", "e_p [mm]")):
        a.set_title(t)
        a.set_xlabel("experiment")
        a.set_yscale("log")
        a.set_xticks(np.arange(n) + 0.4 - w / 2, [str(i + 1) for i in range(n)])
    # one legend for the three panels, above them: inside a panel it covers a bar
    fig = ax[0].figure
    handles, labels = ax[0].get_legend_handles_labels()
    from matplotlib.layout_engine import ConstrainedLayoutEngine

    if isinstance(fig.get_layout_engine(), ConstrainedLayoutEngine):
        fig.legend(handles, labels, loc="outside upper center", ncols=len(methods), fontsize=8, frameon=False)
    else:
        fig.legend(handles, labels, loc="upper center", ncols=len(methods), fontsize=8, frameon=False)
        fig.subplots_adjust(top=0.8)
    return ax
