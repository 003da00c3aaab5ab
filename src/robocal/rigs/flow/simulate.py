"""Simulated robot runs: real-photo ground, downward sensor cameras, gyro, height, wheels.

The ground is a real photograph (scikit-image's ``gravel``, ``grass``,
``brick``, ``moon``; they ship inside its wheel and load offline) tiled by
mirroring over the floor. Each sensor's frames are rendered by casting every
pixel's ray (with ``supersample x supersample`` sub-rays, the binning's area
average) onto the ground plane from the camera's exact pose — robot pose,
mounting, chassis roll/pitch — and sampling the photograph bilinearly. So the
flow kernel sees sub-pixel motion, rotation, perspective from tilt, sensor
noise and texture gaps exactly as a real sensor would.

Without scikit-image (it is a test extra, not a dependency) a procedural
texture (band-limited noise) stands in and ``load_texture`` says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from robocal.errors import InputError
from robocal.rigs.flow.kernel import FlowConfig, speed_limit
from robocal.rigs.flow.kernel_compiled import CACHE
from robocal.rigs.flow.model import SensorArray, integrate_twists, rot2, seed_array

__all__ = [
    "TEXTURES",
    "load_texture",
    "SensorCamera",
    "SimConfig",
    "SimRun",
    "make_trajectory",
    "simulate_run",
    "shifted_pairs",
    "render_frames",
]

TEXTURES = ("gravel", "grass", "brick", "moon")


def load_texture(name: str = "gravel", *, rng: np.random.Generator | None = None):
    """A greyscale ground photograph as float32 ``(512, 512)`` plus a note.

    Parameters
    ----------
    name : {"gravel", "grass", "brick", "moon", "procedural"}
        gravel/grass: good floors; brick: a repeating pattern (aliasing test);
        moon: a low-texture test.

    Returns
    -------
    image : ndarray of float32, shape (H, W)
    note : str
        Where the texture came from (the fallback says so plainly).
    """
    if name not in TEXTURES + ("procedural",):
        raise InputError(f"texture must be one of {TEXTURES + ('procedural',)}, got {name!r}")
    if name != "procedural":
        try:
            import skimage.data as skd
        except ImportError:
            pass
        else:
            return getattr(skd, name)().astype(np.float32), f"scikit-image photograph '{name}'"
    g = np.random.default_rng(12345) if rng is None else rng
    # band-limited noise with a 1/f-like spectrum: a stand-in, not a photograph
    spec = np.fft.rfft2(g.normal(size=(512, 512)))
    fy = np.fft.fftfreq(512)[:, None]
    fx = np.fft.rfftfreq(512)[None, :]
    f = np.sqrt(fx**2 + fy**2)
    img = np.fft.irfft2(spec / np.maximum(f, 1 / 256) * np.exp(-((f / 0.25) ** 2)), s=(512, 512))
    img = (img - img.mean()) / img.std() * 38.0 + 128.0
    if name == "procedural":
        note = "procedural texture (band-limited noise), as requested: not a photograph"
    else:
        note = (f"photograph '{name}' unavailable (scikit-image is not installed): procedural texture "
                "(band-limited noise) instead, not a photograph")
    return np.clip(img, 0, 255).astype(np.float32), note


@dataclass(frozen=True)
class SensorCamera:
    """The sensor's camera (defaults: PX4FLOW's MT9V034 with 4x4 binning, a short lens for a ground robot).

    Attributes
    ----------
    lens_focal : float
        Lens focal length, m (PX4FLOW ships 16 mm; a ground robot at 10 cm needs a short one).
    pixel_size : float
        Native pixel pitch, m (MT9V034: 6 um).
    binning : int
        Pixels binned per side (PX4FLOW: 4 -> 24 um super-pixels).
    window : int
        Frame side, binned pixels (64).
    rate : float
        Frame rate, Hz (PX4FLOW: about 400).
    noise : float
        Read noise per binned pixel, grey levels (std).
    """

    lens_focal: float = 4.0e-3
    pixel_size: float = 6.0e-6
    binning: int = 4
    window: int = 64
    rate: float = 400.0
    noise: float = 1.5

    @property
    def focal_px(self) -> float:
        """Focal length in binned pixels (16 mm / 24 um = 666.7 px)."""
        return self.lens_focal / (self.pixel_size * self.binning)


@dataclass
class SimConfig:
    """Everything a simulated run depends on (SI units).

    ``array_true`` is where the sensors really are; ``array_nominal`` what the
    drawings say (the calibration's starting point and what an uncalibrated
    odometry uses).
    """

    camera: SensorCamera = field(default_factory=SensorCamera)
    array_true: SensorArray = field(default_factory=seed_array)
    array_nominal: SensorArray = field(default_factory=seed_array)
    height: float = 0.10            # lens above the ground, m
    texture: str = "gravel"
    texture_pixel: float | None = None  # ground size of one photo pixel, m (default: GSD / supersample)
    supersample: int = 2
    duration: float = 8.0
    trajectory: str = "loop"       # "loop" | "calibration" | "straight"
    speed: float = 0.4              # m/s, typical
    yaw_rate: float = 0.6           # rad/s, typical
    rock_amplitude: float = np.radians(0.5)  # chassis roll/pitch, rad
    rock_frequency: float = 3.0     # Hz
    rock_pivot_height: float | None = None  # m above the ground; None: at the lenses (pure camera rotation)
    gyro_noise: float = 0.005       # rad/s per sample (std)
    gyro_bias: float = 0.003        # rad/s (std of a constant per-axis bias)
    height_noise: float = 0.002     # m (std per frame)
    height_scale: tuple | None = None  # per-sensor factor of the measured height (a sonar's scale error); None: 1
    gaps: tuple = ()                # ((x, y, radius), ...) low-texture patches on the floor, m
    gap_contrast: float = 0.03
    wheel_track: float = 0.40       # m
    wheel_slip: float = 0.03        # relative std of each wheel's speed error
    wheel_scale_error: float = 0.01  # relative radius error (left/right differ by this)
    slip_events: tuple = ((2.0, 3.0, 0.25),)  # (t0, t1, extra slip of the left wheel)


@dataclass
class SimRun:
    """A simulated run.

    Attributes
    ----------
    t : ndarray, shape (K+1,)
        Frame times, s.
    poses : ndarray, shape (K+1, 3)
        True robot poses ``(X, Y, theta)``.
    frames : ndarray of uint8, shape (n, K+1, W, W) or None
    gyro : ndarray, shape (n, K, 3)
        Mean measured rate over each interval, camera frame, rad/s.
    height : ndarray, shape (n, K)
        Measured distance to the ground per interval, m.
    wheel_poses : ndarray, shape (K+1, 3)
        Wheel-odometry dead reckoning (with slip).
    config : SimConfig
    texture_note : str
    true_height : ndarray, shape (n, K)
    """

    t: np.ndarray
    poses: np.ndarray
    frames: np.ndarray | None
    gyro: np.ndarray
    height: np.ndarray
    wheel_poses: np.ndarray
    config: SimConfig
    texture_note: str
    true_height: np.ndarray


def make_trajectory(kind: str, duration: float, rate: float, *, speed: float = 0.4, yaw_rate: float = 0.6,
                    rng: np.random.Generator):
    """Body twists of a drive, sampled at the frame rate.

    ``"loop"``: smooth random curves (forward speed and yaw rate from a few
    sinusoids); ``"calibration"``: straight lines, turns on the spot and arcs
    (rich in both translation and rotation); ``"straight"``: constant speed.

    Returns
    -------
    t : ndarray, shape (K+1,)
    v : ndarray, shape (K,)   forward speed, m/s
    w : ndarray, shape (K,)   yaw rate, rad/s
    """
    k = int(round(duration * rate))
    if k < 2:
        raise InputError(f"duration {duration} s at {rate} Hz gives fewer than 2 frames")
    t = np.arange(k + 1) / rate
    tm = (t[:-1] + t[1:]) / 2
    if kind == "loop":
        ph = rng.uniform(0, 2 * np.pi, 4)
        v = speed * (0.75 + 0.25 * np.sin(2 * np.pi * 0.11 * tm + ph[0]) + 0.1 * np.sin(2 * np.pi * 0.37 * tm + ph[1]))
        w = yaw_rate * (0.8 * np.sin(2 * np.pi * 0.07 * tm + ph[2]) + 0.4 * np.sin(2 * np.pi * 0.23 * tm + ph[3]))
    elif kind == "calibration":
        seg = (tm // 1.0).astype(int) % 4
        v = np.select([seg == 0, seg == 1, seg == 2, seg == 3], [speed, 0.0, 0.6 * speed, 0.0])
        w = np.select([seg == 0, seg == 1, seg == 2, seg == 3], [0.0, 1.5 * yaw_rate, yaw_rate, -1.5 * yaw_rate])
        # soften the steps so the robot's acceleration stays finite
        ker = np.hanning(max(3, int(0.1 * rate)))
        ker /= ker.sum()
        v = np.convolve(v, ker, mode="same")
        w = np.convolve(w, ker, mode="same")
    elif kind == "straight":
        v = np.full(k, speed)
        w = np.zeros(k)
    else:
        raise InputError(f"trajectory must be 'loop', 'calibration' or 'straight', got {kind!r}")
    return t, v, w


@njit(cache=CACHE, nogil=True, fastmath=True)
def _render(tex, tex_px, centres, R_wc, f_px, window, ss, gaps, gap_contrast, tex_mean, out):  # pragma: no cover
    """Ray-cast every (sub-)pixel onto the ground z = 0 and sample the mirrored photograph."""
    ht = tex.shape[0]
    wt = tex.shape[1]
    py = 2.0 * (ht - 1)
    px = 2.0 * (wt - 1)
    c = (window - 1) / 2.0
    ng = gaps.shape[0]
    for fidx in range(centres.shape[0]):
        C = centres[fidx]
        R = R_wc[fidx]
        for v in range(window):
            for u in range(window):
                acc = 0.0
                for sb in range(ss):
                    for sa in range(ss):
                        xc = u - 0.5 + (sa + 0.5) / ss - c
                        yc = v - 0.5 + (sb + 0.5) / ss - c
                        dx = R[0, 0] * xc + R[0, 1] * yc + R[0, 2] * f_px
                        dy = R[1, 0] * xc + R[1, 1] * yc + R[1, 2] * f_px
                        dz = R[2, 0] * xc + R[2, 1] * yc + R[2, 2] * f_px
                        tt = -C[2] / dz
                        X = C[0] + tt * dx
                        Y = C[1] + tt * dy
                        # photo column along world X, row along -Y; mirror-tiled
                        tx = X / tex_px
                        ty = -Y / tex_px
                        tx -= px * math.floor(tx / px)
                        ty -= py * math.floor(ty / py)
                        if tx > wt - 1:
                            tx = px - tx
                        if ty > ht - 1:
                            ty = py - ty
                        ix = min(int(tx), wt - 2)
                        iy = min(int(ty), ht - 2)
                        a = tx - ix
                        b = ty - iy
                        # eq. 2 of Li, Guan and Chu (2017) is this same bilinear form
                        g = (tex[iy, ix] * (1 - a) * (1 - b) + tex[iy, ix + 1] * a * (1 - b)
                             + tex[iy + 1, ix] * (1 - a) * b + tex[iy + 1, ix + 1] * a * b)
                        for gi in range(ng):
                            if (X - gaps[gi, 0]) ** 2 + (Y - gaps[gi, 1]) ** 2 < gaps[gi, 2] ** 2:
                                g = tex_mean + (g - tex_mean) * gap_contrast
                                break
                        acc += g
                out[fidx, v, u] = acc / (ss * ss)


def _camera_poses(poses, roll, pitch, array: SensorArray, heights, pivot_height):
    """Camera centres (F, 3) and R_world_cam (F, 3, 3) of each sensor at each pose.

    The chassis rocks (roll, pitch) about a point ``pivot_height`` above the
    robot origin.
    """
    th = poses[:, 2]
    cz, sz = np.cos(th), np.sin(th)
    cy, sy = np.cos(pitch), np.sin(pitch)
    cx, sx = np.cos(roll), np.sin(roll)
    Rz = np.zeros((len(th), 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = cz, -sz, sz, cz, 1
    Ry = np.zeros_like(Rz)
    Ry[:, 0, 0], Ry[:, 0, 2], Ry[:, 2, 0], Ry[:, 2, 2], Ry[:, 1, 1] = cy, sy, -sy, cy, 1
    Rx = np.zeros_like(Rz)
    Rx[:, 1, 1], Rx[:, 1, 2], Rx[:, 2, 1], Rx[:, 2, 2], Rx[:, 0, 0] = cx, -sx, sx, cx, 1
    R_wr = Rz @ Ry @ Rx
    out = []
    for i in range(array.n):
        p_r = np.array([array.R[i] * np.cos(array.psi[i]), array.R[i] * np.sin(array.psi[i]), heights[i]])
        # camera x = sensor x_S, camera y = -y_S (image down), optical axis down
        R_rc = np.eye(3)
        R_rc[:2, :2] = rot2(array.phi[i])
        R_rc = R_rc @ np.diag([1.0, -1.0, -1.0])
        q = np.array([0.0, 0.0, pivot_height])
        C = np.concatenate([poses[:, :2], np.zeros((len(th), 1))], 1) + Rz @ q + R_wr @ (p_r - q)
        out.append((C, R_wr @ R_rc))
    return out


def render_frames(texture, tex_px, centres, R_world_cam, camera: SensorCamera, *, supersample=2, gaps=(),
                  gap_contrast=0.03, rng=None):
    """Render ``uint8`` frames ``(F, W, W)`` of cameras at the given poses (noise from ``rng``)."""
    tex = np.ascontiguousarray(texture, np.float32)
    out = np.empty((len(centres), camera.window, camera.window), np.float64)
    g = np.asarray(gaps, float).reshape(-1, 3)
    _render(tex, float(tex_px), np.ascontiguousarray(centres, float), np.ascontiguousarray(R_world_cam, float),
            float(camera.focal_px), camera.window, int(supersample), g, float(gap_contrast), float(tex.mean()), out)
    if rng is not None and camera.noise > 0:
        out += rng.normal(0.0, camera.noise, out.shape)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def _rotvec(Ra, Rb):
    """Rotation vector of ``Ra^T Rb`` (F, 3): the body-frame rotation from a to b."""
    from robocal.geometry import rotvec_from_matrix

    return rotvec_from_matrix(np.swapaxes(Ra, -1, -2) @ Rb)


def simulate_run(config: SimConfig, rng: np.random.Generator, *, render: bool = True) -> SimRun:
    """Simulate one drive: true poses, every sensor's frames, gyro, heights, wheel odometry.

    Parameters
    ----------
    config : SimConfig
    rng : numpy.random.Generator
        The only source of randomness.
    render : bool
        Render frames (False: only the motion and the auxiliary sensors).
    """
    cam = config.camera
    t, v, w = make_trajectory(config.trajectory, config.duration, cam.rate, speed=config.speed,
                              yaw_rate=config.yaw_rate, rng=rng)
    dt = 1.0 / cam.rate
    twists = np.stack([v * dt, np.zeros_like(v), w * dt], 1)
    poses = integrate_twists(twists)
    n = config.array_true.n
    rph = rng.uniform(0, 2 * np.pi, 2)
    roll = config.rock_amplitude * np.sin(2 * np.pi * config.rock_frequency * t + rph[0])
    pitch = config.rock_amplitude * np.sin(2 * np.pi * config.rock_frequency * 1.3 * t + rph[1])
    # a fixed per-sensor height-scale error (a sonar's calibration): what 'scale' calibrates
    h_err = np.ones(n) if config.height_scale is None else np.asarray(config.height_scale, float)
    if h_err.shape != (n,) or np.any(h_err <= 0):
        raise InputError(f"height_scale must be {n} positive factors, got {config.height_scale}")
    heights = np.full(n, config.height)
    pivot = config.height if config.rock_pivot_height is None else config.rock_pivot_height
    cams = _camera_poses(poses, roll, pitch, config.array_true, heights, pivot)
    tex, note = load_texture(config.texture)
    gsd = config.height / cam.focal_px
    tex_px = config.texture_pixel or gsd / config.supersample
    frames = None
    if render:
        frames = np.empty((n, len(t), cam.window, cam.window), np.uint8)
        for i, (C, R) in enumerate(cams):
            frames[i] = render_frames(tex, tex_px, C, R, cam, supersample=config.supersample, gaps=config.gaps,
                                      gap_contrast=config.gap_contrast, rng=rng)
    gyro = np.empty((n, len(t) - 1, 3))
    true_h = np.empty((n, len(t) - 1))
    for i, (C, R) in enumerate(cams):
        gyro[i] = _rotvec(R[:-1], R[1:]) / dt
        gyro[i] += config.gyro_bias * rng.normal(size=3) + config.gyro_noise * rng.normal(size=gyro[i].shape)
        # range along the optical axis to the ground
        dist = -C[:, 2] / R[:, 2, 2]
        true_h[i] = 0.5 * (dist[:-1] + dist[1:])
    meas_h = true_h * h_err[:, None] + config.height_noise * rng.normal(size=true_h.shape)
    # wheel odometry: differential drive with slip and a wheel-radius mismatch
    b = config.wheel_track
    vl = v - w * b / 2
    vr = v + w * b / 2
    tm = (t[:-1] + t[1:]) / 2
    slip_l = config.wheel_slip * rng.normal(size=vl.shape)
    slip_r = config.wheel_slip * rng.normal(size=vr.shape)
    for t0, t1, extra in config.slip_events:
        slip_l = slip_l + np.where((tm >= t0) & (tm < t1), extra, 0.0)
    vl_m = vl * (1 + slip_l) * (1 + config.wheel_scale_error / 2)
    vr_m = vr * (1 + slip_r) * (1 - config.wheel_scale_error / 2)
    tw = np.stack([(vl_m + vr_m) / 2 * dt, np.zeros_like(v), (vr_m - vl_m) / b * dt], 1)
    wheel = integrate_twists(tw)
    return SimRun(t=t, poses=poses, frames=frames, gyro=gyro, height=meas_h, wheel_poses=wheel, config=config,
                  texture_note=note, true_height=true_h)


def max_speed(config: SimConfig, flow: FlowConfig = FlowConfig()) -> float:
    """The sensors' speed ceiling for this configuration, m/s (see :func:`~robocal.rigs.flow.kernel.speed_limit`)."""
    return speed_limit(flow, config.height, config.camera.rate, config.camera.focal_px)


