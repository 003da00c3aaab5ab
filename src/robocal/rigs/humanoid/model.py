"""The NAO-class humanoid model of the leg calibration (seed 001 = Fan and Lou [S1], docs/sources.md; the model in docs/rigs/humanoid.md).

Frames (``docs/conventions.md``: ``T_a_b`` maps frame-b points into frame a):

* the kinematic tree comes from a URDF (default: ``data/nao_h25_legs_head.urdf``,
  real NAO H25 geometry): ``torso -> legs -> <foot>_sole`` and
  ``torso -> HeadYaw -> HeadPitch -> Head -> CameraBottom_frame ->
  CameraBottom_optical_frame`` (OpenCV camera frame: x right, y down, z forward);
* a checkerboard of ``5 x 7`` squares of 25 mm (``4 x 6`` inner corners) on a
  plate pinned under each sole, its centre 170 mm ahead of the ankle (seed
  001, Fig. 2); nominal pose in the sole frame ``T_sole_board0``: board x
  along the foot, board z = -sole z, so the printed face looks up the leg,
  toward the head camera.

The calibration parameters (seed 001 eqs. 2-5, Table 1):

* joint offsets ``alpha_i``: ``q_i = theta_i + alpha_i`` (rad), one per
  independent joint of the tree (the two HipYawPitch joints share one when
  tied);
* camera mounting correction ``(roll, pitch, yaw, x, y)`` (rad, m) applied in
  the camera body frame: ``T_head_cam = T_head_cam0 @ Trans(x, y, 0) @
  Rz(yaw) Ry(pitch) Rx(roll)`` (seed eq. 3; z is not observable here);
* per-foot board mounting ``(yaw, x, y)`` (rad, m): the board turns by ``yaw``
  about the sole's z through its nominal centre ``c`` and shifts by
  ``(x, y)``: ``p_sole = c + Rz(yaw) (p0 - c) + (x, y, 0)`` (seed eq. 4; the
  rotation about the centre, not the sole origin, keeps yaw and shift
  decorrelated).

Corners are projected with the shared pinhole model (seed eq. 5):
``uv = project(T_opt_cam0 @ C^-1 @ T_cam0_sole(theta + alpha) @ p_sole)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path

import numpy as np

from robocal.camera import CameraModel, Checkerboard
from robocal.errors import InputError, ShapeError
from robocal.kinematics import KinematicTree
from robocal.validation import check_array

__all__ = [
    "FEET",
    "CAMERA_PARAMS",
    "BOARD_PARAMS",
    "BoardMount",
    "HumanoidModel",
    "default_model",
    "default_model_path",
    "rpy_matrix",
]

FEET = ("left", "right")
CAMERA_PARAMS = ("roll", "pitch", "yaw", "x", "y")
BOARD_PARAMS = ("yaw", "x", "y")
_CAMERA_UNITS = ("rad", "rad", "rad", "m", "m")
_BOARD_UNITS = ("rad", "m", "m")
#: Board frame in the sole frame: board x along the foot (toes), board z = -sole z,
#: so the printed face (the board's -z side) looks up the leg, toward the head camera.
_BOARD_ROTATION = np.diag([1.0, -1.0, -1.0])


def default_model_path() -> Path:
    """Path of the shipped NAO H25 URDF (legs, head, lower camera)."""
    return Path(str(resources.files("robocal.rigs.humanoid") / "data" / "nao_h25_legs_head.urdf"))


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _hat(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def rpy_matrix(roll: float, pitch: float, yaw: float, *, derivatives: bool = False):
    """``R = Rz(yaw) Ry(pitch) Rx(roll)`` (URDF fixed-axis rpy); with ``derivatives``
    also ``[dR/droll, dR/dpitch, dR/dyaw]`` (3, 3, 3)."""
    Rx, Ry, Rz = _rx(roll), _ry(pitch), _rz(yaw)
    R = Rz @ Ry @ Rx
    if not derivatives:
        return R
    ex, ey, ez = np.eye(3)
    dR = np.stack([Rz @ Ry @ Rx @ _hat(ex), Rz @ Ry @ _hat(ey) @ Rx, Rz @ _hat(ez) @ Ry @ Rx])
    return R, dR


@dataclass(frozen=True)
class BoardMount:
    """Where a foot's checkerboard sits.

    Attributes
    ----------
    foot : {'left', 'right'}
    sole_link : str
        Link of the sole frame in the tree.
    leg_joints : tuple of str
        Independent joints from the torso to that sole (tree order).
    T_sole_board0 : ndarray, shape (4, 4)
        Nominal pose of the board's own frame (the :class:`Checkerboard`
        object-point frame, first inner corner at the origin) in the sole frame [m].
    centre : ndarray, shape (3,)
        Nominal centre of the inner-corner grid in the sole frame [m]: the
        pivot of the board yaw correction.
    """

    foot: str
    sole_link: str
    leg_joints: tuple
    T_sole_board0: np.ndarray
    centre: np.ndarray


@dataclass
class HumanoidModel:
    """Kinematic tree + camera + foot boards: everything the forward model needs.

    Build it with :func:`default_model` or :meth:`from_urdf`.

    Attributes
    ----------
    tree : KinematicTree
        With zero offsets (the offsets are calibration parameters here).
    camera : CameraModel
        Intrinsics (known; seed 001: f = 562.5 px, centre (324, 189)).
    board : Checkerboard
        Inner-corner grid (default 4 x 6 corners, 25 mm squares).
    mounts : dict of str to BoardMount
    camera_link, optical_link : str
        Camera body frame (its parent joint carries the mounting correction)
        and the OpenCV optical frame below it.
    head_joints : tuple of str
    """

    tree: KinematicTree
    camera: CameraModel
    board: Checkerboard
    mounts: dict
    camera_link: str = "CameraBottom_frame"
    optical_link: str = "CameraBottom_optical_frame"
    head_joints: tuple = ("HeadYaw", "HeadPitch")
    source: str = ""
    T_opt_cam: np.ndarray = field(init=False, repr=False)
    object_points: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        self.T_opt_cam = self.tree.transform(np.zeros(self.tree.n_joints), self.optical_link, self.camera_link)
        self.object_points = np.asarray(self.board.object_points(), dtype=float)
        for foot in self.mounts:
            if foot not in FEET:
                raise InputError(f"board mount foot must be one of {FEET}, got {foot!r}")

    # -- construction ---------------------------------------------------------------------
    @classmethod
    def from_urdf(cls, urdf=None, *, camera: CameraModel | None = None, board: Checkerboard | None = None,
                  sole_links=("l_sole", "r_sole"), board_centre=(0.17, 0.0, 0.0),
                  tie_hip_yaw_pitch: bool = False, camera_link: str = "CameraBottom_frame",
                  optical_link: str = "CameraBottom_optical_frame",
                  head_joints=("HeadYaw", "HeadPitch")) -> "HumanoidModel":
        """Load a tree from a URDF (default: the shipped NAO H25) and mount the boards.

        Parameters
        ----------
        urdf : path or str, optional
            URDF file or text; default :func:`default_model_path`.
        camera : CameraModel, optional
            Default: the seed's NAO lower camera, 640 x 480, f = 562.5 px,
            centre (324, 189) px, no distortion.
        board : Checkerboard, optional
            Default ``Checkerboard(4, 6, 0.025)`` (5 x 7 squares of 25 mm).
        sole_links : (str, str)
            Sole links of the left and right foot.
        board_centre : (3,) [m]
            Nominal centre of the corner grid in the sole frame. The seed pins
            the plate into the sole's pressure-sensor recesses and gives its
            centre 17 cm from the ankle's projection: the plate reaches out in
            front of the toes, and its pattern faces up the leg (board z =
            -sole z). A pattern facing out of the sole could never face the
            lower camera within NAO's joint limits (no such pose among 400 000
            random joint configurations, see docs/rigs/humanoid.md).
        tie_hip_yaw_pitch : bool
            Make ``RHipYawPitch`` a mimic of ``LHipYawPitch`` (one motor, one
            angle and one offset), as on the real NAO.
        """
        path = default_model_path() if urdf is None else urdf
        tree = KinematicTree.from_urdf(path)
        if tie_hip_yaw_pitch:
            tree = tie_joints(tree, "RHipYawPitch", "LHipYawPitch")
        if np.any(tree.offsets != 0):
            tree = tree.fold_offsets()
        camera = camera or CameraModel(562.5, 562.5, 324.0, 189.0, width=640, height=480)
        board = board or Checkerboard(4, 6, 0.025)
        centre = check_array(board_centre, "board_centre", shape=(3,))
        grid = np.asarray(board.object_points(), dtype=float)
        grid_centre = 0.5 * (grid.min(axis=0) + grid.max(axis=0))
        mounts = {}
        for foot, sole in zip(FEET, sole_links):
            chain = tree.chain(tree.root, sole)
            legs = _leg_joints(chain)
            T = np.eye(4)
            T[:3, :3] = _BOARD_ROTATION
            T[:3, 3] = centre - _BOARD_ROTATION @ grid_centre
            mounts[foot] = BoardMount(foot, sole, legs, T, centre.copy())
        for j in head_joints:
            tree.joint(j)
        return cls(tree, camera, board, mounts, camera_link, optical_link, tuple(head_joints), str(path))

    @property
    def tied(self) -> bool:
        """Whether the two HipYawPitch joints are one (RHipYawPitch a mimic)."""
        names = [j.name for j in self.tree.joints]
        return "RHipYawPitch" in names and self.tree.joint("RHipYawPitch").mimic is not None

    def with_tie(self, tie: bool) -> "HumanoidModel":
        """The same model with the HipYawPitch tie switched on or off."""
        if tie == self.tied:
            return self
        if tie:
            tree = tie_joints(self.tree, "RHipYawPitch", "LHipYawPitch")
        else:
            tree = self.tree.with_mimic("RHipYawPitch", None)
        mounts = {}
        for foot, m in self.mounts.items():
            legs = _leg_joints(tree.chain(tree.root, m.sole_link))
            mounts[foot] = replace(m, leg_joints=legs)
        return HumanoidModel(tree, self.camera, self.board, mounts, self.camera_link, self.optical_link,
                             self.head_joints, self.source)

    # -- names ------------------------------------------------------------------------------
    @property
    def joint_names(self) -> tuple[str, ...]:
        """Independent joints: columns of ``q`` arrays and of the offset vector."""
        return self.tree.joint_names

    @property
    def recorded_joints(self) -> tuple[str, ...]:
        """Every movable joint, mimics included: what a joint record lists."""
        return tuple(j.name for j in self.tree.joints if j.movable)

    @property
    def leg_joints(self) -> tuple[str, ...]:
        out = []
        for m in self.mounts.values():
            out += [j for j in m.leg_joints if j not in out]
        return tuple(out)

    def parameter_labels(self) -> list[str]:
        """All parameter labels in vector order: joints, ``camera.*``, ``board.<foot>.*``."""
        return (list(self.joint_names) + [f"camera.{p}" for p in CAMERA_PARAMS]
                + [f"board.{f}.{p}" for f in FEET for p in BOARD_PARAMS])

    def parameter_units(self) -> list[str]:
        return ["rad"] * len(self.joint_names) + list(_CAMERA_UNITS) + list(_BOARD_UNITS) * len(FEET)

    def seed_parameters(self) -> list[str]:
        """The seed's Table 1 set: 3 camera rotations, the leg joint offsets, 3 per board
        (21 with untied hips, 20 with the HipYawPitch tie)."""
        return ([f"camera.{p}" for p in ("roll", "pitch", "yaw")] + list(self.leg_joints)
                + [f"board.{f}.{p}" for f in FEET for p in BOARD_PARAMS])

    # -- joint values ----------------------------------------------------------------------------
    def q_from_records(self, records, *, source: str = "joints") -> np.ndarray:
        """``(V, n_joints)`` array from a list of ``{joint: angle [rad]}`` dicts.

        A record must name every independent joint; a mimic joint's reading
        (RHipYawPitch when tied) may be present and is then not used.
        """
        out = np.empty((len(records), len(self.joint_names)))
        for v, rec in enumerate(records):
            missing = [k for k in self.joint_names if k not in rec]
            if missing:
                raise InputError(f"{source}[{v}]: missing joint angles for {missing}")
            unknown = [k for k in rec if k not in self.recorded_joints]
            if unknown:
                raise InputError(f"{source}[{v}]: unknown joints {unknown} (model joints: "
                                 f"{list(self.recorded_joints)})")
            out[v] = [float(rec[k]) for k in self.joint_names]
        if not np.all(np.isfinite(out)):
            bad = np.argwhere(~np.isfinite(out))[0]
            raise InputError(f"{source}[{bad[0]}]: joint {self.joint_names[bad[1]]!r} is not finite")
        return out

    def check_limits(self, q, *, source: str = "joints", tolerance: float = 1e-9) -> None:
        """Raise :class:`InputError` naming the record and joint whose angle is out of limits."""
        q = np.atleast_2d(q)
        for k, name in enumerate(self.joint_names):
            lim = self.tree.joint(name).limits
            if lim is None:
                continue
            bad = np.flatnonzero((q[:, k] < lim[0] - tolerance) | (q[:, k] > lim[1] + tolerance))
            if bad.size:
                v = int(bad[0])
                raise InputError(
                    f"{source}[{v}]: joint {name!r} = {np.degrees(q[v, k]):.2f} deg is outside its limits "
                    f"[{np.degrees(lim[0]):.2f}, {np.degrees(lim[1]):.2f}] deg"
                    + (f" ({bad.size} records out of limits)" if bad.size > 1 else ""))

    # -- forward model -----------------------------------------------------------------------------
    def board_points_sole(self, foot: str, board=(0.0, 0.0, 0.0), *, derivatives: bool = False):
        """Corner positions in the sole frame (N, 3) [m], seed eq. 4; with
        ``derivatives`` also ``d p / d (yaw, x, y)`` (N, 3, 3)."""
        m = self.mounts[foot]
        p0 = self.object_points @ m.T_sole_board0[:3, :3].T + m.T_sole_board0[:3, 3]
        yaw, bx, by = board
        Rz = _rz(yaw)
        d = p0 - m.centre
        p = m.centre + d @ Rz.T + np.array([bx, by, 0.0])
        if not derivatives:
            return p
        D = np.zeros(p.shape + (3,))
        rot = d @ Rz.T
        D[:, 0, 0] = -rot[:, 1]
        D[:, 1, 0] = rot[:, 0]
        D[:, 0, 1] = 1.0
        D[:, 1, 2] = 1.0
        return p, D

    def T_cam0_sole(self, q, foot: str) -> np.ndarray:
        """Pose of the sole in the *nominal* camera body frame, (V, 4, 4), q = theta + alpha."""
        return self.tree.transform(q, self.camera_link, self.mounts[foot].sole_link)

    def T_opt_board(self, q, foot: str, camera=(0, 0, 0, 0, 0), board=(0, 0, 0)) -> np.ndarray:
        """``T_optical_board`` (V, 4, 4) for joint values ``q`` (offsets included) and the
        camera/board corrections: the pose the renderer and PnP use."""
        q = np.atleast_2d(q)
        A = self.T_cam0_sole(q, foot)
        C = np.eye(4)
        C[:3, :3] = rpy_matrix(*camera[:3])
        C[:3, 3] = [camera[3], camera[4], 0.0]
        m = self.mounts[foot]
        B = np.eye(4)
        B[:3, :3] = _rz(board[0])
        B[:3, 3] = m.centre - _rz(board[0]) @ m.centre + np.array([board[1], board[2], 0.0])
        return self.T_opt_cam @ np.linalg.inv(C) @ A @ B @ m.T_sole_board0

    def project(self, theta, feet, params: np.ndarray, *, jacobian: bool = False, check: bool = True):
        """Predicted corners for every view (seed eq. 5).

        Parameters
        ----------
        theta : array_like, shape (V, n_joints)
            Measured joint angles [rad] (:attr:`joint_names` order).
        feet : sequence of str, length V
            Which foot's board each view shows.
        params : ndarray, shape (P,)
            Full parameter vector in :meth:`parameter_labels` order.
        jacobian : bool
            Also return ``d uv / d params``, shape (V, N, 2, P), analytically.

        Returns
        -------
        uv : ndarray, shape (V, N, 2) [px]
        J : ndarray, shape (V, N, 2, P), optional
        """
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        V, n = theta.shape
        if n != len(self.joint_names):
            raise ShapeError(f"theta must have shape (V, {len(self.joint_names)}), got {theta.shape}")
        feet = np.asarray(feet)
        if feet.shape != (V,):
            raise ShapeError(f"feet must have shape ({V},), got {feet.shape}")
        P = len(self.parameter_labels())
        alpha = params[:n]
        cam = params[n:n + 5]
        N = len(self.object_points)
        uv = np.empty((V, N, 2))
        J = np.zeros((V, N, 2, P)) if jacobian else None
        R, dR = rpy_matrix(*cam[:3], derivatives=True)
        d = np.array([cam[3], cam[4], 0.0])
        Ropt = self.T_opt_cam[:3, :3]
        M = Ropt @ R.T  # maps camera-body vectors (after the correction) into the optical frame
        for fi, foot in enumerate(FEET):
            sel = np.flatnonzero(feet == foot)
            if sel.size == 0:
                continue
            bstart = n + 5 + 3 * fi
            p_sole, D_sole = self.board_points_sole(foot, params[bstart:bstart + 3], derivatives=True)
            q = theta[sel] + alpha
            A = self.T_cam0_sole(q, foot)  # (v, 4, 4)
            p_c0 = np.einsum("vij,nj->vni", A[:, :3, :3], p_sole) + A[:, None, :3, 3]
            p_opt = (p_c0 - d) @ M.T
            if not jacobian:
                uv[sel] = self.camera.project(p_opt, check=check)
                continue
            uv_s, Jp = self.camera.project_jacobian(p_opt, check=check)  # (v, N, 2, 3)
            uv[sel] = uv_s
            JM = Jp @ M  # d uv / d p_c0, (v, N, 2, 3)
            # joint offsets: twists [dt; w] of T_cam0_sole in the camera body frame
            tw = self.tree.offset_jacobian(q, self.camera_link, self.mounts[foot].sole_link)  # (v, 6, n)
            t = A[:, None, :3, 3]
            r = p_c0 - t  # (v, N, 3)
            w = tw[:, 3:, :]  # (v, 3, n)
            # w x r = -r x w  -> d p = dt + w x r
            dp = tw[:, None, :3, :] + np.cross(w[:, None, :, :].transpose(0, 1, 3, 2),
                                               r[:, :, None, :]).transpose(0, 1, 3, 2)
            J[sel, :, :, :n] = JM @ dp
            # camera correction: p_body = R^T (p_c0 - d)
            dpb = np.empty(p_c0.shape + (5,))
            for k in range(3):
                dpb[..., k] = (p_c0 - d) @ dR[k]  # (dR^T (p - d))_i = sum_j dR[j, i] (p - d)_j
            dpb[..., 3] = -R.T[:, 0]
            dpb[..., 4] = -R.T[:, 1]
            J[sel, :, :, n:n + 5] = (Jp @ Ropt) @ dpb
            # board mounting: p_c0 = A (p_sole)
            dpc = np.einsum("vij,njk->vnik", A[:, :3, :3], D_sole)
            J[sel, :, :, bstart:bstart + 3] = JM @ dpc
        return (uv, J) if jacobian else uv

    def params_vector(self, *, joints=None, camera=None, boards=None) -> np.ndarray:
        """Full parameter vector from named parts (missing parts are zero)."""
        lab = self.parameter_labels()
        x = np.zeros(len(lab))
        n = len(self.joint_names)
        for k, v in (joints or {}).items():
            if k not in self.joint_names:
                raise InputError(f"unknown joint {k!r} in offsets (joints: {list(self.joint_names)})")
            x[self.joint_names.index(k)] = v
        if camera is not None:
            x[n:n + 5] = check_array(camera, "camera correction", shape=(5,))
        for fi, foot in enumerate(FEET):
            if boards and foot in boards:
                x[n + 5 + 3 * fi:n + 8 + 3 * fi] = check_array(boards[foot], f"board {foot}", shape=(3,))
        return x

    def corrected_tree(self, params) -> KinematicTree:
        """The tree with joint offsets set and the camera correction folded into the
        camera joint origin (a tree another tool can use with the raw sensor angles)."""
        n = len(self.joint_names)
        tree = self.tree.with_offsets(np.asarray(params[:n], dtype=float))
        cam_joint = self.tree.parent_joint(self.camera_link)
        C = np.eye(4)
        C[:3, :3] = rpy_matrix(*params[n:n + 3])
        C[:3, 3] = [params[n + 3], params[n + 4], 0.0]
        return tree.with_origin(cam_joint.name, cam_joint.origin @ C)


def _leg_joints(chain) -> tuple:
    """Independent joints moving a chain (a mimic joint counts as its leader)."""
    out = []
    for j in chain:
        if j.movable:
            name = j.mimic.joint if j.mimic is not None else j.name
            if name not in out:
                out.append(name)
    return tuple(out)


def tie_joints(tree: KinematicTree, follower: str, leader: str) -> KinematicTree:
    """A copy of ``tree`` where joint ``follower`` mimics ``leader`` (one motor, one offset)."""
    return tree.with_mimic(follower, leader)


def default_model(*, tie_hip_yaw_pitch: bool = False) -> HumanoidModel:
    """The shipped NAO H25 model with the seed's camera and 5 x 7 x 25 mm boards."""
    return HumanoidModel.from_urdf(tie_hip_yaw_pitch=tie_hip_yaw_pitch)
