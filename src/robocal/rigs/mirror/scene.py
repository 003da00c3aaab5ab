"""The patent's published example as a simulated scene (seed 002, "实施例").

What the text publishes: distortion ``k1 = -0.28900, k2 = -0.06639,
p1 = 0.0005, p2 = 0.00072``; the mirror rectangle 366 x 256 mm;
``T_cm = [-194.9056, -193.4822, 1648.6289] mm``,
``T_cri = [-23.2453, 163.1634, 3506.1842] mm`` and
``T_rc = [583.7428, -8.9876, 269.5506] mm``. What it does not: the intrinsic
matrix (an image missing from the text), the three rotations and the body
points. This module fills those gaps and says how.

*Intrinsics* — assumed: a 768 x 576 (PAL-era, the patent is from 2006)
camera with ``fx = fy = 800 px`` and the principal point at the centre.

*Rotations* — the three published translations are not independent. The
mirror plane is the perpendicular bisector of ``O_r`` (at ``t_cr`` in ``c``)
and its image ``O_ri`` (at ``T_cri``), and the marker origin ``T_cm`` lies on
it, so ``|T_cm - t_cr| = |T_cm - T_cri|`` with ``|t_cr| = |T_rc|``. That
fixes the angle between the camera's line of sight to marker A and the
robot-origin-to-camera vector at 79.3 deg. A level, forward-looking camera
would make it about 20 deg. The default scene takes the rotation ``R_rc``
closest to that level forward-looking mount that satisfies the constraint
exactly: the camera pitched ~55 deg down. The three published translations are
then reproduced to rounding error (see the tests). The geometry is
self-consistent but not a plausible floor scene (marker A sits ~0.97 m below
the axle plane); the simulator models no floor.

*Mirror axes* — ``z_m`` is the plane normal away from the camera and ``x_m``
is the camera's x axis projected onto the plane (marker A top left, B top
right in the image).

*Body points* — 20 corners of the hexahedra the embodiment describes (a body
front face, a small box on it, three small cubes on that), 0.12 m deep in
``x_r``, so the body points are far from coplanar.
"""

from __future__ import annotations

import numpy as np

from robocal.camera import MarkerRectangle
from robocal.geometry import matrix_from_rotvec, transform_from
from robocal.rigs.mirror.model import MirrorScene, mirror_plane, virtual_transform

__all__ = [
    "PUBLISHED",
    "DEFAULT_INTRINSICS",
    "published_T_r_c_rotation",
    "default_body_points",
    "published_scene",
    "perturbed_placements",
]

#: The patent's published numbers, in the units it prints (mm).
PUBLISHED = {
    "dist": (-0.28900, -0.06639, 0.0005, 0.00072),
    "rectangle_mm": (366.0, 256.0),
    "T_cm_mm": (-194.9056, -193.4822, 1648.6289),
    "T_cri_mm": (-23.2453, 163.1634, 3506.1842),
    "T_rc_mm": (583.7428, -8.9876, 269.5506),
}

#: Assumed intrinsics (the patent's matrix is not in the text), OpenCV convention, px.
DEFAULT_INTRINSICS = {
    "fx": 800.0,
    "fy": 800.0,
    "cx": 383.5,
    "cy": 287.5,
    "dist": PUBLISHED["dist"],
    "width": 768,
    "height": 576,
}

# Level camera looking along x_r: x_c = -y_r, y_c = -z_r, z_c = x_r.
_R_R_C_LEVEL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def published_T_r_c_rotation() -> np.ndarray:
    """``R_rc`` closest to a level forward-looking camera that is consistent with
    the three published translations (closed form, see the module docstring)."""
    t_cm = np.array(PUBLISHED["T_cm_mm"]) / 1e3
    t_cri = np.array(PUBLISHED["T_cri_mm"]) / 1e3
    t_rc = np.array(PUBLISHED["T_rc_mm"]) / 1e3
    # |t_cm - t_cr|^2 = |t_cm - t_cri|^2 and |t_cr| = |t_rc| give t_cm . t_cr:
    dot = t_cm @ t_cri - 0.5 * (t_cri @ t_cri - t_rc @ t_rc)
    # t_cr = -R_cr t_rc  =>  u . t_rc_hat = -dot / (|t_cm| |t_rc|) with u = R_rc t_cm_hat
    cos_target = -dot / (np.linalg.norm(t_cm) * np.linalg.norm(t_rc))
    t_rc_hat = t_rc / np.linalg.norm(t_rc)
    u = _R_R_C_LEVEL @ (t_cm / np.linalg.norm(t_cm))
    axis = np.cross(t_rc_hat, u)
    axis /= np.linalg.norm(axis)
    # the smallest rotation turns u in the plane of (u, t_rc) away from t_rc
    phi = np.arccos(cos_target) - np.arccos(np.clip(u @ t_rc_hat, -1, 1))
    return matrix_from_rotvec(phi * axis) @ _R_R_C_LEVEL


