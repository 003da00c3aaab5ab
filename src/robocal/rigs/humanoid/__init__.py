"""NAO-class humanoid: leg joint offsets and head-camera mounting from foot checkerboards (seed 001).

* :mod:`.model` -- :class:`HumanoidModel` (URDF tree, camera, boards), the
  corner projection of seed eq. 5 and its analytic Jacobian;
* :mod:`.simulate` -- true offsets, visible poses, quantised readings, rendered images;
* :mod:`.detect` -- rendering one view, detecting the corners of every view;
* :mod:`.dataset` -- the data-set file (camera, boards, images, joint records);
* :mod:`.problem` -- parameter sets, the per-view noise model, the gauge, the
  least-squares problem;
* :mod:`.consistency` -- option and data checks before the solve, plausibility
  warnings after it (:mod:`.slips` names the likely slip);
* :mod:`.calibrate` -- LM over the seed's 21 parameters in two passes, corner
  outliers and their rejection (re-exports the names of the two above);
* :mod:`.calibration` -- :class:`HumanoidCalibration`: offset tables, corrected
  URDF, the result record and the summary printed from it;
* :mod:`.montecarlo` -- Monte Carlo check of the reported uncertainty, repeatability;
* :mod:`.plan` -- greedy D-optimal pose planning;
* :mod:`.report` -- offsets file, corrected URDF, the HTML report built from a result;
* :mod:`.workflow` -- the rig contract's steps (simulate, load, calibrate, result,
  summary, demo); :mod:`.commands` -- ``plan``;
* :mod:`.cli` -- the declaration of ``robocal humanoid simulate | calibrate | plan | report``.

The names in ``__all__`` are imported from their submodule on first access
(PEP 562): importing the package, e.g. for ``robocal humanoid --help`` through
:mod:`.cli`, does not import SciPy's optimisers, OpenCV or matplotlib.

``calibrate`` is both an exported function and a submodule. As when this
package imported everything eagerly, the package attribute ``calibrate`` is
always the function, whichever is imported first (so ``from
robocal.rigs.humanoid import calibrate`` and even ``import
robocal.rigs.humanoid.calibrate as m`` give the function); the module is
``sys.modules["robocal.rigs.humanoid.calibrate"]``, or ``from
robocal.rigs.humanoid.calibrate import ...``.
"""

from __future__ import annotations

from robocal._lazy import lazy_exports

#: exported name -> submodule defining it (a test checks both)
_EXPORTS = {
    **dict.fromkeys(("HumanoidModel", "default_model"), "model"),
    **dict.fromkeys(("HumanoidDataset", "Truth", "draw_truth", "sample_poses", "simulate_dataset"), "simulate"),
    **dict.fromkeys(("load_dataset", "write_dataset"), "dataset"),
    **dict.fromkeys(("HumanoidCalibration", "calibrate", "resolve_parameters"), "calibrate"),
    **dict.fromkeys(("PosePlan", "plan_poses"), "plan"),
}

#: exported names that are also submodule names (a test checks that this is all of them)
_COLLISIONS = ("calibrate",)

__all__ = [
    "HumanoidModel",
    "default_model",
    "HumanoidDataset",
    "Truth",
    "draw_truth",
    "sample_poses",
    "simulate_dataset",
    "load_dataset",
    "write_dataset",
    "HumanoidCalibration",
    "calibrate",
    "resolve_parameters",
    "PosePlan",
    "plan_poses",
]


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals(), collisions=_COLLISIONS)
