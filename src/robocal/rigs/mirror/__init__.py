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
"""

from robocal.rigs.mirror.calibrate import (
    MirrorCalibration,
    MirrorObservation,
    PlanarChoice,
    SingleImageResult,
    calibrate,
    calibrate_single,
    choose_planar_solution,
    predicted_covariance,
)
from robocal.rigs.mirror.crossratio import diagonal_points
from robocal.rigs.mirror.model import (
    F_X,
    T_M_OM,
    MirrorScene,
    PatentSteps,
    householder_compose,
    mirror_plane,
    patent_compose,
    ri_from_r_points,
    virtual_transform,
)
from robocal.rigs.mirror.scene import PUBLISHED, published_scene
from robocal.rigs.mirror.simulate import default_camera, default_setup, simulate_observations

__all__ = [
    "F_X", "T_M_OM", "MirrorScene", "PatentSteps", "householder_compose", "mirror_plane", "patent_compose",
    "ri_from_r_points", "virtual_transform", "MirrorObservation", "PlanarChoice", "SingleImageResult",
    "MirrorCalibration", "calibrate_single", "calibrate", "choose_planar_solution", "predicted_covariance",
    "diagonal_points", "PUBLISHED", "published_scene", "default_camera", "default_setup", "simulate_observations",
]
