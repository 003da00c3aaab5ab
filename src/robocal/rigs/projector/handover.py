"""Spot paths over several projectors: assignment, hand-overs, pre-aiming and retiming.

With several projectors (the seed's room has A and B), every sample is served
by a projector that reaches it, whose beam is not blocked by a wall (walls
are floor-to-ceiling partitions given as 2D segments; the beam's floor
projection runs from the projector's nadir to the spot), and that stays
feasible; the current projector is kept while it can serve (few hand-overs),
otherwise the one farthest from its singular set and tilt limit takes over.
Each projector's own trajectory: :mod:`robocal.rigs.projector.trajectory`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from robocal.errors import InputError
from robocal.rigs.projector.model import ProjectorModel, UnreachablePointError, wrap_angle
from robocal.rigs.projector.trajectory import (NADIR_SNAP, JointTrajectory, _kind, _runs, _timed,
                                               check_nadir_snap, joint_trajectory)
from robocal.validation import check_array

__all__ = ["segments_blocked", "MultiPlan", "plan_multi", "unreachable_samples", "require_reachable_path", "retime"]


def segments_blocked(starts, ends, walls) -> np.ndarray:
    """Whether each 2D segment ``starts[k] -> ends[k]`` crosses any wall ``[x0, y0, x1, y1]``.

    Returns a bool array (K,). Touching an end point counts as crossing.
    """
    a = np.asarray(starts, dtype=float)
    b = np.asarray(ends, dtype=float)
    W = np.asarray(walls, dtype=float).reshape(-1, 4)
    if W.size == 0:
        return np.zeros(np.broadcast_shapes(a.shape, b.shape)[:-1], dtype=bool)
    c, d = W[:, :2], W[:, 2:]
    a, b = a[..., None, :], b[..., None, :]

    def orient(p, q, r):
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

    o1, o2 = orient(a, b, c), orient(a, b, d)
    o3, o4 = orient(c, d, a), orient(c, d, b)
    return np.any((o1 * o2 <= 0) & (o3 * o4 <= 0) & ~((o1 == 0) & (o2 == 0)), axis=-1)


@dataclass
class MultiPlan:
    """Assignment of a path's samples to several projectors, with hand-overs.

    Attributes
    ----------
    names : list of str
    t, points : the path samples
    rate_limits, pan_ranges : per projector (rad/s; rad or None), used by :meth:`projector_commands`
    assignment : ndarray of int, shape (K,)
        Index of the serving projector, -1 where none can serve.
    trajectories : list of JointTrajectory
        Per projector, over the whole path.
    available : ndarray of bool, shape (P, K)
        Reachable, not occluded, feasible.
    occluded : ndarray of bool, shape (P, K)
    handovers : list of dict
        ``index, t, point, from, to``.
    segments : list of dict
        Contiguous runs ``projector, start, stop, t0, t1``.
    infeasible : list of dict
        Runs nobody can serve, with each projector's reason at the first sample.
    """

    names: list
    t: np.ndarray
    points: np.ndarray
    assignment: np.ndarray
    trajectories: list
    available: np.ndarray
    occluded: np.ndarray
    handovers: list
    segments: list
    infeasible: list
    rate_limits: list = field(default_factory=list)  # per projector (rad/s), for the idle heads' slews
    pan_ranges: list = field(default_factory=list)  # per projector: (min, max) unwrapped pan (rad) or None

    @property
    def ok(self) -> bool:
        return bool(np.all(self.assignment >= 0))

    def sample_status(self, i: int) -> str:
        """'ok' for a served sample, else 'infeasible: ' and each projector's reason there."""
        if self.assignment[i] >= 0:
            return "ok"
        why = []
        for k, tr in enumerate(self.trajectories):
            r = tr.reason[i] or ("beam blocked by a wall" if self.occluded[k, i] else "unavailable")
            why.append(f"{self.names[k]}: {r}")
        return "infeasible: " + "; ".join(why)

    def commands(self) -> dict:
        """Per-sample commands of the serving projector: t, x, y, projector, theta, theta_dot (NaN if none),
        status ('ok' or 'infeasible: <each projector's reason>', so unserved rows are not silently blank)."""
        K = len(self.t)
        th = np.full((K, 2), np.nan)
        td = np.full((K, 2), np.nan)
        for k, tr in enumerate(self.trajectories):
            m = self.assignment == k
            th[m] = tr.theta[m]
            td[m] = tr.theta_dot[m]
        return dict(t=self.t, x=self.points[:, 0], y=self.points[:, 1], projector=self.assignment, theta=th,
                    theta_dot=td, status=[self.sample_status(i) for i in range(K)])

    def projector_commands(self) -> tuple[list[dict], list[dict]]:
        """One command stream per projector, with the idle heads pre-aimed for their next hand-over.

        Each stream (dict) holds ``name, t, theta (K, 2), theta_dot (K, 2), laser_on (K,), mode (K,)``
        with mode ``'serve'`` (its trajectory, laser on), ``'slew'`` (moving to the pose where it takes
        over next, each joint at its rate limit, laser off) or ``'hold'``. Before its first segment a head
        holds that segment's first pose (set before the path starts); after its last it holds. The pan
        slews the short way round, and the commands after a slew continue on that turn, unless that
        would take the pan outside the head's ``pan_range`` during the slew or the next serving segment:
        then it slews on the nearest turn that keeps both inside (the serving trajectory's own turn always
        does, as its samples are checked against the range).

        Returns ``(streams, preaim)``: ``preaim`` lists each slew ``projector, t_start, t_ready,
        t_handover, ok`` (``ok``: ready by the hand-over time; else the head arrives late and the spot
        jumps there).
        """
        streams, preaim = [], []
        for k, tr in enumerate(self.trajectories):
            lim = np.asarray(tr_limits(self, k))
            th = np.array(tr.theta, dtype=float)
            td = np.array(tr.theta_dot, dtype=float)
            serve = self.assignment == k
            mode = np.where(serve, "serve", "hold").astype(object)
            runs = _runs(serve)
            if not runs:  # never serves: park at the first sample's pose
                th[:] = th[0]
                td[:] = 0.0
                streams.append(dict(name=self.names[k], t=self.t, theta=th, theta_dot=td, laser_on=serve,
                                    mode=mode.tolist()))
                continue
            out_th = np.empty_like(th)
            out_td = np.zeros_like(td)
            shift = 0.0  # whole turns added to the pan after short-way slews
            a0 = runs[0][0]
            out_th[:a0] = th[a0]
            for j, (a, b) in enumerate(runs):
                out_th[a:b + 1] = th[a:b + 1] + [shift, 0.0]
                out_td[a:b + 1] = td[a:b + 1]
                nxt = runs[j + 1][0] if j + 1 < len(runs) else None
                if nxt is None:
                    out_th[b + 1:] = out_th[b]
                    continue
                start = out_th[b]
                goal = th[nxt] + [shift, 0.0]
                d = goal - start
                d0 = float(wrap_angle(d[0]))
                rng = self.pan_ranges[k] if self.pan_ranges else None
                if rng is not None:
                    # the slew is monotone, so it stays in range iff its end does; the next segment must too
                    end = runs[j + 1][1]
                    seg_lo, seg_hi = float(th[nxt:end + 1, 0].min()), float(th[nxt:end + 1, 0].max())
                    m0 = round((start[0] + d0 - th[nxt, 0]) / (2 * math.pi))
                    fits = [m for m in range(m0 - 3, m0 + 4)
                            if seg_lo + 2 * math.pi * m >= rng[0] - 1e-9 and seg_hi + 2 * math.pi * m <= rng[1] + 1e-9]
                    if fits:
                        m = min(fits, key=lambda m: abs(th[nxt, 0] + 2 * math.pi * m - start[0]))
                        d0 = float(th[nxt, 0] + 2 * math.pi * m - start[0])
                shift += d0 - d[0]
                d[0] = d0
                goal = start + d
                dur = np.abs(d) / lim  # time each joint needs at its limit (s)
                for i in range(b + 1, nxt):
                    el = self.t[i] - self.t[b]
                    frac = np.where(dur > 0, np.minimum(el / np.where(dur > 0, dur, 1.0), 1.0), 1.0)
                    out_th[i] = start + frac * d
                    out_td[i] = np.where(frac < 1.0, np.sign(d) * lim, 0.0)
                    mode[i] = "slew" if np.any(frac < 1.0) else "hold"
                t_ready = float(self.t[b] + dur.max())
                preaim.append(dict(projector=self.names[k], t_start=float(self.t[b]), t_ready=t_ready,
                                   t_handover=float(self.t[nxt]), ok=bool(t_ready <= self.t[nxt] + 1e-9)))
            streams.append(dict(name=self.names[k], t=self.t, theta=out_th, theta_dot=out_td, laser_on=serve,
                                mode=mode.tolist()))
        return streams, preaim

    def to_dict(self, *, preaim: list | None = None) -> dict:
        """The plan for plan.json; ``preaim``: :meth:`projector_commands`' second value if already computed."""
        preaim = self.projector_commands()[1] if preaim is None else preaim
        return dict(names=self.names, ok=self.ok, n_samples=len(self.t), handovers=self.handovers,
                    segments=self.segments, infeasible=self.infeasible, preaim=preaim,
                    branches={tr.name: tr.branches for tr in self.trajectories})


