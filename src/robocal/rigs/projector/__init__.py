"""Rig ``projector``: ceiling pan-tilt laser projector (seed 000).

D-H model, inverse kinematics and Jacobians (:mod:`.model`); world-to-projector
extrinsic calibration by the seed's method, the optimal closed form and
nonlinear least squares (:mod:`.calibrate`); the seed's Table 2 evaluation
(:mod:`.evaluate`); spot paths over one or several projectors (:mod:`.path`);
simulation (:mod:`.simulate`) and the command line (:mod:`.cli`).

The names in ``__all__`` (those of :mod:`.model`) are imported on first access
(PEP 562): importing the package, e.g. for ``robocal projector --help`` through
:mod:`.cli`, does not import the model and its dependencies (scipy.spatial via
:mod:`robocal.geometry`).
"""

from __future__ import annotations

from robocal._lazy import lazy_exports

#: exported name -> submodule defining it (``model.__all__``; a test checks that they agree)
_EXPORTS = {
    "ProjectorModel": "model",
    "NearSingularityWarning": "model",
    "UnreachablePointError": "model",
    "wrap_angle": "model",
    "NADIR_TOL": "model",
    "HORIZON_TOL": "model",
    "NEAR_NADIR_WARN": "model",
}

__all__ = [*_EXPORTS]


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
