"""NAO-class humanoid: leg joint offsets and head-camera mounting from foot checkerboards (seed 001).

* :mod:`.model` -- :class:`HumanoidModel` (URDF tree, camera, boards), the
  corner projection of seed eq. 5 and its analytic Jacobian;
* :mod:`.simulate` -- true offsets, visible poses, quantised readings, rendered images;
* :mod:`.detect` -- rendering one view, detecting the corners of every view;
* :mod:`.dataset` -- the data-set file (camera, boards, images, joint records);
* :mod:`.calibrate` -- LM over the seed's 21 parameters with uncertainty,
  identifiability and outliers;
* :mod:`.montecarlo` -- Monte Carlo check of the reported uncertainty, repeatability;
* :mod:`.plan` -- greedy D-optimal pose planning;
* :mod:`.report` -- offsets table, corrected URDF, HTML report;
* :mod:`.cli` -- ``robocal humanoid simulate | calibrate | plan | report``.
"""

from robocal.rigs.humanoid.calibrate import HumanoidCalibration, calibrate, resolve_parameters
from robocal.rigs.humanoid.dataset import load_dataset, write_dataset
from robocal.rigs.humanoid.model import HumanoidModel, default_model
from robocal.rigs.humanoid.plan import PosePlan, plan_poses
from robocal.rigs.humanoid.simulate import HumanoidDataset, Truth, draw_truth, sample_poses, simulate_dataset

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