def unreachable_samples(projectors, points_W) -> np.ndarray:
    """Indices of path samples (K, 2) that lie outside the reachable floor of *every* projector.

    No timing, hand-over or margin can serve them: the input is wrong (a
    waypoint in the wrong unit or frame), unlike a stretch that is too fast.
    """
    p = check_array(points_W, "points_W", shape=("K", 2))
    ok = np.zeros(len(p), dtype=bool)
    for proj in projectors:
        ok |= proj.reachable(proj.to_projector(p), floor_tol=1e-6 * max(1.0, proj.H))
    return np.flatnonzero(~ok)


def require_reachable_path(projectors, t, points_W) -> None:
    """Raise :class:`~robocal.rigs.projector.model.UnreachablePointError` naming samples no projector reaches."""
    bad = unreachable_samples(projectors, points_W)
    if bad.size:
        p = np.asarray(points_W, dtype=float)
        k = int(bad[0])
        disc = "; ".join(f"{q.name}: nadir ({q.nadir_world[0]:.3g}, {q.nadir_world[1]:.3g}) m, radius "
                         f"{q.floor_radius:.3g} m" for q in projectors)
        raise UnreachablePointError(
            f"path: {bad.size} sample(s) outside every projector's reachable floor, first t = {float(t[k]):.3g} s at "
            f"({p[k, 0]:.4g}, {p[k, 1]:.4g}) m ({disc})")


