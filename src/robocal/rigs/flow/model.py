"""The sensor array on the robot and the planar motion model (Li, Guan and Chu 2017, §2, eqs. 6–12).

Frames
------
Robot frame R: origin at the centre between the drive wheels on the ground,
``x`` forward, ``y`` left, ``z`` up. World frame A: fixed, ``z`` up. The robot
pose is ``(X, Y, theta)`` (m, m, rad), ``T_world_robot``.

Sensor ``i`` sits at distance ``R_i`` and angle ``psi_i`` from the robot centre
and its ground frame S_i (see :mod:`robocal.rigs.flow.kernel`) is turned by
``phi_i`` about ``z`` relative to the robot frame. ``scale_i`` multiplies its
metric displacement (it absorbs a height or focal-length error); nominally 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal._stats import median  # noqa: F401 - np.median without numpy.ma's import (issue 16); re-exported
from robocal.errors import DegenerateGeometryError, InputError, NotEnoughDataError
from robocal.validation import check_array

__all__ = ["SensorArray", "seed_array", "median", "rot2", "se2_exp", "se2_log", "integrate_twists", "relative_twists"]


def rot2(angle):
    """2D rotation matrices ``(..., 2, 2)`` of ``angle`` (rad)."""
    a = np.asarray(angle, float)
    c, s = np.cos(a), np.sin(a)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


@dataclass
class SensorArray:
    """Placement of n optical-flow sensors on the robot.

    Attributes
    ----------
    R : ndarray, shape (n,)
        Distance of each sensor from the robot centre, m.
    psi : ndarray, shape (n,)
        Angle of the sensor position in the robot frame, rad.
    phi : ndarray, shape (n,)
        Rotation of the sensor's ground frame relative to the robot frame, rad.
    scale : ndarray, shape (n,)
        Multiplier of each sensor's metric displacement (1 = nominal).
    names : list of str
    """

    R: np.ndarray
    psi: np.ndarray
    phi: np.ndarray
    scale: np.ndarray
    names: list

    def __post_init__(self):
        self.R = check_array(self.R, "sensor R", shape=(None,)).reshape(-1)
        n = self.R.size
        self.psi = check_array(self.psi, "sensor psi", shape=(n,))
        self.phi = check_array(self.phi, "sensor phi", shape=(n,))
        self.scale = check_array(self.scale, "sensor scale", shape=(n,))
        if self.names is None:
            self.names = [f"s{i}" for i in range(n)]
        self.names = [str(x) for x in self.names]
        if len(self.names) != n or len(set(self.names)) != n:
            raise InputError(f"sensor names must be {n} distinct strings, got {self.names}")
        if np.any(self.R < 0):
            raise InputError(f"sensor R must be >= 0 m, got {self.R.tolist()}")
        if np.any(self.scale <= 0):
            raise InputError(f"sensor scale must be > 0, got {self.scale.tolist()}")
        if n < 2:
            raise NotEnoughDataError(
                f"the array has {n} sensor(s): one sensor gives 2 equations for the 3 unknowns "
                "(dX, dY, dtheta) of eq. 9 in Li, Guan and Chu (2017) — at least 2 sensors are needed"
            )
        # eq. 9 needs rank(A) = 3: the rotation is seen only through sensors at different
        # points (all at one point, e.g. every R = 0, leave dtheta undetermined)
        sv = np.linalg.svd(self.design_matrix(), compute_uv=False)
        if sv[-1] <= 1e-9 * max(1.0, sv[0]):
            pos = ", ".join(f"({x * 1e3:.1f}, {y * 1e3:.1f})" for x, y in self.positions)
            raise DegenerateGeometryError(
                f"sensor array: all sensors sit at one point (positions {pos} mm; expected at least 2 distinct "
                "points): A of eq. 9 in Li, Guan and Chu (2017) has rank < 3 and the rotation is undetermined"
            )

    @property
    def n(self) -> int:
        return self.R.size

    @property
    def positions(self) -> np.ndarray:
        """Sensor positions in the robot frame, shape (n, 2), m."""
        return np.stack([self.R * np.cos(self.psi), self.R * np.sin(self.psi)], axis=1)

    def design_matrix(self, theta: float = 0.0) -> np.ndarray:
        """The seed's ``A`` (eq. 9/10) stacked over sensors, shape (2n, 3).

        Row pair i: ``[[1, 0, -R_i sin(theta + psi_i)], [0, 1, R_i cos(theta + psi_i)]]``;
        ``theta = 0`` gives the robot-frame form used internally.
        """
        a = theta + self.psi
        A = np.zeros((self.n, 2, 3))
        A[:, 0, 0] = 1.0
        A[:, 1, 1] = 1.0
        A[:, 0, 2] = -self.R * np.sin(a)
        A[:, 1, 2] = self.R * np.cos(a)
        return A.reshape(2 * self.n, 3)

    def to_dict(self) -> dict:
        return {
            "units": {"length": "m", "angle": "deg"},
            "sensors": [
                {"name": nm, "R": float(r), "psi": float(np.degrees(p)), "phi": float(np.degrees(f)), "scale": float(s)}
                for nm, r, p, f, s in zip(self.names, self.R, self.psi, self.phi, self.scale)
            ],
        }

    @classmethod
    def from_document(cls, doc) -> "SensorArray":
        """From a :class:`robocal.io.Document` holding ``sensors: [{name, R, psi, phi, scale}]``."""
        items = doc.items_list("sensors")
        if len(items) < 2:
            raise NotEnoughDataError(
                f"{doc.source}: 'sensors' lists {len(items)} sensor(s); the array needs at least 2 "
                "(one sensor gives 2 equations for 3 unknowns, eq. 9 of Li, Guan and Chu 2017)"
            )
        R = [it.float("R", kind="length") for it in items]
        psi = [it.float("psi", kind="angle") for it in items]
        phi = [it.float("phi", kind="angle", default=0.0) for it in items]
        scale = [it.float("scale", default=1.0, positive=True) for it in items]
        names = [it.str("name", default=f"s{i}") for i, it in enumerate(items)]
        try:
            return cls(np.array(R), np.array(psi), np.array(phi), np.array(scale), names)
        except (InputError, DegenerateGeometryError) as exc:
            raise type(exc)(f"{doc.source}: {exc}") from None

    def copy(self, **kw) -> "SensorArray":
        d = dict(R=self.R.copy(), psi=self.psi.copy(), phi=self.phi.copy(), scale=self.scale.copy(), names=list(self.names))
        d.update(kw)
        return SensorArray(**d)


def seed_array() -> SensorArray:
    """The seed's rig: three sensors at R = 350 mm, psi = 60, 120, 270 deg, aligned (phi = 0)."""
    return SensorArray(np.full(3, 0.35), np.radians([60.0, 120.0, 270.0]), np.zeros(3), np.ones(3), ["s60", "s120", "s270"])


