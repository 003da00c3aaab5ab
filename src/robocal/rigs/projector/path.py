"""Spot paths: world path -> timed joint commands, over one or several projectors.

The names of :mod:`.trajectory` (one projector) and :mod:`.handover` (several), in one place.

How a path becomes timed joint commands on one projector: :mod:`.trajectory`'s docstring;
which projector serves each sample and when it hands over: :mod:`.handover`'s.
"""

from __future__ import annotations

from robocal.rigs.projector.handover import (MultiPlan, plan_multi, require_reachable_path, retime,  # noqa: F401
                                             segments_blocked, tr_limits, unreachable_samples)
from robocal.rigs.projector.trajectory import (MAX_NADIR_SNAP, NADIR_SNAP, SNAP_LADDER, JointTrajectory,  # noqa: F401
                                               check_nadir_snap, joint_trajectory, sample_polyline)

__all__ = ["NADIR_SNAP", "MAX_NADIR_SNAP", "SNAP_LADDER", "check_nadir_snap", "sample_polyline", "JointTrajectory",
           "joint_trajectory", "segments_blocked", "MultiPlan",
           "plan_multi", "unreachable_samples", "require_reachable_path", "retime", "tr_limits"]
