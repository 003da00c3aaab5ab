"""Rig ``lineprofiler``: hand-eye calibration of an arm-mounted line-laser profiler (seed 004).

The AX = XB / AX = ZB solvers are the core's :mod:`robocal.handeye` (``.handeye``
and ``.handeye_workflow`` here are deprecated aliases). Modules: :mod:`.model`
(arm, profiler, targets, tracker), :mod:`.simulate`, :mod:`.fpdp` (fixed point,
different poses), :mod:`.mct` (multi-coordinate transformation), :mod:`.refine`
(geometric refinement on raw profile points), :mod:`.compare` (e_v, e_theta,
e_p of repeated calibrations; the seed's comparison), :mod:`.io` (profile and
pose files), :mod:`.calibrate` (input file -> calibration), :mod:`.result` and
:mod:`.report` (result file, report from it), :mod:`.workflow` (the steps of
``robocal lineprofiler``), :mod:`.cli` (its declaration).
"""

#: the package exports nothing itself: import from the modules (importing it stays light for the CLI)
__all__: list[str] = []
