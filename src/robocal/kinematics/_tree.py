"""Kinematic trees of named joints and links (a humanoid, a URDF robot).

Each :class:`Joint` connects a ``parent`` link to a ``child`` link::

    T_parent_child = origin @ Motion(axis, value)

with ``origin = T_parent_joint`` (the joint frame in the parent link), the
``axis`` in the joint frame, and ``value = q + offset`` (rad for revolute and
continuous joints, m for prismatic; fixed joints have no value). ``offset`` is
the joint's zero offset, the quantity a kinematic calibration estimates (seed
001: ``q_i = theta_i + alpha_i``). A *mimic* joint has no variable of its own:
``value = multiplier * value_leader + mimic.offset + offset`` -- this is how the
two NAO HipYawPitch joints, one motor, share one angle and one offset.

Joint values go in as a dict ``{name: float or array (...)}`` or an array
``(..., n)`` in :attr:`KinematicTree.joint_names` order (the independent,
non-fixed, non-mimic joints). Everything is vectorised over the leading axes.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from robocal.errors import InputError, ShapeError
from robocal.kinematics._common import (
    ORIGIN_PARAM_SUFFIXES,
    check_q,
    check_scalar,
    fast_inverse,
    joint_motion,
    origin_screws,
    screw_column,
    transform_from_xyz_rpy,
    xyz_rpy_from_transform,
)
from robocal.kinematics._joint import Joint, Mimic
from robocal.validation import check_array

__all__ = ["KinematicTree"]


class KinematicTree:
    """A tree of links connected by :class:`Joint` s (see the module docstring).

    Parameters
    ----------
    joints : sequence of Joint
    root : str, optional
        Root link; found from the joints when omitted (required with no joints).
    name : str
        Robot name (URDF ``<robot name>``).

    Notes
    -----
    Transforms follow ``T_a_b`` = pose of frame ``b`` in frame ``a``:
    :meth:`fk` returns ``T_root_link``, ``transform(q, target, source)`` returns
    ``T_target_source``. Jacobian columns are twists ``[d t; w]`` of
    ``T_target_source`` expressed in ``target`` (``w`` from
    ``dR/dx @ R^T = [w]_x``).
    """

    def __init__(self, joints: Sequence[Joint], *, root: str | None = None, name: str = "robot"):
        joints = tuple(joints)
        if not all(isinstance(j, Joint) for j in joints):
            raise InputError("joints must be Joint objects")
        self.name = str(name)
        self._joints = joints
        self._joint = {}
        for j in joints:
            if j.name in self._joint:
                raise InputError(f"joint name {j.name!r} is used twice")
            self._joint[j.name] = j
        self._parent_joint: dict[str, Joint] = {}
        for j in joints:
            if j.child in self._parent_joint:
                raise InputError(
                    f"link {j.child!r} has two parent joints ({self._parent_joint[j.child].name!r}, {j.name!r})"
                )
            self._parent_joint[j.child] = j
        all_links = {j.parent for j in joints} | {j.child for j in joints}
        roots = sorted(all_links - set(self._parent_joint))
        if not joints:
            if root is None:
                raise InputError("a tree without joints needs root=<link name>")
            roots = [root]
        elif root is not None and roots != [root]:
            raise InputError(f"root {root!r} is not the tree's only root link (roots found: {roots})")
        if len(roots) != 1:
            raise InputError(
                "the joints form a cycle (no root link)" if not roots else f"the tree has several root links: {roots}"
            )
        self._root = roots[0]
        self._children: dict[str, list[Joint]] = {}
        for j in joints:
            self._children.setdefault(j.parent, []).append(j)
        order, links, stack = [], [self._root], [self._root]
        while stack:
            for j in self._children.get(stack.pop(0), []):
                order.append(j)
                links.append(j.child)
                stack.append(j.child)
        if len(order) != len(joints):
            stray = sorted({j.name for j in joints} - {j.name for j in order})
            raise InputError(f"joints {stray} are not connected to root {self._root!r} (a cycle?)")
        self._order = tuple(order)
        self._links = tuple(links)
        self._actuated = tuple(j.name for j in joints if j.movable and j.mimic is None)
        self._index = {n: i for i, n in enumerate(self._actuated)}
        for j in joints:
            if j.mimic is not None and j.mimic.joint not in self._index:
                raise InputError(
                    f"joint {j.name!r} mimics {j.mimic.joint!r}, which is not an independent movable joint "
                    f"of this tree"
                )
        self._urdf = None  # parsed URDF element kept by from_urdf, so to_urdf keeps visuals etc.

    # -- description -------------------------------------------------------------------
    @property
    def root(self) -> str:
        return self._root

    @property
    def links(self) -> tuple[str, ...]:
        """Link names, root first, parents before children."""
        return self._links

    @property
    def joints(self) -> tuple[Joint, ...]:
        """All joints in the order given."""
        return self._joints

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Independent joints (non-fixed, non-mimic): the order of array-valued ``q``."""
        return self._actuated

    @property
    def n_joints(self) -> int:
        return len(self._actuated)

    def joint(self, name: str) -> Joint:
        if name not in self._joint:
            raise InputError(f"unknown joint {name!r}; joints: {sorted(self._joint)}")
        return self._joint[name]

    def parent_joint(self, link: str) -> Joint | None:
        """The joint whose child is ``link`` (``None`` for the root)."""
        self._check_link(link)
        return self._parent_joint.get(link)

    def children(self, link: str) -> list[Joint]:
        self._check_link(link)
        return list(self._children.get(link, []))

    def __repr__(self) -> str:
        return f"KinematicTree({self.name!r}, {len(self._links)} links, {self.n_joints} joints, root={self._root!r})"

    def _check_link(self, link: str):
        if link not in self._parent_joint and link != self._root:
            raise InputError(f"unknown link {link!r}; links: {list(self._links)}")

    def with_mimic(self, follower: str, leader: str | None, *, multiplier: float = 1.0,
                   offset: float = 0.0) -> "KinematicTree":
        """A copy where joint ``follower`` mimics ``leader`` (URDF ``<mimic>``).

        ``q[follower] = multiplier * q[leader] + offset``: one motor drives both,
        so the follower loses its own actuated entry and calibration offset
        (NAO's two HipYawPitch joints). ``leader=None`` makes it independent
        again, with zero offset.
        """
        j = self.joint(follower)
        if not j.movable:
            raise InputError(f"joint {follower!r} is fixed and cannot mimic another joint")
        if leader is None:
            new = replace(j, mimic=None, offset=0.0)
        else:
            lead = self.joint(leader)
            if leader == follower or not lead.movable or lead.mimic is not None:
                raise InputError(f"joint {follower!r} can mimic only another independent movable joint, "
                                 f"got {leader!r}")
            new = replace(j, mimic=Mimic(leader, multiplier, offset), offset=0.0)
        return self._derived([new if jj.name == follower else jj for jj in self.joints])

    def _derived(self, joints) -> "KinematicTree":
        tree = KinematicTree(joints, root=self._root, name=self.name)
        tree._urdf = self._urdf
        return tree

    # -- calibration parameters -----------------------------------------------------------
    @property
    def offsets(self) -> np.ndarray:
        """Offsets of the independent joints, (n_joints,), in :attr:`joint_names` order."""
        return np.array([self._joint[n].offset for n in self._actuated])

    def with_offsets(self, offsets) -> "KinematicTree":
        """A copy with new offsets: an array in :attr:`joint_names` order, or a dict
        ``{joint: offset}`` (may also name mimic joints, whose own offset adds on)."""
        if isinstance(offsets, Mapping):
            new = {}
            for k, v in offsets.items():
                if not self.joint(k).movable:
                    raise InputError(f"joint {k!r} is fixed and has no offset")
                new[k] = check_scalar(v, f"offsets[{k!r}]")
        else:
            arr = check_array(offsets, "offsets", shape=(self.n_joints,))
            if arr.ndim != 1:
                raise ShapeError(f"offsets must have shape ({self.n_joints},), got {arr.shape}")
            new = dict(zip(self._actuated, arr.tolist()))
        return self._derived([replace(j, offset=new[j.name]) if j.name in new else j for j in self._joints])

    def origin_params(self, joint: str) -> np.ndarray:
        """``[x, y, z, roll, pitch, yaw]`` of a joint origin (m, rad; URDF fixed-axis rpy)."""
        return xyz_rpy_from_transform(self.joint(joint).origin)

    def origin_param_names(self, joints: Sequence[str]) -> list[str]:
        """``'<joint>.x' ... '<joint>.yaw'``: the columns of :meth:`origin_jacobian`."""
        return [f"{j}.{s}" for j in joints for s in ORIGIN_PARAM_SUFFIXES]

    def with_origin(self, joint: str, origin) -> "KinematicTree":
        """A copy with one joint origin replaced: a (4, 4) transform or ``[x, y, z, roll, pitch, yaw]``."""
        arr = check_array(origin, "origin")
        if arr.shape == (6,):
            arr = transform_from_xyz_rpy(arr[:3], arr[3:])
        elif arr.shape != (4, 4):
            raise ShapeError(f"origin must have shape (4, 4) or (6,), got {arr.shape}")
        target = self.joint(joint)
        return self._derived([replace(j, origin=arr) if j is target else j for j in self._joints])

    def fold_offsets(self) -> "KinematicTree":
        """The equivalent tree with every offset folded into its joint origin.

        ``origin' = origin @ Motion(c)`` with ``c = offset`` (plus
        ``multiplier * leader offset`` for a mimic joint); then all offsets are
        0 and :meth:`fk` is unchanged. This is the form a URDF can carry.
        """
        out = []
        for j in self._joints:
            if not j.movable:
                out.append(j)
                continue
            c = j.offset + (j.mimic.multiplier * self._joint[j.mimic.joint].offset if j.mimic else 0.0)
            out.append(replace(j, origin=j.origin @ joint_motion(j.type, j.axis, c), offset=0.0))
        return self._derived(out)

    # -- joint values -------------------------------------------------------------------------
    def _values(self, q, default):
        """Batch shape and ``{joint: value incl. offset}`` for every movable joint."""
        n = self.n_joints
        if isinstance(q, Mapping):
            for k in q:
                j = self.joint(k)
                if not j.movable or j.mimic is not None:
                    why = "fixed" if not j.movable else f"a mimic of {j.mimic.joint!r}; give that joint instead"
                    raise InputError(f"q[{k!r}]: joint {k!r} is {why}")
            missing = [k for k in self._actuated if k not in q]
            if missing and default is None:
                raise InputError(f"q is missing joints {missing} (pass default=0.0 to fill them)")
            raw = [check_array(q[k], f"q[{k!r}]") if k in q else check_scalar(default, "default")
                   for k in self._actuated]
            try:
                raw = np.broadcast_arrays(*raw) if raw else []
            except ValueError:
                shapes = {k: np.shape(v) for k, v in zip(self._actuated, raw)}
                raise ShapeError(f"q values must have broadcastable shapes, got {shapes}") from None
            batch = raw[0].shape if raw else ()
        else:
            arr = check_q(q, self._actuated)
            batch, raw = arr.shape[:-1], [arr[..., i] for i in range(n)]
        vals = {k: r + self._joint[k].offset for k, r in zip(self._actuated, raw)}
        for j in self._joints:
            if j.mimic is not None:
                vals[j.name] = j.mimic.multiplier * vals[j.mimic.joint] + j.mimic.offset + j.offset
        return batch, vals

    def within_limits(self, q, *, default=None) -> np.ndarray:
        """Boolean (...): every independent joint variable within its limits."""
        batch, vals = self._values(q, default)
        ok = np.ones(batch, dtype=bool)
        for k in self._actuated:
            lim = self._joint[k].limits
            if lim is not None:
                raw = vals[k] - self._joint[k].offset
                ok &= (raw >= lim[0]) & (raw <= lim[1])
        return ok

    # -- kinematics -----------------------------------------------------------------------------
    def fk(self, q, *, default: float | None = None) -> dict[str, np.ndarray]:
        """Pose of every link in the root frame: ``{link: T_root_link (..., 4, 4)}``.

        Parameters
        ----------
        q : dict or array_like (..., n_joints)
            Joint variables (rad, m); see the module docstring.
        default : float, optional
            Value for independent joints missing from a dict ``q`` (an error
            when not given).
        """
        batch, vals = self._values(q, default)
        out = {self._root: np.array(np.broadcast_to(np.eye(4), batch + (4, 4)))}
        for j in self._order:
            out[j.child] = out[j.parent] @ j._transform_value(vals.get(j.name))
        return out

    def chain(self, root: str, tip: str) -> list[Joint]:
        """Joints from link ``root`` down to link ``tip`` (``root`` must be an ancestor)."""
        self._check_link(root)
        self._check_link(tip)
        out, link = [], tip
        while link != root:
            j = self._parent_joint.get(link)
            if j is None:
                raise InputError(f"link {root!r} is not an ancestor of link {tip!r}")
            out.append(j)
            link = j.parent
        return out[::-1]

    def _path(self, target: str, source: str):
        """Joints from the common ancestor down to ``target`` and down to ``source``."""
        self._check_link(target)
        self._check_link(source)
        above_t, link = [target], target
        while link != self._root:
            link = self._parent_joint[link].parent
            above_t.append(link)
        link = source
        while link not in above_t:
            link = self._parent_joint[link].parent
        return self.chain(link, target), self.chain(link, source)

    @staticmethod
    def _walk(joints, vals, batch):
        """Frames along a downward path: parent frames, joint frames, end frame (in the start link)."""
        T = np.broadcast_to(np.eye(4), batch + (4, 4))
        parents, frames = [], []
        for j in joints:
            parents.append(T)
            G = T @ j.origin
            frames.append(G)
            T = G @ joint_motion(j.type, j.axis, vals[j.name]) if j.movable else G
        return parents, frames, T

    def transform(self, q, target: str, source: str, *, default: float | None = None) -> np.ndarray:
        """``T_target_source`` (..., 4, 4): maps points in link ``source`` into link ``target``.

        Only the joints on the path between the two links are evaluated.
        """
        batch, vals = self._values(q, default)
        up, down = self._path(target, source)
        _, _, T_a_t = self._walk(up, vals, batch)
        _, _, T_a_s = self._walk(down, vals, batch)
        return np.array(np.broadcast_to(fast_inverse(T_a_t) @ T_a_s, batch + (4, 4)))

    def _path_setup(self, q, target, source, default):
        batch, vals = self._values(q, default)
        up, down = self._path(target, source)
        pu, fu, T_a_t = self._walk(up, vals, batch)
        pd, fd, T_a_s = self._walk(down, vals, batch)
        T_t_a = fast_inverse(T_a_t)
        p = (T_t_a @ T_a_s)[..., :3, 3]
        p = np.broadcast_to(p, batch + (3,))
        # Joints on the target side enter T_target_source inverted, hence sign -1.
        sides = [(down, pd, fd, 1.0), (up, pu, fu, -1.0)]
        return batch, T_t_a, p, sides

    def jacobian(self, q, target: str, source: str, *, default: float | None = None) -> np.ndarray:
        """Geometric Jacobian of ``T_target_source`` w.r.t. :attr:`joint_names`, (..., 6, n_joints).

        Column ``k`` is the twist ``[d t; w]`` in frame ``target`` per unit of
        joint variable ``k``; a mimic joint adds ``multiplier`` times its column
        to its leader's. Joints off the path give zero columns. For the usual
        "link Jacobian in the base frame" use ``target=tree.root``.
        """
        batch, T_t_a, p, sides = self._path_setup(q, target, source, default)
        J = np.zeros(batch + (6, self.n_joints))
        for joints, _, frames, sign in sides:
            for j, G in zip(joints, frames):
                if not j.movable:
                    continue
                col = sign * screw_column(T_t_a @ G, j.axis, j.type != "prismatic", p)
                if j.mimic is None:
                    J[..., self._index[j.name]] += col
                else:
                    J[..., self._index[j.mimic.joint]] += j.mimic.multiplier * col
        return J

    def offset_jacobian(self, q, target: str, source: str, *, default: float | None = None) -> np.ndarray:
        """Derivative of ``T_target_source`` w.r.t. :attr:`offsets`, (..., 6, n_joints).

        An offset adds to its joint variable, so this equals :meth:`jacobian`
        (mimic joints tie their leader's offset, as the shared NAO hip motor
        needs). Twist convention as in :meth:`jacobian`.

        References
        ----------
        Seed 001 (joint-offset calibration of the legs, ``q = theta + alpha``).
        """
        return self.jacobian(q, target, source, default=default)

    def origin_jacobian(self, q, target: str, source: str, joints: Sequence[str], *,
                        default: float | None = None) -> np.ndarray:
        """Derivative of ``T_target_source`` w.r.t. ``x, y, z, roll, pitch, yaw`` of joint origins.

        Returns (..., 6, 6 * len(joints)) with columns named by
        :meth:`origin_param_names`; a joint off the path gives zero columns.
        Twist convention as in :meth:`jacobian` (used for camera-mount
        calibration: perturb the camera joint's origin).
        """
        for name in joints:
            self.joint(name)
        batch, T_t_a, p, sides = self._path_setup(q, target, source, default)
        J = np.zeros(batch + (6, 6 * len(joints)))
        where = {n: k for k, n in enumerate(joints)}
        for path, parents, _, sign in sides:
            for j, P in zip(path, parents):
                if j.name not in where:
                    continue
                k = 6 * where[j.name]
                screws = origin_screws(T_t_a @ P, xyz_rpy_from_transform(j.origin))
                for m, (G, ax, rev) in enumerate(screws):
                    J[..., k + m] += sign * screw_column(G, ax, rev, p)
        return J

    # -- files --------------------------------------------------------------------------------------
    @classmethod
    def from_urdf(cls, source) -> "KinematicTree":
        """Load a URDF (path or XML text); see :func:`robocal.kinematics.tree_from_urdf`."""
        from robocal.kinematics._urdf import tree_from_urdf

        return tree_from_urdf(source)

    def to_urdf(self, path=None, *, fold_offsets: bool = True) -> str:
        """URDF text of this tree (written to ``path`` too if given); see
        :func:`robocal.kinematics.urdf_from_tree`."""
        from robocal.kinematics._urdf import urdf_from_tree

        return urdf_from_tree(self, path, fold_offsets=fold_offsets)
