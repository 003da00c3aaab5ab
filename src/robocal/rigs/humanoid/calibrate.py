"""Joint-offset and camera-mount calibration by Levenberg–Marquardt (seed 001, eqs. 6-8).

Each detected corner ``m = (P_img, P_cb, theta)`` gives the residual
``P_img - Proj(theta + alpha, P_cb; offsets)``; the sum of squares is
minimised over the selected parameters, starting from zero (seed 001). The
Jacobian is analytic (:meth:`HumanoidModel.project`) or SciPy's finite
differences. The result carries the residual RMS in x and y, per-view
residuals, outlier corners by view and corner, and the identifiability
analysis of the shared estimation layer: rank, condition number, standard
deviations, strongest correlations, and no value for a parameter the data do
not determine. Corners missing from a view (NaN: removed at detection) are
left out of it; optionally (``reject_outliers``) the named outliers are removed
too and the problem re-solved once. Each view is one residual term holding
only its kept corners, so every count (degrees of freedom, residual variance,
RMS) is over the corners actually used.

The pieces live beside this module and are re-exported here: the problem
(:mod:`.problem`), the data checks (:mod:`.consistency`) and the outcome
(:mod:`.calibration`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import (ImplausibleInputError, InconsistentDataError, InputError, NonFiniteError,
                             NotEnoughDataError)
from robocal.estimation import LSQResult, analyze_jacobian, outlier_threshold, solve
from robocal.estimation import outlier_sigma as bonferroni_sigma
from robocal.rigs.humanoid.calibration import HumanoidCalibration, by_view_text
from robocal.rigs.humanoid.consistency import (NOMINAL_MIN_PX, NOMINAL_RATIO, PLAUSIBLE_OFFSET,
                                               check_options, check_views_consistent, implausible_offsets,
                                               plausibility_warnings)
from robocal.rigs.humanoid.model import FEET, HumanoidModel
from robocal.rigs.humanoid.problem import (PARAMETER_SETS, build_problem, choose_gauge, corner_noise,
                                           noise_weights, present_corners, resolve_parameters, valid_views)
from robocal.rigs.humanoid.simulate import JOINT_RESOLUTION, HumanoidDataset

__all__ = ["PARAMETER_SETS", "resolve_parameters", "HumanoidCalibration", "calibrate", "check_options",
           "build_problem", "noise_weights", "corner_noise",
           "choose_gauge", "check_views_consistent", "plausibility_warnings", "implausible_offsets",
           "NOMINAL_MIN_PX", "NOMINAL_RATIO", "PLAUSIBLE_OFFSET"]

def calibrate(model: HumanoidModel, data: HumanoidDataset, *, parameters: str | Sequence[str] = "seed",
              tie: bool = False, jac: str = "analytic", method: str = "lm", x0=None,
              corner_sigma: float | None = None, joint_resolution: float = JOINT_RESOLUTION,
              outlier_sigma: float | None = None, progress: bool = False,
              check_consistency: bool = True, consistency_px: float = NOMINAL_MIN_PX,
              consistency_ratio: float = NOMINAL_RATIO, reject_outliers: bool = False,
              max_rejected_fraction: float = 0.25, accept_implausible: bool = False,
              declared: dict | None = None) -> HumanoidCalibration:
    """Estimate the selected offsets from the corners of every view.

    Parameters
    ----------
    model : HumanoidModel
    data : HumanoidDataset
        Views with corners. NaN corners (removed at detection) are left out of
        their view; a view without any corner (board not fully found) is
        dropped with a message.
    parameters : str or sequence of str
        See :func:`resolve_parameters`; default the seed's 21.
    tie : bool
        One offset for both HipYawPitch joints (one motor).
    jac : {'analytic', '2-point', '3-point'}
    method : {'lm', 'trf'}
        ``'lm'`` is the seed's Levenberg–Marquardt.
    x0 : array_like, optional
        Start (default zero offsets, as the seed) and value of fixed parameters.
    corner_sigma : float, optional
        Corner noise [px]. Default: measured by :func:`corner_noise` after a
        first LM pass from zero (0.3 px assumed in that pass), then a second
        pass from there with the noise model complete. Only its ratio to the
        joint error changes the estimate; the covariance is rescaled by the
        residual variance.
    joint_resolution : float
        Joint sensor resolution [rad] (0.1 deg); its quantisation error (std
        ``resolution / sqrt(12)``) enters the per-view noise model (see
        :func:`noise_weights`). 0 treats the readings as exact.
    outlier_sigma : float, optional
        Corners whose residual exceeds this many sigma (chi-square(2) test on
        the 2x2 noise block, scaled by the residual variance) are named.
        Default: :func:`robocal.estimation.outlier_sigma` of the number of
        present corners (Bonferroni: 1 % chance of naming any corner of clean
        data; 384 corners: 4.2 sigma). The test is the rig's own, per corner,
        because the solver's observations are whole views (the joint-reading
        noise correlates a view's corners), which cannot name a corner.
    reject_outliers : bool
        Remove the corners named as outliers (``outlier_sigma``) and re-solve once from the
        solution, with the noise model marginalised to the kept corners (:func:`build_problem`
        ``keep``) and, when ``corner_sigma`` is measured, the corner noise re-measured without them.
        What was removed is reported (``rejected_corners``, ``rejected_views``, a ``low_quality``
        warning); corners still beyond ``outlier_sigma`` afterwards are named, not removed.
    max_rejected_fraction : float
        With ``reject_outliers``, a view with more than this fraction of its corners flagged is
        removed whole (its detection or joint record, not single corners, is then suspect).
    check_consistency : bool
        Refuse views whose corners are far from where the joint record and
        foot label put them (:func:`check_views_consistent`), and warn
        (``inconsistent_data``) about implausible offsets after the solve
        (:func:`plausibility_warnings`).
        With it, the data set is first checked for the likely slips
        (:func:`robocal.rigs.humanoid.slips.check_data`: transposed board, mirrored images, square,
        board centre or joint records in the wrong unit, swapped feet, reversed image list) and
        joint/camera offsets beyond :data:`PLAUSIBLE_OFFSET` after the solve are implausible
        (:class:`~robocal.errors.ImplausibleInputError`, naming the slip when one explains it).
    consistency_px, consistency_ratio : float
        The thresholds of that check [px, -]: a view is refused beyond
        ``max(consistency_px, consistency_ratio * median view)`` (defaults 60 px, 4).
    accept_implausible : bool
        Go on with implausible data as given: an ``implausible_input`` warning instead of the error
        (CLI ``--accept-implausible``).
    declared : dict, optional
        Units the data set's fields were written in (``load_dataset``'s ``info["declared"]``), so a
        slip is named in the file's units; default SI.

    Returns
    -------
    HumanoidCalibration
    """
    free = check_options(model, parameters=parameters, corner_sigma=corner_sigma,
                         joint_resolution=joint_resolution, consistency_px=consistency_px,
                         consistency_ratio=consistency_ratio, max_rejected_fraction=max_rejected_fraction)
    if x0 is not None:
        x0 = np.asarray(x0, dtype=float)
        n_labels = len(model.parameter_labels())
        if x0.shape != (n_labels,) or not np.all(np.isfinite(x0)):
            raise InputError(f"x0: expected {n_labels} finite start values (model.parameter_labels()), got "
                             f"shape {x0.shape}" + ("" if np.all(np.isfinite(x0)) else " with NaN or infinity"))
    messages = list(data.messages)
    ok = valid_views(data)
    for v in np.flatnonzero(~ok):
        if not any(m.startswith(f"view {data.names[v]!r}:") and "dropped" in m for m in messages):
            # (detection has said so already, with the reason)
            messages.append(f"view {data.names[v]!r}: no corners (board not fully or not correctly detected), "
                            f"view dropped")
    used = data.subset(ok)
    if used.n_views == 0:
        raise NotEnoughDataError("no view with a fully detected board")
    missing = [f for f in FEET if any(lab.startswith(f"board.{f}.") for lab in free) and f not in used.feet]
    if missing:
        raise NotEnoughDataError(f"no usable view of the {missing[0]} board, but its mounting offsets are "
                                 f"selected; drop them from the parameters or add views")
    present = present_corners(used)  # corners removed at detection are NaN: left out of their view
    missing_corners = [(used.names[v], int(c)) for v, c in zip(*np.nonzero(~present))]
    n_res = 2 * int(present.sum())
    if outlier_sigma is None:
        # the corner test runs over every present corner: its threshold grows with their number
        # (Bonferroni, the estimation layer's one default)
        outlier_sigma = bonferroni_sigma(int(present.sum()))
    if n_res < len(free):
        raise NotEnoughDataError(f"{n_res} residuals for {len(free)} parameters")
    slip_warnings: list[Diagnostic] = []
    if check_consistency:
        from robocal.rigs.humanoid.slips import check_data

        slip_warnings = check_data(model, used, declared=declared, consistency_px=consistency_px,
                                   accept_implausible=accept_implausible)
        if not slip_warnings:  # accepted implausible data would only be refused view by view here
            try:
                check_views_consistent(model, used, x0, min_px=consistency_px, ratio=consistency_ratio)
            except InconsistentDataError as exc:
                # some views only: a slip such as two swapped joint columns can explain them all
                from robocal.rigs.humanoid.slips import name_slip

                name_slip(model, used, declared=declared, consistency_px=consistency_px)
                raise exc
    joint_sigma = joint_resolution / np.sqrt(12.0)
    sig = 0.3 if corner_sigma is None else float(corner_sigma)
    prob, S = build_problem(model, used, free, tie=tie, x0=x0, analytic=True,
                            corner_sigma=sig, joint_sigma=joint_sigma)
    # Gauge: along each null-space direction LM would wander, so hold one parameter per direction
    # at its start value (k parameters for a k-dimensional null space) and solve for all others.
    # Parameters orthogonal to the null space are estimable: their least-squares estimate does not
    # depend on which point of the solution set the gauge picks, so they stay unbiased; the ones
    # with a null-space component are gauge-dependent and get no value. Holding every such
    # parameter instead (k' > k) removes directions the data do determine and biases the rest.
    pre = analyze_jacobian(prob.jacobian_at(), prob.free_labels)
    undetermined = list(pre.unidentifiable)
    # (a null direction spread so thinly that no parameter reaches the 0.1 component of
    # analyze_jacobian is left to LM, as before: nothing is held or withheld for it)
    gauge = choose_gauge(pre) if undetermined else []
    warn_held = None
    if undetermined:
        tied_to = {lab: prob.ties[lab][0] for lab in prob.ties} if prob.ties else {}
        undetermined += [lab for lab, master in tied_to.items() if master in undetermined]
        held_all = set(gauge) | {lab for lab, master in tied_to.items() if master in gauge}
        solvable = [lab for lab in free if lab not in held_all]
        if not solvable or all(lab in undetermined for lab in solvable):
            raise NotEnoughDataError(f"the {used.n_views} view(s) determine none of the selected parameters "
                                     f"({', '.join(undetermined)}): add views (`robocal humanoid plan` shows "
                                     f"how many poses determine the offsets) or select fewer parameters "
                                     f"(--params)")
        k = len(pre.labels) - pre.rank
        warn_held = Diagnostic(
            "rank_deficient",
            f"the poses do not determine {', '.join(undetermined)} (Jacobian rank {pre.rank} of "
            f"{len(pre.labels)} at the start; unobservable: {'; '.join(pre.null_directions())}): no value "
            f"reported for them; {', '.join(gauge)} held at the start value to fix the {k} null "
            f"direction(s), the others are estimated", params=tuple(undetermined))
        free = solvable
        gauge = sorted(held_all, key=model.parameter_labels().index)
    prob, S = build_problem(model, used, free, tie=tie, x0=x0, analytic=(jac == "analytic"),
                            corner_sigma=sig, joint_sigma=joint_sigma)
    try:
        res = _solve(prob, method=method, jac=None if jac == "analytic" else jac, progress=progress)
    except ImplausibleInputError:  # diverged (a NaN corner): name the slip behind it when one explains it
        if check_consistency:
            from robocal.rigs.humanoid.slips import name_slip

            name_slip(model, used, declared=declared, consistency_px=consistency_px)
        raise
    first_iterations = res.iterations
    first_history = np.asarray(res.cost_history)
    two_pass = False
    if corner_sigma is None and joint_sigma > 0:
        # Second pass with the corner noise measured where joint errors cannot reach.
        sig = corner_noise(model, used, res.params["p"].reshape(-1), present)
        prob, S = build_problem(model, used, free, tie=tie, x0=res.params["p"].reshape(-1),
                                analytic=(jac == "analytic"), corner_sigma=sig, joint_sigma=joint_sigma)
        res = _solve(prob, method=method, jac=None if jac == "analytic" else jac, progress=progress)
        two_pass = True
    params = res.params["p"].reshape(-1)
    V, N = used.corners.shape[:2]
    resid, view_rms, score, flat = _corner_stats(model, used, params, S, res.residual_variance, outlier_sigma,
                                                 present)
    keep, rejected, rejected_views = present, [], []
    outlier_warning = None
    if reject_outliers and flat.size:
        # Drop the flagged corners (a view that loses more than max_rejected_fraction of its corners as
        # a whole: so many bad corners say its detection or joint record is wrong) and re-solve once, from
        # the solution, with the noise model of the kept corners.
        keep = present.copy()
        keep.reshape(-1)[flat] = False
        lost = (present & ~keep).sum(axis=1)  # flagged now (corners missing from the data not counted)
        whole = np.flatnonzero(lost > max_rejected_fraction * N)
        rejected = [(used.names[int(i) // N], int(i) % N) for i in flat if int(i) // N not in whole]
        rejected_views = [used.names[v] for v in whole]
        keep[whole] = False
        gone = [f for f in FEET if any(lab.startswith(f"board.{f}.") for lab in free)
                and not keep[[i for i, ft in enumerate(used.feet) if ft == f]].any()]
        if gone or keep.sum() * 2 < len(free):
            raise NotEnoughDataError(f"--reject-outliers: removing the outlier corners ({len(flat)}) leaves "
                                     + (f"no view of the {gone[0]} board" if gone else "too few corners")
                                     + "; check the data or calibrate without rejection")
        first_outliers = [(used.names[int(i) // N], int(i) % N) for i in flat]
        outlier_warning = _outlier_diagnostic(first_outliers, flat, outlier_sigma, int(present.sum()),
                                              " (before rejection)")
        if corner_sigma is None and joint_sigma > 0:
            sig = corner_noise(model, used, params, keep)
        prob, S = build_problem(model, used, free, tie=tie, x0=params, analytic=(jac == "analytic"),
                                corner_sigma=sig, joint_sigma=joint_sigma, keep=keep)
        res = _solve(prob, method=method, jac=None if jac == "analytic" else jac, progress=progress)
        params = res.params["p"].reshape(-1)
        resid, view_rms, score, flat = _corner_stats(model, used, params, S, res.residual_variance,
                                                     outlier_sigma, keep)
    outliers = [(used.names[int(i) // N], int(i) % N) for i in flat]
    warnings = [w for w in res.warnings if w.code != "outliers"]
    if warn_held is not None:
        warnings.insert(0, warn_held)
    if outlier_warning is not None:
        warnings.append(outlier_warning)
        text = by_view_text(rejected)
        if rejected_views:
            text += ("; " if text else "") + f"whole view(s) {rejected_views} (more than " \
                    f"{100 * max_rejected_fraction:.0f} % of their corners beyond {outlier_sigma:.3g} sigma)"
        removed = present & ~keep
        warnings.append(Diagnostic("low_quality", f"--reject-outliers: removed {int(removed.sum())} corner(s) "
                                                  f"and re-solved once: {text}",
                                   indices=tuple(int(i) for i in np.flatnonzero(removed.reshape(-1)))))
    if outliers:
        warnings.append(_outlier_diagnostic(outliers, flat, outlier_sigma, int(present.sum()),
                                            " (after rejection, kept)" if outlier_warning is not None else ""))
    if missing_corners:
        warnings.append(Diagnostic("low_quality", f"{len(missing_corners)} corner(s) removed at detection, left "
                                                  f"out of their views: {by_view_text(missing_corners)}",
                                   indices=tuple(int(i) for i in np.flatnonzero(~present.reshape(-1)))))
    dropped = [i for i, good in enumerate(ok) if not good]
    if dropped:
        warnings.append(Diagnostic("dropped", f"{len(dropped)} view(s) without a fully and correctly detected "
                                              f"board were dropped: {[data.names[i] for i in dropped]}",
                                   indices=tuple(dropped)))
    warnings = slip_warnings + warnings
    if check_consistency:
        vr = np.where(keep.any(axis=1), view_rms, np.nan)
        big = implausible_offsets(model, free, params)
        if big and not slip_warnings:  # (an accepted slip has said why already)
            rms = float(np.sqrt(np.nanmean(resid[keep] ** 2))) if keep.any() else float("nan")
            from robocal.rigs.humanoid.slips import check_data

            # the slips of the pre-check, tried now whatever the corner distance: the offsets say the data
            # are wrong, the distance figure says which slip explains them
            warnings += check_data(
                model, used, declared=declared, consistency_px=consistency_px, accept_implausible=accept_implausible,
                implausible_answer="implausible offsets (> {:.0f} deg) for an assembled robot: {} (reprojection RMS "
                                   "{:.3g} px); check the joint records, foot labels and model".format(
                                       np.degrees(PLAUSIBLE_OFFSET), ", ".join(f"{a} {b:+.1f} deg" for a, b in big),
                                       rms))
        warnings += plausibility_warnings(model, free, params, vr, used.names, res.residual_variance,
                                          offsets=bool(slip_warnings))
    selected = [lab for lab in model.parameter_labels() if lab in free or lab in gauge]
    return HumanoidCalibration(model, used, res, params, selected, resid, view_rms, outliers, messages,
                               warnings, score, sig, joint_resolution, first_iterations, list(gauge),
                               first_history, undetermined=undetermined, rank=pre.rank,
                               n_params=len(pre.labels), two_pass=two_pass, keep=keep,
                               rejected_corners=rejected, rejected_views=rejected_views,
                               missing_corners=missing_corners, reject_outliers=bool(reject_outliers),
                               outlier_sigma=float(outlier_sigma))


def _solve(prob, **kw) -> LSQResult:
    """:func:`robocal.estimation.solve`, with a NaN residual turned into the one-line reason.

    The forward model returns NaN for a corner behind the camera (``project(check=False)``): LM only
    gets there when the corners and joint records cannot come from one robot (the slips
    :func:`robocal.rigs.humanoid.slips.check_data` names, or data accepted despite them), and
    wanders through offsets of tens of radians before. The parameter dump of the solver's message
    would tell the user nothing."""
    try:
        return solve(prob, **kw)
    except NonFiniteError:
        # the start is finite (zero offsets, or the previous pass's solution) and so are the kept
        # corners: a non-finite residual or Jacobian can only come from where LM went
        raise ImplausibleInputError(
            "the fit diverged: the offsets grew until a board fell behind the camera (a NaN corner), so "
            "the corners and joint records cannot come from one robot; check the joint records and their "
            "unit, the feet, the board (rows, cols, square, centre) and the camera") from None


def _corner_stats(model, data, params, S, residual_variance, outlier_sigma, keep=None):
    """Residuals (V, N, 2) [px], per-view RMS (V,) over the kept corners, outlier scores (V, N) and the
    flat indices of the kept corners beyond ``outlier_sigma``: each corner's raw residual against its
    own 2x2 noise block (chi-square(2)), scaled by the residual variance."""
    V, N = data.corners.shape[:2]
    resid = model.project(data.theta, data.feet, params, check=False) - data.corners
    k = np.all(np.isfinite(resid), axis=2) if keep is None else keep
    sq = np.sum(resid ** 2, axis=2)
    # a view without kept corners (removed whole) reports the RMS of its present ones
    k_rms = np.where(k.any(1)[:, None], k, np.isfinite(sq))
    view_rms = np.sqrt(np.sum(np.where(k_rms, sq, 0.0), 1) / np.maximum(k_rms.sum(1), 1) / 2)
    idx = np.arange(N)
    blocks = np.stack([np.stack([S[:, 2 * idx, 2 * idx], S[:, 2 * idx, 2 * idx + 1]], -1),
                       np.stack([S[:, 2 * idx + 1, 2 * idx], S[:, 2 * idx + 1, 2 * idx + 1]], -1)], -2)
    score = np.einsum("vni,vnij,vnj->vn", resid, np.linalg.inv(blocks), resid) / residual_variance
    thr = outlier_threshold(outlier_sigma, 2)
    flat = np.flatnonzero((score > thr).reshape(-1) & k.reshape(-1))
    return resid, view_rms, score, flat


def _outlier_diagnostic(outliers, flat, outlier_sigma, n_corners, note="") -> Diagnostic:
    text = by_view_text(outliers)
    return Diagnostic("outliers", f"{len(outliers)} corner residuals beyond {outlier_sigma:.3g} sigma"
                                  f"{note} ({100 * len(outliers) / n_corners:.1f} %): {text}",
                      indices=tuple(int(i) for i in flat))
