"""Rig ``lineprofiler``: hand-eye calibration of an arm-mounted line-laser profiler (seed 004).

Modules: :mod:`.handeye` (AX = XB / AX = ZB solvers), :mod:`.model` (arm,
profiler, targets, tracker), :mod:`.simulate`, :mod:`.fpdp` (fixed point,
different poses), :mod:`.mct` (multi-coordinate transformation), :mod:`.refine`
(geometric refinement on raw profile points), :mod:`.errors_seed` (e_v, e_theta,
e_p), :mod:`.io` (profile and pose files), :mod:`.cli`.
"""
