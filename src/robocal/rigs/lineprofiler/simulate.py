"""Simulated measurements with known ground truth for the line-profiler rig (seed 004).

* :func:`perturbed_chain` -- the "real" arm: the nominal D-H table plus
  manufacturing/assembly errors (what FPDP is sensitive to, seed §4.3).
* :func:`simulate_fpdp` -- a fixed precision sphere scanned from many arm
  poses; joint readings carry encoder/backlash noise.
* :func:`simulate_mct` -- the tracker ball on P3 traced along an R2 arc and a
  P3 stroke, the measured heights ``h0, h1``, the standard block probed by the
  tracker and scanned by the profiler during a P3 stroke.

Every function takes a :class:`numpy.random.Generator`; nothing else is random.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from robocal.errors import InputError, NotEnoughDataError
from robocal.geometry import apply_transform, transform_from
from robocal.kinematics import DHChain
from robocal.rigs.lineprofiler.model import Block, LineProfilerRig, Sphere

__all__ = ["FPDPData", "MCTData", "SimTruth", "perturbed_chain", "simulate_fpdp", "simulate_mct",
           "DEFAULT_Q0", "DEFAULT_SPREAD"]

#: The seed's Table 1 neighbourhood: d1 ~ 175 mm, theta2 ~ 0 deg, d3 ~ 90 mm.
DEFAULT_Q0 = np.array([0.175, 0.0, 0.090])
#: Half-widths of the pose sampling box (m, rad, m).
DEFAULT_SPREAD = np.array([0.006, np.deg2rad(14.0), 0.012])


@dataclass
class FPDPData:
    """Fixed-point data: joint readings ``q`` (N, dof) and one profile ``(x, z)`` (M_i, 2) per pose, in L."""

    q: np.ndarray
    profiles: list
    sphere_radius: float
    timestamps: np.ndarray | None = None


@dataclass
class MCTData:
    """Multi-coordinate-transformation data (seed 004 §3), tracker frame T, metres.

    Attributes
    ----------
    q_arc : (n, dof) joint values while R2 turns; ``arc_T`` (n, 3) ball centres.
    q_line : (k, dof) joint values while P3 slides; ``line_T`` (k, 3) ball centres.
    h0, h1 : measured heights of the ball centre and of frame 2's origin above P3's top face.
    q_scan0 : (dof,) pose at the start of the block scan (``q30`` is its P3 value).
    block_faces_T : list of three (m, 3) tracker points on the block's faces x_B=0, y_B=0, z_B=0.
    block_size : block edges (m).
    scan_q3 : (s,) P3 readings of the scan profiles; ``scan_profiles`` list of (M, 2) in L.
    """

    q_arc: np.ndarray
    arc_T: np.ndarray
    q_line: np.ndarray
    line_T: np.ndarray
    h0: float
    h1: float
    q_scan0: np.ndarray
    block_faces_T: list
    block_size: tuple
    scan_q3: np.ndarray
    scan_profiles: list


@dataclass
class SimTruth:
    """Ground truth of a simulation."""

    X: np.ndarray
    chain: DHChain
    sphere_centre: np.ndarray | None = None
    T_W_B: np.ndarray | None = None
    T_T_L: np.ndarray | None = None
    extra: dict = field(default_factory=dict)


def perturbed_chain(chain: DHChain, rng: np.random.Generator, *, sigma_length: float = 0.3e-3,
                    sigma_angle: float = np.deg2rad(0.1)) -> DHChain:
    """The nominal chain with Gaussian errors on every D-H length (m) and angle (rad)."""
    names = chain.param_names
    p = chain.params.copy()
    for k, name in enumerate(names):
        base = name.split("_")[0]
        if base in ("a", "d"):
            p[k] += rng.normal() * sigma_length
        elif base in ("alpha", "theta"):
            p[k] += rng.normal() * sigma_angle
    return chain.with_params(p)


def _check_rng(rng):
    if not isinstance(rng, np.random.Generator):
        raise InputError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")


def simulate_fpdp(rig: LineProfilerRig, rng: np.random.Generator, *, n_poses: int = 16, q0=None, spread=None,
                  true_chain: DHChain | None = None, sigma_q=None, sphere_offset=(0.0, 0.010, 0.26),
                  min_points: int = 30, noise: bool = True) -> tuple[FPDPData, SimTruth]:
    """Scan a fixed sphere from ``n_poses`` random poses (seed 004 §2, Fig. 2).

    The sphere sits at ``sphere_offset`` (x, y, z in L, m) from the laser at
    the nominal pose ``q0``; poses are drawn uniformly in ``q0 +/- spread``
    and kept when the profile holds at least ``min_points`` sphere points.

    Parameters
    ----------
    true_chain : DHChain, optional
        The real arm (default: ``rig.chain``, i.e. no kinematic error).
    sigma_q : array_like, shape (dof,), optional
        Encoder / backlash noise of the recorded joint values (m or rad).
    """
    _check_rng(rng)
    chain = rig.chain
    true_chain = true_chain or chain
    q0 = DEFAULT_Q0 if q0 is None else np.asarray(q0, float)
    spread = DEFAULT_SPREAD if spread is None else np.asarray(spread, float)
    if q0.shape != (chain.dof,) or spread.shape != (chain.dof,):
        raise InputError(f"q0 and spread must have shape ({chain.dof},), got {q0.shape} and {spread.shape}")
    centre = apply_transform(rig.T_W_L(q0, true_chain), np.asarray(sphere_offset, float))
    sphere = Sphere(centre, rig.sphere_radius)
    qs, profiles = [], []
    for _ in range(200 * n_poses):
        q = q0 + rng.uniform(-1, 1, chain.dof) * spread
        xz, _ = rig.profiler.measure(rig.T_W_L(q, true_chain), [sphere], rng, noise=noise)
        if len(xz) >= min_points:
            qs.append(q)
            profiles.append(xz)
            if len(qs) == n_poses:
                break
    if len(qs) < n_poses:
        raise NotEnoughDataError(f"only {len(qs)} of {n_poses} poses see the sphere: widen spread or move it")
    q = np.array(qs)
    if sigma_q is not None and noise:
        q = q + rng.normal(size=q.shape) * np.asarray(sigma_q, float)
    return (FPDPData(q, profiles, rig.sphere_radius),
            SimTruth(X=rig.X.copy(), chain=true_chain, sphere_centre=centre))


def _align(a, b):
    """Rotation taking unit vector a to unit vector b."""
    return Rotation.align_vectors([b], [a])[0].as_matrix()


def simulate_mct(rig: LineProfilerRig, rng: np.random.Generator, *, q0=None, true_chain: DHChain | None = None,
                 arc_deg: float = 60.0, n_arc: int = 9, stroke: float = 0.08, n_line: int = 9,
                 sigma_h: float = 0.02e-3, scan_half: float = 0.015, n_scan: int = 31, n_face: int = 20,
                 block_distance: float = 0.27, sigma_q3: float = 0.0,
                 noise: bool = True) -> tuple[MCTData, SimTruth]:
    """Simulate the MCT procedure (seed 004 §3, steps 1-5; Figs. 3-4).

    Only R2 and P3 move; P1 stays at ``q0[0]``. The block is placed with its
    corner ``block_distance`` in front of the laser and its body diagonal
    pointing back at it, so all three corner faces are lit.

    ``sigma_q3`` (m): P3 encoder read-out noise, added to the recorded P3
    values of the tracker line and of every scan profile (the profiles are
    taken at the true positions); default 0, exact readings. It is drawn
    after every other random number, so the rest of the data does not
    depend on it. ``q_scan0`` is the exact reference value ``q0``.
    """
    _check_rng(rng)
    chain = rig.chain
    true_chain = true_chain or chain
    if not (np.isfinite(sigma_q3) and sigma_q3 >= 0):
        raise InputError(f"sigma_q3 must be finite and >= 0 (m), got {sigma_q3!r}")
    if chain.dof != 3:
        raise InputError(f"MCT needs the last two joints to be R2 and P3 of a 3-joint chain, got dof {chain.dof}")
    q0 = DEFAULT_Q0 if q0 is None else np.asarray(q0, float)
    r = rng if noise else None
    # 1. R2 arc
    q_arc = np.tile(q0, (n_arc, 1))
    q_arc[:, 1] = q0[1] + np.deg2rad(np.linspace(-arc_deg / 2, arc_deg / 2, n_arc))
    arc_T = rig.tracker.measure(apply_transform(true_chain.fk(q_arc), rig.ball_E), r)
    # 2. P3 stroke
    q_line = np.tile(q0, (n_line, 1))
    q_line[:, 2] = q0[2] + np.linspace(-stroke / 2, stroke / 2, n_line)
    line_T = rig.tracker.measure(apply_transform(true_chain.fk(q_line), rig.ball_E), r)
    # 3. heights: ball centre and frame-2 origin above P3's top face (along z_2)
    T_2_E = np.linalg.inv(true_chain.fk_all(q0)[2]) @ true_chain.fk(q0)
    ball_z2 = apply_transform(T_2_E, rig.ball_E)[2]
    h0_true = rig.h0
    h1_true = h0_true - ball_z2
    h0 = h0_true + (rng.normal() * sigma_h if noise else 0.0)
    h1 = h1_true + (rng.normal() * sigma_h if noise else 0.0)
    # 4-5. block fixed in front of the laser, probed by the tracker, scanned during a P3 stroke
    T_W_L0 = rig.T_W_L(q0, true_chain)
    R_L_B = _align(np.ones(3) / np.sqrt(3), np.array([0.0, 0.0, -1.0])) @ Rotation.from_rotvec(
        [0, 0, 0.3]).as_matrix()
    T_W_B = T_W_L0 @ transform_from(R_L_B, [0.0, 0.0, block_distance])
    block = Block(T_W_B, rig.block_size)
    faces = []
    for k in range(3):
        p_B = -rng.uniform(0.05, 0.8, (n_face, 3)) * np.array(rig.block_size)
        p_B[:, k] = 0.0
        faces.append(rig.tracker.measure(apply_transform(T_W_B, p_B), r))
    scan_q3 = q0[2] + np.linspace(-scan_half, scan_half, n_scan)
    profiles = []
    for q3 in scan_q3:
        q = q0.copy()
        q[2] = q3
        xz, _ = rig.profiler.measure(rig.T_W_L(q, true_chain), [block], rng, noise=noise)
        profiles.append(xz)
    T_T_L = np.linalg.inv(rig.tracker.T_W_T) @ T_W_L0
    if noise and sigma_q3 > 0:
        q_line[:, 2] += rng.normal(size=n_line) * sigma_q3
        scan_q3 = scan_q3 + rng.normal(size=n_scan) * sigma_q3
    data = MCTData(q_arc, arc_T, q_line, line_T, float(h0), float(h1), q0.copy(), faces, tuple(rig.block_size),
                   scan_q3, profiles)
    return data, SimTruth(X=rig.X.copy(), chain=true_chain, T_W_B=T_W_B, T_T_L=T_T_L,
                          extra={"h0": h0_true, "h1": h1_true})
