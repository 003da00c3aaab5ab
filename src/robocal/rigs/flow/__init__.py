"""Rig ``flow``: dead reckoning from several downward optical-flow sensors (Li, Guan and Chu 2017).

Source: LI Shi-yun, GUAN Le, CHU Jin-kui, *Dead-reckoning for mobile robot
based on multiple optical flow sensors*, 2017, DOI
10.13873/J.1000-9787(2017)10-0061-03 ("the seed"; equations cited by its
numbers, see docs/sources.md [S3]).

Modules: :mod:`.kernel` (SAD block matching, sub-pixel, the per-sensor flow
API) over :mod:`.kernel_config` (``FlowConfig``, no numba),
:mod:`.kernel_compiled` (the numba loops) and :mod:`.kernel_metric` (gyro
compensation, metric flow); :mod:`.kernel_bias` (the kernel's sub-pixel bias),
:mod:`.model` (the array, SE(2) helpers), :mod:`.odometry` (the seed's
``A u = b``, robust fusion, integration), :mod:`.simulate` (real-photo ground,
sensor cameras, gyro, height, wheels), :mod:`.calibrate` (array calibration),
:mod:`.evaluate` (ATE, RPE, plots), :mod:`.log` (file formats),
:mod:`.mavlink` / :mod:`.mavlink_convert` (MAVLink logs), :mod:`.plausibility`,
:mod:`.workflow` (the steps), :mod:`.report` (reports from a result),
:mod:`.commands` (the extra commands), :mod:`.demo` and :mod:`.cli` (the
declaration).

The names in ``__all__`` are imported from their submodule on first access
(PEP 562): importing the package, e.g. for ``robocal flow --help`` through
:mod:`.cli`, does not import numba, OpenCV, matplotlib or scipy.
"""

from __future__ import annotations

from robocal._lazy import lazy_exports

#: exported name -> submodule defining it (no exported name is also a submodule's name; a test checks both)
_EXPORTS = {
    **dict.fromkeys(("FlowConfig", "FrameFlow", "compute_flow", "match_blocks", "match_sequence"), "kernel"),
    **dict.fromkeys(("SensorArray", "seed_array"), "model"),
    **dict.fromkeys(("Odometry", "SensorSteps", "dead_reckon", "fuse_steps"), "odometry"),
    **dict.fromkeys(("ArrayCalibration", "calibrate_array"), "calibrate"),
    **dict.fromkeys(("evaluate_trajectory", "rpe_lengths", "rpe_per_distance", "ate"), "evaluate"),
}

__all__ = [
    "FlowConfig", "FrameFlow", "compute_flow", "match_blocks", "match_sequence",
    "SensorArray", "seed_array", "Odometry", "SensorSteps", "dead_reckon", "fuse_steps",
    "ArrayCalibration", "calibrate_array", "evaluate_trajectory", "rpe_lengths", "rpe_per_distance", "ate",
]


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
