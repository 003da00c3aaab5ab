"""The patent's method on one image (seed 002 §2, eqs. [1]-[7]), with the planar-ambiguity choice.

:func:`calibrate_single`: planar PnP of the four mirror markers (both IPPE
solutions, one chosen with the body points by :func:`choose_planar_solution`),
PnP of the reflected body points with the x-flipped object set, and the
composition of :func:`~robocal.rigs.mirror.model.patent_compose`. The
warnings of one image (degenerate geometry, implausible answers) are here too,
since a later change of the planar choice reruns them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.camera import CameraModel, MarkerRectangle, solve_pnp, solve_pnp_planar
from robocal.diagnostics import Diagnostic
from robocal.errors import ConvergenceError, DegenerateGeometryError, InconsistentDataError, RobocalError
from robocal.geometry import invert_transform, rotation_angle
from robocal.rigs.mirror.checks import handedness_warnings, marker_fit_warnings
from robocal.rigs.mirror.model import PatentSteps, householder_compose, mirror_plane, patent_compose, ri_from_r_points
from robocal.rigs.mirror.observation import MirrorObservation, check_in_image, check_observation

__all__ = ["PlanarChoice", "SingleImageResult", "choose_planar_solution", "calibrate_single", "geometry_warnings",
           "plausibility_warnings", "MIN_GOOD_POINTS", "FLAT_RATIO", "PARALLEL_DEG", "CAMERA_BODY_MAX_M",
           "BODY_EXTENT_RANGE_M", "CHI2_P_MIN"]

#: Below this many body points a warning is issued (the patent uses 10-30).
MIN_GOOD_POINTS = 6
#: Smallest/largest principal spread of the body points below which they count as "too flat".
FLAT_RATIO = 0.05
#: Angle between the optical axis and the mirror plane below which the mirror is "near-parallel".
PARALLEL_DEG = 20.0
#: Camera-to-nearest-body-point distance [m] always accepted as plausible (see plausibility_warnings).
CAMERA_BODY_MAX_M = 1.0
#: Plausible span [m] of the body points (bounding-box diagonal): outside it the unit is suspect.
BODY_EXTENT_RANGE_M = (0.01, 20.0)
#: Chi-square tail probability of the body-point fit below which a known sigma_px is contradicted.
CHI2_P_MIN = 1e-3


@dataclass
class PlanarChoice:
    """Which of the two IPPE poses of the mirror markers was taken, and why.

    Attributes
    ----------
    chosen : int
        Index into ``candidates`` (0 = lower marker reprojection error).
    reason : str
        One sentence for the report.
    decisive : bool
        False when no test separated the two (the choice is then a guess).
    marker_rms_px : ndarray, shape (n,)
        Per candidate, marker reprojection rms per point [px] (2-D residual norm).
    marker_chi2_gap : float
        ``(SSE_other - SSE_chosen) / sigma^2`` of the marker residuals.
    virtual_in_front : ndarray of int, shape (n,)
        Per candidate, how many reflected points would lie in front of the mirror
        (impossible for a real reflection).
    camera_body_distance : ndarray, shape (n,)
        Per candidate, distance from the implied camera centre to the nearest
        body point [m] (the camera is mounted on the body).
    T_c_m : ndarray, shape (n, 4, 4)
    T_r_c : ndarray, shape (n, 4, 4)
        Candidate mirror poses and the camera poses they imply.
    marker_residuals : ndarray, shape (n, 4, 2)
        Per candidate, marker reprojection residuals [px] (so a later switch of
        ``chosen`` keeps residuals and pose together).
    """

    chosen: int
    reason: str
    decisive: bool
    marker_rms_px: np.ndarray
    marker_chi2_gap: float
    virtual_in_front: np.ndarray
    camera_body_distance: np.ndarray
    T_c_m: np.ndarray
    T_r_c: np.ndarray
    marker_residuals: np.ndarray | None = None

    @property
    def ambiguous(self) -> bool:
        """True when IPPE gave two distinct marker poses (so a choice was made)."""
        if len(self.T_c_m) < 2:
            return False
        d_rot = rotation_angle(self.T_c_m[0, :3, :3] @ self.T_c_m[1, :3, :3].T)
        d_t = np.linalg.norm(self.T_c_m[0, :3, 3] - self.T_c_m[1, :3, 3])
        return bool(d_rot >= 1e-6 or d_t >= 1e-6 * np.linalg.norm(self.T_c_m[0, :3, 3]))

    def to_dict(self) -> dict:
        """JSON record; candidate poses in metres, ``T_r_c`` is ``robot -> camera`` of each candidate."""
        return {
            "chosen": int(self.chosen),
            "reason": self.reason,
            "decisive": bool(self.decisive),
            "ambiguous": self.ambiguous,
            # per point (norm of the 2-D residual), unlike single_image[k].marker_rms_px (per coordinate)
            "marker_rms_px_per_point": self.marker_rms_px.tolist(),
            "marker_chi2_gap": float(self.marker_chi2_gap),
            "virtual_in_front": [int(v) for v in self.virtual_in_front],
            "camera_body_distance_m": self.camera_body_distance.tolist(),
            "candidate_T_c_m": self.T_c_m.tolist(),
            "candidate_T_r_c": self.T_r_c.tolist(),
        }


def choose_planar_solution(candidates, T_c_ri, body_points_r, *, sigma_px: float,
                           chi2_decisive: float = 25.0, distance_ratio: float = 2.0) -> PlanarChoice:
    """Pick the mirror pose among the IPPE candidates using the body points.

    Tests, in order (the first that separates the candidates decides):

    1. *Sidedness* — the reflected body points (``T_c_ri`` applied to the
       x-flipped model) must lie behind the mirror plane: a candidate plane
       with any of them in front is impossible.
    2. *Marker fit* — when the marker reprojection error differs by more than
       ``chi2_decisive`` (chi-square units at ``sigma_px``), the better fit.
    3. *Camera on the body* — the composed ``T_r_c`` puts the camera centre at
       some distance from the nearest body point; the camera is mounted on the
       body, so the candidate with the smaller distance wins when the other's
       is ``distance_ratio`` times larger.

    If none separates them the lower-error IPPE pose is kept and
    ``decisive`` is False.
    """
    cands = list(candidates)
    n = len(cands)
    T_c_m = np.stack([c.T_cam_obj for c in cands])
    rms = np.array([c.rms_px for c in cands])
    sse = np.array([np.sum(c.residuals**2) for c in cands])
    p_v = ri_from_r_points(body_points_r) @ T_c_ri[:3, :3].T + T_c_ri[:3, 3]
    nrm, d = mirror_plane(T_c_m)
    in_front = np.array([int(np.sum(p_v @ nrm[i] <= d[i])) for i in range(n)])
    T_r_c = np.stack([invert_transform(householder_compose(T_c_m[i], T_c_ri)) for i in range(n)])
    dist = np.array([np.min(np.linalg.norm(body_points_r - T_r_c[i, :3, 3], axis=1)) for i in range(n)])
    gap = float((sse[1] - sse[0]) / sigma_px**2) if n > 1 else np.inf

    def done(k, reason, decisive=True):
        other_gap = float((sse[1 - k] - sse[k]) / sigma_px**2) if n > 1 else np.inf
        return PlanarChoice(k, reason, decisive, rms, other_gap, in_front, dist, T_c_m, T_r_c,
                            np.stack([np.asarray(c.residuals, dtype=float).reshape(-1, 2) for c in cands]))

    if n == 1:
        return done(0, "IPPE returned a single pose in front of the camera")
    same_rot = rotation_angle(T_c_m[0, :3, :3] @ T_c_m[1, :3, :3].T)
    same_t = np.linalg.norm(T_c_m[0, :3, 3] - T_c_m[1, :3, 3])
    if same_rot < 1e-6 and same_t < 1e-6 * np.linalg.norm(T_c_m[0, :3, 3]):
        return done(0, "both IPPE poses refine to the same pose: no planar ambiguity at this view")
    ok = in_front == 0
    if ok.sum() == 1:
        k = int(np.flatnonzero(ok)[0])
        return done(k, f"with pose {1 - k} of the markers {in_front[1 - k]} reflected body point(s) would lie in "
                       "front of the mirror, which a reflection cannot do")
    if ok.sum() == 0:
        raise InconsistentDataError(
            "body points: under both marker poses some reflected body points lie in front of the mirror; "
            "the body point model (or its x flip) does not match the image"
        )
    if gap > chi2_decisive:
        return done(0, f"the markers fit pose 0 better by chi2 = {gap:.3g} (rms {rms[0]:.3g} vs {rms[1]:.3g} px)")
    k = int(np.argmin(dist))
    if dist[1 - k] > distance_ratio * max(dist[k], 1e-3):
        return done(k, f"pose {k} puts the camera {dist[k]:.3g} m from the nearest body point, pose {1 - k} "
                       f"{dist[1 - k]:.3g} m; the camera is mounted on the body")
    return done(0, f"no test separates the two marker poses (chi2 gap {gap:.3g}, camera-body distances "
                   f"{dist[0]:.3g} / {dist[1]:.3g} m); kept the lower-error IPPE pose", decisive=False)


def geometry_warnings(body_points_r, T_c_m, *, name: str = "image") -> list[Diagnostic]:
    """Degeneracy warnings for one image (see module constants for thresholds)."""
    out = []
    P = np.asarray(body_points_r, dtype=float)
    if P.shape[0] < MIN_GOOD_POINTS:
        out.append(Diagnostic("weakly_determined", f"{name}: only {P.shape[0]} body points seen (the patent uses "
                              f"10-30; fewer than {MIN_GOOD_POINTS} makes PnP fragile)", params=("T_r_c",)))
    s = np.linalg.svd(P - P.mean(axis=0), compute_uv=False)
    if s[0] > 0 and s[-1] / s[0] < FLAT_RATIO:
        out.append(Diagnostic("degenerate_geometry", f"{name}: body points are nearly coplanar (thickness/extent "
                              f"{s[-1] / s[0]:.3g} < {FLAT_RATIO}); their PnP has a planar ambiguity of its own",
                              params=("T_r_c",)))
    n, _ = mirror_plane(T_c_m)
    ang = np.degrees(np.arcsin(min(1.0, abs(float(n[2])))))
    if ang < PARALLEL_DEG:
        out.append(Diagnostic("degenerate_geometry", f"{name}: mirror plane is {ang:.1f} deg from the optical axis "
                              f"(< {PARALLEL_DEG} deg): markers and reflections are seen at grazing angles",
                              params=("T_c_m",)))
    return out


def plausibility_warnings(body_points_r, T_r_c, body_residuals, sigma_px: float | None, *,
                          name: str = "image") -> list[Diagnostic]:
    """Warnings for answers that fit but are physically implausible (wrong units or frames).

    Two silent failure modes of the patent's method that no error catches:

    * The camera is mounted on the body, so its centre ``t_r_c`` lies within
      about the body's size of the body points. A rectangle given in the wrong
      unit scales the mirror distance (PnP of a planar target is exact up to
      scale) and moves the camera metres away: warned when the camera is
      farther than ``max(CAMERA_BODY_MAX_M, 2 x body extent)`` from the nearest
      body point (extent = diagonal of the points' bounding box).
    * A body model in the wrong unit (mm read as m) scales the whole scene
      behind the mirror, camera included, so the first test cannot see it:
      warned when the body points span less than 1 cm or more than 20 m
      (``BODY_EXTENT_RANGE_M``).
    * With a known ``sigma_px`` the body-point PnP residual must be chi-square
      with ``2N - 6`` dof: ``sum(r^2) / sigma^2``. A body model in the wrong
      frame (e.g. x not flipped, points given in ``ri``) can still be fitted
      within the 5 sigma rms error limit; warned when the chi-square tail
      probability is below ``CHI2_P_MIN``.

    Parameters
    ----------
    body_points_r : (M, 3) body model in ``r`` [m]
    T_r_c : (4, 4) camera pose in ``r`` [m]
    body_residuals : (N, 2) body-point PnP residuals [px]
    sigma_px : float or None
        Known pixel noise; None skips the chi-square test (sigma then comes from
        the same residuals, so the test would be empty).
    """
    from scipy import special  # not scipy.stats: its import costs ~0.5 s per CLI run

    out = []
    P = np.asarray(body_points_r, dtype=float)
    extent = float(np.linalg.norm(np.ptp(P, axis=0)))
    dist = float(np.min(np.linalg.norm(P - np.asarray(T_r_c)[:3, 3], axis=1)))
    limit = max(CAMERA_BODY_MAX_M, 2.0 * extent)
    lo, hi = BODY_EXTENT_RANGE_M
    if not lo <= extent <= hi:
        out.append(Diagnostic("inconsistent_data", f"{name}: the body points span {extent:.4g} m (plausible "
                              f"{lo:g}-{hi:g} m): check the unit of body_points", params=("T_r_c",)))
    if dist > limit:
        out.append(Diagnostic("inconsistent_data", f"{name}: the estimate puts the camera {dist:.3g} m from the "
                              f"nearest body point (body extent {extent:.3g} m, limit {limit:.3g} m), but it is "
                              "mounted on the body: check the mirror_rectangle size and its unit",
                              params=("T_r_c",)))
    r = np.asarray(body_residuals, dtype=float)
    dof = r.size - 6
    if sigma_px is not None and dof > 0:
        chi2 = float(np.sum(r**2) / sigma_px**2)
        p = float(special.chdtrc(dof, chi2))  # chi2.sf
        if p < CHI2_P_MIN:
            out.append(Diagnostic("inconsistent_data", f"{name}: body points fit worse than sigma_px = "
                                  f"{sigma_px:.3g} px allows: chi2 = {chi2:.4g} on {dof} dof (p = {p:.2g}); check "
                                  "the handedness of body_points (frame r, x forward, y left, z up; not the "
                                  "mirrored ri, no axis sign flipped, no two axes swapped, u and v not swapped), "
                                  "the point order, and for single bad points", params=("T_r_c",)))
    return out


def _single_warnings(P_seen, body_points_r, steps: PatentSteps, body_residuals, sigma_known, choice: PlanarChoice,
                     name: str, *, camera: CameraModel | None = None, body_uv=None,
                     rectangle: MarkerRectangle | None = None) -> list[Diagnostic]:
    """All warnings of one image for the chosen marker pose (rerun when the choice changes)."""
    warnings = geometry_warnings(P_seen, steps.T_c_m, name=name)
    warnings += plausibility_warnings(body_points_r, steps.T_r_c, body_residuals, sigma_known, name=name)
    if rectangle is not None and choice.marker_residuals is not None:
        warnings += marker_fit_warnings(choice.marker_residuals[choice.chosen], sigma_known, rectangle, name=name)
    if camera is not None and body_uv is not None:
        warnings += handedness_warnings(camera, P_seen, body_uv, body_residuals, sigma_known, name=name)
    if not choice.decisive:
        warnings.append(Diagnostic("degenerate_geometry", f"{name}: planar ambiguity of the mirror markers not "
                                   f"resolved: {choice.reason}", params=("T_c_m",)))
    return warnings


@dataclass
class SingleImageResult:
    """The patent's method on one image.

    Attributes
    ----------
    steps : PatentSteps
        Every intermediate transform (eqs. [1]-[7]).
    T_c_r_householder : ndarray, shape (4, 4)
        The compact form on the same ``T_c_m, T_c_ri`` (agrees with ``steps.T_c_r``).
    choice : PlanarChoice
    marker_residuals, body_residuals : ndarray, shape (4, 2), (N, 2)
        ``observed - projected`` [px] of the two PnPs.
    sigma_px : float
        Pixel noise used for decisions (given, or estimated from the residuals).
    warnings : list of Diagnostic
    """

    steps: PatentSteps
    T_c_r_householder: np.ndarray
    choice: PlanarChoice
    marker_residuals: np.ndarray
    body_residuals: np.ndarray
    sigma_px: float
    warnings: list = field(default_factory=list)

    @property
    def T_r_c(self) -> np.ndarray:
        return self.steps.T_r_c

    @property
    def T_c_m(self) -> np.ndarray:
        return self.steps.T_c_m


def calibrate_single(camera: CameraModel, rectangle: MarkerRectangle, body_points_r, obs: MirrorObservation, *,
                     sigma_px: float | None = None, max_body_rms_px: float = 3.0) -> SingleImageResult:
    """The patent's method (seed 002 §2) on one image.

    Parameters
    ----------
    camera : CameraModel
        Known intrinsics and distortion.
    rectangle : MarkerRectangle
        Mirror markers, metres.
    body_points_r : array_like, shape (M, 3)
        Body point model in ``r`` [m].
    obs : MirrorObservation
    sigma_px : float, optional
        Pixel noise; estimated from the body-point PnP residuals when absent.
    max_body_rms_px : float
        Without ``sigma_px``: body-point PnP residual (rms per coordinate)
        above which the correspondences are declared wrong (with it: 5 sigma).

    Raises
    ------
    InconsistentDataError
        Markers not a plausible image of the rectangle, body points that do not
        fit the model, or a pose that puts points behind the camera.
    NotEnoughDataError, ShapeError, InputError
        See :func:`check_observation`.
    """
    m_uv, b_uv, ids, P = check_observation(obs, body_points_r, rectangle)
    src = obs.name
    check_in_image(camera, m_uv, f"{src}: marker_uv")
    check_in_image(camera, b_uv, f"{src}: body_uv")
    try:
        T_c_ri_sol = solve_pnp(camera, ri_from_r_points(P), b_uv)  # eq. [2]
    except ConvergenceError as exc:
        # the core message already says what to check about the correspondences; add only the frame
        raise InconsistentDataError(f"{src}: body_uv / body_points: {exc.message} (body_points must be in the "
                                    "robot frame r)") from None
    except DegenerateGeometryError as exc:
        raise DegenerateGeometryError(f"{src}: body_points_r: {exc.message}") from None
    try:
        cands = solve_pnp_planar(camera, rectangle.object_points(), m_uv)  # eq. [1], both IPPE poses
    except ConvergenceError as exc:
        raise InconsistentDataError(f"{src}: marker_uv: {exc.message}") from None
    sigma_given = sigma_px is not None
    if sigma_px is None:
        r = T_c_ri_sol.residuals
        dof = max(r.size - 6, 1)
        sigma_px = max(float(np.sqrt(np.sum(r**2) / dof)), 0.05)
    body_rms = T_c_ri_sol.rms_px / np.sqrt(2.0)  # per coordinate
    limit = 5.0 * sigma_px if sigma_given else max_body_rms_px
    if body_rms > limit:
        why = (f"5 x sigma_px = {limit:.3g} px; if sigma_px = {sigma_px:.3g} px is below your detector's noise, "
               "raise it or leave it out" if sigma_given else f"{limit:.3g} px, max_body_rms_px")
        raise InconsistentDataError(
            f"{src}: body_uv does not match body_points_r: the best pose leaves {body_rms:.3g} px rms per "
            f"coordinate (limit {why}); check the point order / body_ids, the unit of body_points and that "
            "the model is in frame r"
        )
    best = cands[0]
    size_px = np.linalg.norm(m_uv[2] - m_uv[0])
    marker_limit = max(5.0 * sigma_px, 0.02 * size_px, 1.0)
    if best.rms_px > marker_limit:
        hint = ""
        try:
            turned = solve_pnp_planar(camera, MarkerRectangle(rectangle.height, rectangle.width).object_points(), m_uv)
            if turned[0].rms_px <= marker_limit:
                hint = (f"; they fit a {rectangle.height * 1e3:.4g} x {rectangle.width * 1e3:.4g} mm one "
                        f"({turned[0].rms_px:.2g} px): width is the A-B edge (A top left, B top right in the image), so width and height "
                        "are swapped or the marker order starts at the wrong corner")
        except RobocalError:
            pass
        raise InconsistentDataError(
            f"{src}: marker_uv is not a plausible image of a {rectangle.width * 1e3:.4g} x "
            f"{rectangle.height * 1e3:.4g} mm rectangle: best pose leaves {best.rms_px:.3g} px rms (check the marker "
            f"order and the rectangle size){hint}"
        )
    choice = choose_planar_solution(cands, T_c_ri_sol.T_cam_obj, P, sigma_px=sigma_px)
    T_c_m = choice.T_c_m[choice.chosen]
    n, d = mirror_plane(T_c_m)
    if d <= 0:
        raise InconsistentDataError(f"{src}: the markers put the camera behind the mirror; check the marker order")
    steps = patent_compose(T_c_m, T_c_ri_sol.T_cam_obj)  # eqs. [3]-[7]
    warnings = _single_warnings(P, body_points_r, steps, T_c_ri_sol.residuals, sigma_px if sigma_given else None,
                                choice, src, camera=camera, body_uv=b_uv, rectangle=rectangle)
    return SingleImageResult(
        steps=steps,
        T_c_r_householder=householder_compose(T_c_m, T_c_ri_sol.T_cam_obj),
        choice=choice,
        marker_residuals=cands[choice.chosen].residuals,
        body_residuals=T_c_ri_sol.residuals,
        sigma_px=float(sigma_px),
        warnings=warnings,
    )
