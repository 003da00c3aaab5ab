"""One projector's spot path: world samples -> joint angles and rates (seed 000 eqs. 1, 2, 8, 9).

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
Several projectors and their hand-overs: :mod:`robocal.rigs.projector.handover`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from robocal.errors import InputError, NotEnoughDataError, ShapeError
from robocal.rigs.projector.model import NADIR_TOL, ProjectorModel, wrap_angle
from robocal.validation import check_array

#: Distance (m) from the nadir within which a path sample is commanded onto the nadir (pan held).
NADIR_SNAP = 1e-3
#: Largest accepted ``nadir_snap`` (m): the spot error near the nadir is up to ``nadir_snap``.
MAX_NADIR_SNAP = 0.1
#: ``nadir_snap`` values (m) tried when suggesting one for an infeasible pass near the nadir.
SNAP_LADDER = (2e-3, 3e-3, 5e-3, 1e-2, 1.5e-2, 2e-2, 3e-2, 5e-2, 0.1)

__all__ = ["NADIR_SNAP", "MAX_NADIR_SNAP", "SNAP_LADDER", "check_nadir_snap", "sample_polyline", "JointTrajectory",
           "joint_trajectory"]


def sample_polyline(waypoints, speed: float, dt: float):
    """Constant-speed samples along a polyline.

    Parameters
    ----------
    waypoints : array_like, shape (M, 2)
        World floor points (m), M >= 2.
    speed : float
        Spot speed (m/s), > 0.
    dt : float
        Sample period (s), > 0.

    Returns
    -------
    t : ndarray, shape (K,)
    points : ndarray, shape (K, 2)
    velocity : ndarray, shape (K, 2)
        The polyline's velocity (m/s); at a corner the outgoing segment's.
    """
    w = check_array(waypoints, "waypoints", shape=("M", 2))
    if w.ndim != 2:
        raise ShapeError(f"waypoints must have shape (M, 2), got {tuple(w.shape)}")
    if w.shape[0] < 2:
        raise NotEnoughDataError(f"a path needs at least 2 waypoints, got {w.shape[0]}")
    if not (math.isfinite(speed) and speed > 0) or not (math.isfinite(dt) and dt > 0):
        raise InputError(f"speed and dt must be > 0, got speed={speed!r} m/s, dt={dt!r} s")
    seg = np.diff(w, axis=0)
    L = np.linalg.norm(seg, axis=1)
    if np.any(L == 0):
        k = int(np.flatnonzero(L == 0)[0])
        raise InputError(f"waypoints {k} and {k + 1} coincide (zero-length segment)")
    s_cum = np.concatenate([[0.0], np.cumsum(L)])
    total = s_cum[-1]
    n = int(math.floor(total / (speed * dt) + 1e-9)) + 1
    if n > 2_000_000:
        raise InputError(f"path would have {n} samples: increase dt or speed")
    s = np.minimum(np.arange(n) * speed * dt, total)
    if s[-1] < total - 1e-12:
        s = np.append(s, total)
    t = s / speed
    k = np.clip(np.searchsorted(s_cum, s, side="right") - 1, 0, len(L) - 1)
    u = (s - s_cum[k]) / L[k]
    pts = w[k] + u[:, None] * seg[k]
    vel = speed * seg[k] / L[k][:, None]
    return t, pts, vel


def _timed(t, points, velocity):
    t = check_array(t, "t", shape=("K",))
    p = check_array(points, "points", shape=("K", 2))
    if t.ndim != 1 or p.ndim != 2 or p.shape[0] != t.shape[0]:
        raise ShapeError(f"t must have shape (K,) and points (K, 2) with the same K, got {t.shape} and {p.shape}")
    if t.size < 2:
        raise NotEnoughDataError(f"a timed path needs at least 2 samples, got {t.size}")
    if np.any(np.diff(t) <= 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise InputError(f"times must increase strictly, got t[{k}] = {t[k]:g} s >= t[{k + 1}] = {t[k + 1]:g} s")
    if velocity is None:
        v = np.gradient(p, t, axis=0)
    else:
        v = check_array(velocity, "velocity", shape=("K", 2))
        if v.shape != p.shape:
            raise ShapeError(f"velocity must have shape {p.shape}, got {v.shape}")
    return t, p, v


@dataclass
class JointTrajectory:
    """Timed joint commands for one projector along a world path.

    Attributes
    ----------
    name : str
    t : ndarray, shape (K,)
    points : ndarray, shape (K, 2)
    theta : ndarray, shape (K, 2)
        Commanded angles (rad), pan unwrapped to be continuous.
    theta_dot : ndarray, shape (K, 2)
        Joint rates (rad/s): eq. (9) inverted where defined, else finite
        differences (never inf/NaN).
    feasible : ndarray of bool, shape (K,)
    reason : list of str
        Per sample, '' when feasible.
    margin : ndarray, shape (K,)
        Distance (rad) of the tilt from the nadir and from the tilt limit.
    segments : list of dict
        Infeasible runs: ``start, stop`` (sample indices, inclusive), ``t0, t1``,
        ``reason``, ``slowdown`` (factor the path speed must be divided by
        to respect the rate limits, when speed is the problem), and
        ``nadir_pass`` when passing close to the nadir is the cause (see
        :func:`joint_trajectory`).
    branches : list of dict
        Per stretch between nadir crossings: ``start, stop, t0, t1``, ``branch``
        (0: eq. 8, tilt >= 0; 1: ``(theta1 + pi, -theta2)``), ``ik`` (its name)
        and ``why`` (crossing followed or not, and what the other branch would
        cost there).
    nadir_distance : ndarray, shape (K,)
        Nearest approach (m) of the path to the nadir around each sample (its
        own distance and its two steps' chords).
    """

    name: str
    t: np.ndarray
    points: np.ndarray
    theta: np.ndarray
    theta_dot: np.ndarray
    feasible: np.ndarray
    reason: list
    margin: np.ndarray
    segments: list = field(default_factory=list)
    branches: list = field(default_factory=list)
    nadir_distance: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return bool(np.all(self.feasible))


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    m = np.concatenate([[False], mask, [False]]).astype(int)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1))


def _turns(p0: np.ndarray, pan: np.ndarray):
    """Per step ``i-1 -> i`` (value at ``i``; False/inf at 0): whether the eq. (8) pan turns by more than
    pi/2, and the distance (m) of the step's chord from the nadir.

    A turn with its chord within ``nadir_snap`` of the nadir is a *crossing*: eq. (8) flips the pan by
    ~pi there and the continuous joint motion is the other branch ``(theta1 + pi, -theta2)``. A turn
    farther out means the path is sampled too coarsely near the nadir to follow the pan between samples.
    """
    turn = np.zeros(len(pan), dtype=bool)
    closest = np.full(len(pan), np.inf)
    if len(pan) < 2:
        return turn, closest
    turn[1:] = np.abs(wrap_angle(np.diff(pan))) > math.pi / 2
    q0, q1 = p0[:-1, :2], p0[1:, :2]
    d = q1 - q0
    dd = np.einsum("ij,ij->i", d, d)
    u = np.clip(-np.einsum("ij,ij->i", q0, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    closest[1:] = np.hypot(*(q0 + u[:, None] * d).T)
    return turn, closest


def _fill_pan(pan: np.ndarray, defined: np.ndarray) -> np.ndarray:
    """Eq. (8) pans (K,) with the undefined ones (spot on the nadir) held from the previous defined sample."""
    if not np.any(defined) or np.all(defined):
        return pan.copy()
    idx = np.maximum.accumulate(np.where(defined, np.arange(len(pan)), -1))
    idx[idx < 0] = int(np.flatnonzero(defined)[0])
    return pan[idx]


def _branch_theta(model: ProjectorModel, th0: np.ndarray, flips: np.ndarray, b0: int):
    """Commanded angles (K, 2) and branch (K,) with the branch switched at ``flips``, starting on ``b0``.

    Branch 0 is seed eq. (8); branch 1 is ``(theta1 + pi, -theta2)`` (actual angles, offsets kept), the same
    spot by eq. (6). ``th0``: eq. (8) angles with the undefined pans filled (:func:`_fill_pan`).
    """
    pan = th0[:, 0]
    branch = (b0 + np.cumsum(flips)) % 2
    tilt_act = th0[:, 1] + model.offsets[1]
    theta = np.empty_like(th0)
    theta[:, 0] = np.unwrap(pan + math.pi * branch)
    theta[:, 1] = np.where(branch == 1, -tilt_act, tilt_act) - model.offsets[1]
    return theta, branch


def check_nadir_snap(nadir_snap) -> float:
    """``nadir_snap`` (m) as a float in ``[0, MAX_NADIR_SNAP]``, else :class:`~robocal.errors.InputError`."""
    try:
        s = float(nadir_snap)
    except (TypeError, ValueError):
        raise InputError(f"nadir_snap must be a distance in m, got {nadir_snap!r}") from None
    if not (math.isfinite(s) and 0.0 <= s <= MAX_NADIR_SNAP):
        raise InputError(f"nadir_snap must be in [0, {MAX_NADIR_SNAP:g}] m (the spot error there is up to "
                         f"nadir_snap), got {s!r} m")
    return s


def joint_trajectory(model: ProjectorModel, t, points_W, velocity_W=None, *, nadir_margin: float = math.radians(2),
                     limit_margin: float = 0.0, nadir_snap: float = NADIR_SNAP) -> JointTrajectory:
    """Joint angles and rates that move the spot along a timed world path (seed eqs. 1, 2, 8, 9).

    Parameters
    ----------
    model : ProjectorModel
        Calibrated projector (extrinsics, ``rate_limits``, ``tilt_limit``, ``tilt_min``, ``pan_range``).
    t : array_like, shape (K,)
        Sample times (s), strictly increasing.
    points_W : array_like, shape (K, 2)
        Spot positions on the floor (m).
    velocity_W : array_like, shape (K, 2), optional
        Spot velocities (m/s); default: numerical derivative of the points.
    nadir_margin : float
        Tilt (rad) under which a sample counts as at the nadir singularity.
    limit_margin : float
        Tilt (rad) kept free below the tilt limit.
    nadir_snap : float
        Samples closer than this (m, in ``[0, MAX_NADIR_SNAP]``) to the nadir are commanded onto the
        nadir itself (tilt 0, pan held from the previous sample): the spot error there is at most
        ``nadir_snap`` (default 1 mm), and a path passing that close counts as going through the nadir
        whatever the sampling phase.

    IK branch, decided per stretch between nadir crossings. A *crossing* is a
    step turning the spot's direction by > pi/2 with its chord within
    ``nadir_snap`` of the nadir; the crossings cut the path into stretches.
    Each stretch is on eq. (8) (branch 0, tilt >= 0) or on the other branch
    ``(theta1 + pi, -theta2)`` (branch 1, the same spot by eq. 6, needs
    ``model.tilt_min < 0``). A crossing between stretches on different
    branches is *followed*: the pan stays put and the tilt goes through zero.
    Between stretches on the same branch the pan flips by pi there and the
    crossing's two samples are infeasible. The branches are chosen by dynamic
    programming over the stretches: fewest infeasible samples, then fewest
    unfollowed crossings, then starting on eq. (8); the all-switching and
    never-switching choices are kept as fall-backs (the pan-range centring is
    global, so the per-stretch counts are estimates). ``result.branches``
    says, per stretch, which branch is used and why.

    Near the nadir eq. (9)^-1 is undefined: with ``tilt_min < 0`` the rates
    there are finite differences of the continuous joint series and only the
    rate limits decide; with ``tilt_min = 0`` those samples are infeasible
    (reason "within ... of the nadir singularity", or "nadir crossing needs
    negative tilt"). A step whose pan turns by > pi/2 farther from the nadir is
    infeasible ("pan turns by over 90 deg between two samples"): eq. (9) at its
    ends cannot see that. An infeasible stretch caused by passing close to the
    nadir (the pan must swing ~pi at up to ``v / d`` rad/s) carries a
    ``nadir_pass`` record in ``result.segments`` (distance, needed pan rate,
    limit, and the smallest ``nadir_snap`` found to make it feasible, if any).

    The pan is unwrapped along the path; with ``model.pan_range`` the whole
    series is shifted by whole turns to centre it in the range, and samples
    still outside are infeasible ("pan beyond its range").
    """
    snap = check_nadir_snap(nadir_snap)
    t, p, v = _timed(t, points_W, velocity_W)
    tr = _trajectory(model, t, p, v, nadir_margin, limit_margin, snap)
    for seg in tr.segments:
        note = _nadir_pass(model, tr, seg, t, p, v, nadir_margin, limit_margin, snap)
        if note is not None:
            seg["nadir_pass"] = note
            seg["reason"] += "; " + note["text"]
    return tr


def _trajectory(model, t, p, v, nadir_margin, limit_margin, snap) -> JointTrajectory:
    """:func:`joint_trajectory` on checked inputs, without the nadir-pass notes."""
    K = len(t)
    p0 = model.to_projector(p)
    r = np.hypot(p0[:, 0], p0[:, 1])
    tilt_actual = np.arctan2(r, model.h)
    th0 = model.ik(p0, check_reach=False, on_nadir="ignore")
    # within nadir_snap of the nadir the spot is put on the nadir itself (error <= nadir_snap): the pan there is
    # undefined and held, so a path that passes that close is followed through the nadir, not round it
    thr = max(snap, NADIR_TOL * model.h)
    defined = r > thr
    th0[:, 0] = _fill_pan(th0[:, 0], defined)
    th0[~defined, 1] = -model.offsets[1]
    turn, closest = _turns(p0, th0[:, 0])
    crossing = turn & (closest <= thr)
    jump = turn & ~crossing
    nadir = tilt_actual < nadir_margin
    reach = tilt_actual <= model.tilt_limit - limit_margin
    negative_ok = model.tilt_min < 0.0
    none = np.zeros(K, dtype=bool)
    ci = np.flatnonzero(crossing)  # a crossing's end sample starts the next stretch
    bounds = np.concatenate([[0], ci, [K]]).astype(int)
    # per sample, the tilt the other branch needs on the stretch after the nearest crossing (for the reason text)
    need = np.zeros(K)
    if ci.size:
        need_c = -np.array([tilt_actual[bounds[j]:bounds[j + 1]].max() for j in range(1, len(bounds) - 1)])
        i = np.arange(K)
        k = np.clip(np.searchsorted(ci, i), 0, ci.size - 1)
        km = np.maximum(k - 1, 0)
        need = need_c[np.where(np.abs(ci[km] - i) < np.abs(ci[k] - i), km, k)]
    # nearest approach to the nadir around each sample: its own distance and its two steps' chords (m)
    near = np.minimum(r, np.minimum(closest, np.append(closest[1:], np.inf)))

    def run(b0, flips):
        return b0, flips, _evaluate(model, t, p, v, th0, flips, b0, crossing & ~flips, jump, closest, nadir, reach,
                                    tilt_actual, nadir_margin, limit_margin, need)

    if negative_ok:
        both = [run(0, crossing)[2], run(1, crossing)[2]]  # every crossing followed: stretch j on branch (b0 + j) % 2
        b0, flips = _choose_branches([e[2] for e in both], bounds)
        cands = [run(b0, flips), (0, crossing, both[0]), (1, crossing, both[1])]
        if ci.size:
            cands.append(run(0, none))
    else:
        both = None
        cands = [run(0, none)]
    b0, flips, best = cands[0]
    for c in cands[1:]:
        if int(c[2][2].sum()) > int(best[2].sum()):
            b0, flips, best = c
    theta, rates, feasible, reason, slow_ok, ratio = best
    margin = np.minimum(tilt_actual, model.tilt_limit - tilt_actual)
    segments = []
    for a, b in _runs(~feasible):
        kinds = sorted({_kind(reason[i]) for i in range(a, b + 1)})
        seg = dict(start=int(a), stop=int(b), t0=float(t[a]), t1=float(t[b]), reason="; ".join(kinds))
        if np.all(slow_ok[a:b + 1]):
            seg["slowdown"] = float(ratio[a:b + 1].max())
        segments.append(seg)
    branch = (b0 + np.cumsum(flips)) % 2
    branches = _branch_report(model, t, bounds, branch, feasible, reason, both)
    return JointTrajectory(model.name, t, p, theta, rates, feasible, reason, margin, segments, branches, near)


def _kind(reason: str) -> str:
    """The kind of a per-sample reason, for a stretch's summary: its text before the details."""
    if reason.startswith(("pan rate", "tilt rate")):
        return reason.split(" rate")[0] + " rate above its limit"
    return reason.split(" (")[0]


def _choose_branches(feasible_by_b0, bounds):
    """``(b0, flips)``: the branch of each stretch between nadir crossings, by dynamic programming.

    ``feasible_by_b0[b]``: per-sample feasibility (K,) with every crossing followed, starting on branch ``b``
    (stretch ``j`` on branch ``(b + j) % 2``). Cost, compared in order: infeasible samples (an unfollowed
    crossing also loses its step's two samples), unfollowed crossings, the first stretch not on eq. (8).
    """
    K = int(bounds[-1])
    nseg = len(bounds) - 1

    def ok(j, b, i):  # sample i of stretch j feasible on branch b
        return bool(feasible_by_b0[(b + j) % 2][i])

    bad = [[int(np.sum(~feasible_by_b0[(b + j) % 2][bounds[j]:bounds[j + 1]])) for b in (0, 1)] for j in range(nseg)]
    cost = [(bad[0][b], 0, b) for b in (0, 1)]
    back = []
    for j in range(1, nseg):
        c = int(bounds[j])
        new, bk = [], []
        for b in (0, 1):
            opts = []
            for a in (0, 1):
                if a != b:  # followed: pan held, tilt through zero
                    add = (bad[j][b], 0, 0)
                else:  # the pan flips by pi: the step's samples c-1, c are lost too
                    add = (bad[j][b] + ok(j - 1, b, c - 1) + ok(j, b, c), 1, 0)
                opts.append((tuple(x + y for x, y in zip(cost[a], add)), a))
            best = min(opts)
            new.append(best[0])
            bk.append(best[1])
        cost = new
        back.append(bk)
    b = 0 if cost[0] <= cost[1] else 1
    seq = [b]
    for bk in reversed(back):
        b = bk[b]
        seq.append(b)
    seq.reverse()
    flips = np.zeros(K, dtype=bool)
    for j in range(1, nseg):
        flips[bounds[j]] = seq[j] != seq[j - 1]
    return seq[0], flips


_BRANCH_NAMES = ("eq. 8 (tilt >= 0)", "(theta1 + pi, -theta2) (tilt <= 0)")


def _branch_report(model, t, bounds, branch, feasible, reason, both) -> list:
    """Per stretch between nadir crossings: ``start, stop, t0, t1, branch (0/1), ik, why``."""
    out = []
    for j in range(len(bounds) - 1):
        a, b = int(bounds[j]), int(bounds[j + 1]) - 1
        br = int(branch[a])
        why = []
        followed = j > 0 and br != int(branch[a - 1])
        if j == 0:
            why.append("path start" + (" (eq. 8, the default)" if br == 0 else ""))
        else:
            why.append(f"nadir crossing at t = {t[a]:.3f} s " + (
                "followed: pan held, tilt through zero" if followed else
                "not followed: the pan flips by 180 deg there (infeasible)"))
        if both is None:
            if j > 0:
                why.append(f"tilt_min = {math.degrees(model.tilt_min):g} deg: no negative-tilt branch")
        elif not followed:
            other = both[(1 - br + j) % 2]
            n_other = int(np.sum(~other[2][a:b + 1]))
            n_here = int(np.sum(~feasible[a:b + 1]))
            next_followed = b + 1 < len(branch) and int(branch[b + 1]) != br
            if n_other > n_here or (j > 0 and n_other):
                first = next((other[3][i] for i in range(a, b + 1) if not other[2][i]), "")
                why.append(f"the other branch would leave {n_other} sample(s) infeasible here "
                           f"({first.split(' (')[0]})")
            elif br == 1 and next_followed:
                why.append(f"so that the nadir crossing at t = {t[b + 1]:.3f} s is followed (the stretch after it "
                           f"is on eq. 8)")
        out.append(dict(start=a, stop=b, t0=float(t[a]), t1=float(t[b]), branch=br, ik=_BRANCH_NAMES[br],
                        why="; ".join(w for w in why if w)))
    return out


def _nadir_pass(model, tr, seg, t, p, v, nadir_margin, limit_margin, snap):
    """The ``nadir_pass`` record of an infeasible stretch caused by passing close to the nadir, else None.

    Passing at distance ``d`` with speed ``v`` the pan must swing ~pi at up to ``v / d``: when that exceeds the
    pan's rate limit the stretch is infeasible whatever the sampling. With ``tilt_min < 0`` the larger
    ``nadir_snap`` values of a short ladder are tried on the stretch (with 50 samples either side) and the first
    that makes it feasible is suggested; the spot error is then at most that distance near the nadir.
    """
    a, b = seg["start"], seg["stop"]
    if not any(("pan" in tr.reason[i]) for i in range(a, b + 1)):
        return None
    d = tr.nadir_distance[a:b + 1]
    i = a + int(np.argmin(d))
    dmin = float(d[i - a])
    speed = float(np.hypot(*v[i]))
    lim = float(model.rate_limits[0])
    if not (dmin > max(snap, NADIR_TOL * model.h) and speed / dmin > lim):
        return None  # within nadir_snap it is a crossing, whose own reason says what is wrong
    note = dict(distance=dmin, speed=speed, pan_rate=speed / dmin, limit=lim, snap=None)
    text = (f"the path passes {1000 * dmin:.3g} mm from the nadir at {speed:.3g} m/s: the pan must swing ~180 deg "
            f"there, at up to v/d = {math.degrees(speed / dmin):.0f} deg/s (limit {math.degrees(lim):.0f} deg/s)")
    if dmin > MAX_NADIR_SNAP:
        text += f"; keep the path at least v / limit = {speed / lim:.2g} m from the nadir, or slow it down"
    elif model.tilt_min < 0.0:
        lo, hi = max(a - 50, 0), min(b + 51, len(t))
        ladder = sorted({math.ceil(dmin * 1e4) / 1e4, *SNAP_LADDER})
        for s in ladder:
            if s <= snap or s < dmin or s > MAX_NADIR_SNAP:
                continue
            trial = _trajectory(model, t[lo:hi], p[lo:hi], v[lo:hi], nadir_margin, limit_margin, s)
            if np.all(trial.feasible[a - lo:b + 1 - lo]):
                note["snap"] = s
                break
        if note["snap"] is not None:
            text += (f"; nadir_snap = {1000 * note['snap']:g} mm (--nadir-snap {1000 * note['snap']:g}) takes it "
                     f"through the nadir instead (spot error up to {1000 * note['snap']:g} mm there)")
        else:
            text += (f"; no nadir_snap up to {1000 * MAX_NADIR_SNAP:g} mm helps: keep the path at least "
                     f"v / limit = {speed / lim:.2g} m from the nadir, or slow it down")
    else:
        text += (f"; keep the path at least v / limit = {speed / lim:.2g} m from the nadir, or slow it down "
                 f"(going through the nadir with a larger nadir_snap needs tilt_min < 0)")
    note["text"] = text
    return note


def _evaluate(model, t, p, v, th0, flips, b0, unfollowed, jump, closest, nadir, reach, tilt_actual, nadir_margin,
              limit_margin, need):
    """Joint series on one branch choice and its per-sample feasibility (see :func:`joint_trajectory`).

    ``unfollowed``: nadir crossings (True at the step's end sample) taken on the same branch, i.e. with the
    pan flipping by ~pi; ``jump``: steps whose pan turns by > pi/2 away from the nadir (too coarse a
    sampling: eq. 9 at the samples cannot see the pan's motion between them). Both steps' two samples are
    infeasible. ``need`` (K,): per sample, the signed tilt (rad) the stretch after the nearest crossing would
    need on the negative-tilt branch (quoted when an unfollowed crossing is for want of negative tilt).
    """
    K = len(t)
    theta, branch = _branch_theta(model, th0, flips, b0)
    negative_ok = model.tilt_min < 0.0
    flipped = np.zeros(K, dtype=bool)
    i_unf = np.flatnonzero(unfollowed)
    flipped[i_unf] = True
    flipped[i_unf - 1] = True
    if not negative_ok:
        # the whole nadir stretch of a crossing is infeasible for that one reason (the first sample is quoted)
        for a, b in _runs(nadir | flipped):
            if np.any(flipped[a:b + 1]):
                flipped[a:b + 1] = True
    jumped = np.zeros(K, dtype=bool)
    i_j = np.flatnonzero(jump)
    jumped[i_j] = True
    jumped[i_j - 1] = True
    pan_out = np.zeros(K, dtype=bool)
    if model.pan_range is not None:
        # start on the turn that centres the wound-up pan in the mechanical range
        lo, hi = model.pan_range
        mid = 0.5 * (theta[:, 0].min() + theta[:, 0].max())
        theta[:, 0] += 2 * math.pi * round((0.5 * (lo + hi) - mid) / (2 * math.pi))
        pan_out = (theta[:, 0] < lo - 1e-12) | (theta[:, 0] > hi + 1e-12)
    signed_tilt = np.where(branch == 1, -tilt_actual, tilt_actual)
    too_low = signed_tilt < model.tilt_min - 1e-12
    # eq. (9)^-1 is undefined near the nadir: there the rates are those of the continuous joint series
    singular = nadir if negative_ok else (nadir | flipped)
    rates = np.gradient(theta, t, axis=0)
    good = reach & ~nadir
    if np.any(good):
        rates[good] = model.joint_rates_world(theta[good], v[good], nadir_tol=nadir_margin * 0.5)
    lim = np.asarray(model.rate_limits)
    ratio = np.max(np.abs(rates) / lim, axis=1)
    fast = ratio > 1.0 + 1e-9
    blocked = (singular if not negative_ok else flipped) | jumped
    reason = []
    for i in range(K):
        if not reach[i]:
            reason.append(f"outside the reachable floor (tilt {math.degrees(tilt_actual[i]):.1f} deg > "
                          f"{math.degrees(model.tilt_limit - limit_margin):.1f} deg)")
        elif flipped[i] and (not negative_ok or need[i] < model.tilt_min - 1e-12):
            reason.append(f"nadir crossing needs negative tilt (the eq. 8 pan flips by 180 deg here; following "
                          f"the path on the (theta1 + pi, -theta2) branch needs tilt down to "
                          f"{math.degrees(need[i]):.1f} deg, tilt_min = {math.degrees(model.tilt_min):g} deg)")
        elif flipped[i]:
            reason.append("nadir crossing not followed (the pan flips by 180 deg here: switching the IK branch "
                          "there would make the next stretch infeasible, see the branch report)")
        elif jumped[i]:
            d = float(np.min(closest[i:i + 2]))
            w = float(np.hypot(*v[i])) / max(d, 1e-12)
            # when v/d is over the pan limit finer sampling cannot help: the stretch's nadir_pass note says so
            reason.append(f"pan turns by over 90 deg between two samples near the nadir (the path passes "
                          f"{1000 * d:.3g} mm from it" + ("; sample it more finely)" if w <= lim[0] else ")"))
        elif blocked[i]:
            reason.append(f"within {math.degrees(nadir_margin):g} deg of the nadir singularity (pan undefined; "
                          f"set tilt_min < 0 to pass through it on the (theta1 + pi, -theta2) branch)")
        elif too_low[i]:
            reason.append(f"tilt below tilt_min (tilt {math.degrees(signed_tilt[i]):.1f} deg < "
                          f"{math.degrees(model.tilt_min):g} deg on the (theta1 + pi, -theta2) branch after a "
                          f"nadir crossing)")
        elif pan_out[i]:
            reason.append(f"pan beyond its range (unwrapped pan {math.degrees(theta[i, 0]):.1f} deg outside "
                          f"[{math.degrees(model.pan_range[0]):g}, {math.degrees(model.pan_range[1]):g}] deg)")
        elif fast[i]:
            j = int(np.argmax(np.abs(rates[i]) / lim))
            reason.append(f"{'pan' if j == 0 else 'tilt'} rate {math.degrees(abs(rates[i, j])):.1f} deg/s > "
                          f"{math.degrees(lim[j]):.1f} deg/s")
        else:
            reason.append("")
    other = ~reach | blocked | too_low | pan_out
    feasible = ~other & ~fast
    return theta, rates, feasible, reason, ~other, ratio


