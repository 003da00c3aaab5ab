"""URDF reading and writing for :class:`~robocal.kinematics.KinematicTree`.

Only the kinematic part is interpreted: ``<link name>``, and per ``<joint>``
its type (revolute, continuous, prismatic, fixed), ``<parent>``, ``<child>``,
``<origin xyz rpy>`` (rpy fixed-axis: ``R = Rz(yaw) Ry(pitch) Rx(roll)``),
``<axis xyz>`` (default ``1 0 0``), ``<limit lower upper>`` and
``<mimic joint multiplier offset>``. Everything else (visuals, inertials,
transmissions, gazebo tags) is kept verbatim when a loaded tree is written
back, so a calibrated URDF differs from the original only in joint origins.

Parsing uses :mod:`xml.etree.ElementTree` (no entity expansion beyond XML's
own, no network access). Any problem raises
:class:`~robocal.errors.FileFormatError` naming the file and the element.
"""

from __future__ import annotations

import copy
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from robocal.errors import FileFormatError, RobocalError
from robocal.io import atomic_write_text
from robocal.kinematics._common import transform_from_xyz_rpy, xyz_rpy_from_transform
from robocal.kinematics._joint import Joint, Mimic
from robocal.kinematics._tree import KinematicTree

__all__ = ["tree_from_urdf", "urdf_from_tree"]

_SUPPORTED = ("revolute", "continuous", "prismatic", "fixed")


def _read_source(source) -> tuple[ET.Element, str]:
    if isinstance(source, bytes):
        text, label = source.decode("utf-8", errors="replace"), "<urdf string>"
    elif isinstance(source, str) and source.lstrip().startswith("<"):
        text, label = source, "<urdf string>"
    else:
        label = str(source)
        try:
            text = Path(source).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise FileFormatError(f"cannot read URDF: {exc}", source=label) from None
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise FileFormatError(f"not well-formed XML ({exc})", source=label) from None
    return root, label


def _numbers(elem: ET.Element, attr: str, count: int, default: str | None, where: str) -> np.ndarray:
    text = elem.get(attr, default)
    if text is None:
        raise FileFormatError(f"{where}: <{elem.tag}> needs attribute {attr!r}")
    try:
        vals = np.array([float(t) for t in text.split()])
    except ValueError:
        raise FileFormatError(f"{where}: <{elem.tag} {attr}> must be {count} numbers, got {text!r}") from None
    if vals.shape != (count,) or not np.all(np.isfinite(vals)):
        raise FileFormatError(f"{where}: <{elem.tag} {attr}> must be {count} finite numbers, got {text!r}")
    return vals


def _parse_joint(elem: ET.Element, index: int, links: set[str]) -> Joint:
    name = elem.get("name")
    if not name:
        raise FileFormatError(f"<joint> #{index + 1} has no name attribute")
    where = f"joint {name!r}"
    kind = elem.get("type")
    if kind not in _SUPPORTED:
        raise FileFormatError(f"{where}: type {kind!r} is not supported (expected one of {list(_SUPPORTED)})")
    ends = {}
    for tag in ("parent", "child"):
        sub = elem.find(tag)
        if sub is None or not sub.get("link"):
            raise FileFormatError(f"{where}: missing <{tag} link=...>")
        if sub.get("link") not in links:
            raise FileFormatError(f"{where}: <{tag} link={sub.get('link')!r}> names no <link> of the robot")
        ends[tag] = sub.get("link")
    origin = np.eye(4)
    o = elem.find("origin")
    if o is not None:
        origin = transform_from_xyz_rpy(_numbers(o, "xyz", 3, "0 0 0", where), _numbers(o, "rpy", 3, "0 0 0", where))
    axis = np.array([1.0, 0.0, 0.0])
    a = elem.find("axis")
    if a is not None and kind != "fixed":
        axis = _numbers(a, "xyz", 3, "1 0 0", where)
        if np.linalg.norm(axis) < 1e-12:
            raise FileFormatError(f"{where}: <axis xyz> must not be zero, got {a.get('xyz')!r}")
    limits = None
    lim = elem.find("limit")
    if lim is not None and kind in ("revolute", "prismatic"):
        lo = _numbers(lim, "lower", 1, "0", where)[0]
        hi = _numbers(lim, "upper", 1, "0", where)[0]
        if lo > hi:
            raise FileFormatError(f"{where}: <limit> lower {lo:g} > upper {hi:g}")
        # URDF defaults both to 0; a revolute joint with 0..0 means "not given".
        limits = None if lo == hi == 0.0 else (lo, hi)
    mimic = None
    m = elem.find("mimic")
    if m is not None and kind != "fixed":
        if not m.get("joint"):
            raise FileFormatError(f"{where}: <mimic> needs attribute 'joint'")
        mimic = Mimic(m.get("joint"), _numbers(m, "multiplier", 1, "1", where)[0], _numbers(m, "offset", 1, "0", where)[0])
    try:
        return Joint(name, ends["parent"], ends["child"], origin, axis, kind, limits, 0.0, mimic)
    except RobocalError as exc:
        raise FileFormatError(f"{where}: {exc}") from None


