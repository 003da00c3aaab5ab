"""Two pose streams on two clocks (issue 13): stamps cleaned, the time offset estimated, the streams paired.

A robot log (``T_base_gripper`` at the robot's stamps) and a camera stream (``T_cam_target`` at the
camera's stamps) are paired by time: the robot pose of camera sample ``i`` is the robot stream
interpolated (SLERP + linear) at ``t_cam[i] + clock_offset``. The **clock offset** (s) is thus what to add
to a camera stamp to put it on the robot's clock (Kalibr's ``t_imu = t_cam + shift``).

* :func:`clean_stamps`: samples whose stamp does not exceed every earlier one (a logger's repeated
  stamp, a clock stepping back) are dropped, as a stream consumer does, and counted.
* :func:`correlate_rates`: the offset from the rotation rates. ``|omega|`` of the gripper and of the
  camera (or the target, eye-to-hand) are equal at every instant whatever the unknown X (both are one
  rigid body's rotation, seen in two frames), so their normalised cross-correlation on a common time
  grid peaks at the offset (Kelly & Sukhatme, "A general framework for temporal calibration of multiple
  proprioceptive and exteroceptive sensors", ISER 2010; Furgale, Rehder, Siegwart, "Unified temporal and
  spatial calibration for multi-sensor systems", IROS 2013, for the joint refinement below); the
  peak is located to a fraction of the grid step by a parabola through its three samples.
* :func:`pair_streams`: cleaned, shifted, cropped to the overlap (counted), paired.
* :func:`refine_with_clock`: X, the target pose Y and the offset by one least-squares problem on the
  closure ``G(t_cam[i] + dt) X T_cam_target[i] = Y`` (:mod:`robocal.estimation`), which gives the
  offset's std beside X's, with their correlation.
* :func:`simulate_streams`: a robot log and a camera stream of one smooth motion with a known offset.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import InputError, NotEnoughDataError
from robocal.geometry import invert_transform, matrix_from_rotvec, rotvec_from_matrix, transform_from

__all__ = ["CLOCK_MODES", "MIN_CORRELATION", "StreamPairing", "ClockRefinement", "clean_stamps", "rotation_rate",
           "correlate_rates", "interpolate_stream", "pair_streams", "refine_with_clock", "parse_clock_offset",
           "simulate_streams"]

#: ``--clock-offset``: ``none`` (the stamps are on one clock), ``auto`` (estimated), or seconds.
CLOCK_MODES = ("none", "auto")
#: A correlation peak below this (normalised, 1 = identical rate profiles) gets a ``weakly_determined`` warning.
MIN_CORRELATION = 0.5
#: The correlation's time grid holds at most this many samples (its step grows for longer streams).
MAX_GRID = 1 << 20


def parse_clock_offset(value) -> str | float:
    """``"none"``, ``"auto"`` or a finite number of seconds (the ``--clock-offset`` text or a number)."""
    if isinstance(value, str) and value.strip().lower() in CLOCK_MODES:
        return value.strip().lower()
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise InputError(f"clock offset must be none, auto or a number of seconds, got {value!r}") from None
    if not np.isfinite(out):
        raise InputError(f"clock offset must be finite, got {value!r}")
    return out


def clean_stamps(t) -> np.ndarray:
    """Mask of the samples kept: each stamp must exceed every earlier one (repeats and steps back dropped).

    A stream's stamps repeat when a driver republishes and step back when its clock resyncs; keeping the
    samples that advance the running maximum is what a consumer of the stream sees (no reordering: a
    stamp written out of order is more often wrong than the order).
    """
    t = np.asarray(t, float)
    if t.size == 0:
        return np.zeros(0, bool)
    prev = np.maximum.accumulate(np.r_[-np.inf, t[:-1]])
    return t > prev


def rotation_rate(t, R) -> tuple[np.ndarray, np.ndarray]:
    """``(t_mid, |omega|)``: the rotation rate (rad/s) between consecutive samples, at their mid-times (s)."""
    t = np.asarray(t, float)
    R = np.asarray(R, float)
    dR = np.swapaxes(R[:-1], -1, -2) @ R[1:]
    ang = np.linalg.norm(rotvec_from_matrix(dR), axis=-1)
    return 0.5 * (t[:-1] + t[1:]), ang / np.diff(t)


def _median_step(t) -> float:
    return float(np.median(np.diff(t)))


def correlate_rates(t_robot, R_robot, t_cam, R_cam, *, max_offset: float | None = None
                    ) -> tuple[float, float, float, tuple | None]:
    """The clock offset (s) at the peak of the normalised cross-correlation of the two streams' ``|omega|``.

    Each rate is resampled (linear interpolation) on a grid of its own stream's start with one step for
    both (the finer median sample interval, coarser only past :data:`MAX_GRID` samples), so stamps on two
    different epochs (a camera from 0 s, a robot in Unix time) still correlate. Each lag's coefficient is
    Pearson's over the samples the two grids share there (means and norms per lag, by FFT correlations of
    the signals, their squares and the masks); lags sharing less than half the shorter stream, or beyond
    ``max_offset`` (s), are not considered.

    Returns ``(offset, peak, step, runner_up)``: ``robot(t_cam + offset)`` pairs with ``cam(t_cam)``;
    ``peak`` the coefficient at the peak (1: identical rate profiles); ``step`` the grid step (s);
    ``runner_up`` ``(offset, coefficient)`` of the highest other local maximum at least 0.2 s away (a
    repetitive motion's next period), or None.
    """
    from scipy.signal import correlate, correlation_lags

    tr, wr = rotation_rate(t_robot, R_robot)
    tc, wc = rotation_rate(t_cam, R_cam)
    span = max(tr[-1] - tr[0], tc[-1] - tc[0])
    h = max(min(_median_step(t_robot), _median_step(t_cam)), span / MAX_GRID)
    a = np.interp(tr[0] + h * np.arange(int((tr[-1] - tr[0]) / h) + 1), tr, wr)
    b = np.interp(tc[0] + h * np.arange(int((tc[-1] - tc[0]) / h) + 1), tc, wc)
    a, b = a - a.mean(), b - b.mean()           # conditioning only: Pearson per lag below is shift-invariant
    oa, ob = np.ones_like(a), np.ones_like(b)

    def xc(u, v):
        return correlate(u, v, mode="full", method="auto")
    n = np.rint(xc(oa, ob))
    sa, sb, sab = xc(a, ob), xc(oa, b), xc(a, b)
    saa, sbb = xc(a * a, ob), xc(oa, b * b)
    lags = correlation_lags(len(a), len(b), mode="full")
    offsets = lags * h + tr[0] - tc[0]
    ok = n >= max(0.5 * min(len(a), len(b)), 3)
    if max_offset is not None:
        ok &= np.abs(offsets) <= max_offset
    if not ok.any():
        raise NotEnoughDataError("the two streams' rotation rates share too few samples to correlate (at least "
                                 "half the shorter stream at some offset)")
    nn = np.maximum(n, 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        num = sab - sa * sb / nn
        den = np.sqrt(np.maximum(saa - sa ** 2 / nn, 0) * np.maximum(sbb - sb ** 2 / nn, 0))
        r = np.where(ok & (den > 0), num / den, -np.inf)
    k = int(np.argmax(r))
    if not np.isfinite(r[k]):
        raise NotEnoughDataError("the rotation rate is constant in one stream: the clock offset cannot be "
                                 "found by correlation (give --clock-offset SECONDS)")
    frac = 0.0
    if 0 < k < len(r) - 1 and np.isfinite(r[k - 1]) and np.isfinite(r[k + 1]):
        c = r[k - 1] - 2 * r[k] + r[k + 1]
        if c < 0:
            frac = float(np.clip(0.5 * (r[k - 1] - r[k + 1]) / c, -0.5, 0.5))
    from scipy.signal import find_peaks

    peaks, _ = find_peaks(np.where(np.isfinite(r), r, -1.0))
    far = peaks[np.abs(offsets[peaks] - offsets[k]) >= 0.2]
    runner = None if not far.size else (float(offsets[far[np.argmax(r[far])]]), float(np.max(r[far])))
    return float(offsets[k] + frac * h), float(r[k]), float(h), runner


def interpolate_stream(t_src, T_src, t_query) -> np.ndarray:
    """Poses at ``t_query`` (s): ``R_k Exp(s log(R_k^T R_k+1))`` (SLERP) and linear translation.

    Queries outside ``[t_src[0], t_src[-1]]`` take the end pose (the callers crop before; inside the
    least squares a step may graze an end). The same values as :func:`robocal.io.interpolate_poses`,
    vectorised for the refinement's many evaluations.
    """
    t_src = np.asarray(t_src, float)
    T_src = np.asarray(T_src, float)
    q = np.clip(np.asarray(t_query, float), t_src[0], t_src[-1])
    k = np.clip(np.searchsorted(t_src, q, side="right") - 1, 0, len(t_src) - 2)
    s = (q - t_src[k]) / (t_src[k + 1] - t_src[k])
    R0 = T_src[k, :3, :3]
    w = rotvec_from_matrix(np.swapaxes(R0, -1, -2) @ T_src[k + 1, :3, :3])
    R = R0 @ matrix_from_rotvec(s[:, None] * w)
    p = T_src[k, :3, 3] + s[:, None] * (T_src[k + 1, :3, 3] - T_src[k, :3, 3])
    return transform_from(R, p)


@dataclass
class StreamPairing:
    """Two timed streams paired: the robot pose at each kept camera sample's time on the robot's clock.

    Attributes
    ----------
    T_base_gripper, T_cam_target : (N, 4, 4)
        The pairs (m); ``t`` (N,) the camera stamps (s, camera clock) of the kept samples, ``index`` their
        rows in the camera file (from 0).
    robot_t, robot_T : the robot stream after :func:`clean_stamps` (for :func:`refine_with_clock`).
    clock_offset : float
        Added to the camera stamps (s); ``mode``: "none", "given" or "auto" (``correlation`` the peak's
        coefficient, ``grid_step`` its grid, s).
    dropped : dict
        Samples dropped for a stamp that does not advance, per stream (``"robot"``, ``"camera"``).
    cropped : dict
        Samples outside the other stream's span: ``"camera"`` (dropped: no robot pose there), ``"robot"``
        (before the first / after the last camera sample: unused).
    """

    T_base_gripper: np.ndarray
    T_cam_target: np.ndarray
    t: np.ndarray
    index: np.ndarray
    robot_t: np.ndarray
    robot_T: np.ndarray
    clock_offset: float = 0.0
    mode: str = "none"
    correlation: float | None = None
    grid_step: float | None = None
    dropped: dict = field(default_factory=dict)
    cropped: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)

    def to_dict(self) -> dict:
        """The counts and the offset's origin, JSON-safe (``diagnostics.streams`` of the result)."""
        return {"mode": self.mode, "clock_offset_s": float(self.clock_offset),
                "correlation": self.correlation, "grid_step_s": self.grid_step,
                "dropped_stamps": {k: int(v) for k, v in self.dropped.items()},
                "cropped": {k: int(v) for k, v in self.cropped.items()}, "n_pairs": int(len(self.t))}


def _dropped_warning(keep, t, name: str) -> Diagnostic | None:
    bad = np.flatnonzero(~keep)
    if not bad.size:
        return None
    k = int(bad[0])
    return Diagnostic("dropped", f"{name}: {bad.size} sample(s) whose stamp does not advance dropped (first: "
                      f"row {k}, t = {t[k]:.6f} s after {np.max(t[:k]):.6f} s)", indices=tuple(int(i) for i in bad))


def pair_streams(t_robot, T_robot, t_cam, T_cam, clock_offset="none", *, names=("robot", "camera"),
                 max_offset: float | None = None) -> StreamPairing:
    """Pair a robot stream and a camera stream by time (module docstring).

    ``clock_offset``: ``"none"`` (0), ``"auto"`` (:func:`correlate_rates`, to within a fraction of the
    grid step: :func:`refine_with_clock` takes it from there) or seconds. Stamps that do not advance are
    dropped in both streams (``dropped`` warning naming the file, the count and the first row); camera
    samples whose time on the robot's clock is outside the robot stream are cropped. Raises
    :class:`~robocal.errors.NotEnoughDataError` when fewer than 3 pairs remain (the spans named).
    """
    mode = parse_clock_offset(clock_offset)
    t_robot, t_cam = np.asarray(t_robot, float), np.asarray(t_cam, float)
    T_robot, T_cam = np.asarray(T_robot, float), np.asarray(T_cam, float)
    kr, kc = clean_stamps(t_robot), clean_stamps(t_cam)
    warns = [w for w in (_dropped_warning(kr, t_robot, names[0]), _dropped_warning(kc, t_cam, names[1])) if w]
    rows = np.flatnonzero(kc)
    tr, Tr, tc, Tc = t_robot[kr], T_robot[kr], t_cam[kc], T_cam[kc]
    if len(tr) < 3 or len(tc) < 3:
        raise NotEnoughDataError(f"{names[0]} has {len(tr)} and {names[1]} {len(tc)} samples with advancing "
                                 "stamps: hand-eye calibration by time needs at least 3 poses in each stream")
    corr = step = None
    if mode == "auto":
        offset, corr, step, runner = correlate_rates(tr, Tr[:, :3, :3], tc, Tc[:, :3, :3], max_offset=max_offset)
        if runner is not None and runner[1] > 1 - 0.2 * (1 - corr) - 0.02:
            # a repetitive motion: another offset (the next period) fits nearly as well as the best
            warns.append(Diagnostic(
                "weakly_determined", f"the rotation rates of {names[0]} and {names[1]} correlate nearly as well "
                f"at {1e3 * runner[0]:.1f} ms ({runner[1]:.3f}) as at the clock offset found ({1e3 * offset:.1f} "
                f"ms, {corr:.3f}): a repetitive motion; give --clock-offset SECONDS if it is known, or record a "
                "motion that does not repeat", params=("clock_offset",)))
        if corr < MIN_CORRELATION:
            warns.append(Diagnostic(
                "weakly_determined", f"the rotation rates of {names[0]} and {names[1]} correlate only to "
                f"{corr:.2f} at the clock offset found ({1e3 * offset:.1f} ms): too little or too regular "
                "motion; give --clock-offset SECONDS if it is known", params=("clock_offset",)))
    else:
        offset = 0.0 if mode == "none" else float(mode)
    q = tc + offset
    inside = (q >= tr[0]) & (q <= tr[-1])
    if inside.sum() < 3:
        raise NotEnoughDataError(
            f"{names[1]} at {tc[0]:.3f}..{tc[-1]:.3f} s (+ clock offset {offset:.3f} s) and {names[0]} at "
            f"{tr[0]:.3f}..{tr[-1]:.3f} s overlap in {int(inside.sum())} camera sample(s); pairing by time "
            "needs at least 3 (different clocks? --clock-offset auto or SECONDS)")
    qi = q[inside]
    first = int(np.searchsorted(tr, qi[0], side="right")) - 1          # the robot samples bracketing the
    last = int(np.searchsorted(tr, qi[-1], side="left"))               # overlap are used; beyond, unused
    cropped = {"camera": int((~inside).sum()), "robot": int(first + (len(tr) - 1 - last))}
    mode_name = mode if isinstance(mode, str) else "given"
    return StreamPairing(interpolate_stream(tr, Tr, qi), Tc[inside], tc[inside], rows[inside], tr, Tr,
                         float(offset), mode_name, corr, step,
                         {"robot": int((~kr).sum()), "camera": int((~kc).sum())}, cropped, warns)


@dataclass
class ClockRefinement:
    """X, Y and the clock offset refined together (:func:`refine_with_clock`).

    ``cov`` (13, 13) over X's ``(rx, ry, rz, tx, ty, tz)``, Y's, then the offset (s); ``clock_offset_std``
    (s) from it; ``pairing`` the streams re-paired at the refined offset; ``lsq`` the solver's record.
    """

    X: np.ndarray
    Y: np.ndarray
    clock_offset: float
    clock_offset_std: float | None
    cov: np.ndarray
    rot_rms: float
    trans_rms: float
    pairing: StreamPairing
    lsq: object = None
    warnings: list = field(default_factory=list)


def refine_with_clock(pairing: StreamPairing, X0, Y0, *, setup: str = "eye-in-hand") -> ClockRefinement:
    """X, the target pose Y and the clock offset by least squares on every kept camera sample.

    Residual of sample ``i``: ``G(t_cam[i] + dt) X T_cam_target[i]`` against ``Y`` (rotation vector, rad;
    translation, m), ``G`` the robot stream interpolated (:func:`interpolate_stream`; its inverse
    eye-to-hand), weighted by the start's RMS as :func:`~robocal.handeye.calibrate_hand_eye` does;
    ``robocal.estimation`` (LM, finite differences) gives the 13 x 13 covariance. The samples are those of
    ``pairing`` less the ones within a margin (4 correlation grid steps + 2 robot intervals) of the robot
    stream's ends, so that the set stays fixed while ``dt`` moves. Starts: ``X0``, ``Y0`` (a refined X at
    the pairing's offset), ``pairing.clock_offset``. Outliers are named by their row in the camera file
    (from 0) and their stamp.
    """
    from robocal.estimation import Problem, solve
    from robocal.handeye.motions import _LABELS, _perturbed, _pose_residual, _rms, _sigmas, name_outliers

    tr, Tr, tc, Tc = pairing.robot_t, pairing.robot_T, pairing.t, pairing.T_cam_target
    margin = 4 * (pairing.grid_step or 0.0) + 2 * _median_step(tr)
    q = tc + pairing.clock_offset
    use = (q >= tr[0] + margin) & (q <= tr[-1] - margin)
    if use.sum() < 3:
        raise NotEnoughDataError(f"only {int(use.sum())} camera samples lie inside the robot stream with a "
                                 f"{1e3 * margin:.0f} ms margin: the clock offset cannot be refined")
    tc, Tc = tc[use], Tc[use]
    X0, Y0 = np.asarray(X0, float), np.asarray(Y0, float)
    dt0 = float(pairing.clock_offset)

    cache = {}

    def gripper(dt):
        # 12 of the 13 finite-difference columns move X or Y only: the robot poses at one dt are reused
        if dt not in cache:
            G = interpolate_stream(tr, Tr, tc + dt)
            cache.clear()
            cache[dt] = G if setup == "eye-in-hand" else invert_transform(G)
        return cache[dt]

    sr, st = _sigmas(*_rms(_pose_residual(gripper(dt0) @ X0 @ Tc, Y0[None])))

    def fun(p):
        X, Y = _perturbed(X0, p["X"]), _perturbed(Y0, p["Y"])
        return _pose_residual(gripper(dt0 + p["dt"][0]) @ X @ Tc, Y[None])

    prob = Problem()
    prob.add_block("X", np.r_[0, 0, 0, X0[:3, 3]], labels=[f"X.{k}" for k in _LABELS],
                   unit=["rad"] * 3 + ["m"] * 3)
    prob.add_block("Y", np.r_[0, 0, 0, Y0[:3, 3]], labels=[f"Y.{k}" for k in _LABELS],
                   unit=["rad"] * 3 + ["m"] * 3)
    # the offset as a correction to the start: its finite-difference step then scales with the correction
    prob.add_block("dt", np.zeros(1), labels=["clock_offset"], unit="s")
    prob.add_residuals(fun, name="closure", residual_dim=6, sigma=[sr] * 3 + [st] * 3)
    res = solve(prob, method="lm")
    X, Y = _perturbed(X0, res.params["X"]), _perturbed(Y0, res.params["Y"])
    dt = dt0 + float(res.params["dt"][0])
    r = _pose_residual(gripper(dt) @ X @ Tc, Y[None])
    labels = [f"X.{k}" for k in _LABELS] + [f"Y.{k}" for k in _LABELS] + ["clock_offset"]
    idx = [res.free_labels.index(k) for k in labels]
    cov = np.asarray(res.cov)[np.ix_(idx, idx)]
    repaired = _repaired(pairing, dt)
    # the solver numbers the samples it used; the user knows the camera file's rows
    rows = pairing.index[use]
    t_row = np.full(int(pairing.index.max()) + 1, np.nan)
    t_row[pairing.index] = pairing.t
    warns = [Diagnostic(w.code, w.message, w.params, tuple(int(rows[i]) for i in w.indices))
             if w.code == "outliers" and w.indices else w for w in res.warnings]
    return ClockRefinement(X, Y, dt, res.std.get("clock_offset"), cov,
                           float(np.sqrt(np.mean(r[:, :3] ** 2))), float(np.sqrt(np.mean(r[:, 3:] ** 2))),
                           repaired, res, name_outliers(warns, t_row, what="T_base_gripper(t + dt) X T_cam_target = Y"))


def _repaired(p: StreamPairing, offset: float) -> StreamPairing:
    """``p`` paired again at ``offset`` (the same cleaned streams; the crop follows the offset)."""
    q = p.t + offset
    inside = (q >= p.robot_t[0]) & (q <= p.robot_t[-1])
    qi = q[inside]
    first = int(np.searchsorted(p.robot_t, qi[0], side="right")) - 1
    last = int(np.searchsorted(p.robot_t, qi[-1], side="left"))
    cropped = {"camera": p.cropped.get("camera", 0) + int((~inside).sum()),
               "robot": int(first + (len(p.robot_t) - 1 - last))}
    return StreamPairing(interpolate_stream(p.robot_t, p.robot_T, qi), p.T_cam_target[inside], p.t[inside],
                         p.index[inside], p.robot_t, p.robot_T, float(offset), p.mode, p.correlation, p.grid_step,
                         dict(p.dropped), cropped, list(p.warnings))


# ----------------------------------------------------------------------------- simulation
@dataclass(frozen=True)
class StreamSimulation:
    """A simulated robot log and camera stream: stamps (s, each on its own clock), poses (N, 4, 4), the truth
    ``X``, ``Y`` (:func:`~robocal.handeye.simulate_eye_in_hand`'s) and ``clock_offset`` (s)."""

    t_robot: np.ndarray
    T_base_gripper: np.ndarray
    t_cam: np.ndarray
    T_cam_target: np.ndarray
    X: np.ndarray
    Y: np.ndarray
    clock_offset: float
    sigma_rotation: float
    sigma_translation: float


def simulate_streams(rng: np.random.Generator, *, duration: float = 20.0, robot_rate: float = 100.0,
                     camera_rate: float = 10.0, clock_offset: float = 0.037, noise: bool = True,
                     sigma_rotation: float = 1e-3, sigma_translation: float = 0.2e-3) -> StreamSimulation:
    """An eye-in-hand camera moving smoothly over a target, logged by the robot and the camera on two clocks.

    The camera's distance (0.30-0.45 m), tilt (0.1-0.6 rad from the target's normal), tilt direction and
    roll about its optical axis vary as sums of two sinusoids of random frequencies (0.05-0.3 Hz) and
    phases, so the rotation rate is neither constant nor periodic (geometry of
    :func:`~robocal.handeye.simulate_eye_in_hand`, the same X and Y). The robot logs ``T_base_gripper``
    at ``robot_rate`` (Hz) on its clock, from 0; the camera ``T_cam_target`` at ``camera_rate`` with its
    stamps ``clock_offset`` (s) behind: the camera sample stamped ``t`` shows the robot at its ``t +
    clock_offset``. Camera noise as :func:`~robocal.handeye.simulate_eye_in_hand` (per-axis rad, m).
    """
    from robocal.handeye.simulate import default_hand_eye

    if not isinstance(rng, np.random.Generator):
        raise InputError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    X = default_hand_eye()
    Y = transform_from(np.eye(3), [0.6, 0.0, 0.0])
    f = rng.uniform(0.05, 0.3, (4, 2))
    ph = rng.uniform(-np.pi, np.pi, (4, 2))
    az0 = rng.uniform(-np.pi, np.pi)

    def wave(k, tau):
        return 0.5 * np.sum(np.sin(2 * np.pi * f[k] * tau[:, None] + ph[k]), axis=1)   # in [-1, 1]

    def camera_in_base(tau):
        d = 0.375 + 0.075 * wave(0, tau)
        tilt = 0.35 + 0.25 * wave(1, tau)
        az = az0 + 2.0 * wave(2, tau)
        roll = 0.6 * wave(3, tau)
        up = np.column_stack([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)])
        z = -up
        x = np.cross(np.array([0.0, 1.0, 0.0]), z)
        x /= np.linalg.norm(x, axis=1, keepdims=True)
        R = np.stack([x, np.cross(z, x), z], axis=-1) @ matrix_from_rotvec(roll[:, None] * [0.0, 0.0, 1.0])
        return transform_from(R, Y[:3, 3] + d[:, None] * up)

    t_robot = np.arange(0.0, duration, 1.0 / robot_rate)
    Tg = camera_in_base(t_robot) @ invert_transform(X)
    # camera samples inside the robot log (a margin of 0.5 s each side, so a cropped pair is the exception)
    t_cam = np.arange(0.5, duration - 0.5 - abs(clock_offset), 1.0 / camera_rate) - min(clock_offset, 0.0)
    Tc = invert_transform(camera_in_base(t_cam + clock_offset)) @ Y
    sr, st = (sigma_rotation, sigma_translation) if noise else (0.0, 0.0)
    if noise:
        n = len(Tc)
        Tc = transform_from(matrix_from_rotvec(rng.normal(size=(n, 3)) * sr) @ Tc[:, :3, :3],
                            Tc[:, :3, 3] + rng.normal(size=(n, 3)) * st)
    return StreamSimulation(t_robot, Tg, t_cam, Tc, X, Y, float(clock_offset), float(sr), float(st))
