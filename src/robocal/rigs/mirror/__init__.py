"""Rig ``mirror``: camera-to-robot-body ("foot-eye") calibration from a plane mirror (seed 002).

One image of a plane mirror carrying four markers (a known rectangle) in which
the camera sees the reflection of feature points on the robot body gives the
camera pose in the robot frame. See ``docs/rigs/mirror.md``.

Modules: :mod:`.model` (frames, the patent's chain, the Householder form),
:mod:`.scene` (the published example), :mod:`.calibrate` (single-image method,
planar-ambiguity choice, joint refinement), :mod:`.checks` (camera, rectangle,
handedness and marker-fit checks of a user's inputs), :mod:`.crossratio`,
:mod:`.simulate`, :mod:`.render` (images, ArUco path), :mod:`.montecarlo`,
:mod:`.files`, :mod:`.report`, :mod:`.workflow`, :mod:`.cli`.

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
    **dict.fromkeys(("MirrorCalibration", "MirrorObservation", "PlanarChoice", "SingleImageResult", "calibrate",
                     "calibrate_single", "choose_planar_solution", "predicted_covariance"), "calibrate"),
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
]


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals(), collisions=_COLLISIONS)