def tree_from_urdf(source) -> KinematicTree:
    """Build a :class:`KinematicTree` from a URDF file path or URDF XML text.

    Parameters
    ----------
    source : str, path-like or bytes
        A path, or the XML itself (a string starting with ``<``).

    Raises
    ------
    FileFormatError
        Unreadable file, malformed XML, missing or bad elements/attributes,
        unsupported joint types (floating, planar), links that are not a tree.
    """
    root, label = _read_source(source)
    if root.tag != "robot":
        raise FileFormatError(f"root element must be <robot>, got <{root.tag}>", source=label)
    try:
        links = []
        for i, lk in enumerate(root.findall("link")):
            if not lk.get("name"):
                raise FileFormatError(f"<link> #{i + 1} has no name attribute")
            links.append(lk.get("name"))
        if len(set(links)) != len(links):
            dup = sorted({n for n in links if links.count(n) > 1})
            raise FileFormatError(f"<link> names used twice: {dup}")
        if not links:
            raise FileFormatError("<robot> has no <link>")
        joints = [_parse_joint(e, i, set(links)) for i, e in enumerate(root.findall("joint"))]
        try:
            tree = KinematicTree(joints, name=root.get("name", "robot"), root=None if joints else links[0])
        except RobocalError as exc:
            raise FileFormatError(f"<joint> structure: {exc}") from None
        stray = sorted(set(links) - set(tree.links))
        if stray:
            raise FileFormatError(f"<link> {stray} not connected to the tree rooted at {tree.root!r}")
    except FileFormatError as exc:
        raise exc.with_source(label) from None
    tree._urdf = copy.deepcopy(root)
    return tree


def _fmt(values) -> str:
    # repr() of a float is the shortest string that reads back to the same double.
    return " ".join(repr(float(v)) for v in np.atleast_1d(values))


def _set_child(parent: ET.Element, tag: str, attrs: dict[str, str]) -> ET.Element:
    elem = parent.find(tag)
    if elem is None:
        elem = ET.SubElement(parent, tag)
    for k, v in attrs.items():
        elem.set(k, v)
    return elem


def _fill_joint(elem: ET.Element, j: Joint) -> None:
    xyz_rpy = xyz_rpy_from_transform(j.origin)
    elem.set("name", j.name)
    elem.set("type", j.type)
    _set_child(elem, "parent", {"link": j.parent})
    _set_child(elem, "child", {"link": j.child})
    _set_child(elem, "origin", {"xyz": _fmt(xyz_rpy[:3]), "rpy": _fmt(xyz_rpy[3:])})
    if j.movable:
        _set_child(elem, "axis", {"xyz": _fmt(j.axis)})
    if j.limits is not None:
        lim = _set_child(elem, "limit", {"lower": _fmt(j.limits[0]), "upper": _fmt(j.limits[1])})
        # URDF requires effort and velocity; 0 here means "unknown", not "cannot move".
        lim.set("effort", lim.get("effort", "0"))
        lim.set("velocity", lim.get("velocity", "0"))
    if j.mimic is not None:
        _set_child(elem, "mimic", {"joint": j.mimic.joint, "multiplier": _fmt(j.mimic.multiplier),
                                   "offset": _fmt(j.mimic.offset)})


def urdf_from_tree(tree: KinematicTree, path=None, *, fold_offsets: bool = True) -> str:
    """URDF text for ``tree``; also written atomically to ``path`` when given.

    Parameters
    ----------
    tree : KinematicTree
    path : str or path-like, optional
    fold_offsets : bool
        Fold joint offsets into the origins (:meth:`KinematicTree.fold_offsets`),
        which is how a calibrated URDF carries them. With ``False`` any non-zero
        offset raises, since URDF has no field for it.

    Notes
    -----
    A tree loaded by :func:`tree_from_urdf` is written by editing a copy of
    the original document (joint origins, axes, limits, mimic), so visuals,
    inertials and other tags survive. Other trees get links with names only.
    """
    if fold_offsets:
        tree = tree.fold_offsets()
    else:
        bad = [j.name for j in tree.joints if j.offset != 0.0]
        if bad:
            raise FileFormatError(f"joints {bad} have non-zero offsets, which URDF cannot store; use fold_offsets=True")
    base = tree._urdf
    names = {e.get("name") for e in base.findall("joint")} if base is not None else set()
    if base is not None and names == {j.name for j in tree.joints}:
        root = copy.deepcopy(base)
        by_name = {e.get("name"): e for e in root.findall("joint")}
        for j in tree.joints:
            _fill_joint(by_name[j.name], j)
    else:
        root = ET.Element("robot", {"name": tree.name})
        for link in tree.links:
            ET.SubElement(root, "link", {"name": link})
        for j in tree.joints:
            _fill_joint(ET.SubElement(root, "joint"), j)
    ET.indent(root)
    text = '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
    if path is not None:
        atomic_write_text(path, text)
    return text
