"""Checks of the humanoid data and answer against what one assembled robot can give (seed 001 set-up).

* before the solve: :func:`check_options` (the calibration's options) and
  :func:`check_views_consistent` (a view whose corners lie far from where its
  joint record and foot label put them is refused);
* after the solve: :func:`implausible_offsets` and :func:`plausibility_warnings`
  (offsets beyond :data:`PLAUSIBLE_OFFSET`, views that fit far worse than the
  rest, a residual variance the noise model does not explain).

The likely slips behind such data (units, transposed board, swapped feet ...)
are named by :mod:`robocal.rigs.humanoid.slips`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import InconsistentDataError, InputError
from robocal.rigs.humanoid.model import HumanoidModel
from robocal.rigs.humanoid.problem import present_corners, resolve_parameters
from robocal.rigs.humanoid.simulate import JOINT_RESOLUTION, HumanoidDataset

__all__ = ["NOMINAL_MIN_PX", "NOMINAL_RATIO", "PLAUSIBLE_OFFSET", "check_views_consistent", "check_options",
           "implausible_offsets", "plausibility_warnings"]

#: Defaults of ``check_views_consistent(min_px=, ratio=)`` (``calibrate(consistency_px=,
#: consistency_ratio=)``, CLI ``--consistency-px``, ``--consistency-ratio``): a view is refused when its
#: corners lie further than this from the nominal prediction [px] and :data:`NOMINAL_RATIO` times the
#: median view's distance. Offsets of 0.5 deg (the simulator's
#: scale) put corners up to 28 px from it, 2 deg up to 110 px; a mislabelled foot 250 px, two
#: swapped joint records 136 px (measured, 20 x 16 simulated views).
NOMINAL_MIN_PX = 60.0
NOMINAL_RATIO = 4.0
#: After the solve: a joint or camera-rotation offset beyond this [rad] is implausible for an
#: assembled robot (NAO's are within ~1 deg, seed 001 Table 2).
PLAUSIBLE_OFFSET = np.radians(5.0)


def check_views_consistent(model: HumanoidModel, data: HumanoidDataset, x0=None, *,
                           min_px: float = NOMINAL_MIN_PX, ratio: float = NOMINAL_RATIO) -> np.ndarray:
    """Refuse views whose joint record or foot label does not match the image.

    For each view, the median distance [px] between the detected corners and the corners the
    model predicts from the joint readings at ``x0`` (default zero offsets, seed 001 eq. 5) is
    compared with ``max(min_px, ratio * median over views)`` (defaults 60 px and 4,
    :data:`NOMINAL_MIN_PX`, :data:`NOMINAL_RATIO`): offsets move every view's corners alike, a
    wrong record or foot moves one view's. Raise ``min_px`` for a robot whose offsets are larger
    than ~1 deg (2 deg put corners up to 110 px off, still under ``ratio`` times the median view).
    Raises :class:`InconsistentDataError` naming the first such view; returns the distances (V,) [px].
    """
    _check_consistency_thresholds(min_px, ratio)
    x0 = np.zeros(len(model.parameter_labels())) if x0 is None else np.asarray(x0, dtype=float)
    pred = model.project(data.theta, data.feet, x0, check=False)
    d = np.linalg.norm(pred - data.corners, axis=-1)
    # corners missing from the data (NaN) do not count; a view without any, or a board behind the
    # camera (NaN prediction), is as far as can be
    present = present_corners(data)
    d = np.where(present, np.where(np.isfinite(d), d, np.inf), np.nan)
    dist = np.full(len(d), np.inf)
    dist[present.any(axis=1)] = np.nanmedian(d[present.any(axis=1)], axis=1)
    typical = float(np.median(dist))
    tol = max(float(min_px), float(ratio) * typical)
    bad = np.flatnonzero(dist > tol)
    if bad.size:
        v = int(bad[np.argmax(dist[bad])])
        raise InconsistentDataError(
            f"view {data.names[v]!r} (feet: {data.feet[v]!r}, and its joints record): detected corners are "
            f"{dist[v]:.0f} px (median) from where the record puts them, expected < {tol:.0f} px (median view "
            f"{typical:.0f} px): the joint record or the foot label does not match the image"
            + (f" ({bad.size} such views: {[data.names[i] for i in bad]})" if bad.size > 1 else ""))
    return dist


def _check_consistency_thresholds(min_px, ratio) -> None:
    if not (np.isfinite(min_px) and min_px > 0):
        raise InputError(f"consistency threshold min_px (--consistency-px) must be a finite number > 0 px, "
                         f"got {min_px}")
    if not (np.isfinite(ratio) and ratio >= 1):
        raise InputError(f"consistency ratio (--consistency-ratio) must be a finite number >= 1, got {ratio}")


def implausible_offsets(model: HumanoidModel, free, params) -> list[tuple[str, float]]:
    """``(label, value [deg])`` of the free joint/camera-rotation offsets beyond :data:`PLAUSIBLE_OFFSET`."""
    labels = model.parameter_labels()
    units = model.parameter_units()
    return [(lab, float(np.degrees(params[labels.index(lab)]))) for lab in free
            if units[labels.index(lab)] == "rad" and not lab.startswith("board.")
            and abs(params[labels.index(lab)]) > PLAUSIBLE_OFFSET]


def plausibility_warnings(model: HumanoidModel, free, params, view_rms, names,
                          residual_variance: float, *, offsets: bool = True) -> list[Diagnostic]:
    """``inconsistent_data`` warnings after a solve: joint/camera-rotation offsets beyond
    :data:`PLAUSIBLE_OFFSET` (unless ``offsets`` is false: :func:`calibrate` judges those with
    :func:`robocal.plausibility.check_slips`), views whose RMS is 10x the median view's (and > 1 px),
    and a residual variance 25x the noise model's. Each suggests a wrong joint record, foot label or
    model."""
    out = []
    big = implausible_offsets(model, free, params) if offsets else []
    if big:
        out.append(Diagnostic("inconsistent_data", "implausible offsets (> {:.0f} deg): {}; check the joint "
                              "records, foot labels and model".format(
                                  np.degrees(PLAUSIBLE_OFFSET), ", ".join(f"{a} {b:+.1f} deg" for a, b in big)),
                              params=tuple(a for a, _ in big)))
    med = float(np.nanmedian(view_rms))  # NaN: a view removed by reject_outliers
    far = [i for i, r in enumerate(view_rms) if np.isfinite(r) and r > max(1.0, 10 * med)]
    if far:
        out.append(Diagnostic("inconsistent_data", f"view(s) fit far worse than the rest (RMS > 10x the median "
                              f"{med:.2f} px): " + ", ".join(f"{names[i]} {view_rms[i]:.1f} px" for i in far)
                              + "; check their joint records and foot labels", indices=tuple(far)))
    if residual_variance > 25.0:
        out.append(Diagnostic("inconsistent_data", f"residual variance {residual_variance:.3g} times the noise "
                              f"model's: the model does not explain the data"))
    return out


def check_options(model: HumanoidModel, *, parameters: str | Sequence[str] = "seed",
                  corner_sigma: float | None = None, joint_resolution: float = JOINT_RESOLUTION,
                  consistency_px: float = NOMINAL_MIN_PX, consistency_ratio: float = NOMINAL_RATIO,
                  max_rejected_fraction: float = 0.25) -> list[str]:
    """Check :func:`calibrate`'s options (raise :class:`InputError` naming the bad one) and return the
    free parameter labels; the CLI calls it before the slow corner detection."""
    if corner_sigma is not None and not (np.isfinite(corner_sigma) and corner_sigma > 0):
        raise InputError(f"corner_sigma must be a finite number > 0 px, got {corner_sigma}")
    if not (np.isfinite(joint_resolution) and joint_resolution >= 0):
        raise InputError(f"joint_resolution must be a finite number >= 0 rad, got {joint_resolution}")
    _check_consistency_thresholds(consistency_px, consistency_ratio)
    if not (0.0 <= max_rejected_fraction <= 1.0):
        raise InputError(f"max_rejected_fraction must be within [0, 1], got {max_rejected_fraction}")
    return resolve_parameters(model, parameters)
