"""Slips in a mirror calibration input, named in one line (issue 18).

The patent's method (seed 002) fits a body model given in the wrong unit or the
wrong frame, and a mirror rectangle in the wrong unit, without any error: a
rectangle in m declared mm puts the camera metres from the body it is mounted
on, a body model in the mirror-image frame ``ri`` (or with an axis flipped)
moves the answer by metres, a body model in m declared mm is so small that
OpenCV's PnP fails with an assertion. Until now these were warnings after an
exit 0 (or OpenCV's message). The checks here judge them against the rest of
the data and undo the likely slips (:func:`robocal.plausibility.check_slips`):

1. **body span** (before any PnP): the body points must span 1 cm - 20 m
   (:data:`~robocal.rigs.mirror.calibrate.BODY_EXTENT_RANGE_M`); slips: the
   body points in another length unit, the one bringing the span closest to
   a typical 0.45 m (the range's middle on a log scale) named.
2. **camera on the body** (after the single-image estimates): the camera lies
   within ``max(1 m, 2 x body span)`` of the nearest body point (it is mounted
   on the body); slips: the rectangle in another unit. The images fix only
   the ratio of the rectangle's size to the body's (perspective has no
   scale), so the message names the body points as the other suspect.
   Figure: that distance [m] from the first image's estimate, recomputed with
   the slip undone.
3. **handedness**: when the x-flipped body model fits the reflections better
   by more than 25 chi-square units
   (:func:`~robocal.rigs.mirror.checks.handedness_warnings`), the body model
   is mirrored (given in ``ri``, an axis sign flipped or two axes swapped: all
   the same up to a rotation, so the images cannot tell which). Figure: the
   body-point PnP RMS [px].

A correct input costs nothing measurable: check 1 is a bounding box, checks 2
and 3 read figures the single-image estimates have computed already; the
slips are evaluated (a PnP each) only when a check fails.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.plausibility import LENGTH_UNITS, Slip, check_slips, length_slips

__all__ = ["LENGTH_UNITS", "check_body_span", "check_answer", "declared_units"]


def declared_units(doc) -> dict:
    """Units ``mirror_rectangle`` and ``body_points`` were written in (``{"mirror_rectangle": "mm", "body_points":
    "mm"}``; None where not known), from the input's :class:`~robocal.io.Document` (``load_input`` stores them in
    ``MirrorInput.declared``: no second parse of a large file)."""

    def unit(d, key):
        raw = d.data.get(key) if isinstance(d.data, dict) else None
        if isinstance(raw, dict) and "unit" in raw:
            return str(raw["unit"])
        return d.units.get("length")

    rect = doc.sub("mirror_rectangle", {})
    body = doc.sub("body_tags", {}) if "body_tags" in doc else doc
    return {"mirror_rectangle": unit(rect, "width"), "body_points": unit(body, "size" if "body_tags" in doc
                                                                          else "body_points")}


def _length_slips(field: str, declared: str | None, apply) -> list[Slip]:
    """:func:`robocal.plausibility.length_slips`; with no declared unit (the library, SI values) a factor of
    10, 100 or 1000 either way."""
    return length_slips(field, declared, apply, undeclared_factors=(10.0, 100.0, 1000.0, 0.1, 0.01, 0.001))


def _times(slip: Slip) -> str:
    """'1000x' from a slip's fix ('with x1000' / 'with /1000'), the factor the other field is off by."""
    k = slip.fix.split()[-1]
    return f"{k[1:]}x" if k.startswith("x") else f"1/{k[1:]}"


def _extent(P) -> float:
    return float(np.linalg.norm(np.ptp(np.asarray(P, dtype=float), axis=0)))