def default_body_points() -> np.ndarray:
    """20 body feature points in ``r``, metres (hexahedra corners, see module doc)."""
    pts = []
    # front face of the body (x = 0.45 m)
    for y in (-0.25, 0.25):
        for z in (0.05, 0.25):
            pts.append((0.45, y, z))
    # a small box on the front face, front corners at x = 0.52 m
    for y in (-0.12, 0.12):
        for z in (0.08, 0.20):
            pts.append((0.52, y, z))
    # three small cubes on the box, front corners at x = 0.57 m
    for yc in (-0.08, 0.0, 0.08):
        for dy in (-0.02, 0.02):
            for z in (0.12, 0.16):
                pts.append((0.57, yc + dy, z))
    return np.array(pts)


def published_scene(body_points_r=None) -> MirrorScene:
    """The patent's example as a :class:`MirrorScene` with one mirror placement.

    Reproduces the published ``T_cm``, ``T_cri`` and ``T_rc`` (metres here).
    """
    t_cm = np.array(PUBLISHED["T_cm_mm"]) / 1e3
    t_rc = np.array(PUBLISHED["T_rc_mm"]) / 1e3
    R_rc = published_T_r_c_rotation()
    R_cr = R_rc.T
    t_cr = -R_cr @ t_rc
    t_cri = np.array(PUBLISHED["T_cri_mm"]) / 1e3
    n = t_cri - t_cr
    n /= np.linalg.norm(n)
    x_m = np.array([1.0, 0.0, 0.0]) - n[0] * n
    x_m /= np.linalg.norm(x_m)
    y_m = np.cross(n, x_m)
    T_c_m = transform_from(np.column_stack([x_m, y_m, n]), t_cm)
    w, h = PUBLISHED["rectangle_mm"]
    return MirrorScene(
        T_c_r=transform_from(R_cr, t_cr),
        T_c_m=T_c_m,
        body_points_r=default_body_points() if body_points_r is None else body_points_r,
        rectangle=MarkerRectangle(w / 1e3, h / 1e3),
    )


def perturbed_placements(scene: MirrorScene, k: int, rng: np.random.Generator, *,
                         tilt_deg: float = 8.0, shift: float = 0.15) -> np.ndarray:
    """``k`` further mirror poses ``T_c_m`` (k, 4, 4) around the scene's first one.

    Each is the first placement rotated by a random ``tilt_deg``-sized rotation
    about the rectangle's centre and shifted by up to ``shift`` metres, the way
    a person would move the mirror between shots. Placement 0 is kept as is.
    """
    base = scene.T_c_m[0]
    centre = base[:3, :3] @ np.array([scene.rectangle.width / 2, scene.rectangle.height / 2, 0.0]) + base[:3, 3]
    out = [base]
    while len(out) < k:
        rv = rng.normal(size=3)
        rv *= np.deg2rad(tilt_deg) * rng.uniform(0.5, 1.0) / np.linalg.norm(rv)
        R = matrix_from_rotvec(rv)
        c_new = centre + rng.uniform(-shift, shift, size=3)
        R_new = R @ base[:3, :3]
        t_new = c_new - R_new @ np.array([scene.rectangle.width / 2, scene.rectangle.height / 2, 0.0])
        out.append(transform_from(R_new, t_new))
    return np.stack(out)


def _check_scene(scene: MirrorScene) -> dict:  # pragma: no cover - used while designing
    n, d = mirror_plane(scene.T_c_m)
    return {"T_c_ri": virtual_transform(scene.T_c_r, n[0], d[0]), "n": n, "d": d}
