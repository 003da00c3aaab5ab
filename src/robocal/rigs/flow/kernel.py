"""Optical flow of one downward sensor: SAD block matching, sub-pixel refinement,
gyro compensation and metric conversion (Li, Guan and Chu 2017, §1, eqs. 1–5).

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
generic compiled path. The C kernel (the default where it was built) splits a call's pairs into chunks on
:func:`kernel_threads` threads, with the same bits as one thread. See ``bench/bench_flow.py``.

The module is split along its seams: :mod:`.kernel_config` (:class:`FlowConfig`,
no numba), :mod:`.kernel_compiled` (the numba loops), :mod:`.kernel_metric`
(gyro compensation, metric displacement, speed ceiling) and this one, the
Python API over them; every name stays importable from here.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from robocal.errors import InputError, ShapeError
from robocal.rigs.flow.kernel_config import AGGREGATE_MODES, SIGMA_PX, SUBPIXEL_MODES, FlowConfig, block_origins
from robocal.rigs.flow.kernel_metric import compensate_rotation, metric_displacement, rotational_flow, speed_limit
from robocal.validation import check_array

#: the numba loops re-exported from here for tests and benches (imported on first access: numba's import
#: alone costs ~0.6-1 s of a command's start-up, which the C kernel does not pay)
_COMPILED = ("_aggregate_frames", "_interp3", "_lk_refine", "_refine_bilinear", "_refine_blocks", "_refine_step",
             "_sad8_batch", "_sad_batch", "_sad_frac", "_select_lanes", "_small_median", "_tensor_combine")

#: environment variable choosing the block matcher: ``auto`` (default: C when built, else numba),
#: ``c`` (the C extension; an error when it was not built) or ``numba``
KERNEL_ENV = "ROBOCAL_FLOW_KERNEL"

#: environment variable capping the C kernel's threads (a positive integer; ``1``: the calling thread only).
#: Unset: one thread per CPU this process may run on (``os.sched_getaffinity``)
THREADS_ENV = "ROBOCAL_FLOW_THREADS"

#: fewest frame pairs a thread of the C kernel gets (~2 ms of work at ~140k pairs/s a core): below that,
#: handing work to another thread costs more than it saves, so a single pair never leaves the caller's thread
MIN_PAIRS_PER_THREAD = 256


def __getattr__(name):
    if name in _COMPILED:
        from robocal.rigs.flow import kernel_compiled

        return getattr(kernel_compiled, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _flowc():
    """The C extension :mod:`robocal.rigs.flow._flowc`, or None when it was not built (no C compiler or
    Python headers at install time: setuptools builds it as optional)."""
    global _FLOWC
    if _FLOWC is False:
        try:
            from robocal.rigs.flow import _flowc as mod
        except ImportError:
            mod = None
        _FLOWC = mod
    return _FLOWC


_FLOWC = False      # not yet looked for


def kernel_backend() -> str:
    """Which block matcher :func:`compute_flow` and :func:`match_blocks` run: ``"c"`` (the C extension
    ``_flowc``: SSE2 ``psadbw`` on x86, with an AVX2 copy where GCC builds one; plain C elsewhere; no numba
    import) or ``"numba"`` (the numba
    kernel of :mod:`.kernel_compiled`, when the extension was not built or ``ROBOCAL_FLOW_KERNEL=numba``).

    Both give bit-identical block flows, statuses and frame flows (integer SADs; the same double-precision
    fit and aggregation in the same order; tests/rigs/flow/test_flow_kernel_c.py). ``refine="lk"`` and
    ``aggregate="tensor"`` add a numba step after either.
    """
    choice = os.environ.get(KERNEL_ENV, "auto").strip().lower() or "auto"
    if choice not in ("auto", "c", "numba"):
        raise InputError(f"${KERNEL_ENV} must be 'auto', 'c' or 'numba', got {choice!r}")
    if choice == "numba":
        return "numba"
    if _flowc() is None:
        if choice == "c":
            raise InputError(f"${KERNEL_ENV}=c but the C kernel (robocal.rigs.flow._flowc) was not built at install "
                             "(no C compiler or Python headers then): reinstall with a compiler, or unset it")
        return "numba"
    return "c"


def kernel_threads() -> int:
    """How many threads the C kernel may use: ``$ROBOCAL_FLOW_THREADS`` when set, else the CPUs this process
    may run on (its affinity mask, which a container or ``taskset`` narrows; ``os.cpu_count()`` where the
    system has no such mask). The numba fallback runs in the caller's thread."""
    v = os.environ.get(THREADS_ENV, "").strip()
    if v:
        try:
            n = int(v)
        except ValueError:
            n = 0
        if n < 1:
            raise InputError(f"${THREADS_ENV} must be a positive integer (1: no extra threads), got {v!r}")
        return n
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):      # not Linux
        return max(1, os.cpu_count() or 1)


