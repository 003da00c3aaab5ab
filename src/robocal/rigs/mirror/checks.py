"""Checks of a user's inputs that the geometry alone cannot catch (camera, rectangle, handedness).

Each returns named warnings (:class:`~robocal.diagnostics.Diagnostic`) or
raises an :class:`~robocal.errors.InputError`; see ``docs/rigs/mirror.md``,
"Your own camera" and "What the images cannot tell". Re-exported by
:mod:`robocal.rigs.mirror.calibrate`, which calls them.
"""

from __future__ import annotations

import numpy as np

from robocal.camera import (
    PRINCIPAL_POINT_OFF_CENTRE,  # noqa: F401  (re-exported)
    CameraModel,
    MarkerRectangle,
    check_principal_point,
    principal_point_warnings,
    solve_pnp,
)
from robocal.diagnostics import Diagnostic
from robocal.errors import RobocalError

__all__ = ["check_camera", "camera_warnings", "rectangle_warnings", "handedness_warnings", "marker_fit_warnings"]

#: Chi-square tail probability of the marker fit below which a known sigma_px is contradicted.
MARKER_CHI2_P_MIN = 1e-3


def check_camera(camera: CameraModel) -> None:
    """Reject a camera whose principal point lies outside its ``width x height`` image.

    The core check, :func:`robocal.camera.check_principal_point` (which
    :func:`robocal.camera.camera_from_document` applies to every camera it
    reads); kept here for cameras built in code.
    """
    check_principal_point(camera)


def camera_warnings(camera: CameraModel) -> list[Diagnostic]:
    """Warn when the principal point is far from the image centre (:func:`robocal.camera.principal_point_warnings`)."""
    return principal_point_warnings(camera)


#: Plausible side lengths [m] of the mirror marker rectangle (the patent's is 0.366 x 0.256 m).
RECTANGLE_RANGE_M = (0.02, 2.5)


def rectangle_warnings(rectangle: MarkerRectangle) -> list[Diagnostic]:
    """Warn when the marker rectangle's size is implausible for a mirror (a unit error).

    A unit error shared by the rectangle and the body model scales the whole
    scene; the images are exactly the same (perspective has no scale), so only
    such size checks can see it: 366 x 256 mm read as cm is a 3.66 m mirror.
    """
    lo, hi = RECTANGLE_RANGE_M
    sides = (rectangle.width, rectangle.height)
    if lo <= min(sides) and max(sides) <= hi:
        return []
    return [Diagnostic("inconsistent_data", f"mirror_rectangle is {sides[0]:.4g} x {sides[1]:.4g} m (plausible sides "
                       f"{lo:g}-{hi:g} m): check its unit; a unit error shared with body_points scales the answer "
                       "by the same factor and cannot be seen in the images", params=("T_r_c",))]


#: Chi-square units by which the mirror image of the body model must fit better to be reported.
HANDEDNESS_CHI2 = 25.0


def handedness_warnings(camera: CameraModel, P_seen, body_uv, body_residuals, sigma_px: float | None, *,
                        name: str = "image") -> list[Diagnostic]:
    """Warn when the mirror image of the body model fits the reflections better than the model.

    The reflection of a body point ``(x, y, z)_r`` is imaged like the point
    ``(-x, y, z)`` of a rigid object (frame ``ri``). A model of the wrong
    handedness (given in ``ri``, one axis sign flipped, two axes swapped, or
    ``u`` and ``v`` swapped in ``body_uv``: all the same error up to a
    rotation) is fitted by a PnP too, worse by an amount that grows with the
    thickness of the point set (for coplanar points it fits exactly, and no
    test can see it). This compares the two fits, ``(SSE_model - SSE_mirrored)
    / sigma^2 > HANDEDNESS_CHI2``; without a known ``sigma_px`` sigma is
    estimated from the better of the two fits, so it works without one.
    """
    try:
        # the x-flipped model; SQPnP alone (its SSE is within ~1 % of the refined one's, at half the time)
        alt = solve_pnp(camera, np.ascontiguousarray(P_seen, dtype=float), body_uv, refine=False)
    except RobocalError:
        return []
    if sigma_px is None:
        sse = min(float(np.sum(np.asarray(body_residuals) ** 2)), float(np.sum(alt.residuals**2)))
        sigma_px = max(float(np.sqrt(sse / max(alt.residuals.size - 6, 1))), 0.05)
    gap = float((np.sum(np.asarray(body_residuals) ** 2) - np.sum(alt.residuals**2)) / sigma_px**2)
    if gap <= HANDEDNESS_CHI2:
        return []
    rms = (float(np.sqrt(np.mean(np.asarray(body_residuals) ** 2))), float(np.sqrt(np.mean(alt.residuals**2))))
    return [Diagnostic("inconsistent_data", f"{name}: the mirror image of body_points (x flipped) fits the reflections "
                       f"better than body_points itself (rms {rms[1]:.3g} vs {rms[0]:.3g} px, chi2 gap {gap:.3g}): "
                       "the body model likely has the wrong handedness (given in the mirrored frame ri, an axis "
                       "sign flipped, two axes swapped, or u and v swapped in body_uv); the answer is then wrong "
                       "by metres", params=("T_r_c",))]


def marker_fit_warnings(marker_residuals, sigma_px: float | None, rectangle: MarkerRectangle, *,
                        name: str = "image") -> list[Diagnostic]:
    """Warn when, at a known ``sigma_px``, the four markers fit a rectangle of the given size badly.

    Four markers give 8 numbers for a 6-dof pose, so only 2 dof test the
    rectangle; most of a size or aspect error is absorbed by a tilt of the
    mirror, which the reflection turns into a camera shift with lever arm
    ``2d``. Published scene: 1 mm on the height moves ``t_r_c`` by ~47 mm,
    1 mm on the width by ~33 mm, with no visible misfit; 6 mm (2 %) moves it
    by ~0.3 m at chi2 = 8. Warned at ``chi2 = sum r^2 / sigma^2`` on 2 dof,
    p < ``MARKER_CHI2_P_MIN``.
    """
    from scipy import special

    r = np.asarray(marker_residuals, dtype=float)
    if sigma_px is None or r.size < 8:
        return []
    chi2 = float(np.sum(r**2) / sigma_px**2)
    p = float(special.chdtrc(r.size - 6, chi2))
    if p >= MARKER_CHI2_P_MIN:
        return []
    return [Diagnostic("inconsistent_data", f"{name}: the four markers fit a {rectangle.width * 1e3:.4g} x "
                       f"{rectangle.height * 1e3:.4g} mm rectangle worse than sigma_px = {sigma_px:.3g} px allows "
                       f"(chi2 = {chi2:.3g} on {r.size - 6} dof, p = {p:.2g}): check mirror_rectangle (measure it "
                       "to 1 mm: each mm moves t_r_c by tens of mm) and the marker positions", params=("T_c_m",))]
