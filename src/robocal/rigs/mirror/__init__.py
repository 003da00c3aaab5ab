"""Rig ``mirror``: camera-to-robot-body ("foot-eye") calibration from a plane mirror (seed 002).

One image of a plane mirror carrying four markers (a known rectangle) in which
the camera sees the reflection of feature points on the robot body gives the
camera pose in the robot frame. See ``docs/rigs/mirror.md``.

Modules: :mod:`.model` (frames, the patent's chain, the Householder form),
:mod:`.scene` (the published example), :mod:`.observation` (what an image
gives, validated), :mod:`.single` (the patent's single-image method and the
planar-ambiguity choice), :mod:`.joint` (the joint problem over K placements),
:mod:`.consistency` (agreement of the images, outliers named),
:mod:`.calibrate` (the API: :func:`calibrate`), :mod:`.checks` (camera,
rectangle, handedness and marker-fit checks of a user's inputs),
:mod:`.slips`, :mod:`.crossratio`, :mod:`.simulate`, :mod:`.tags`,
:mod:`.render` (rendered images), :mod:`.detect` (the ArUco path),
:mod:`.montecarlo`, :mod:`.markerless` (no mirror markers, K >= 3 mirror poses; mixed data),
:mod:`.markerless_result`, :mod:`.mirrored_target` (planar targets seen in a mirror),
:mod:`.files`, :mod:`.report`, :mod:`.workflow` (the
rig's steps for :mod:`robocal.workflow`), :mod:`.cli` (the declaration).

The names in ``__all__`` are imported from their submodule on first access
(PEP 562): importing the package, e.g. for ``robocal mirror --help`` through
:mod:`.cli`, does not import OpenCV, SciPy or matplotlib. ``calibrate`` is
both an exported function and a submodule; the package attribute is always
the function (as when the package imported everything eagerly); the module
is ``from robocal.rigs.mirror.calibrate import ...``.
"""

from __future__ import annotations

from robocal._lazy import lazy_exports

#: exported name -> submodule defining it (a test checks both)
_EXPORTS = {
    **dict.fromkeys(("MirrorCalibration", "calibrate"), "calibrate"),
    "MirrorObservation": "observation",
    **dict.fromkeys(("PlanarChoice", "SingleImageResult", "calibrate_single", "choose_planar_solution"), "single"),
    "predicted_covariance": "joint",
    **dict.fromkeys(("MarkerlessObservation", "calibrate_markerless"), "markerless"),
    "calibrate_mixed": "mixed",
    **dict.fromkeys(("detect_mirrored_target", "check_mirrored_order"), "mirrored_target"),
    "diagonal_points": "crossratio",
    **dict.fromkeys(("F_X", "T_M_OM", "MirrorScene", "PatentSteps", "householder_compose", "mirror_plane",
                     "patent_compose", "ri_from_r_points", "virtual_transform"), "model"),
    **dict.fromkeys(("PUBLISHED", "published_scene"), "scene"),
    **dict.fromkeys(("default_camera", "default_setup", "simulate_observations"), "simulate"),
}

#: exported names that are also submodule names (a test checks that this is all of them)
_COLLISIONS = ("calibrate",)

__all__ = [
    "F_X", "T_M_OM", "MirrorScene", "PatentSteps", "householder_compose", "mirror_plane", "patent_compose",
    "ri_from_r_points", "virtual_transform", "MirrorObservation", "PlanarChoice", "SingleImageResult",
    "MirrorCalibration", "calibrate_single", "calibrate", "choose_planar_solution", "predicted_covariance",
    "diagonal_points", "PUBLISHED", "published_scene", "default_camera", "default_setup", "simulate_observations",
    "MarkerlessObservation", "calibrate_markerless", "calibrate_mixed", "detect_mirrored_target",
    "check_mirrored_order",
]


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals(), collisions=_COLLISIONS)
