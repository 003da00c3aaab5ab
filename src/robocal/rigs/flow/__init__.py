"""Rig ``flow``: dead reckoning from several downward optical-flow sensors (seed 003).

Modules: :mod:`.kernel` (SAD block matching, sub-pixel, gyro compensation,
metric flow; numba), :mod:`.model` (the array, SE(2) helpers),
:mod:`.odometry` (the seed's ``A u = b``, robust fusion, integration),
:mod:`.simulate` (real-photo ground, sensor cameras, gyro, height, wheels),
:mod:`.calibrate` (array calibration), :mod:`.evaluate` (ATE, RPE, plots),
:mod:`.log` (file formats), :mod:`.workflow` and :mod:`.cli`.
"""

from robocal.rigs.flow.kernel import FlowConfig, FrameFlow, compute_flow, match_blocks, match_sequence
from robocal.rigs.flow.model import SensorArray, seed_array
from robocal.rigs.flow.odometry import Odometry, SensorSteps, dead_reckon, fuse_steps
from robocal.rigs.flow.calibrate import ArrayCalibration, calibrate_array
from robocal.rigs.flow.evaluate import evaluate_trajectory, rpe_lengths, rpe_per_distance, ate

__all__ = [
    "FlowConfig", "FrameFlow", "compute_flow", "match_blocks", "match_sequence",
    "SensorArray", "seed_array", "Odometry", "SensorSteps", "dead_reckon", "fuse_steps",
    "ArrayCalibration", "calibrate_array", "evaluate_trajectory", "rpe_lengths", "rpe_per_distance", "ate",
]
