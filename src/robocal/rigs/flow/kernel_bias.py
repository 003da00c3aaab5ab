"""The flow kernel's sub-pixel bias ("pixel locking"), measured on a run's own frames.

Every interpolation of the SAD surface (eq. 2 and the parabolic / equiangular
fits of :mod:`robocal.rigs.flow.kernel`) pulls the flow towards whole pixels.
The pull is a periodic function of the flow's sub-pixel phase on both axes,
``b(u mod 1, v mod 1)`` (px), whose amplitude depends on the texture and its
scale on the sensor; on the simulator's gravel floor it is about 0.02-0.03 px
at phases near 0.3 / 0.7 and up to 0.1 px on one axis when the other sits at
half a pixel (the integer minimum is then off by 0.5 px across the fit).

A drive repeats the same few speeds, so the pull is the same in every part
of it (no resampling sees it) and a calibration absorbs it into the sensor
parameters. Measured on the rendered calibration drive (seeds 100-101,
docs/rigs/flow.md): sensor s270, whose flow lies along its x axis in every
manoeuvre, reads 1.7 px/frame straights about 0.02 px long (phase 0.3, pulled
to 2) and 1.3 px/frame turns 0.025 px short (phase 0.7, pulled to 1), so its
``R`` comes out about 10 mm short and its scale 1.4 % low.

This module measures ``b`` on a sample of the run's own frames: each frame is
shifted by ``-s/2`` and ``+s/2`` (Lanczos-4, so both frames of a pair are
smoothed alike and the smoothing moves nothing) for ``s`` on a grid of
sub-pixel phases, the same kernel configuration matches the pairs, and the
mean error per phase cell is the table. :func:`displacement_bias` evaluates it
at each frame's measured flow; the calibration re-solves with the predicted
bias removed and reports the change as the kernel systematic
(:func:`robocal.rigs.flow.calibrate.calibrate_array`). A flow log has no
frames: its flow phases are evaluated in :func:`reference_bias_table`, the
same measurement on frames cut from the gravel photograph at the simulator's
scale (a model, not the log's own floor).
"""

from __future__ import annotations

from dataclasses import dataclass

import functools
import math

import numpy as np

from robocal.errors import ShapeError
from robocal.rigs.flow.kernel import FlowConfig, compute_flow

__all__ = ["KernelTrace", "N_PHASE", "N_FRAMES", "sample_frames", "measure_bias_table", "reference_bias_table", "predict_bias",
           "displacement_bias"]

#: Phase cells per axis of the bias table (8: the table's own noise is ~0.005 px at 32 frames).
N_PHASE = 8
#: Frames of the run the table is measured on (spread evenly over the sensors and the drive).
N_FRAMES = 32


@dataclass
class KernelTrace:
    """What the kernel saw in a run, kept for its bias model.

    Attributes
    ----------
    flow_px : ndarray, shape (n, K, 2)
        Raw flow (before gyro compensation) per sensor and interval, px (NaN where invalid).
    px_to_m : ndarray, shape (n, K)
        Metres of ground per pixel of flow, ``h / f`` (eq. 5).
    frames : ndarray of uint8, shape (F, W, W), or None
        A sample of the run's frames (:func:`sample_frames`); None for a
        flow log (then :func:`reference_bias_table` stands in).
    config : FlowConfig
        The kernel configuration that produced ``flow_px``.
    debiased : bool
        The steps' displacements already have the bias removed (``config.debias``).
    """

    flow_px: np.ndarray
    px_to_m: np.ndarray
    frames: np.ndarray | None
    config: FlowConfig
    debiased: bool = False
    _table: tuple | None = None

    def bias_table(self) -> tuple[np.ndarray, str]:
        """The kernel's bias table for this run and where it comes from (``"run"`` or ``"model"``)."""
        if self._table is None:
            self._table = ((measure_bias_table(self.frames, self.config), "run") if self.frames is not None
                           else (reference_bias_table(self.config), "model"))
        return self._table

    def debias(self, disp: np.ndarray) -> np.ndarray:
        """``disp`` (n, T, 2) [m] minus this run's predicted kernel bias; marks the trace debiased."""
        out = disp - displacement_bias(self, self.bias_table()[0])
        self.debiased = True
        return out


def sample_frames(frames, n_frames: int = N_FRAMES) -> np.ndarray:
    """``n_frames`` frames spread evenly over all sensors and times of ``(n, T, W, W)`` (no randomness)."""
    f = np.asarray(frames)
    if f.ndim != 4:
        raise ShapeError(f"frames must have shape (n_sensors, T, W, W), got {f.shape}")
    flat = f.reshape((-1,) + f.shape[2:])
    idx = np.linspace(0, len(flat) - 1, min(n_frames, len(flat))).round().astype(int)
    # ascending: dropping repeats is np.unique's result, without its first-call import of numpy.ma (14 ms of
    # a command's fixed cost)
    idx = idx[np.diff(idx, prepend=-1) != 0]
    return np.ascontiguousarray(flat[idx])


