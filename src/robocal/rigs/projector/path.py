"""Spot paths: world path -> timed joint commands, over one or several projectors.

The names of :mod:`.trajectory` (one projector) and :mod:`.handover` (several), in one place.

A world path is given as waypoints plus a speed (:func:`sample_polyline`) or
as timed samples. Each sample goes through seed eqs. (1) and (8) to joint
angles, and the spot velocity through eqs. (2) and (9)^-1 to joint rates. A
sample is infeasible when the spot is outside the reachable floor, within
``nadir_margin`` of the nadir singularity (the pan rate is unbounded there),
or when a joint would exceed its speed limit; infeasible samples are grouped
into segments with their reason and the slow-down factor that would fix a
speed violation. A path through the nadir is followed on the other IK branch
``(theta1 + pi, -theta2)`` (constant pan, the tilt through zero) when the
model's ``tilt_min < 0`` allows negative tilt; see :func:`joint_trajectory`.

With several projectors (the seed's room has A and B), every sample is served
by a projector that reaches it, whose beam is not blocked by a wall (walls
are floor-to-ceiling partitions given as 2D segments; the beam's floor
projection runs from the projector's nadir to the spot), and that stays
feasible; the current projector is kept while it can serve (few hand-overs),
otherwise the one farthest from its singular set and tilt limit takes over.
"""

from __future__ import annotations

from robocal.rigs.projector.handover import (MultiPlan, plan_multi, require_reachable_path, retime,  # noqa: F401
                                             segments_blocked, tr_limits, unreachable_samples)
from robocal.rigs.projector.trajectory import (MAX_NADIR_SNAP, NADIR_SNAP, SNAP_LADDER, JointTrajectory,  # noqa: F401
                                               check_nadir_snap, joint_trajectory, sample_polyline)

__all__ = ["NADIR_SNAP", "MAX_NADIR_SNAP", "SNAP_LADDER", "check_nadir_snap", "sample_polyline", "JointTrajectory",
           "joint_trajectory", "segments_blocked", "MultiPlan",
           "plan_multi", "unreachable_samples", "require_reachable_path", "retime", "tr_limits"]
