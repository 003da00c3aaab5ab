"""Arm, line-laser profiler, targets and laser tracker of the line-profiler rig (seed 004).

Frames (``T_a_b`` maps b into a): ``W`` world/base of the arm, ``E`` the last
link (end of joint P3), ``L`` the laser (profiler) frame whose measuring plane
is ``x_L - z_L`` (``z_L`` along the laser's depth axis), ``T`` the laser
tracker, ``B`` the standard block. The hand-eye matrix is ``X = T_E_L`` and a
profile point ``m = (x, 0, z)`` maps to the world as ``T_W_E(q) X m`` (seed
eq. 2). Units: metres and radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.errors import InputError
from robocal.geometry import apply_transform, invert_transform, matrix_from_rotvec, transform_from
from robocal.kinematics import DHChain, DHLink
from robocal.validation import check_array, check_positive, check_transform

__all__ = [
    "p1r2p3_chain",
    "default_hand_eye",
    "Sphere",
    "Block",
    "ProfilerModel",
    "LaserTracker",
    "LineProfilerRig",
    "default_rig",
]


def p1r2p3_chain(a2: float = 0.10, *, convention: str = "modified") -> DHChain:
    """The seed's P1R2P3 welding arm as a modified D-H chain.

    P1 lifts along the base z axis, R2 turns about the same (vertical) axis,
    P3 slides horizontally (``alpha_2 = -90 deg``, ``a_2`` out from the
    axis). Frame E = frame 3: ``x_E`` radial, ``y_E`` down (``-z_2``),
    ``z_E`` along P3. Every end-effector rotation is about the vertical, so
    fixed-point calibration (FPDP) cannot determine ``X``'s translation along
    ``y_E`` (seed §4.3: "p_y = 0").
    """
    return DHChain(
        [
            DHLink(0.0, 0.0, 0.0, 0.0, joint="prismatic", name="P1", limits=(0.0, 0.5)),
            DHLink(0.0, 0.0, 0.0, 0.0, joint="revolute", name="R2", limits=(-np.pi, np.pi)),
            DHLink(-np.pi / 2, a2, 0.0, 0.0, joint="prismatic", name="P3", limits=(0.0, 0.3)),
        ],
        convention=convention,
    )


def default_hand_eye() -> np.ndarray:
    """A realistic ``X = T_E_L``: laser looking down (``z_L = y_E``), scanning along P3 (``y_L = -z_E``),
    mounted a few degrees off and some centimetres from frame E."""
    R0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    R = matrix_from_rotvec(np.deg2rad([1.5, -2.0, 3.0])) @ R0
    return transform_from(R, [0.035, 0.060, 0.120])


# ----------------------------------------------------------------------------- targets
@dataclass(frozen=True)
class Sphere:
    """Precision sphere: ``centre`` (3,) in the world frame W, ``radius`` (m)."""

    centre: np.ndarray
    radius: float

    def __post_init__(self):
        object.__setattr__(self, "centre", check_array(self.centre, "Sphere.centre", shape=(3,)))
        object.__setattr__(self, "radius", float(check_positive(self.radius, "Sphere.radius")))

    def ray_hit(self, origins, dirs) -> np.ndarray:
        """Distance along unit rays to the first hit (inf where missed), shape (...,)."""
        oc = np.asarray(origins) - self.centre
        b = np.sum(oc * dirs, axis=-1)
        c = np.sum(oc * oc, axis=-1) - self.radius**2
        disc = b * b - c
        t = -b - np.sqrt(np.maximum(disc, 0.0))
        return np.where((disc >= 0) & (t > 0), t, np.inf)

    def normal(self, p) -> np.ndarray:
        v = np.asarray(p) - self.centre
        return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass(frozen=True)
class Block:
    """Standard block (cuboid): occupies ``[-a, 0] x [-b, 0] x [-c, 0]`` in its frame B.

    The corner at B's origin joins the three faces ``x_B = 0``, ``y_B = 0``,
    ``z_B = 0`` (outward normals ``+x, +y, +z``), which the profiler scans and
    the tracker probes (seed 004 §3, step 4). ``T_W_B`` places it in the world.
    """

    T_W_B: np.ndarray
    size: tuple = (0.05, 0.05, 0.05)

    def __post_init__(self):
        object.__setattr__(self, "T_W_B", check_transform(self.T_W_B, "Block.T_W_B"))
        object.__setattr__(self, "size", tuple(float(s) for s in check_positive(self.size, "Block.size")))

    def ray_hit(self, origins, dirs) -> np.ndarray:
        T_B_W = invert_transform(self.T_W_B)
        o = apply_transform(T_B_W, origins)
        d = np.einsum("ij,...j->...i", T_B_W[:3, :3], dirs)
        lo = -np.array(self.size)
        hi = np.zeros(3)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (lo - o) / d
            t2 = (hi - o) / d
        tmin = np.nanmax(np.minimum(t1, t2), axis=-1)
        tmax = np.nanmin(np.maximum(t1, t2), axis=-1)
        return np.where((tmax >= tmin) & (tmin > 0), tmin, np.inf)

    def face_of(self, p_W) -> np.ndarray:
        """Index (0, 1, 2) of the corner face a world point lies on (-1 for the other faces)."""
        p = apply_transform(invert_transform(self.T_W_B), p_W)
        k = np.argmin(np.abs(p), axis=-1)
        on = np.abs(np.take_along_axis(p, k[..., None], -1)[..., 0]) < 1e-9
        return np.where(on, k, -1)


# ----------------------------------------------------------------------------- profiler
@dataclass(frozen=True)
class ProfilerModel:
    """Line-laser profiler (laser triangulation) measuring in its ``x_L - z_L`` plane.

    Rays leave the laser origin in the plane at angles ``phi`` in
    ``[-fov/2, fov/2]`` from ``z_L`` (``n_points`` of them); a point is kept
    when its depth ``z`` lies in ``z_range``, the camera (at ``(baseline, 0,
    0)`` in L) sees it (no other surface between), and it survives the random
    ``dropout``. Gaussian noise ``sigma_x``, ``sigma_z`` is added.

    Defaults follow the seed's LMI Gocator 2340: 1280 points per profile,
    0.037 mm accuracy; its clearance distance of 190 mm and measurement range
    of 210 mm (the seed prints "190~210 mm") give ``z`` in 0.19-0.40 m; field of
    view 96-194 mm, i.e. about 28 deg.
    """

    n_points: int = 1280
    fov: float = np.deg2rad(28.0)
    z_range: tuple = (0.190, 0.400)
    sigma_x: float = 0.037e-3
    sigma_z: float = 0.037e-3
    dropout: float = 0.02
    baseline: float = 0.08

    def __post_init__(self):
        if int(self.n_points) < 3:
            raise InputError(f"ProfilerModel.n_points must be >= 3, got {self.n_points}")
        check_positive([self.fov, *self.z_range], "ProfilerModel fov/z_range")
        if not self.z_range[0] < self.z_range[1]:
            raise InputError(f"ProfilerModel.z_range must be increasing, got {self.z_range}")
        if not 0 <= self.dropout < 1:
            raise InputError(f"ProfilerModel.dropout must be in [0, 1), got {self.dropout}")

    def measure(self, T_W_L, targets, rng: np.random.Generator | None = None, *, noise: bool = True):
        """One profile: points ``(x, z)`` (M, 2) in L, and the index of the target each hit.

        Parameters
        ----------
        T_W_L : array_like, shape (4, 4)
            Laser pose in the world.
        targets : sequence of Sphere or Block
        rng : numpy.random.Generator, optional
            Needed for noise and dropout.
        """
        T_W_L = np.asarray(T_W_L, float)
        phi = np.linspace(-self.fov / 2, self.fov / 2, int(self.n_points))
        d_L = np.column_stack([np.sin(phi), np.zeros_like(phi), np.cos(phi)])
        o_W = np.broadcast_to(T_W_L[:3, 3], d_L.shape)
        d_W = d_L @ T_W_L[:3, :3].T
        dist = np.stack([t.ray_hit(o_W, d_W) for t in targets])
        which = np.argmin(dist, axis=0)
        t = dist[which, np.arange(len(phi))]
        hit = np.isfinite(t)
        p_L = d_L * np.where(hit, t, 0.0)[:, None]
        keep = hit & (p_L[:, 2] >= self.z_range[0]) & (p_L[:, 2] <= self.z_range[1])
        # camera-side occlusion: something between the lit point and the camera
        cam_L = np.array([self.baseline, 0.0, 0.0])
        v = cam_L - p_L
        L = np.linalg.norm(v, axis=1)
        u_W = (v / np.maximum(L, 1e-300)[:, None]) @ T_W_L[:3, :3].T
        start_W = apply_transform(T_W_L, p_L) + 1e-7 * u_W
        blocked = np.min(np.stack([tg.ray_hit(start_W, u_W) for tg in targets]), axis=0) < L - 1e-6
        keep &= ~blocked
        if noise and rng is not None and self.dropout > 0:
            keep &= rng.random(len(phi)) >= self.dropout
        xz = p_L[keep][:, [0, 2]]
        if noise and rng is not None:
            xz = xz + rng.normal(size=xz.shape) * np.array([self.sigma_x, self.sigma_z])
        return xz, which[keep]


@dataclass(frozen=True)
class LaserTracker:
    """Laser tracker at ``T_W_T`` measuring target-ball centres with isotropic noise ``sigma`` (m)."""

    T_W_T: np.ndarray = field(default_factory=lambda: transform_from(matrix_from_rotvec([0.0, 0.0, 0.7]),
                                                                     [2.0, -1.0, 0.1]))
    sigma: float = 10e-6

    def measure(self, p_W, rng: np.random.Generator | None = None) -> np.ndarray:
        """Points (..., 3) in the world -> tracker frame, with noise when ``rng`` is given."""
        p_T = apply_transform(invert_transform(self.T_W_T), p_W)
        if rng is not None and self.sigma > 0:
            p_T = p_T + rng.normal(size=p_T.shape) * self.sigma
        return p_T


# ----------------------------------------------------------------------------- rig
@dataclass(frozen=True)
class LineProfilerRig:
    """Everything a simulation needs.

    Attributes
    ----------
    chain : DHChain
        Nominal arm model (what calibration uses).
    X : ndarray (4, 4)
        True ``T_E_L``.
    profiler : ProfilerModel
    sphere_radius : float
        Radius of the precision sphere (m).
    ball_E : ndarray (3,)
        Tracker target-ball centre on joint P3, in frame E (MCT).
    h0 : float
        Height of the ball centre above P3's top face (m, along ``z_2``).
    tracker : LaserTracker
    block_size : tuple
        Standard block edges (m).
    """

    chain: DHChain = field(default_factory=p1r2p3_chain)
    X: np.ndarray = field(default_factory=default_hand_eye)
    profiler: ProfilerModel = field(default_factory=ProfilerModel)
    sphere_radius: float = 0.0254
    ball_E: np.ndarray = field(default_factory=lambda: np.array([0.02, -0.04, 0.03]))
    h0: float = 0.025
    tracker: LaserTracker = field(default_factory=LaserTracker)
    block_size: tuple = (0.06, 0.06, 0.06)

    def __post_init__(self):
        object.__setattr__(self, "X", check_transform(self.X, "X"))
        object.__setattr__(self, "ball_E", check_array(self.ball_E, "ball_E", shape=(3,)))

    def T_W_L(self, q, chain: DHChain | None = None) -> np.ndarray:
        """Laser pose(s) ``T_W_E(q) X`` (..., 4, 4)."""
        return (chain or self.chain).fk(q) @ self.X


def default_rig() -> LineProfilerRig:
    """The seed-like rig: P1R2P3 arm, Gocator-class profiler, 50.8 mm sphere, tracker at 2 m."""
    return LineProfilerRig()