def measure_bias_table(frames, config: FlowConfig = FlowConfig(), *, n_phase: int = N_PHASE) -> np.ndarray:
    """Mean flow error of the kernel per sub-pixel phase cell, measured on ``frames``.

    Parameters
    ----------
    frames : array_like of uint8, shape (F, W, W)
        Frames of the run (the texture whose bias is wanted).
    config : FlowConfig
        The kernel configuration of the run.
    n_phase : int
        Cells per axis; cell ``(a, c)`` is the true flow ``(a / n_phase - 1, c / n_phase)`` px.

    Returns
    -------
    ndarray, shape (n_phase, n_phase, 2)
        ``measured - true`` flow ``(du, dv)``, px (0 where no pair was valid).
    """
    src = np.asarray(frames, np.float32)
    if src.ndim != 3 or src.shape[1:] != (config.window, config.window):
        raise ShapeError(f"frames must have shape (F, {config.window}, {config.window}), got {src.shape}")
    W = config.window
    ph = np.arange(n_phase) / n_phase
    shifts = np.array([(pu - 1.0, pv) for pu in ph for pv in ph])
    prev = np.empty((len(shifts), len(src), W, W), np.float32)
    curr = np.empty_like(prev)
    for a, pu in enumerate(ph):
        # separable: the u-shift is shared by a row of cells
        xp, xc = _shift1(src, -0.5 * (pu - 1.0), 2), _shift1(src, 0.5 * (pu - 1.0), 2)
        for c, pv in enumerate(ph):
            prev[a * n_phase + c] = _shift1(xp, -0.5 * pv, 1)
            curr[a * n_phase + c] = _shift1(xc, 0.5 * pv, 1)
    to8 = lambda a: np.clip(np.rint(a), 0, 255).astype(np.uint8).reshape(-1, W, W)  # noqa: E731
    ff = compute_flow(to8(prev), to8(curr), config)
    err = ff.flow_px.reshape(len(shifts), len(src), 2) - shifts[:, None, :]
    ok = np.isfinite(err).all(axis=2)
    n_ok = ok.sum(axis=1)
    mean = np.where(ok[..., None], err, 0.0).sum(axis=1) / np.maximum(n_ok, 1)[:, None]
    return mean.reshape(n_phase, n_phase, 2)


def _shift1(a, d: float, axis: int):
    """Content of ``a`` moved by ``d`` (|d| <= 1) px along ``axis``: Lanczos-4 interpolation, mirrored borders."""
    n0 = math.floor(-d)
    fr = -d - n0
    taps = np.arange(-3, 5)
    w = np.sinc(fr - taps) * np.sinc((fr - taps) / 4.0)
    w /= w.sum()
    P, W = 6, a.shape[axis]
    pad = [(0, 0)] * a.ndim
    pad[axis] = (P, P)
    ap = np.pad(a, pad, mode="symmetric")
    out = np.zeros_like(a)
    sl = [slice(None)] * a.ndim
    for wi, i in zip(w.astype(a.dtype), taps):
        sl[axis] = slice(P + n0 + i, P + n0 + i + W)
        out += wi * ap[tuple(sl)]
    return out


@functools.lru_cache(maxsize=8)
def reference_bias_table(config: FlowConfig = FlowConfig(), *, binning: int = 2, noise: float = 1.5) -> np.ndarray:
    """:func:`measure_bias_table` on :data:`N_FRAMES` frames cut from the gravel photograph.

    ``binning`` photo pixels per sensor pixel (2: the simulator's default
    ``supersample``), read noise ``noise`` grey levels; deterministic.
    """
    from robocal.rigs.flow.simulate import load_texture

    img, _ = load_texture("gravel")
    W = config.window
    side = W * binning
    rng = np.random.default_rng(2024)
    ys = np.linspace(0, img.shape[0] - side, 6).astype(int)
    xs = np.linspace(0, img.shape[1] - side, 6).astype(int)
    fr = [img[y:y + side, x:x + side].reshape(W, binning, W, binning).mean(axis=(1, 3)) for y in ys for x in xs]
    fr = np.asarray(fr[:N_FRAMES]) + rng.normal(0.0, noise, (min(N_FRAMES, len(fr)), W, W))
    return measure_bias_table(np.clip(np.rint(fr), 0, 255).astype(np.uint8), config)


def predict_bias(flow_px, table) -> np.ndarray:
    """The table's bias at each flow (periodic bilinear interpolation in the phases), px; 0 where NaN."""
    fl = np.asarray(flow_px, float)
    T = np.asarray(table, float)
    nb = T.shape[0]
    finite = np.isfinite(fl).all(axis=-1)
    p = np.mod(np.where(finite[..., None], fl, 0.0), 1.0) * nb
    i0 = np.floor(p).astype(int)
    w = p - i0
    a0, b0 = i0[..., 0] % nb, i0[..., 1] % nb
    a1, b1 = (a0 + 1) % nb, (b0 + 1) % nb
    wu, wv = w[..., 0][..., None], w[..., 1][..., None]
    out = (T[a0, b0] * (1 - wu) * (1 - wv) + T[a1, b0] * wu * (1 - wv)
           + T[a0, b1] * (1 - wu) * wv + T[a1, b1] * wu * wv)
    return np.where(finite[..., None], out, 0.0)


def displacement_bias(trace: KernelTrace, table) -> np.ndarray:
    """Predicted bias of each metric displacement, ``(n, K, 2)`` m, in the sensor frame S (eq. 5 signs)."""
    b = predict_bias(trace.flow_px, table)
    return np.stack([-b[..., 0], b[..., 1]], axis=-1) * np.asarray(trace.px_to_m, float)[..., None]
