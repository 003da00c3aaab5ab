"""Optical flow of one downward sensor: SAD block matching, sub-pixel refinement,
gyro compensation and metric conversion (seed 003 §1, eqs. 1–5).

The defaults are the PX4FLOW firmware's: a 64x64 window, 8x8 blocks on a 5x5
grid, an integer search over +/-4 px (81 candidates), a per-block texture gate,
half-pixel refinement by bilinear interpolation, the mean of the accepted
blocks as the frame's flow, at least 10 accepted blocks or no output, and
``quality = accepted / n_blocks * 255``.

Pixel and frame conventions
---------------------------
Frames are ``uint8`` arrays ``(H, W)`` or a batch ``(N, H, W)``; pixel
``(u, v)`` = (column, row), ``u`` right, ``v`` down, the centre of the
top-left pixel is ``(0, 0)`` (as OpenCV). The *flow* of a frame pair is the
image motion of the ground texture from ``prev`` to ``curr``: a texture point
at ``p`` in ``prev`` is at ``p + flow`` in ``curr``.

The sensor's ground frame ``S`` is right-handed seen from above: ``x_S`` along
the image ``u`` axis, ``y_S`` along ``-v`` (image up), ``z_S`` up. The camera
frame (x = u, y = v, z = optical axis, pointing down) has the gyro's axes.

Speed
-----
The integer search is a numba kernel batched over frame pairs: frames are
laid out pixel-major with the pairs innermost, so each absolute difference is
one SIMD lane and no Python loop touches a pixel or an offset. An 8x8 block
has its own fully unrolled path (the PX4FLOW default); other block sizes use a
generic compiled path. See ``bench/bench_flow.py``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from numba import njit

from robocal.errors import InputError, ShapeError
from robocal.validation import check_array

__all__ = [
    "FlowConfig",
    "FrameFlow",
    "block_origins",
    "match_blocks",
    "match_sequence",
    "BlockMatches",
    "compute_flow",
    "compute_flow_sequence",
    "rotational_flow",
    "compensate_rotation",
    "metric_displacement",
    "speed_limit",
    "SUBPIXEL_MODES",
    "AGGREGATE_MODES",
]

SUBPIXEL_MODES = ("none", "half", "quarter", "parabolic", "equiangular")
AGGREGATE_MODES = ("mean", "median", "trimmed", "tensor")

#: Per-frame flow error (RMS per axis, px) with all 25 blocks in use, by sub-pixel mode, and
#: with ``refine="lk"``: measured on shifted real photographs (gravel, 2x2 binning,
#: ``test_flow_rmse_on_real_photographs_vs_opencv -s``, docs/rigs/flow.md). The fusion's
#: weights, covariance and outlier test scale with it (:attr:`FlowConfig.sigma_px`).
SIGMA_PX = {"none": 0.32, "half": 0.16, "quarter": 0.075, "parabolic": 0.12, "equiangular": 0.06, "lk": 0.03}
_BATCH = 256  # frame pairs per kernel call: large enough to fill SIMD lanes, small enough for L2


@dataclass(frozen=True)
class FlowConfig:
    """Block-matching parameters (defaults: the PX4FLOW firmware).

    Attributes
    ----------
    window : int
        Side of the square frame in pixels (64).
    block : int
        Side of a matching block in pixels (8).
    grid : int
        Blocks per side of the block grid (5 -> 25 blocks).
    search : int
        Integer search range ``d`` of eq. 1, +/- pixels (4 -> 81 candidates).
    subpixel : str
        ``"half"`` (PX4FLOW: the 8 neighbours at +/-0.5 px, bilinear eq. 2),
        ``"quarter"`` (then the 8 neighbours at +/-0.25 px), ``"parabolic"``
        (a parabola through the integer SAD surface per axis),
        ``"equiangular"`` (a symmetric V through it — the shape of a SAD
        minimum, so less pulled towards whole pixels) or ``"none"``.
    aggregate : str
        How the accepted blocks make the frame's flow: ``"mean"`` (PX4FLOW),
        ``"median"`` (per axis), ``"trimmed"`` (mean of the blocks within
        ``trim_px`` of the median — rejects single wrong blocks), or
        ``"tensor"``: the same blocks as ``"trimmed"`` (same validity,
        quality and spread), combined by their gradient structure tensors
        ``T_b = sum over the block of (g_x, g_y)^T (g_x, g_y)`` in the earlier
        frame, ``flow = (sum T_b + lambda I)^-1 (sum T_b flow_b + lambda mean)``
        with ``lambda = 0.02 trace(sum T_b) / 2``: a block that sees only an
        edge fixes the flow across the edge, not along it (the aperture
        problem), so it no longer pulls the frame along the edge. Opt-in
        (measured in docs/rigs/flow.md: on brick floors it cuts the accepted
        frames that are wrong by > 0.5 px from 8.7 to ~3 %, on gravel and grass
        the RMS error by ~15 %; the other documented figures are with
        ``"trimmed"``).
    trim_px : float
        Radius of the ``"trimmed"`` aggregation, pixels.
    feature_threshold : float
        Texture gate: sum of absolute differences between neighbouring rows
        and columns of the block's centre (PX4FLOW: 4x4 centre, threshold 30).
    sad_threshold : float
        A block whose best SAD exceeds this is rejected (PX4FLOW: 5000 for 8x8;
        scaled by ``block**2 / 64`` for other sizes).
    min_distinctness : float
        A block is rejected as ambiguous when the best SAD outside the 3x3
        neighbourhood of the minimum is less than ``(1 + min_distinctness)``
        times the minimum (flat SAD surface: no texture, only noise; or a
        second minimum: a repeating pattern).
    min_blocks : int
        A frame with fewer accepted blocks has no flow (PX4FLOW: 10).
    gyro_threshold : float
        Rates below this (rad/s, per axis) are not compensated (PX4FLOW: 0.01).
    max_spread_px : float
        A frame whose used blocks scatter more than this (RMS distance from
        the frame's flow, px) is rejected as ambiguous: on a repeating pattern
        a group of blocks locks onto a wrong period together, and their
        scatter, not the block count, gives it away. 0.45 px leaks: on 600
        shifted brick pairs it accepts 15 frames wrong by 0.5-2 px (6 at
        0.35 px), but a tighter gate rejects good frames of fast motion (0.35
        px: 4 % of gravel and grass frames moving 3-4 px; none at 0.45), so the
        default stays; the fusion's outlier test catches such frames when the
        other sensors see texture.
    refine : {"none", "lk"}
        ``"lk"``: after block matching, refine the frame's flow by Gauss–Newton
        on the pixels of the used blocks (a translational Lucas–Kanade step
        with bilinear sampling, eq. 2). Removes the pull towards whole pixels
        that any SAD-surface interpolation has; costs about as much again as
        the block matching. Beyond the PX4FLOW firmware.
    refine_iterations : int
        Gauss–Newton iterations of ``refine="lk"``.
    debias : bool
        Remove the kernel's pull towards whole pixels from a run's
        displacements (:mod:`robocal.rigs.flow.kernel_bias`: the bias per
        sub-pixel phase, measured on the run's own frames, or on gravel
        frames for a flow log, evaluated at each frame's flow). Acts in
        :func:`robocal.rigs.flow.log.steps_from_frames` / ``steps_from_records``,
        not in :func:`compute_flow`. Off by default (the documented figures
        are without it); on rendered drives it halves the ATE (docs/rigs/flow.md).
    """

    window: int = 64
    block: int = 8
    grid: int = 5
    search: int = 4
    subpixel: str = "equiangular"
    aggregate: str = "trimmed"
    trim_px: float = 1.0
    feature_threshold: float = 30.0
    sad_threshold: float | None = None
    min_distinctness: float = 0.25
    min_blocks: int = 10
    gyro_threshold: float = 0.01
    max_spread_px: float = 0.45
    refine: str = "none"
    refine_iterations: int = 3
    debias: bool = False

    @property
    def sigma_px(self) -> float:
        """Flow error of a frame with all blocks in use, px (:data:`SIGMA_PX` of this mode)."""
        return SIGMA_PX["lk" if self.refine == "lk" else self.subpixel]

    def __post_init__(self):
        for name in ("window", "block", "grid", "min_blocks"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or v < 1:
                raise InputError(f"FlowConfig.{name} must be a positive integer, got {v!r}")
        if not isinstance(self.search, (int, np.integer)) or self.search < 1:
            raise InputError(f"FlowConfig.search must be an integer >= 1, got {self.search!r}")
        if self.subpixel not in SUBPIXEL_MODES:
            raise InputError(f"FlowConfig.subpixel must be one of {SUBPIXEL_MODES}, got {self.subpixel!r}")
        if self.refine not in ("none", "lk"):
            raise InputError(f"FlowConfig.refine must be 'none' or 'lk', got {self.refine!r}")
        if self.aggregate not in AGGREGATE_MODES:
            raise InputError(f"FlowConfig.aggregate must be one of {AGGREGATE_MODES}, got {self.aggregate!r}")
        if self.block < 4:
            raise InputError(f"FlowConfig.block must be >= 4 (the texture gate uses its centre), got {self.block}")
        if self.min_blocks > self.grid**2:
            raise InputError(f"FlowConfig.min_blocks ({self.min_blocks}) exceeds the number of blocks ({self.grid**2})")
        ys = block_origins(self)
        if self.search > 15 or self.block > 90:
            # the compiled argmin packs (SAD << 10 | offset) into 32 bits
            raise InputError(f"FlowConfig: search must be <= 15 px and block <= 90 px, got {self.search} and {self.block}")
        if ys.size == 0 or ys.max() + self.block + self.search + 1 > self.window:
            raise InputError(
                f"FlowConfig: a {self.grid}x{self.grid} grid of {self.block}px blocks with a +/-{self.search} px "
                f"search does not fit a {self.window}px window"
            )

    @property
    def n_blocks(self) -> int:
        return self.grid * self.grid

    @property
    def sad_limit(self) -> float:
        """The SAD rejection threshold in use (PX4FLOW's 5000 scaled to the block area)."""
        return 5000.0 * self.block**2 / 64.0 if self.sad_threshold is None else float(self.sad_threshold)

    def with_(self, **kw) -> "FlowConfig":
        return replace(self, **kw)


def block_origins(config: FlowConfig) -> np.ndarray:
    """Top-left pixel coordinate of the blocks along one axis, as the PX4FLOW firmware.

    ``lo = search + 1``, ``hi = window - (search + 1) - block``,
    ``step = (hi - lo) // grid + 1``: 5, 15, 25, 35, 45 for the defaults.
    The margin of ``search + 1`` keeps every candidate and its sub-pixel
    neighbours inside the frame.
    """
    lo = config.search + 1
    hi = config.window - (config.search + 1) - config.block
    if hi < lo:
        return np.zeros(0, np.int64)
    step = (hi - lo) // config.grid + 1
    return (lo + step * np.arange(config.grid)).astype(np.int64)


# ---------------------------------------------------------------------------------------------
# compiled kernels
# ---------------------------------------------------------------------------------------------


@njit(cache=True, fastmath=True, nogil=True)
def _sad8_batch(prev_t, curr_t, ys, xs, search, out, keys):  # pragma: no cover - compiled
    """SAD (eq. 1) of every 8x8 block at every integer offset, for N pairs at once.

    prev_t, curr_t : uint8 (H, W, N) — pairs innermost (SIMD lanes).
    out : uint16 (n_blocks, (2 search + 1)^2, N). 8x8x255 = 16320 fits uint16.
    keys : int32 (n_blocks, N) — ``min over offsets of (SAD << 10 | offset)``: the
    best offset and its SAD in one vectorisable min (ties keep the first offset in
    scan order, as the firmware's strict '<').
    Three horizontal offsets share each load of the reference block (10
    loads of ``curr`` serve 24 differences instead of 8).
    """
    n = out.shape[2]
    nb = ys.shape[0]
    side = 2 * search + 1
    n3 = side // 3
    a0 = np.empty(n, np.uint16)
    a1 = np.empty(n, np.uint16)
    a2 = np.empty(n, np.uint16)
    for b in range(nb):
        y0 = ys[b]
        x0 = xs[b]
        kb = keys[b]
        for k in range(n):
            kb[k] = 0x7FFFFFFF
        for dy in range(-search, search + 1):
            orow = (dy + search) * side
            for j in range(n3):
                dx = -search + 3 * j
                a0[:] = 0
                a1[:] = 0
                a2[:] = 0
                for r in range(8):
                    pr = prev_t[y0 + r, x0:x0 + 8]
                    cr = curr_t[y0 + r + dy, x0 + dx:x0 + dx + 10]
                    for k in range(n):
                        s0 = np.uint16(0)
                        s1 = np.uint16(0)
                        s2 = np.uint16(0)
                        for c in range(8):
                            p = pr[c, k]
                            q0 = cr[c, k]
                            q1 = cr[c + 1, k]
                            q2 = cr[c + 2, k]
                            s0 += np.uint16(max(p, q0) - min(p, q0))
                            s1 += np.uint16(max(p, q1) - min(p, q1))
                            s2 += np.uint16(max(p, q2) - min(p, q2))
                        a0[k] += s0
                        a1[k] += s1
                        a2[k] += s2
                o = orow + 3 * j
                for k in range(n):
                    out[b, o, k] = a0[k]
                    out[b, o + 1, k] = a1[k]
                    out[b, o + 2, k] = a2[k]
                    m = min((np.int32(a0[k]) << 10) | o, (np.int32(a1[k]) << 10) | (o + 1))
                    kb[k] = min(kb[k], min(m, (np.int32(a2[k]) << 10) | (o + 2)))
            for dx in range(-search + 3 * n3, search + 1):  # the remainder when 3 does not divide 2S+1
                a0[:] = 0
                for r in range(8):
                    pr = prev_t[y0 + r, x0:x0 + 8]
                    cr = curr_t[y0 + r + dy, x0 + dx:x0 + dx + 8]
                    for k in range(n):
                        s0 = np.uint16(0)
                        for c in range(8):
                            p = pr[c, k]
                            q0 = cr[c, k]
                            s0 += np.uint16(max(p, q0) - min(p, q0))
                        a0[k] += s0
                o = orow + dx + search
                for k in range(n):
                    out[b, o, k] = a0[k]
                    kb[k] = min(kb[k], (np.int32(a0[k]) << 10) | o)


@njit(cache=True, fastmath=True, nogil=True)
def _sad_batch(prev_t, curr_t, ys, xs, block, search, out, keys):  # pragma: no cover - compiled
    """Generic-block-size version of :func:`_sad8_batch` (uint32 sums)."""
    n = out.shape[2]
    nb = ys.shape[0]
    acc = np.empty(n, np.uint32)
    for b in range(nb):
        y0 = ys[b]
        x0 = xs[b]
        kb = keys[b]
        for k in range(n):
            kb[k] = 0x7FFFFFFF
        o = 0
        for dy in range(-search, search + 1):
            for dx in range(-search, search + 1):
                acc[:] = 0
                for r in range(block):
                    pr = prev_t[y0 + r]
                    cr = curr_t[y0 + r + dy]
                    for c in range(block):
                        pc = pr[x0 + c]
                        cc = cr[x0 + dx + c]
                        for k in range(n):
                            p = pc[k]
                            q = cc[k]
                            acc[k] += np.uint32(max(p, q) - min(p, q))
                for k in range(n):
                    out[b, o, k] = acc[k]
                    kb[k] = min(kb[k], (np.int32(acc[k]) << 10) | o)
                o += 1


@njit(cache=True, nogil=True, fastmath=True)
def _sad_frac(prev, curr, y0, x0, block, iy, ix, qy, qx, scale):  # pragma: no cover - compiled
    """SAD of a block against ``curr`` sampled at offset ``(ix + qx/scale, iy + qy/scale)``.

    Bilinear interpolation in exact integer arithmetic (seed 003 eq. 2,
    ``g = A00 + A10 a + A01 b + A11 a b`` with ``a = qx/scale``,
    ``b = qy/scale``); ``qx, qy`` in ``0 .. scale-1``. Returns the SAD in
    grey levels (float).
    """
    wa = np.int32((scale - qx) * (scale - qy))
    wb = np.int32(qx * (scale - qy))
    wc = np.int32((scale - qx) * qy)
    wd = np.int32(qx * qy)
    s2 = np.int32(scale * scale)
    acc = np.int32(0)
    for r in range(block):
        # row views: the inner loop indexes them from 0 up, which lets LLVM vectorise it
        pr = prev[y0 + r, x0:x0 + block]
        c0 = curr[y0 + r + iy, x0 + ix:x0 + ix + block + 1]
        c1 = curr[y0 + r + iy + 1, x0 + ix:x0 + ix + block + 1]
        for c in range(block):
            g = (wa * np.int32(c0[c]) + wb * np.int32(c0[c + 1])
                 + wc * np.int32(c1[c]) + wd * np.int32(c1[c + 1]))
            acc += abs(s2 * np.int32(pr[c]) - g)
    return acc / s2


@njit(cache=True, nogil=True)
def _refine_step(prev, curr, y0, x0, block, bx, by, best, step_q, scale):  # pragma: no cover - compiled
    """Try the 8 neighbours of ``(bx, by)`` (in 1/scale px units) at +/- step_q; keep the best."""
    nbx = bx
    nby = by
    for sy in range(-1, 2):
        for sx in range(-1, 2):
            if sx == 0 and sy == 0:
                continue
            cx = bx + sx * step_q
            cy = by + sy * step_q
            ix = cx // scale
            iy = cy // scale
            v = _sad_frac(prev, curr, y0, x0, block, iy, ix, cy - iy * scale, cx - ix * scale, scale)
            if v < best:
                best = v
                nbx = cx
                nby = cy
    return nbx, nby, best


@njit(cache=True, fastmath=True, nogil=True)
def _select_lanes(prev_t, sads, keys, ys, xs, block, search, best, bo, second, gate, neigh, big):  # pragma: no cover
    """Per block and pair (lanes innermost): decode the best offset and its SAD from
    ``keys``, keep its 4 axis neighbours (for the sub-pixel fit), find the best SAD
    outside its 3x3 neighbourhood, and the texture gate (PX4FLOW compute_diff: row
    and column differences of the block's centre).

    The 3x3 neighbourhood is masked in ``sads`` (overwritten with ``big``) so that
    the second minimum is one plain vectorised min over the offsets.
    """
    n = best.shape[1]
    nb = ys.shape[0]
    side = 2 * search + 1
    q0 = block // 4
    qn = block // 2
    sec = np.empty(n, sads.dtype)
    for b in range(nb):
        kb = keys[b]
        for k in range(n):
            o = kb[k] & 1023
            bo[b, k] = o
            best[b, k] = kb[k] >> 10
            oy = o // side
            ox = o - oy * side
            neigh[b, k, 0] = sads[b, o - 1, k] if ox > 0 else big
            neigh[b, k, 1] = sads[b, o + 1, k] if ox < side - 1 else big
            neigh[b, k, 2] = sads[b, o - side, k] if oy > 0 else big
            neigh[b, k, 3] = sads[b, o + side, k] if oy < side - 1 else big
            for dy in range(max(oy - 1, 0), min(oy + 2, side)):
                for dx in range(max(ox - 1, 0), min(ox + 2, side)):
                    sads[b, dy * side + dx, k] = big
        for k in range(n):
            sec[k] = big
        for o in range(side * side):
            so = sads[b, o]
            for k in range(n):
                sec[k] = min(sec[k], so[k])
        for k in range(n):
            second[b, k] = sec[k]
        for k in range(n):
            gate[b, k] = 0
        y0 = ys[b] + q0
        x0 = xs[b] + q0
        for r in range(qn - 1):
            for c in range(qn):
                for k in range(n):
                    gate[b, k] += (abs(np.int32(prev_t[y0 + r, x0 + c, k]) - np.int32(prev_t[y0 + r + 1, x0 + c, k]))
                                   + abs(np.int32(prev_t[y0 + c, x0 + r, k]) - np.int32(prev_t[y0 + c, x0 + r + 1, k])))


@njit(cache=True, nogil=True)
def _interp3(sm, s0, sp, mode):  # pragma: no cover - compiled
    """Sub-pixel offset of a minimum from three samples at -1, 0, +1 (clipped to +/-0.5)."""
    if mode == 3:
        den = sm - 2.0 * s0 + sp
        d = 0.5 * (sm - sp) / den if den > 0 else 0.0
    else:
        den = max(sm, sp) - s0
        d = 0.5 * (sm - sp) / den if den > 0 else 0.0
    return min(0.5, max(-0.5, d))


@njit(cache=True, nogil=True)
def _refine_blocks(prev, curr, pidx, cidx, neigh, ys, xs, block, search, feat_thr, sad_thr, min_distinct, mode,
                   best, bo, second, gate, flow_b, status_b, sadmin_b, distinct_b):  # pragma: no cover
    """Per pair and block: accept/reject, then sub-pixel refinement of accepted blocks.

    prev/curr frames are ``prev[pidx[k]]``, ``curr[cidx[k]]`` (natural layout).
    status: 0 accepted, 1 no texture (gate), 2 SAD above threshold,
    3 ambiguous (flat SAD surface or a second minimum). mode: 0 none,
    1 half, 2 quarter, 3 parabolic.
    """
    n = pidx.shape[0]
    nb = ys.shape[0]
    side = 2 * search + 1
    for k in range(n):
        P = prev[pidx[k]]
        C = curr[cidx[k]]
        for b in range(nb):
            y0 = ys[b]
            x0 = xs[b]
            bv = best[b, k]
            o = bo[b, k]
            sv = second[b, k]
            bdy = o // side - search
            bdx = o % side - search
            sadmin_b[k, b] = bv
            distinct_b[k, b] = (sv - bv) / max(bv, 1)
            flow_b[k, b, 0] = np.nan
            flow_b[k, b, 1] = np.nan
            if gate[b, k] < feat_thr:
                status_b[k, b] = 1
                continue
            if bv > sad_thr:
                status_b[k, b] = 2
                continue
            if sv < (1.0 + min_distinct) * bv or sv == bv:
                status_b[k, b] = 3
                continue
            status_b[k, b] = 0
            fx = float(bdx)
            fy = float(bdy)
            if mode >= 3:
                # a parabola (mode 3) or a symmetric V (mode 4, "equiangular": the shape of a
                # SAD surface near its minimum) through the SAD values along each axis
                if abs(bdx) < search:
                    fx += _interp3(float(neigh[b, k, 0]), float(bv), float(neigh[b, k, 1]), mode)
                if abs(bdy) < search:
                    fy += _interp3(float(neigh[b, k, 2]), float(bv), float(neigh[b, k, 3]), mode)
            flow_b[k, b, 0] = fx
            flow_b[k, b, 1] = fy


@njit(cache=True, nogil=True)
def _refine_bilinear(prev, curr, pidx, cidx, ys, xs, block, mode, status_b, flow_b):  # pragma: no cover
    """Half-pixel (mode 1, PX4FLOW) or half-then-quarter-pixel (mode 2) refinement of the
    accepted blocks with bilinear interpolation (eq. 2), starting from their integer offsets."""
    n = pidx.shape[0]
    nb = ys.shape[0]
    scale = 4
    for k in range(n):
        P = prev[pidx[k]]
        C = curr[cidx[k]]
        for b in range(nb):
            if status_b[k, b] != 0:
                continue
            y0 = ys[b]
            x0 = xs[b]
            qx = int(flow_b[k, b, 0]) * scale
            qy = int(flow_b[k, b, 1]) * scale
            fv = _sad_frac(P, C, y0, x0, block, qy // scale, qx // scale, 0, 0, scale)
            qx, qy, fv = _refine_step(P, C, y0, x0, block, qx, qy, fv, 2, scale)
            if mode == 2:
                qx, qy, fv = _refine_step(P, C, y0, x0, block, qx, qy, fv, 1, scale)
            flow_b[k, b, 0] = qx / scale
            flow_b[k, b, 1] = qy / scale


@njit(cache=True, nogil=True)  # no fastmath: it would drop the NaN test below
def _lk_refine(prev, curr, ys, xs, block, search, used, flow, iters, max_step, out):  # pragma: no cover - compiled
    """Frame-level inverse-compositional Gauss–Newton refinement of a pure translation.

    Over the pixels of the used blocks, minimise ``sum (C(x + f) - P(x))^2``
    with ``C`` sampled bilinearly (eq. 2); the template gradient and the 2x2
    Hessian are computed once (inverse compositional). Starts at the block-matching flow; a frame
    whose refinement wanders more than ``max_step`` px from it keeps the
    block-matching value.
    """
    n = prev.shape[0]
    nb = ys.shape[0]
    for k in range(n):
        fx0 = flow[k, 0]
        fy0 = flow[k, 1]
        out[k, 0] = fx0
        out[k, 1] = fy0
        if np.isnan(fx0) or np.isnan(fy0):
            continue
        P = prev[k]
        C = curr[k]
        hxx = 0.0
        hxy = 0.0
        hyy = 0.0
        for b in range(nb):
            if not used[k, b]:
                continue
            for r in range(block):
                y = ys[b] + r
                for c in range(block):
                    x = xs[b] + c
                    gx = 0.5 * (float(P[y, x + 1]) - float(P[y, x - 1]))
                    gy = 0.5 * (float(P[y + 1, x]) - float(P[y - 1, x]))
                    hxx += gx * gx
                    hxy += gx * gy
                    hyy += gy * gy
        det = hxx * hyy - hxy * hxy
        if det <= 1e-9 * (hxx + hyy) ** 2 or det <= 0:
            continue
        fx = fx0
        fy = fy0
        ok = True
        for it in range(iters):
            ix = int(math.floor(fx))
            iy = int(math.floor(fy))
            a = fx - ix
            bb = fy - iy
            w00 = (1 - a) * (1 - bb)
            w10 = a * (1 - bb)
            w01 = (1 - a) * bb
            w11 = a * bb
            sx = 0.0
            sy = 0.0
            for b in range(nb):
                if not used[k, b]:
                    continue
                for r in range(block):
                    y = ys[b] + r
                    for c in range(block):
                        x = xs[b] + c
                        g = (w00 * float(C[y + iy, x + ix]) + w10 * float(C[y + iy, x + ix + 1])
                             + w01 * float(C[y + iy + 1, x + ix]) + w11 * float(C[y + iy + 1, x + ix + 1]))
                        e = g - float(P[y, x])
                        gx = 0.5 * (float(P[y, x + 1]) - float(P[y, x - 1]))
                        gy = 0.5 * (float(P[y + 1, x]) - float(P[y - 1, x]))
                        sx += gx * e
                        sy += gy * e
            dx = (hyy * sx - hxy * sy) / det
            dy = (hxx * sy - hxy * sx) / det
            fx -= dx
            fy -= dy
            # the frame margin of search + 1 px bounds where C may be sampled
            if abs(fx - fx0) > max_step or abs(fy - fy0) > max_step or abs(fx) >= search + 0.99 or abs(fy) >= search + 0.99:
                ok = False
                break
            if abs(dx) < 1e-3 and abs(dy) < 1e-3:
                break
        if ok:
            out[k, 0] = fx
            out[k, 1] = fy


# ---------------------------------------------------------------------------------------------
# public API
# ---------------------------------------------------------------------------------------------


@dataclass
class BlockMatches:
    """Per-block results of :func:`match_blocks` for N frame pairs.

    Attributes
    ----------
    flow : ndarray, shape (N, n_blocks, 2)
        Sub-pixel flow ``(du, dv)`` of each block, px; NaN for rejected blocks.
    status : ndarray of int8, shape (N, n_blocks)
        0 accepted, 1 no texture, 2 SAD above threshold, 3 ambiguous.
    sad_min : ndarray, shape (N, n_blocks)
        Best integer SAD, grey levels.
    distinctness : ndarray, shape (N, n_blocks)
        ``(second best outside the 3x3 neighbourhood - best) / best``.
    centres : ndarray, shape (n_blocks, 2)
        Block centres ``(u, v)``, px.
    texture : ndarray, shape (N, n_blocks)
        The texture-gate value of each block (grey levels).
    """

    flow: np.ndarray
    status: np.ndarray
    sad_min: np.ndarray
    distinctness: np.ndarray
    centres: np.ndarray
    texture: np.ndarray


def _check_frames(frames, name: str, config: FlowConfig) -> np.ndarray:
    arr = np.asarray(frames)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[1:] != (config.window, config.window):
        raise ShapeError(
            f"{name} must have shape (N, {config.window}, {config.window}) or "
            f"({config.window}, {config.window}) (the sensor window), got {tuple(np.shape(frames))}"
        )
    if arr.dtype != np.uint8:
        if not np.issubdtype(arr.dtype, np.number):
            raise InputError(f"{name} must be numeric grey levels, got dtype {arr.dtype}")
        if not np.all(np.isfinite(arr)):
            raise InputError(f"{name} contains NaN or infinity")
        if arr.size and (arr.min() < 0 or arr.max() > 255):
            raise InputError(f"{name} must hold 8-bit grey levels 0..255, got range [{arr.min()}, {arr.max()}]")
        arr = np.rint(arr).astype(np.uint8)
    return arr


def match_blocks(prev, curr, config: FlowConfig = FlowConfig()) -> BlockMatches:
    """SAD block matching (eq. 1) and sub-pixel refinement (eq. 2) of frame pairs.

    Parameters
    ----------
    prev, curr : array_like of uint8, shape (N, W, W) or (W, W)
        Consecutive frames of one sensor; ``W = config.window``.
    config : FlowConfig

    Returns
    -------
    BlockMatches
    """
    prev = _check_frames(prev, "prev", config)
    curr = _check_frames(curr, "curr", config)
    if prev.shape != curr.shape:
        raise ShapeError(f"prev and curr must have the same shape, got {prev.shape} and {curr.shape}")
    n = prev.shape[0]
    return _match_indexed(prev, curr, np.arange(n), np.arange(n), config)


def match_sequence(frames, config: FlowConfig = FlowConfig()) -> BlockMatches:
    """:func:`match_blocks` of every consecutive pair of one sensor's frames ``(T, W, W)``.

    Each frame is converted to the kernel's layout once, not twice.
    """
    frames = _check_frames(frames, "frames", config)
    t = frames.shape[0]
    if t < 2:
        raise InputError(f"frames: need at least 2 frames for a flow, got {t}")
    idx = np.arange(t - 1)
    return _match_indexed(frames, frames, idx, idx + 1, config)


def _match_indexed(prev, curr, pidx, cidx, config: FlowConfig) -> BlockMatches:
    # pidx, cidx are consecutive index ranges (np.arange)
    n = pidx.shape[0]
    sequence = prev is curr and n > 0 and cidx[0] == pidx[0] + 1
    prev = np.ascontiguousarray(prev)
    curr = prev if sequence else np.ascontiguousarray(curr)
    o1 = block_origins(config)
    ys = np.repeat(o1, config.grid)
    xs = np.tile(o1, config.grid)
    nb = ys.size
    side = 2 * config.search + 1
    w = config.window
    flow = np.empty((n, nb, 2))
    status = np.empty((n, nb), np.int8)
    sad_min = np.empty((n, nb))
    distinct = np.empty((n, nb))
    texture = np.empty((n, nb))
    mode = SUBPIXEL_MODES.index(config.subpixel)
    for s in range(0, n, _BATCH):
        e = min(n, s + _BATCH)
        m = e - s
        # pixel-major layout, pairs innermost (OpenCV's transpose is the fastest byte transpose at hand);
        # consecutive frames of one sequence are transposed once and read at lane k and k + 1
        if sequence:
            both = cv2.transpose(prev[pidx[s]:pidx[s] + m + 1].reshape(m + 1, w * w)).reshape(w, w, m + 1)
            pt = np.ascontiguousarray(both[:, :, :m])   # strided copies: much cheaper than a transpose
            ct = np.ascontiguousarray(both[:, :, 1:])
        else:
            pt = cv2.transpose(prev[pidx[s]:pidx[s] + m].reshape(m, w * w)).reshape(w, w, m)
            ct = cv2.transpose(curr[cidx[s]:cidx[s] + m].reshape(m, w * w)).reshape(w, w, m)
        keys = np.empty((nb, m), np.int32)
        if config.block == 8:
            sads = np.empty((nb, side * side, m), np.uint16)
            _sad8_batch(pt, ct, ys, xs, config.search, sads, keys)
        else:
            sads = np.empty((nb, side * side, m), np.uint32)
            _sad_batch(pt, ct, ys, xs, config.block, config.search, sads, keys)
        best = np.empty((nb, m), np.int32)
        bo = np.empty((nb, m), np.int32)
        second = np.empty((nb, m), np.int32)
        gate = np.empty((nb, m), np.int32)
        neigh = np.empty((nb, m, 4), np.int64)
        _select_lanes(pt, sads, keys, ys, xs, config.block, config.search, best, bo, second, gate, neigh,
                      sads.dtype.type(np.iinfo(sads.dtype).max))
        _refine_blocks(
            prev, curr, pidx[s:e], cidx[s:e], neigh, ys, xs, config.block, config.search,
            float(config.feature_threshold), float(config.sad_limit), float(config.min_distinctness), mode,
            best, bo, second, gate, flow[s:e], status[s:e], sad_min[s:e], distinct[s:e],
        )
        if mode in (1, 2):
            _refine_bilinear(prev, curr, pidx[s:e], cidx[s:e], ys, xs, config.block, mode, status[s:e], flow[s:e])
        texture[s:e] = gate.T
    centres = np.stack([xs, ys], axis=1) + (config.block - 1) / 2.0
    return BlockMatches(flow, status, sad_min, distinct, centres.astype(float), texture)


@dataclass
class FrameFlow:
    """Per-frame flow of N frame pairs (:func:`compute_flow`).

    Attributes
    ----------
    flow_px : ndarray, shape (N, 2)
        Measured image flow ``(du, dv)``, px (NaN where not valid).
    flow_comp_px : ndarray, shape (N, 2)
        Flow with the rotation-induced part removed (eqs. 3–4), px.
    displacement : ndarray, shape (N, 2) or None
        Sensor displacement over the ground in the sensor frame S at the end
        of the interval, m (eq. 5); None without heights.
    quality : ndarray, shape (N,)
        ``used / n_blocks * 255`` (PX4FLOW's accepted/25*255; with
        ``aggregate="trimmed"`` only the blocks that agree with the median
        count), 0 where not valid.
    valid : ndarray of bool, shape (N,)
        At least ``min_blocks`` blocks used.
    n_accepted, n_no_texture, n_bad_sad, n_ambiguous : ndarray of int, shape (N,)
        Block counts by outcome.
    agreement : ndarray, shape (N,)
        Fraction of accepted blocks within ``trim_px`` of the median flow.
    spread_px : ndarray, shape (N,)
        RMS distance of the used blocks from the frame flow, px (a per-frame
        noise indicator; NaN when not valid).
    reason : list of str
        ``""`` for valid frames, else why (``"low texture"``, ``"ambiguous"``,
        ``"poor match"``).
    centroid_px : ndarray, shape (N, 2)
        Mean centre of the used blocks relative to the principal point, px.
    """

    flow_px: np.ndarray
    flow_comp_px: np.ndarray
    displacement: np.ndarray | None
    quality: np.ndarray
    valid: np.ndarray
    n_accepted: np.ndarray
    n_no_texture: np.ndarray
    n_bad_sad: np.ndarray
    n_ambiguous: np.ndarray
    agreement: np.ndarray
    spread_px: np.ndarray
    reason: list = field(default_factory=list)
    centroid_px: np.ndarray | None = None

    def __len__(self) -> int:
        return self.flow_px.shape[0]

    def summary(self) -> dict:
        """Counts of valid / invalid frames by reason."""
        reasons = {}
        for r in self.reason:
            if r:
                reasons[r] = reasons.get(r, 0) + 1
        return {"frames": len(self), "valid": int(self.valid.sum()), "invalid_by_reason": reasons,
                "mean_quality": float(np.mean(self.quality)) if len(self) else math.nan}


@njit(cache=True, nogil=True)
def _small_median(a, m):  # pragma: no cover - compiled
    """Median of ``a[:m]`` (m <= a few dozen) by insertion sort, in place (cheap to compile)."""
    for i in range(1, m):
        v = a[i]
        j = i - 1
        while j >= 0 and a[j] > v:
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = v
    h = m // 2
    return a[h] if m % 2 == 1 else 0.5 * (a[h - 1] + a[h])


@njit(cache=True, nogil=True)
def _aggregate_frames(flow, status, cen, mode, trim, used, out_flow, agreement, spread, centroid):  # pragma: no cover
    """Per frame: median of the accepted blocks, the blocks within ``trim`` of it, the frame's
    flow (mode 0 mean, 1 median, 2 trimmed mean), scatter and centroid of the used blocks."""
    n, nb = status.shape
    xs = np.empty(nb)
    ys = np.empty(nb)
    for k in range(n):
        m = 0
        for b in range(nb):
            if status[k, b] == 0:
                xs[m] = flow[k, b, 0]
                ys[m] = flow[k, b, 1]
                m += 1
        for b in range(nb):
            used[k, b] = False
        if m == 0:
            out_flow[k, 0] = np.nan
            out_flow[k, 1] = np.nan
            agreement[k] = 0.0
            spread[k] = np.nan
            centroid[k, 0] = 0.0
            centroid[k, 1] = 0.0
            continue
        mx = _small_median(xs, m)
        my = _small_median(ys, m)
        near = 0
        for b in range(nb):
            if status[k, b] == 0:
                d2 = (flow[k, b, 0] - mx) ** 2 + (flow[k, b, 1] - my) ** 2
                if d2 <= trim * trim:
                    near += 1
                    if mode == 2:
                        used[k, b] = True
                if mode != 2:
                    used[k, b] = True
        agreement[k] = near / m
        sx = 0.0
        sy = 0.0
        cx = 0.0
        cy = 0.0
        cnt = 0
        for b in range(nb):
            if used[k, b]:
                sx += flow[k, b, 0]
                sy += flow[k, b, 1]
                cx += cen[b, 0]
                cy += cen[b, 1]
                cnt += 1
        if cnt == 0:
            out_flow[k, 0] = np.nan
            out_flow[k, 1] = np.nan
            spread[k] = np.nan
            centroid[k, 0] = 0.0
            centroid[k, 1] = 0.0
            continue
        if mode == 1:
            fx = mx
            fy = my
        else:
            fx = sx / cnt
            fy = sy / cnt
        out_flow[k, 0] = fx
        out_flow[k, 1] = fy
        centroid[k, 0] = cx / cnt
        centroid[k, 1] = cy / cnt
        ss = 0.0
        for b in range(nb):
            if used[k, b]:
                ss += (flow[k, b, 0] - fx) ** 2 + (flow[k, b, 1] - fy) ** 2
        spread[k] = math.sqrt(ss / cnt)


@njit(cache=True, nogil=True)
def _tensor_combine(prev, used, bflow, ys, xs, block, reg, out):  # pragma: no cover - compiled
    """Per frame: the used blocks' flows weighted by their gradient structure tensors (central
    differences in ``prev``); ``out`` holds the trimmed mean on entry, the pull in the weakly
    determined direction (``reg`` times the mean eigenvalue)."""
    n, nb = used.shape
    for k in range(n):
        if not (out[k, 0] == out[k, 0]):
            continue
        s00 = 0.0
        s01 = 0.0
        s11 = 0.0
        r0 = 0.0
        r1 = 0.0
        for b in range(nb):
            if not used[k, b]:
                continue
            a = 0.0
            c = 0.0
            d = 0.0
            for y in range(ys[b], ys[b] + block):
                for x in range(xs[b], xs[b] + block):
                    gx = 0.5 * (float(prev[k, y, x + 1]) - float(prev[k, y, x - 1]))
                    gy = 0.5 * (float(prev[k, y + 1, x]) - float(prev[k, y - 1, x]))
                    a += gx * gx
                    c += gx * gy
                    d += gy * gy
            s00 += a
            s01 += c
            s11 += d
            r0 += a * bflow[k, b, 0] + c * bflow[k, b, 1]
            r1 += c * bflow[k, b, 0] + d * bflow[k, b, 1]
        lam = reg * 0.5 * (s00 + s11)
        if lam <= 0.0:
            continue
        s00 += lam
        s11 += lam
        r0 += lam * out[k, 0]
        r1 += lam * out[k, 1]
        det = s00 * s11 - s01 * s01
        out[k, 0] = (s11 * r0 - s01 * r1) / det
        out[k, 1] = (s00 * r1 - s01 * r0) / det


#: ``aggregate="tensor"``: the pull towards the trimmed mean, as a fraction of the mean eigenvalue
TENSOR_REGULARISATION = 0.02


def _aggregate(bm: BlockMatches, config: FlowConfig):
    n, nb = bm.status.shape
    n_acc = (bm.status == 0).sum(axis=1)
    used = np.empty((n, nb), np.bool_)
    flow = np.empty((n, 2))
    agreement = np.empty(n)
    spread = np.empty(n)
    centroid = np.empty((n, 2))
    cen = bm.centres - (config.window - 1) / 2.0
    mode = {"mean": 0, "median": 1, "trimmed": 2, "tensor": 2}[config.aggregate]
    _aggregate_frames(bm.flow, bm.status, np.ascontiguousarray(cen), mode, float(config.trim_px), used, flow,
                      agreement, spread, centroid)
    return n_acc, used, flow, agreement, spread, centroid


def rotational_flow(angle, xy_px, focal_px):
    """Image flow caused by a small camera rotation (seed 003 eqs. 3–4, rotational part).

    For a rotation by the small angles ``angle = (dx, dy, dz)`` (rad, camera
    axes: x = u, y = v, z = optical axis) a static point at image position
    ``(x, y)`` (px, relative to the principal point) moves by

    .. math::
        u_r = -f d_y + d_z y + d_x x y / f - d_y x^2 / f, \\qquad
        v_r = f d_x - d_z x + d_x y^2 / f - d_y x y / f

    (the rotational terms of the Longuet-Higgins–Prazdny flow equations that
    eqs. 3–4 of the seed write as velocities; multiply rates by ``dt``).

    Parameters
    ----------
    angle : array_like, shape (..., 3)
        Rotation angle over the frame interval, rad (gyro rate x dt).
    xy_px : array_like, shape (..., 2)
        Image position relative to the principal point, px.
    focal_px : float
        Focal length, px.

    Returns
    -------
    ndarray, shape (..., 2)
        Flow ``(u_r, v_r)``, px.
    """
    a = np.asarray(angle, float)
    p = np.asarray(xy_px, float)
    f = float(focal_px)
    dx, dy, dz = a[..., 0], a[..., 1], a[..., 2]
    x, y = p[..., 0], p[..., 1]
    ur = -f * dy + dz * y + dx * x * y / f - dy * x * x / f
    vr = f * dx - dz * x + dx * y * y / f - dy * x * y / f
    return np.stack([ur, vr], axis=-1)


def compensate_rotation(flow_px, gyro, dt, focal_px, *, centroid_px=None, threshold: float = 0.01):
    """Remove the flow the sensor's own rotation causes (seed 003 eqs. 3–4).

    Parameters
    ----------
    flow_px : array_like, shape (N, 2)
        Measured flow, px.
    gyro : array_like, shape (N, 3)
        Mean angular rate over each frame interval in the camera frame, rad/s.
    dt : array_like, shape (N,) or float
        Frame interval, s.
    focal_px : float
        Focal length, px.
    centroid_px : array_like, shape (N, 2), optional
        Where the flow was measured relative to the principal point (the mean
        block centre); the yaw term ``d_z (y, -x)`` vanishes at the centre.
    threshold : float
        Rates whose magnitude is below this (rad/s, per axis) are treated as
        zero, as the PX4FLOW firmware does to keep gyro noise out of a still sensor.

    Returns
    -------
    ndarray, shape (N, 2)
    """
    w = np.asarray(gyro, float)
    w = np.where(np.abs(w) >= threshold, w, 0.0)
    ang = w * np.asarray(dt, float)[..., None]
    c = np.zeros_like(np.asarray(flow_px, float)) if centroid_px is None else np.asarray(centroid_px, float)
    return np.asarray(flow_px, float) - rotational_flow(ang, c, focal_px)


def metric_displacement(flow_px, height, focal_px):
    """Sensor displacement over the ground from compensated flow (seed 003 eq. 5).

    The ground moves opposite to the sensor, so in the sensor frame S
    (``x_S`` = image u, ``y_S`` = image up):
    ``dS = (-du, +dv) * h / f``.

    Parameters
    ----------
    flow_px : array_like, shape (N, 2)
        Rotation-compensated flow ``(du, dv)``, px.
    height : array_like, shape (N,)
        Distance from the lens to the ground along the optical axis, m (> 0).
    focal_px : float
        Focal length, px.

    Returns
    -------
    ndarray, shape (N, 2)
        Displacement, m.
    """
    fl = np.asarray(flow_px, float)
    h = np.asarray(height, float)
    return np.stack([-fl[..., 0], fl[..., 1]], axis=-1) * (h / float(focal_px))[..., None]


def speed_limit(config: FlowConfig, height: float, rate_hz: float, focal_px: float) -> float:
    """Fastest measurable ground speed, ``v_max = (S + 0.5) h rate / f`` (m/s).

    Beyond it the true offset leaves the search range and the block matcher
    returns garbage (it aliases to the range's edge).
    """
    return (config.search + 0.5) * float(height) * float(rate_hz) / float(focal_px)


def compute_flow(prev, curr, config: FlowConfig = FlowConfig(), *, gyro=None, dt=None, height=None,
                 focal_px: float | None = None) -> FrameFlow:
    """Flow, quality and (with heights) metric displacement of N frame pairs.

    Parameters
    ----------
    prev, curr : array_like of uint8, shape (N, W, W) or (W, W)
        Consecutive frames.
    config : FlowConfig
    gyro : array_like, shape (N, 3), optional
        Mean gyro rate over each interval, camera frame, rad/s (eqs. 3–4).
    dt : float or array_like, shape (N,), optional
        Frame intervals, s (needed with ``gyro``).
    height : array_like, shape (N,), optional
        Distance to the ground, m, > 0 (eq. 5).
    focal_px : float, optional
        Focal length, px (needed with ``gyro`` or ``height``).

    Returns
    -------
    FrameFlow
        Invalid frames (fewer than ``min_blocks`` accepted blocks) carry NaN
        flow, quality 0 and a ``reason`` — never a silent average.
    """
    bm = match_blocks(prev, curr, config)
    prev = _check_frames(prev, "prev", config)
    curr = _check_frames(curr, "curr", config)
    return _frame_flow(bm, prev, curr, config, gyro, dt, height, focal_px)


def compute_flow_sequence(frames, config: FlowConfig = FlowConfig(), *, gyro=None, dt=None, height=None,
                          focal_px: float | None = None) -> FrameFlow:
    """:func:`compute_flow` of every consecutive pair of one sensor's frames ``(T, W, W)``.

    Each frame enters the kernel's layout once (not twice as with separate
    ``prev``/``curr`` arrays). Arguments as :func:`compute_flow`, for the T-1 intervals.
    """
    bm = match_sequence(frames, config)
    frames = np.ascontiguousarray(_check_frames(frames, "frames", config))
    return _frame_flow(bm, frames[:-1], frames[1:], config, gyro, dt, height, focal_px)


def _frame_flow(bm, prev, curr, config, gyro, dt, height, focal_px) -> FrameFlow:
    n = bm.flow.shape[0]
    n_acc, used, flow, agreement, spread, centroid = _aggregate(bm, config)
    if config.aggregate == "tensor" and n:
        o1 = block_origins(config)
        _tensor_combine(np.ascontiguousarray(prev), used, np.ascontiguousarray(bm.flow), np.repeat(o1, config.grid),
                        np.tile(o1, config.grid), config.block, TENSOR_REGULARISATION, flow)
    n_used = used.sum(axis=1)
    # the quantisation of the coarse sub-pixel modes adds its own scatter (RMS of a uniform step in 2D)
    q = {"none": 0.41, "half": 0.2, "quarter": 0.1}.get(config.subpixel, 0.0)
    valid = (n_used >= config.min_blocks) & ~(spread > np.hypot(config.max_spread_px, q))
    flow = np.where(valid[:, None], flow, np.nan)
    if config.refine == "lk" and n:
        o1 = block_origins(config)
        refined = np.empty_like(flow)
        _lk_refine(np.ascontiguousarray(prev), np.ascontiguousarray(curr),
                   np.repeat(o1, config.grid), np.tile(o1, config.grid), config.block, config.search, used,
                   np.ascontiguousarray(flow), int(config.refine_iterations), 1.0, refined)
        flow = refined
    spread = np.where(valid, spread, np.nan)
    quality = np.where(valid, n_used / config.n_blocks * 255.0, 0.0)
    # an ambiguous block with little more texture than sensor noise gives at the gate
    # (noise alone passes PX4FLOW's threshold of 30) is a texture problem, not aliasing
    faint = (bm.status == 3) & (bm.texture < 3.0 * config.feature_threshold)
    n_tex = (bm.status == 1).sum(axis=1) + faint.sum(axis=1)
    n_sad = (bm.status == 2).sum(axis=1)
    n_amb = (bm.status == 3).sum(axis=1) - faint.sum(axis=1)
    # accepted blocks that disagree (too few agree, or they scatter) are ambiguous too
    reason = np.select(
        [valid, (n_tex >= np.maximum(n_amb, n_sad)), (n_amb >= n_sad) | (n_acc >= config.min_blocks)],
        ["", "low texture", "ambiguous"], "poor match").tolist()
    if (gyro is not None or height is not None) and focal_px is None:
        raise InputError("focal_px is needed to compensate rotation or convert to metres")
    comp = flow.copy()
    if gyro is not None:
        if dt is None:
            raise InputError("dt (frame interval, s) is needed with gyro")
        g = check_array(gyro, "gyro", shape=(n, 3))
        d = np.broadcast_to(np.asarray(dt, float), (n,))
        if np.any(~np.isfinite(d)) or np.any(d <= 0):
            raise InputError("dt must be positive (frame timestamps must increase)")
        comp = compensate_rotation(flow, g, d, focal_px, centroid_px=centroid, threshold=config.gyro_threshold)
    disp = None
    if height is not None:
        h = check_array(height, "height", shape=(n,))
        if np.any(h <= 0):
            bad = np.flatnonzero(h <= 0)
            raise InputError(f"height must be > 0 m, got {h[bad[0]]:g} at frame {int(bad[0])} ({bad.size} such frames)")
        disp = metric_displacement(comp, h, focal_px)
    return FrameFlow(
        flow_px=flow, flow_comp_px=comp, displacement=disp, quality=quality, valid=valid,
        n_accepted=n_acc, n_no_texture=n_tex, n_bad_sad=n_sad, n_ambiguous=n_amb,
        agreement=agreement, spread_px=spread, reason=reason, centroid_px=centroid,
    )
