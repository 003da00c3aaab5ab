"""Simulated leg-calibration runs with known ground truth (docs/rigs/humanoid.md, "Beyond the seed").

* :func:`draw_truth` -- true offsets at a realistic scale (~0.5 deg joints and
  camera, ~0.5 deg / 1 mm board mounting);
* :func:`sample_poses` -- leg poses within the joint limits with the viewed
  board fully inside the image, its printed face toward the camera and the
  feet clear of each other;
* :func:`simulate_dataset` -- joint sensor readings quantised to 0.1 deg
  (seed 001: NAO's joint resolution), corners either projected with Gaussian
  noise (fast, for Monte Carlo) or found by the detector on **rendered**
  images (blur + noise), so the pipeline runs from pixels.

All randomness comes from the ``np.random.Generator`` passed in.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robocal.errors import InputError, NotEnoughDataError
from robocal.rigs.humanoid.model import FEET, HumanoidModel

__all__ = [
    "JOINT_RESOLUTION",
    "OUTLINE_MARGIN",
    "board_outline",
    "DEFAULT_HEAD",
    "Truth",
    "HumanoidDataset",
    "draw_truth",
    "sample_poses",
    "quantise",
    "simulate_dataset",
]

#: Joint sensor resolution of NAO's servos (seed 001: 0.1 deg) [rad].
JOINT_RESOLUTION = np.radians(0.1)
#: Head pose during the run: looking down at the raised feet (HeadYaw, HeadPitch) [rad];
#: on the 0.1 deg grid so that the still head adds no constant reading error.
DEFAULT_HEAD = (0.0, np.radians(25.8))
#: Rest angles of the leg that is not being viewed (a straight leg) [rad].
_REST = 0.0


@dataclass
class Truth:
    """Ground truth of a simulation: the full parameter vector and its labels."""

    params: np.ndarray
    labels: list

    def as_dict(self) -> dict:
        return dict(zip(self.labels, self.params.tolist()))


@dataclass
class HumanoidDataset:
    """One calibration data set: per view the foot, the joint readings and the corners.

    Attributes
    ----------
    feet : list of str, length V
        ``'left'`` or ``'right'``: whose board the view shows.
    theta : ndarray, shape (V, n_joints)
        Joint sensor readings [rad], in the model's ``joint_names`` order.
    corners : ndarray, shape (V, N, 2) [px], or None
        Detected (or simulated) corners, ``object_points`` order; NaN for a
        view whose board was not found, or for single corners removed at
        detection (calibration leaves them out of their view).
    images : list of (Path or ndarray or None)
        Image of each view (a path on disk, or an array in memory).
    names : list of str
        Label of each view (used in messages and reports).
    truth : Truth, optional
        Ground truth when simulated.
    messages : list of str
        Notes made while loading/detecting (e.g. dropped views).
    """

    feet: list
    theta: np.ndarray
    corners: np.ndarray | None = None
    images: list = field(default_factory=list)
    names: list = field(default_factory=list)
    truth: Truth | None = None
    messages: list = field(default_factory=list)
    head: tuple = DEFAULT_HEAD

    def __post_init__(self):
        self.theta = np.atleast_2d(np.asarray(self.theta, dtype=float))
        V = len(self.theta)
        if len(self.feet) != V:
            raise InputError(f"{len(self.feet)} feet given for {V} joint records")
        bad = [f for f in self.feet if f not in FEET]
        if bad:
            raise InputError(f"foot must be one of {FEET}, got {bad[0]!r}")
        if not self.names:
            self.names = [f"view{v:03d}" for v in range(V)]
        if not self.images:
            self.images = [None] * V

    @property
    def n_views(self) -> int:
        return len(self.theta)

    def subset(self, keep) -> "HumanoidDataset":
        keep = np.asarray(keep)
        idx = np.flatnonzero(keep) if keep.dtype == bool else keep
        return HumanoidDataset([self.feet[i] for i in idx], self.theta[idx],
                               None if self.corners is None else self.corners[idx],
                               [self.images[i] for i in idx], [self.names[i] for i in idx], self.truth,
                               list(self.messages), self.head)


def draw_truth(model: HumanoidModel, rng: np.random.Generator, *, joint_deg: float = 0.5,
               camera_deg: float = 0.5, camera_mm: float = 0.0, board_deg: float = 0.5,
               board_mm: float = 1.0, head_deg: float = 0.0) -> Truth:
    """True offsets drawn from zero-mean normals with the given standard deviations.

    Defaults follow the seed's Table 2 magnitudes (leg offsets up to ~0.5 deg,
    small board mounting errors). Camera x/y shifts and head-joint offsets are
    zero unless asked for (they are not in the seed's 21-parameter set).
    """
    labels = model.parameter_labels()
    x = np.zeros(len(labels))
    n = len(model.joint_names)
    for k, name in enumerate(model.joint_names):
        sd = head_deg if name in model.head_joints else joint_deg
        x[k] = rng.normal(0.0, np.radians(sd)) if sd > 0 else 0.0
    x[n:n + 3] = rng.normal(0.0, np.radians(camera_deg), 3) if camera_deg > 0 else 0.0
    x[n + 3:n + 5] = rng.normal(0.0, camera_mm * 1e-3, 2) if camera_mm > 0 else 0.0
    for fi in range(len(FEET)):
        b = n + 5 + 3 * fi
        x[b] = rng.normal(0.0, np.radians(board_deg)) if board_deg > 0 else 0.0
        x[b + 1:b + 3] = rng.normal(0.0, board_mm * 1e-3, 2) if board_mm > 0 else 0.0
    return Truth(x, labels)


def quantise(theta, resolution: float = JOINT_RESOLUTION) -> np.ndarray:
    """Sensor readings rounded to ``resolution`` [rad] (0 disables)."""
    theta = np.asarray(theta, dtype=float)
    return theta if resolution <= 0 else np.round(theta / resolution) * resolution


#: Margin [px] the outer edge of the printed squares keeps from the image border: the detector
#: needs the outer squares whole (a cut square shifts or loses the corner next to it).
OUTLINE_MARGIN = 4.0


def board_outline(board) -> np.ndarray:
    """Outer edge of the squares (not of the quiet zone) in the board frame [m], shape (8, 3):
    the four outer corners, one square beyond the extreme inner corners, and the edge midpoints
    (so that lens distortion cannot bend an edge out of the image between corners)."""
    sq = board.square
    x0, x1 = -sq, board.cols * sq
    y0, y1 = -sq, board.rows * sq
    xm, ym = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    return np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0],
                     [xm, y0, 0], [x1, ym, 0], [xm, y1, 0], [x0, ym, 0]], dtype=float)


def _views_ok(model, q, foot, params, margin, min_facing, min_clearance):
    """Visibility, facing and foot-clearance test for candidate joint values q (offsets included).

    Visible: every inner corner ``margin`` px inside the image and the outer edge of the squares
    (:func:`board_outline`) :data:`OUTLINE_MARGIN` px inside, i.e. the whole 5 x 7 board shows.
    """
    n = len(model.joint_names)
    cam = params[n:n + 5]
    fi = FEET.index(foot)
    board = params[n + 5 + 3 * fi:n + 8 + 3 * fi]
    T = model.T_opt_board(q, foot, cam, board)
    ok = np.ones(len(T), dtype=bool)
    for pts, mg in ((model.object_points, margin), (board_outline(model.board), OUTLINE_MARGIN)):
        p = np.einsum("vij,nj->vni", T[:, :3, :3], pts) + T[:, None, :3, 3]
        front = np.all(p[..., 2] > 0.05, axis=1)
        uv = model.camera.project(np.where(p[..., 2:3] > 0.05, p, 1.0), check=False)
        ok &= front & np.all(model.camera.in_image(uv, margin=mg), axis=1)
    # printed face toward the camera: the board's +z (into the plate) points away from it
    facing = np.einsum("vi,vi->v", T[:, :3, 2], T[:, :3, 3]) / np.linalg.norm(T[:, :3, 3], axis=1)
    ok &= facing > min_facing
    # feet clear of each other: board plates and soles of the two feet apart
    other = FEET[1 - fi]
    src = model.mounts[foot]
    dst = model.mounts[other]
    T1 = model.tree.transform(q, model.tree.root, src.sole_link)
    T2 = model.tree.transform(q, model.tree.root, dst.sole_link)
    c1 = T1[:, :3, :3] @ src.centre + T1[:, :3, 3]
    c2 = T2[:, :3, :3] @ dst.centre + T2[:, :3, 3]
    ok &= np.linalg.norm(c1 - c2, axis=1) > min_clearance
    ok &= np.linalg.norm(T1[:, :3, 3] - T2[:, :3, 3], axis=1) > 0.5 * min_clearance
    ok &= np.linalg.norm(c1 - T2[:, :3, 3], axis=1) > 0.5 * min_clearance
    ok &= np.linalg.norm(c2 - T1[:, :3, 3], axis=1) > 0.5 * min_clearance
    return ok


def sample_poses(model: HumanoidModel, n_per_foot: int, rng: np.random.Generator, *,
                 truth: Truth | None = None, head=DEFAULT_HEAD, margin: float = 15.0,
                 min_facing: float = 0.5, min_clearance: float = 0.2, batch: int | None = None,
                 max_batches: int = 200) -> tuple[list, np.ndarray]:
    """Random leg poses within the joint limits that show one board fully.

    For each view, the joints of the viewed leg are drawn uniformly within
    their limits (the HipYawPitch range is shared when tied), the other leg
    rests straight, the head is at ``head``; a pose is kept when every inner
    corner of the board lies ``margin`` px inside the image of the *true* robot
    and the outer edge of the squares :data:`OUTLINE_MARGIN` px inside, the
    printed face is turned toward the camera (cosine > ``min_facing``) and
    the two feet stay ``min_clearance`` m apart (plate centres).

    Returns
    -------
    feet : list of str, length 2 * n_per_foot
    q : ndarray, shape (V, n_joints)
        True joint angles (what the robot is physically at, offsets included) [rad].
    """
    if n_per_foot < 1:
        raise InputError(f"n_per_foot must be >= 1, got {n_per_foot}")
    params = truth.params if truth is not None else np.zeros(len(model.parameter_labels()))
    names = model.joint_names
    n = len(names)
    lim = np.array([model.tree.joint(j).limits or (-np.pi, np.pi) for j in names])
    alpha = params[:n]
    batch = batch or max(256, 80 * n_per_foot)  # about 1.5 % of random leg poses show the whole board
    feet, poses = [], []
    for foot in FEET:
        legs = [names.index(j) for j in model.mounts[foot].leg_joints]
        found = []
        for _ in range(max_batches):
            theta = np.full((batch, n), _REST)
            for k, hv in zip([names.index(h) for h in model.head_joints], head):
                theta[:, k] = hv
            theta[:, legs] = rng.uniform(lim[legs, 0], lim[legs, 1], size=(batch, len(legs)))
            q = theta + alpha
            ok = _views_ok(model, q, foot, params, margin, min_facing, min_clearance)
            found.extend(q[ok])
            if len(found) >= n_per_foot:
                break
        if len(found) < n_per_foot:
            raise NotEnoughDataError(f"found only {len(found)} of {n_per_foot} visible poses for the {foot} board")
        feet += [foot] * n_per_foot
        poses.extend(found[:n_per_foot])
    return feet, np.array(poses)


def simulate_dataset(model: HumanoidModel, rng: np.random.Generator, *, n_per_foot: int = 10,
                     truth: Truth | None = None, feet=None, q=None, noise_px: float = 0.3,
                     resolution: float = JOINT_RESOLUTION, render: bool = False,
                     blur_sigma: float = 0.8, image_noise: float = 2.0, head=DEFAULT_HEAD,
                     progress: bool = False) -> HumanoidDataset:
    """A simulated run: readings, and corners from noise or from rendered images.

    Parameters
    ----------
    model : HumanoidModel
    rng : numpy.random.Generator
    n_per_foot : int
        Views of each board (ignored when ``q`` is given).
    truth : Truth, optional
        Default: :func:`draw_truth` with ``rng``.
    feet, q : optional
        Given poses (true joint angles, offsets included [rad]) instead of
        :func:`sample_poses`.
    noise_px : float
        Corner noise [px] when not rendering.
    resolution : float
        Joint sensor quantisation [rad] (0.1 deg; 0 disables).
    render : bool
        Render each board (blur ``blur_sigma`` px, grey noise ``image_noise``
        levels) and detect its corners; a board not fully found is dropped.
    """
    truth = truth if truth is not None else draw_truth(model, rng)
    if q is None:
        feet, q = sample_poses(model, n_per_foot, rng, truth=truth, head=head)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    feet = list(feet)
    n = len(model.joint_names)
    theta = quantise(q - truth.params[:n], resolution)
    uv_true = model.project(q - truth.params[:n], feet, truth.params)
    data = HumanoidDataset(feet, theta, truth=truth, head=tuple(head))
    if not render:
        data.corners = uv_true + rng.normal(0.0, noise_px, uv_true.shape)
        return data
    from robocal.rigs.humanoid.detect import detect_views, render_view

    images = []
    iterator = range(len(q))
    if progress:
        from robocal.progress import progress as _progress

        iterator = _progress(iterator, desc="rendering", total=len(q))
    for v in iterator:
        images.append(render_view(model, q[v] - truth.params[:n], feet[v], truth.params, rng,
                                  blur_sigma=blur_sigma, noise_sigma=image_noise))
    data.images = images
    return detect_views(model, data, progress=progress)


def save_images(data: HumanoidDataset, folder: Path) -> list[Path]:
    """Write in-memory images as PNG files ``<name>.png`` into ``folder``; returns the paths."""
    import cv2

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for name, img in zip(data.names, data.images):
        path = folder / f"{name}.png"
        if not cv2.imwrite(str(path), np.asarray(img), [cv2.IMWRITE_PNG_COMPRESSION, 9]):
            raise InputError(f"could not write image {path}")
        out.append(path)
    return out