def tr_limits(plan: "MultiPlan", k: int) -> tuple:
    """Rate limits (rad/s) of projector ``k`` of a plan (default 90 deg/s when the plan predates them)."""
    return plan.rate_limits[k] if plan.rate_limits else (math.radians(90.0), math.radians(90.0))


def _peak_rate(tr: JointTrajectory, model: ProjectorModel, a: int, b: int):
    """``(text, slowdown)`` for the fastest joint over samples a..b (inclusive) where rates exist, else None."""
    lim = np.asarray(model.rate_limits)
    idx = [i for i in range(a, b + 1) if " rate " in tr.reason[i] or not tr.reason[i]]
    if not idx:
        return None
    ratio = np.abs(tr.theta_dot[idx]) / lim
    i, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    f = float(ratio[i, j])
    if f <= 1.0:
        return None
    return (f"{'pan' if j == 0 else 'tilt'} rate up to {math.degrees(abs(tr.theta_dot[idx[i], j])):.1f} deg/s > "
            f"{math.degrees(lim[j]):.1f} deg/s (slow the path down by x{f:.2f})", f)


def plan_multi(projectors, t, points_W, velocity_W=None, *, walls=None, nadir_margin: float = math.radians(2),
               limit_margin: float = math.radians(2), nadir_snap: float = NADIR_SNAP) -> MultiPlan:
    """Choose which projector serves each sample of a path and where to hand over.

    Rules: a projector is *available* at a sample when its trajectory there is
    feasible (reach with ``limit_margin``, ``nadir_margin``, rate limits) and
    the beam's floor projection (nadir -> spot) crosses no wall. The serving
    projector is kept while available; otherwise the available one with the
    largest singularity margin takes over (a hand-over point). Samples no
    projector can serve are reported as infeasible.

    Parameters
    ----------
    projectors : sequence of ProjectorModel
        Calibrated projectors with distinct names.
    t, points_W, velocity_W, nadir_margin, nadir_snap : see :func:`joint_trajectory`
    limit_margin : float
        Tilt (rad) kept free below each projector's tilt limit.
    walls : array_like, shape (W, 4), optional
        Wall segments ``[x0, y0, x1, y1]`` on the floor (m).

    Each infeasible run lists every projector's reason at its first sample;
    a speed problem gives the run's peak rate and ``slowdown``, and a pass
    close to a projector's nadir its distance, the pan rate it needs and the
    ``nadir_snap`` that would help (``nadir_pass`` of
    :func:`joint_trajectory`).
    """
    projectors = list(projectors)
    if not projectors:
        raise InputError("plan_multi needs at least one projector")
    names = [p.name for p in projectors]
    if len(set(names)) != len(names):
        raise InputError(f"projector names must be unique, got {names}")
    snap = check_nadir_snap(nadir_snap)
    t, p, v = _timed(t, points_W, velocity_W)
    W = np.zeros((0, 4)) if walls is None else check_array(walls, "walls", shape=("W", 4)).reshape(-1, 4)
    trajs, avail, occl, score = [], [], [], []
    for proj in projectors:
        tr = joint_trajectory(proj, t, p, v, nadir_margin=nadir_margin, limit_margin=limit_margin, nadir_snap=snap)
        occ = segments_blocked(np.broadcast_to(proj.nadir_world, p.shape), p, W)
        trajs.append(tr)
        occl.append(occ)
        avail.append(tr.feasible & ~occ)
        score.append(tr.margin)
    avail = np.array(avail)
    occl = np.array(occl)
    score = np.where(avail, np.array(score), -np.inf)
    K = len(t)
    assign = np.full(K, -1)
    cur = -1
    for i in range(K):
        if cur >= 0 and avail[cur, i]:
            assign[i] = cur
            continue
        best = int(np.argmax(score[:, i]))
        cur = best if avail[best, i] else -1
        assign[i] = cur
    handovers, segments, infeasible = [], [], []
    for i in range(1, K):
        if assign[i] != assign[i - 1] and assign[i] >= 0 and assign[i - 1] >= 0:
            handovers.append(dict(index=i, t=float(t[i]), point=p[i].tolist(), **{"from": names[assign[i - 1]],
                                                                                   "to": names[assign[i]]}))
    start = 0
    for i in range(1, K + 1):
        if i == K or assign[i] != assign[start]:
            if assign[start] >= 0:
                segments.append(dict(projector=names[assign[start]], start=start, stop=i - 1, t0=float(t[start]),
                                     t1=float(t[i - 1])))
            else:
                why, slow = {}, {}
                for k, tr in enumerate(trajs):
                    why[names[k]] = "beam blocked by a wall" if occl[k, start] and tr.feasible[start] else (
                        tr.reason[start] or ("beam blocked by a wall" if occl[k, start] else "unavailable"))
                    peak = _peak_rate(tr, projectors[k], start, i - 1)
                    if peak is not None and " rate " in why[names[k]]:
                        # the first sample's rate understates the stretch: report its peak and the fix
                        why[names[k]] = peak[0]
                        slow[names[k]] = peak[1]
                    note = next((sg["nadir_pass"] for sg in tr.segments if "nadir_pass" in sg
                                 and sg["start"] <= i - 1 and sg["stop"] >= start), None)
                    if note is not None and not occl[k, start]:
                        why[names[k]] = _kind(why[names[k]]) if why[names[k]].startswith("pan turns") else why[names[k]]
                        why[names[k]] += "; " + note["text"]
                infeasible.append(dict(start=start, stop=i - 1, t0=float(t[start]), t1=float(t[i - 1]),
                                       reasons=why, **({"slowdown": slow} if slow else {})))
            start = i
    return MultiPlan(names, t, p, assign, trajs, avail, occl, handovers, segments, infeasible,
                     [tuple(q.rate_limits) for q in projectors], [q.pan_range for q in projectors])