def check_body_span(body_points_r, *, declared: dict | None = None, accept: bool = False,
                    field: str = "body_points") -> list[Diagnostic]:
    """Check 1 of the module doc: raise (or warn with ``accept``) when the body points' span is implausible.

    ``field``: the input's name for the points (``reference_points`` in a markerless file).
    """
    from robocal.rigs.mirror.single import BODY_EXTENT_RANGE_M

    lo, hi = BODY_EXTENT_RANGE_M
    typical = float(np.sqrt(lo * hi))  # 0.45 m: the middle of the range on a log scale
    ext = _extent(body_points_r)

    def off(e: float) -> float:  # factor by which a span differs from the typical one
        return max(e / typical, typical / e) if e > 0 else float("inf")

    d = check_slips(what=f"factor between the body points' span and a typical robot's {typical:.2g} m",
                    residual=off(ext), unit="", plausible=lo <= ext <= hi, threshold=hi / typical,
                    reason=f"the {'body points' if field == 'body_points' else field} span {ext:.4g} m (plausible {lo:g}-{hi:g} m): check the unit of "
                           f"{field}",
                    slips=_length_slips(field, (declared or {}).get(field),
                                        lambda k: off(ext * k)),
                    accept=accept)
    return [] if d is None else [d]


def check_answer(camera, rectangle, body_points_r, observations, singles, *, sigma_px=None,
                 declared: dict | None = None, accept: bool = False) -> list[Diagnostic]:
    """Checks 2 and 3 of the module doc on the single-image estimates ``singles`` (one per observation)."""
    from robocal.camera import MarkerRectangle
    from robocal.rigs.mirror.single import CAMERA_BODY_MAX_M, calibrate_single

    declared = declared or {}
    P = np.asarray(body_points_r, dtype=float)
    out: list[Diagnostic] = []

    def distance(T_r_c, pts) -> float:
        return float(np.min(np.linalg.norm(pts - np.asarray(T_r_c)[:3, 3], axis=1)))

    dists = [distance(s.T_r_c, P) for s in singles]
    ext = _extent(P)
    limit = max(CAMERA_BODY_MAX_M, 2.0 * ext)
    worst = int(np.argmax(dists))
    if dists[worst] > limit:
        def rect_scaled(k: float) -> float:
            r = MarkerRectangle(rectangle.width * k, rectangle.height * k)
            s = calibrate_single(camera, r, P, observations[worst], sigma_px=sigma_px)
            return distance(s.T_r_c, P)

        d = check_slips(
            what="camera's distance from the nearest body point", residual=dists[worst], unit="m",
            plausible=False, threshold=limit,
            reason=f"{observations[worst].name}: the estimate puts the camera {dists[worst]:.3g} m from the nearest "
                   f"body point (body span {ext:.3g} m, limit {limit:.3g} m), but it is mounted on the body: check "
                   f"mirror_rectangle (size and unit) and body_points",
            # only the ratio of the two sizes shows in the images (perspective has no scale): a rectangle
            # k x too small is the same scene as body points k x too large, so one slip names both
            slips=[replace(sl, describe=f"{sl.describe} (or `body_points` {_times(sl)} too large: the images fix "
                                        f"only the ratio of the two)")
                   for sl in _length_slips("mirror_rectangle", declared.get("mirror_rectangle"), rect_scaled)],
            accept=accept)
        if d is not None:
            out.append(d)
        return out

    for s, o in zip(singles, observations):
        if not any(w.code == "inconsistent_data" and "mirror image of body_points" in w.message
                   for w in s.warnings):
            continue
        rms = float(np.sqrt(np.mean(np.asarray(s.body_residuals) ** 2)))

        def flipped() -> float:
            s2 = calibrate_single(camera, rectangle, P * [-1.0, 1.0, 1.0], o, sigma_px=sigma_px)
            return float(np.sqrt(np.mean(np.asarray(s2.body_residuals) ** 2)))

        d = check_slips(
            what="body-point reprojection RMS", residual=rms, unit="px", plausible=False,
            factor=1.5,  # the thinner the body, the closer the two fits (handedness_warnings' chi2 gap decides)
            reason=f"{o.name}: the mirror image of body_points fits the reflections better than body_points itself",
            slips=[Slip("body_points_mirrored",
                        f"`body_points` look mirrored ({o.name}; given in the mirror-image frame ri, an axis sign "
                        f"flipped or two axes swapped: frame r is x forward, y left, z up)",
                        "with x negated", flipped)],
            accept=accept)
        if d is not None:
            out.append(d)
        break  # one image says it for all: the body model is shared
    return out