def _chunked(n: int, run) -> None:
    """``run(start, stop)`` over ``0 .. n`` in contiguous chunks, on up to :func:`kernel_threads` threads.

    Every frame pair (and every frame's aggregation) is computed alone, from its own inputs into its own
    output rows, so the chunks give the same bits as one call (tests/rigs/flow/test_flow_threads.py).
    ``run`` must release the GIL (the C kernel's loops do, ``Py_BEGIN_ALLOW_THREADS``): the caller's
    thread takes the first chunk, a new thread each of the others (a command makes a few such calls, each
    of milliseconds: no pool to keep, and no 7 ms import of :mod:`concurrent.futures`, which
    :mod:`.background` avoids for the same reason); the first chunk's error is raised after all have ended.
    """
    k = min(kernel_threads(), -(-n // MIN_PAIRS_PER_THREAD))
    if k <= 1:
        run(0, n)
        return
    import threading

    edges = [n * i // k for i in range(k + 1)]
    errors = [None] * k

    def work(i):
        try:
            run(edges[i], edges[i + 1])
        except BaseException as exc:  # raised in the caller's thread below
            errors[i] = exc

    threads = [threading.Thread(target=work, args=(i,), name="robocal-flow", daemon=True) for i in range(1, k)]
    for t in threads:
        t.start()
    try:
        work(0)
    finally:
        for t in threads:
            t.join()
    for exc in errors:
        if exc is not None:
            raise exc


def kernel_name() -> str:
    """:func:`kernel_backend` as a run records it: ``"c (avx2)"`` (x86-64 with AVX2: the loader picked the
    kernel's AVX2 copy), ``"c (sse2)"``, ``"c (portable)"`` (the C kernel without SIMD intrinsics: not x86)
    or ``"numba"``."""
    return f"c ({_flowc().SIMD})" if kernel_backend() == "c" else "numba"


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
    "SIGMA_PX",
    "kernel_backend",
    "kernel_name",
    "kernel_threads",
]

_BATCH = 256  # frame pairs per kernel call: large enough to fill SIMD lanes, small enough for L2


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
    flow = np.empty((n, nb, 2))
    status = np.empty((n, nb), np.int8)
    sad_min = np.empty((n, nb))
    distinct = np.empty((n, nb))
    texture = np.empty((n, nb))
    mode = SUBPIXEL_MODES.index(config.subpixel)
    centres = (np.stack([xs, ys], axis=1) + (config.block - 1) / 2.0).astype(float)
    if kernel_backend() == "c":
        # natural layout, no batches: the C kernel reads each pair where it lies (a memory map too)
        match, p0, c0 = _flowc().match, int(pidx[0]) if n else 0, int(cidx[0]) if n else 0
        ys64, xs64 = ys.astype(np.int64), xs.astype(np.int64)
        args = (config.window, config.block, config.search, ys64, xs64, float(config.feature_threshold),
                float(config.sad_limit), float(config.min_distinctness), mode)

        def run(s, e):
            match(prev, curr, p0 + s, c0 + s, e - s, *args, flow[s:e], status[s:e], sad_min[s:e], distinct[s:e],
                  texture[s:e])

        if n:
            _chunked(n, run)
        return BlockMatches(flow, status, sad_min, distinct, centres, texture)
    import cv2

    from robocal.rigs.flow.kernel_compiled import _refine_bilinear, _refine_blocks, _sad8_batch, _sad_batch, _select_lanes

    side = 2 * config.search + 1
    w = config.window
    for s in range(0, n, _BATCH):
        e = min(n, s + _BATCH)
        m = e - s
        # pixel-major layout, pairs innermost (OpenCV's transpose is the fastest byte transpose at hand);
        # consecutive frames of one sequence are transposed once and read at lanes k and k + 1
        if sequence:
            pt = ct = cv2.transpose(prev[pidx[s]:pidx[s] + m + 1].reshape(m + 1, w * w)).reshape(w, w, m + 1)
            coff = 1
        else:
            pt = cv2.transpose(prev[pidx[s]:pidx[s] + m].reshape(m, w * w)).reshape(w, w, m)
            ct = cv2.transpose(curr[cidx[s]:cidx[s] + m].reshape(m, w * w)).reshape(w, w, m)
            coff = 0
        keys = np.empty((nb, m), np.int32)
        if config.block == 8:
            sads = np.empty((nb, side * side, m), np.uint16)
            _sad8_batch(pt, ct, coff, ys, xs, config.search, sads, keys)
        else:
            sads = np.empty((nb, side * side, m), np.uint32)
            _sad_batch(pt, ct, coff, ys, xs, config.block, config.search, sads, keys)
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
    return BlockMatches(flow, status, sad_min, distinct, centres, texture)


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
    if kernel_backend() == "c":
        bflow, status, cen = np.ascontiguousarray(bm.flow), np.ascontiguousarray(bm.status), np.ascontiguousarray(cen)
        aggregate, trim = _flowc().aggregate, float(config.trim_px)

        def run(s, e):
            aggregate(bflow[s:e], status[s:e], cen, e - s, nb, mode, trim, used[s:e], flow[s:e], agreement[s:e],
                      spread[s:e], centroid[s:e])

        if n:
            _chunked(n, run)
        return n_acc, used, flow, agreement, spread, centroid
    from robocal.rigs.flow.kernel_compiled import _aggregate_frames

    _aggregate_frames(bm.flow, bm.status, np.ascontiguousarray(cen), mode, float(config.trim_px), used, flow,
                      agreement, spread, centroid)
    return n_acc, used, flow, agreement, spread, centroid



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
        from robocal.rigs.flow.kernel_compiled import _tensor_combine

        o1 = block_origins(config)
        _tensor_combine(np.ascontiguousarray(prev), used, np.ascontiguousarray(bm.flow), np.repeat(o1, config.grid),
                        np.tile(o1, config.grid), config.block, TENSOR_REGULARISATION, flow)
    n_used = used.sum(axis=1)
    # the quantisation of the coarse sub-pixel modes adds its own scatter (RMS of a uniform step in 2D)
    q = {"none": 0.41, "half": 0.2, "quarter": 0.1}.get(config.subpixel, 0.0)
    valid = (n_used >= config.min_blocks) & ~(spread > np.hypot(config.max_spread_px, q))
    flow = np.where(valid[:, None], flow, np.nan)
    if config.refine == "lk" and n:
        from robocal.rigs.flow.kernel_compiled import _lk_refine

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