def retime(projectors, t, points_W, velocity_W=None, *, walls=None, nadir_margin: float = math.radians(2),
           limit_margin: float = math.radians(2), nadir_snap: float = NADIR_SNAP, max_passes: int = 8):
    """Slow a path down where, and only where, the joint rate limits require it.

    Joint rates are linear in the spot velocity at a given pose (seed eq. 9^-1),
    so a sample whose best projector needs the factor ``f`` (largest ``|rate| /
    limit``) is served once the spot moves ``f`` times slower there. Each pass
    stretches the sample intervals next to such samples by ``f`` (given
    velocities are divided by it; without velocities they follow from the new
    times) and plans again, until no sample is limited by speed alone or
    ``max_passes`` is reached. Samples infeasible for other reasons (reach,
    nadir, walls, pan range) are left as they are.

    Returns ``(t, velocity, plan)``: the new times (s), velocities (m/s, None
    when none were given) and the :class:`MultiPlan` on them.
    """
    projectors = list(projectors)
    t, p, v = _timed(t, points_W, velocity_W)
    vel = None if velocity_W is None else v
    kw = dict(walls=walls, nadir_margin=nadir_margin, limit_margin=limit_margin, nadir_snap=nadir_snap)
    plan = plan_multi(projectors, t, p, vel, **kw)
    for _ in range(max_passes):
        need = np.ones(len(t))
        for i in np.flatnonzero(plan.assignment < 0):
            f = [float(np.max(np.abs(tr.theta_dot[i]) / np.asarray(q.rate_limits)))
                 for k, (tr, q) in enumerate(zip(plan.trajectories, projectors))
                 if tr.reason[i].startswith(("pan rate", "tilt rate")) and not plan.occluded[k, i]]
            if f:
                need[i] = min(f) * (1 + 1e-6)
        if np.all(need == 1.0):
            break
        stretch = np.maximum(need[:-1], need[1:])
        t = np.concatenate([[t[0]], t[0] + np.cumsum(np.diff(t) * stretch)])
        if vel is not None:
            vel = vel / need[:, None]
        plan = plan_multi(projectors, t, p, vel, **kw)
    return t, vel, plan
