"""The block matcher's configuration: :class:`FlowConfig` (defaults: the PX4FLOW firmware),
the block grid and the flow error per sub-pixel mode (Li, Guan and Chu 2017, §1).

Kept apart from the compiled kernels (:mod:`.kernel_compiled`) so that a
configuration can be built, checked and shown without importing numba.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from robocal.errors import InputError

__all__ = ["FlowConfig", "block_origins", "SUBPIXEL_MODES", "AGGREGATE_MODES", "SIGMA_PX"]

SUBPIXEL_MODES = ("none", "half", "quarter", "parabolic", "equiangular")
AGGREGATE_MODES = ("mean", "median", "trimmed", "tensor")

#: Per-frame flow error (RMS per axis, px) with all 25 blocks in use, by sub-pixel mode, and
#: with ``refine="lk"``: measured on shifted real photographs (gravel, 2x2 binning,
#: ``test_flow_rmse_on_real_photographs_vs_opencv -s``, docs/rigs/flow.md). The fusion's
#: weights, covariance and outlier test scale with it (:attr:`FlowConfig.sigma_px`).
SIGMA_PX = {"none": 0.32, "half": 0.16, "quarter": 0.075, "parabolic": 0.12, "equiangular": 0.06, "lk": 0.03}


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

