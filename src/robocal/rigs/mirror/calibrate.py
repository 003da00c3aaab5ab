"""Camera-to-robot calibration from images of a plane mirror (seed 002).

Two estimators:

* :func:`calibrate_single` — the patent's method on one image: planar PnP of
  the four mirror markers (both IPPE solutions, one chosen with the body
  points, see :func:`choose_planar_solution`), PnP of the reflected body
  points with the x-flipped object set, and the composition of
  :func:`~robocal.rigs.mirror.model.patent_compose` (eqs. [1]-[7]).
* :func:`calibrate` — beyond the patent: one nonlinear least-squares problem
  over ``T_r_c`` and every mirror pose ``T_c_m_k`` of K images (mirror
  placements), on the reprojection error of the markers and of the reflected
  body points, started from the single-image estimates; covariance from the
  estimation layer.

For one image the joint problem splits into the two PnPs (``T_c_ri`` is a
re-parametrisation of ``T_c_r`` for a fixed mirror), so both estimators agree
and the joint problem's covariance is the first-order covariance of the
patent's estimate.

Parametrisation (all results): ``T_r_c`` (camera in the robot frame; the
patent's ``(R_rc, T_rc)``); rotation uncertainty is that of the rotation
vector ``delta`` in ``R_rc = exp(delta) R_rc_ref`` (left, robot-side
perturbation, as ``docs/conventions.md``), in radians; translation in metres.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from robocal.camera import CameraModel, MarkerRectangle, solve_pnp, solve_pnp_planar
from robocal.diagnostics import Diagnostic
from robocal.errors import (
    ConvergenceError,
    DegenerateGeometryError,
    InconsistentDataError,
    InputError,
    NotEnoughDataError,
    RobocalError,
    ShapeError,
)
from robocal.estimation import LSQResult, Problem, solve
from robocal.geometry import (
    invert_transform,
    matrix_from_rotvec,
    quaternion_from_matrix,
    rotation_angle,
    rotvec_from_matrix,
    skew,
    so3_left_jacobian,
    transform_from,
)
from robocal.rigs.mirror.checks import (
    camera_warnings,
    check_camera,
    handedness_warnings,
    marker_fit_warnings,
    rectangle_warnings,
)
from robocal.rigs.mirror.model import (
    PatentSteps,
    householder_compose,
    mirror_plane,
    patent_compose,
    ri_from_r_points,
)
from robocal.validation import check_array

__all__ = [
    "MirrorObservation",
    "PlanarChoice",
    "SingleImageResult",
    "MirrorCalibration",
    "check_observation",
    "check_camera",
    "check_in_image",
    "camera_warnings",
    "choose_planar_solution",
    "calibrate_single",
    "calibrate",
    "geometry_warnings",
    "plausibility_warnings",
    "handedness_warnings",
    "marker_fit_warnings",
    "rectangle_warnings",
    "residual_model",
    "predicted_covariance",
]

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
class MirrorObservation:
    """What one image gives: the four markers and the imaged reflections.

    Attributes
    ----------
    marker_uv : ndarray, shape (4, 2)
        Markers A, B, C, D [px] in the rectangle's order (A top left, clockwise).
    body_uv : ndarray, shape (N, 2)
        Image of the reflection of each listed body point [px].
    body_ids : ndarray of int, shape (N,)
        Index of each observed point in the body point model.
    name : str
        Label used in messages and reports (file name, "image 3", ...).
    warnings : list of Diagnostic
        From the detection (tags not found, repeated or unknown ids); passed
        on to the calibration's warnings.
    marker_sigma_scale : float
        Noise std of a marker coordinate relative to a body point's (1: the
        same); multiplies ``marker_cov`` when both are given. The joint
        refinement weights the markers by it. The ArUco path leaves it at 1
        and gives ``marker_cov`` instead (a tag centre is ~0.6-0.7 x as
        noisy as a tag corner; the former scalar 0.265 was too optimistic).
    body_cov : ndarray, shape (N // 4, 8, 8), optional
        Noise covariance of the body points in groups of four consecutive
        rows of ``body_uv`` (the corners of one tag, order ``u0, v0, ..., u3,
        v3``), relative: times ``sigma_px^2``. The ArUco path sets it from
        the edge-fit geometry (:func:`~robocal.rigs.mirror.render.tag_corner_covariance`):
        a tag's corners share its four fitted border lines, so their errors
        are correlated (-0.68 between the ends of one side); the joint
        refinement whitens each tag's residuals with it. None: independent,
        unit variance.
    marker_cov : ndarray, shape (4, 2, 2), optional
        Relative noise covariance of each marker (times
        ``(marker_sigma_scale sigma_px)^2``); None: identity.
    """

    marker_uv: np.ndarray
    body_uv: np.ndarray
    body_ids: np.ndarray | None = None
    name: str = "image"
    warnings: list = field(default_factory=list)
    marker_sigma_scale: float = 1.0
    body_cov: np.ndarray | None = None
    marker_cov: np.ndarray | None = None

    def __post_init__(self):
        s = self.marker_sigma_scale
        if isinstance(s, bool) or not isinstance(s, (int, float, np.floating, np.integer)) or not 0 < s < np.inf:
            raise InputError(f"{self.name}: marker_sigma_scale must be a number > 0, got {s!r}")
        for fld, shape in (("body_cov", (None, 8, 8)), ("marker_cov", (4, 2, 2))):
            c = getattr(self, fld)
            if c is None:
                continue
            c = check_array(c, f"{self.name}: {fld}")
            if c.ndim != 3 or c.shape[1:] != shape[1:] or (shape[0] is not None and c.shape[0] != shape[0]):
                want = "(N // 4, 8, 8)" if shape[0] is None else "(4, 2, 2)"
                raise ShapeError(f"{self.name}: {fld} must have shape {want}, got {c.shape}")
            if not np.allclose(c, np.swapaxes(c, 1, 2), rtol=1e-6, atol=1e-12 * max(np.abs(c).max(), 1e-300)) \
                    or np.any(np.linalg.eigvalsh(0.5 * (c + np.swapaxes(c, 1, 2)))[:, 0] <= 0):
                raise InputError(f"{self.name}: {fld} must be symmetric positive definite matrices")
            object.__setattr__(self, fld, c)

    def to_dict(self) -> dict:
        d = {
            "name": self.name,
            "marker_uv": np.asarray(self.marker_uv).tolist(),
            "body_uv": np.asarray(self.body_uv).tolist(),
            "body_ids": None if self.body_ids is None else [int(i) for i in self.body_ids],
        }
        if self.marker_sigma_scale != 1.0:
            d["marker_sigma_scale"] = float(self.marker_sigma_scale)
        if self.body_cov is not None:
            d["body_cov"] = np.asarray(self.body_cov).tolist()
        if self.marker_cov is not None:
            d["marker_cov"] = np.asarray(self.marker_cov).tolist()
        return d


def _signed_area(q: np.ndarray) -> float:
    x, y = q[:, 0], q[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def check_observation(obs: MirrorObservation, body_points_r: np.ndarray, rectangle: MarkerRectangle):
    """Validate one observation; returns ``(marker_uv, body_uv, body_ids, p_r)`` as arrays.

    Raises a :class:`~robocal.errors.RobocalError` naming the observation and field:
    wrong shapes, mismatched counts, fewer than 4 body points, markers that are
    not a convex quadrilateral in the documented clockwise order.
    """
    src = obs.name
    m = check_array(obs.marker_uv, f"{src}: marker_uv")
    if m.shape != (4, 2):
        raise ShapeError(f"{src}: marker_uv must have shape (4, 2) (markers A, B, C, D), got {m.shape}")
    q = check_array(obs.body_uv, f"{src}: body_uv")
    if q.ndim != 2 or q.shape[1] != 2:
        raise ShapeError(f"{src}: body_uv must have shape (N, 2), got {q.shape}")
    P = check_array(body_points_r, "body_points_r")
    if P.ndim != 2 or P.shape[1] != 3:
        raise ShapeError(f"body_points_r must have shape (N, 3), got {P.shape}")
    if obs.body_ids is None:
        if q.shape[0] != P.shape[0]:
            raise InputError(
                f"{src}: {q.shape[0]} body image points but {P.shape[0]} body model points; "
                "give body_ids to say which model point each image point is"
            )
        ids = np.arange(P.shape[0])
    else:
        ids = np.asarray(obs.body_ids)
        if ids.shape != (q.shape[0],) or not np.issubdtype(ids.dtype, np.integer):
            raise InputError(f"{src}: body_ids must be {q.shape[0]} integers (one per body_uv row), got shape {ids.shape}")
        if ids.size and (ids.min() < 0 or ids.max() >= P.shape[0]):
            raise InputError(f"{src}: body_ids must index the {P.shape[0]} body model points, got {ids.min()}..{ids.max()}")
        if len(np.unique(ids)) != ids.size:
            raise InputError(f"{src}: body_ids has repeated entries")
    if q.shape[0] < 4:
        raise NotEnoughDataError(f"{src}: needs at least 4 imaged body points for PnP, got {q.shape[0]}")
    # markers: a convex quadrilateral A, B, C, D, clockwise in the image (v down)
    e = np.roll(m, -1, axis=0) - m
    cross = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
    diag = max(np.linalg.norm(m[2] - m[0]), np.linalg.norm(m[3] - m[1]))
    if diag < 4.0:
        raise InconsistentDataError(f"{src}: marker_uv: the four markers are within {diag:.2g} px of each other")
    if not (np.all(cross > 0) or np.all(cross < 0)):
        raise InconsistentDataError(
            f"{src}: marker_uv does not form a convex quadrilateral A-B-C-D (crossed or reflex corners); "
            "check the marker order"
        )
    if _signed_area(m) < 0:
        raise InconsistentDataError(
            f"{src}: marker_uv runs counter-clockwise in the image; expected A (top left), B (top right), "
            "C (bottom right), D (bottom left) as seen on the mirror's front"
        )
    # contiguous copies: cv2.solvePnP rejects strided views (core PnP passes them through)
    return np.ascontiguousarray(m), np.ascontiguousarray(q), ids, np.ascontiguousarray(P[ids])


#: Image points farther than this fraction of the image size outside it are rejected as wrong input.
OUTSIDE_IMAGE_FRACTION = 0.02
#: ... but never less than this many pixels (sub-pixel detections and noise at the border).
OUTSIDE_IMAGE_MIN_PX = 3.0
def check_in_image(camera: CameraModel, uv, what: str) -> None:
    """Reject image points outside the camera's ``width x height`` image [px].

    A detector cannot report such points, so they are a unit or column mix-up
    or points of another image size (e.g. picked in a full-resolution photo
    with a camera calibrated on reduced images); without this check PnP fails
    later with a misleading "behind the camera", or succeeds with a wrong
    answer. The margin (``OUTSIDE_IMAGE_FRACTION`` of the image size, at
    least ``OUTSIDE_IMAGE_MIN_PX``) leaves room for noisy detections at the
    border.
    """
    uv = np.asarray(uv, dtype=float)
    size = np.array([camera.width, camera.height], dtype=float)
    margin = np.maximum(OUTSIDE_IMAGE_FRACTION * size, OUTSIDE_IMAGE_MIN_PX)
    lo, hi = -0.5 - margin, size - 0.5 + margin
    bad = np.flatnonzero(np.any((uv < lo) | (uv > hi), axis=1))
    if bad.size:
        i = int(bad[0])
        raise InconsistentDataError(
            f"{what}: row {i} = ({uv[i, 0]:.4g}, {uv[i, 1]:.4g}) px lies outside the {camera.width} x "
            f"{camera.height} px image{f' ({bad.size} such rows)' if bad.size > 1 else ''}; check the camera "
            "width/height (the size of the images the points come from) and that the points are pixels, "
            "in (u, v) = (column, row) order")


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


# --------------------------------------------------------------------- joint model
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


@dataclass
class MirrorCalibration:
    """Result of :func:`calibrate` (K images, joint refinement).

    Attributes
    ----------
    T_r_c : ndarray, shape (4, 4)
        Camera pose in the robot frame (the answer; ``robot -> camera``).
    T_c_m : ndarray, shape (K, 4, 4)
        Mirror (marker) pose in each image.
    cov : ndarray, shape (6, 6)
        Covariance of ``(rot_rc [rad], t_rc [m])`` (rotation as a left perturbation).
    singles : list of SingleImageResult
        The patent's estimate from each image alone.
    lsq : LSQResult or None
        The joint problem's solution (None with ``refine=False``).
    warnings : list of Diagnostic
    noise_components : ndarray, shape (2,) or None
        With per-tag covariances (ArUco path) and sigma estimated: the two
        noise variances ``(s1^2, s2^2)`` [px^2] of the edge-fit part and of
        the independent-corner part (:func:`_two_component_covariance`;
        ``s2^2 = 0`` when they could not be separated).
    """

    T_r_c: np.ndarray
    T_c_m: np.ndarray
    cov: np.ndarray
    singles: list
    lsq: LSQResult | None
    warnings: list
    observations: list
    rectangle: MarkerRectangle
    body_points_r: np.ndarray
    camera: CameraModel
    noise_components: np.ndarray | None = None

    @property
    def T_c_r(self) -> np.ndarray:
        return invert_transform(self.T_r_c)

    @property
    def std_rotation(self) -> np.ndarray:
        """Per-axis std of the rotation [rad], (3,)."""
        return np.sqrt(np.diag(self.cov)[:3])

    @property
    def std_translation(self) -> np.ndarray:
        """Per-axis std of ``t_rc`` [m], (3,)."""
        return np.sqrt(np.diag(self.cov)[3:])

    def residuals(self):
        """``(marker (K, 4, 2), body list of (N_k, 2))`` reprojection residuals [px], projected - observed."""
        layout = _layout(self.observations, self.body_points_r, self.rectangle)
        markers, body, _, _, _ = residual_model(self.camera, self.rectangle, layout, self.T_r_c[:3, :3],
                                                self.T_c_m[:, :3, :3])
        p = {"rot_rc": np.zeros(3), "t_rc": self.T_r_c[:3, 3], "rot_cm": np.zeros((layout.K, 3)),
             "t_cm": self.T_c_m[:, :3, 3]}
        b = body(p)
        splits = np.cumsum([len(i) for i in layout.ids])[:-1]
        return markers(p).reshape(layout.K, 4, 2), np.split(b, splits)


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


#: Family-wise false-alarm probability of the outlier test over all observations of a calibration.
OUTLIER_FAMILY_P = 0.01


def outlier_sigma(n_obs: int, family_p: float = OUTLIER_FAMILY_P) -> float:
    """Outlier threshold [sigma] with a Bonferroni correction for ``n_obs`` observations.

    A fixed 3 sigma (tail 0.27 %) names ~0.6 of 216 clean observations on
    average; testing each at ``family_p / n_obs`` keeps the chance of any false
    alarm in a clean calibration at ``family_p`` (216 observations: 4.07 sigma).
    Never below 3 sigma.
    """
    from scipy import special

    return max(3.0, float(np.sqrt(2.0) * special.erfcinv(family_p / max(int(n_obs), 1))))


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


def calibrate(camera: CameraModel, rectangle: MarkerRectangle, body_points_r, observations, *,
              sigma_px: float | None = None, refine: bool = True, progress: bool = False,
              accept_implausible: bool = False, declared: dict | None = None) -> MirrorCalibration:
    """Calibrate ``T_r_c`` from K >= 1 mirror images (joint refinement).

    Parameters
    ----------
    camera, rectangle, body_points_r
        As :func:`calibrate_single`.
    observations : sequence of MirrorObservation
        One per image / mirror placement; the camera must not move on the body
        between them.
    sigma_px : float, optional
        Pixel noise; when given the covariance uses it as the true noise,
        otherwise the residual variance scales it.
    refine : bool
        Run the joint least squares (else: average of the single-image
        estimates, with the covariance of that average, ``sum(C_k) / K^2``
        from each image's :func:`predicted_covariance` ``C_k``).
    accept_implausible : bool
        Body points or rectangle in an implausible unit, a camera estimated far from the body it is
        mounted on, or a mirrored body model (:mod:`robocal.rigs.mirror.slips`) are an
        :class:`~robocal.errors.ImplausibleInputError` naming the slip; with this, an
        ``implausible_input`` warning and the answer for the data as given (CLI ``--accept-implausible``).
    declared : dict, optional
        Units ``mirror_rectangle`` and ``body_points`` were written in
        (:func:`robocal.rigs.mirror.slips.declared_units`), to name a slip in the file's units.
    """
    obs_list = list(observations)
    if not obs_list:
        raise NotEnoughDataError("observations: need at least one image")
    names = [o.name for o in obs_list]
    if len(set(names)) != len(names):
        obs_list = [dataclasses.replace(o, name=f"{o.name} #{i}", warnings=list(o.warnings))
                    for i, o in enumerate(obs_list)]
    P_all = check_array(body_points_r, "body_points_r")
    if P_all.ndim != 2 or P_all.shape[1] != 3:
        raise ShapeError(f"body_points_r must have shape (N, 3), got {P_all.shape}")
    check_camera(camera)
    from robocal.rigs.mirror.slips import check_answer, check_body_span

    # before any PnP: a body model 1000x too small makes OpenCV's SQPnP fail with an assertion
    slip_warnings = check_body_span(P_all, declared=declared, accept=accept_implausible)
    singles = [calibrate_single(camera, rectangle, P_all, o, sigma_px=sigma_px) for o in obs_list]
    singles = _consensus_choice(singles, camera, rectangle, P_all, obs_list, sigma_px)
    if not slip_warnings:
        slip_warnings = check_answer(camera, rectangle, P_all, obs_list, singles, sigma_px=sigma_px,
                                     declared=declared, accept=accept_implausible)
    warnings = slip_warnings + camera_warnings(camera) + rectangle_warnings(rectangle)
    warnings += [w for o in obs_list for w in o.warnings]
    warnings += [w for s in singles for w in s.warnings]
    T_c_m0 = np.stack([s.T_c_m for s in singles])
    # start from the first image's estimate, rotation-averaged over the images
    T_r_c0 = singles[0].T_r_c.copy()
    if len(singles) > 1:
        dev = np.mean([rotvec_from_matrix(s.T_r_c[:3, :3] @ T_r_c0[:3, :3].T) for s in singles], axis=0)
        T_r_c0[:3, :3] = matrix_from_rotvec(dev) @ T_r_c0[:3, :3]
        T_r_c0[:3, 3] = np.mean([s.T_r_c[:3, 3] for s in singles], axis=0)
    layout = _layout(obs_list, P_all, rectangle)
    if not refine:
        # The answer is the mean of K independent single-image estimates, so its first-order
        # covariance is sum(C_k) / K^2 — not the joint ML covariance, which is up to ~2x smaller
        # in variance because the joint fit weights the images by their information.
        cov = np.zeros((6, 6))
        for s, o in zip(singles, obs_list):
            sig = sigma_px if sigma_px is not None else s.sigma_px
            cov += predicted_covariance(camera, rectangle, P_all, s.T_r_c, s.T_c_m, [o], sig)
        cov /= len(singles) ** 2
        return MirrorCalibration(T_r_c0, T_c_m0, cov, singles, None, warnings, obs_list, rectangle, P_all, camera)
    n_obs = 4 * layout.K + sum(len(i) for i in layout.ids)
    # The joint solve holds a dense Jacobian of 2 n_obs rows by 6 + 6K columns (each placement adds a
    # mirror pose): memory grows with K^2 and the solver's SVD time with K^3. About 8 copies of it
    # live at the peak (measured: 0.74 GB resident at K = 200 placements x 20 points).
    from robocal.resources import require_memory

    require_memory(8 * 8.0 * 2 * n_obs * (6 + 6 * layout.K),
                   f"the joint solve of {layout.K} mirror placements ({n_obs} points; dense, grows with the "
                   f"square of the placements)")
    prob, poses, whitened = _problem(camera, rectangle, layout, T_r_c0, T_c_m0, sigma_px)
    res = solve(prob, method="lm", absolute_sigma=sigma_px is not None, progress=progress,
                outlier_sigma=outlier_sigma(n_obs))
    T_r_c, T_c_m = poses(res.params)
    cov = res.cov[:6, :6]
    components = None
    if layout.correlated and sigma_px is None:
        full, components = _two_component_covariance(prob, whitened, res)
        cov = full[:6, :6]
    warnings.extend(_name_outliers(w, layout, obs_list) for w in res.warnings)
    if len(singles) > 1:
        warnings.extend(_consistency_warnings(camera, rectangle, P_all, singles, obs_list, T_r_c, sigma_px))
    return MirrorCalibration(T_r_c, T_c_m, cov, singles, res, warnings, obs_list, rectangle, P_all, camera,
                             components)


def result_estimate(cal: MirrorCalibration) -> tuple[dict, dict, dict]:
    """``(estimate, std, units)`` dicts for a :class:`~robocal.io.CalibrationResult`."""
    est = {
        "T_r_c": cal.T_r_c.tolist(),
        "t_r_c": cal.T_r_c[:3, 3].tolist(),
        "q_r_c": quaternion_from_matrix(cal.T_r_c[:3, :3]).tolist(),
        "rotvec_r_c": rotvec_from_matrix(cal.T_r_c[:3, :3]).tolist(),
        "T_c_m": cal.T_c_m.tolist(),
    }
    std = {"t_r_c": cal.std_translation.tolist(), "rotvec_r_c": cal.std_rotation.tolist()}
    units = {"T_r_c": "m", "t_r_c": "m", "q_r_c": "1", "rotvec_r_c": "rad", "T_c_m": "m"}
    return est, std, units