def shifted_pairs(texture, n: int, rng: np.random.Generator, *, binning: int = 4, window: int = 64,
                  max_shift: float = 3.0, noise: float = 1.5):
    """Frame pairs cut from a photograph and shifted by known sub-pixel amounts.

    Each frame pixel is the mean of ``binning x binning`` photo pixels (the
    sensor's binning); the second frame samples the photo shifted by
    ``s * binning`` photo pixels with bilinear interpolation *before* binning,
    so the shift is exact to far below the flow accuracy.

    Returns
    -------
    prev, curr : ndarray of uint8, shape (n, window, window)
    shift : ndarray, shape (n, 2)
        True flow ``(du, dv)``, px.
    """
    import cv2

    img = np.asarray(texture, np.float32)
    side = window * binning
    H, W = img.shape
    if H < side + 2 * (max_shift + 2) * binning or W < side + 2 * (max_shift + 2) * binning:
        raise InputError(f"texture {img.shape} too small for {window}px frames binned {binning}x")
    prev = np.empty((n, window, window), np.uint8)
    curr = np.empty_like(prev)
    shift = rng.uniform(-max_shift, max_shift, (n, 2))
    lo = (max_shift + 1) * binning
    for k in range(n):
        x0 = rng.uniform(lo, W - side - lo)
        y0 = rng.uniform(lo, H - side - lo)
        for out, (ox, oy) in ((prev, (x0, y0)), (curr, (x0 - shift[k, 0] * binning, y0 - shift[k, 1] * binning))):
            M = np.float32([[1, 0, ox], [0, 1, oy]])
            big = cv2.warpAffine(img, M, (side, side), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
            fr = big.reshape(window, binning, window, binning).mean(axis=(1, 3)) + rng.normal(0, noise, (window, window))
            out[k] = np.clip(np.rint(fr), 0, 255)
    return prev, curr, shift