def se2_exp(twist):
    """Relative pose ``(dx, dy, dtheta)`` reached by a constant body twist ``(vx, vy, w)*dt``.

    Exact integration of a constant-velocity arc (reduces to the seed's eq. 12
    Euler step for small ``dtheta``). Shape (..., 3) -> (..., 3).
    """
    u = np.asarray(twist, float)
    w = u[..., 2]
    small = np.abs(w) < 1e-9
    ws = np.where(small, 1.0, w)
    a = np.where(small, 1.0 - w * w / 6.0, np.sin(ws) / ws)
    b = np.where(small, w / 2.0, (1.0 - np.cos(ws)) / ws)
    dx = a * u[..., 0] - b * u[..., 1]
    dy = b * u[..., 0] + a * u[..., 1]
    return np.stack([dx, dy, w], -1)


def se2_log(rel):
    """Inverse of :func:`se2_exp`."""
    r = np.asarray(rel, float)
    w = r[..., 2]
    small = np.abs(w) < 1e-9
    ws = np.where(small, 1.0, w)
    a = np.where(small, 1.0 - w * w / 6.0, np.sin(ws) / ws)
    b = np.where(small, w / 2.0, (1.0 - np.cos(ws)) / ws)
    det = a * a + b * b
    vx = (a * r[..., 0] + b * r[..., 1]) / det
    vy = (-b * r[..., 0] + a * r[..., 1]) / det
    return np.stack([vx, vy, w], -1)


def integrate_twists(twists, pose0=(0.0, 0.0, 0.0), *, method: str = "exact"):
    """Chain body-frame twists into poses (Li, Guan and Chu 2017, eq. 12).

    Parameters
    ----------
    twists : array_like, shape (K, 3)
        Per-step body twists ``(dx, dy, dtheta)`` (m, m, rad).
    pose0 : array_like, shape (3,)
    method : {"exact", "euler"}
        ``"euler"`` is eq. 12 literally (world increment rotated by the
        heading at the start of the step); ``"exact"`` integrates the arc.

    Returns
    -------
    ndarray, shape (K + 1, 3)
    """
    u = np.asarray(twists, float)
    rel = se2_exp(u) if method == "exact" else u
    # heading is a cumulative sum; positions follow in one vectorised pass
    theta = np.concatenate([[pose0[2]], pose0[2] + np.cumsum(rel[:, 2])])
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    dX = c * rel[:, 0] - s * rel[:, 1]
    dY = s * rel[:, 0] + c * rel[:, 1]
    X = np.concatenate([[pose0[0]], pose0[0] + np.cumsum(dX)])
    Y = np.concatenate([[pose0[1]], pose0[1] + np.cumsum(dY)])
    return np.stack([X, Y, theta], 1)


def relative_twists(poses):
    """Body twists between consecutive poses ``(K+1, 3) -> (K, 3)`` (inverse of :func:`integrate_twists`)."""
    from robocal.geometry import wrap_angle  # here: robocal.geometry imports scipy.spatial (issue 16, fixed cost)

    p = np.asarray(poses, float)
    d = p[1:, :2] - p[:-1, :2]
    c, s = np.cos(p[:-1, 2]), np.sin(p[:-1, 2])
    rel = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], wrap_angle(p[1:, 2] - p[:-1, 2])], 1)
    return se2_log(rel)
