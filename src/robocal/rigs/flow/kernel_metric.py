"""From image flow to ground motion: gyro compensation (eqs. 3-4 of Li, Guan and Chu 2017), metric
displacement (eq. 5) and the speed ceiling of the block matcher.

Plain NumPy, vectorised over leading dimensions; the frame conventions are
those of :mod:`.kernel` (camera x = image u, y = image v, z = optical axis;
sensor ground frame ``x_S`` = u, ``y_S`` = image up).
"""

from __future__ import annotations

import numpy as np

from robocal.rigs.flow.kernel_config import FlowConfig

__all__ = ["rotational_flow", "compensate_rotation", "metric_displacement", "speed_limit"]


def rotational_flow(angle, xy_px, focal_px):
    """Image flow caused by a small camera rotation (Li, Guan and Chu 2017, eqs. 3–4, rotational part).

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
    """Remove the flow the sensor's own rotation causes (Li, Guan and Chu 2017, eqs. 3–4).

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
    """Sensor displacement over the ground from compensated flow (Li, Guan and Chu 2017, eq. 5).

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
