"""The tf tree of a recording (``/tf`` + ``/tf_static``), resolved between any two frames at any stamps.

tf's convention: a ``TransformStamped`` with ``header.frame_id = parent`` and
``child_frame_id = child`` is the pose of ``child`` in ``parent``, i.e. it maps
child-frame points into the parent frame: ``T_parent_child`` in robocal's
naming (docs/conventions.md). Each child has one parent; the tree's edges are
*static* (``/tf_static``, one value for all time) or *dynamic* (``/tf``, a
time series interpolated at the stamps asked for: SLERP for the rotation,
linear for the translation, :func:`robocal.io.interpolate_poses`).

Frame names lose a leading ``/`` (ROS 1's ``/base_link`` is ``base_link``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robocal.bags._reader import UnknownFrameError, closest_names, open_recording, seconds_from_ns, stamp_ns
from robocal.errors import InputError

__all__ = ["TfEdge", "TfTree", "PoseStream", "read_tf", "CLOCK_MISMATCH", "tf_clock_offset"]

#: Two streams whose median (receive - header) [s] differ by more than this look like two clocks (a camera's
#: own, sim time): transport latencies differ by milliseconds. The one threshold of every rig's bag reader.
CLOCK_MISMATCH = 0.1

#: Message types that carry tf (ROS 2 / ROS 1 tf2, ROS 1's old tf).
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")


def _frame(name: str) -> str:
    return name.lstrip("/")


def tf_clock_offset(edges) -> float | None:
    """Median receive time minus header stamp [s] over the dynamic edges of a tf chain (``None`` when every
    edge is static: static transforms carry no clock), the tf side of a clock comparison."""
    dyn = [e.receive_ns - e.stamps_ns for e in edges if not e.static]
    return float(np.median(np.concatenate(dyn))) / 1e9 if dyn else None


@dataclass(frozen=True)
class TfEdge:
    """One parent -> child transform: ``T`` (N, 4, 4) ``T_parent_child`` [m] at ``stamps_ns`` (N,) header stamps."""

    parent: str
    child: str
    static: bool
    stamps_ns: np.ndarray
    T: np.ndarray
    receive_ns: np.ndarray

    @property
    def rate(self) -> float:
        """Median rate [Hz] of a dynamic edge (0 for a static one or a single sample)."""
        if self.static or len(self.stamps_ns) < 2:
            return 0.0
        d = np.diff(self.stamps_ns)
        return float(1e9 / np.median(d)) if np.median(d) > 0 else 0.0


@dataclass(frozen=True)
class PoseStream:
    """Poses ``T_parent_child`` (N, 4, 4) [m] at ``stamps_ns`` (N,) int64 [ns, header clock].

    ``gap`` (N,) [s]: for each stamp, the largest distance, over the dynamic
    edges of the chain, to the nearest recorded sample (0 where every edge is
    static or sampled at that stamp): how far the answer is interpolated.
    ``edges``: the chain, as ``(parent, child, "static" | "dynamic")``.
    """

    parent: str
    child: str
    stamps_ns: np.ndarray
    T: np.ndarray
    gap: np.ndarray
    edges: tuple

    @property
    def stamps(self) -> np.ndarray:
        """Stamps [s] (float64; ``stamps_ns`` is exact)."""
        return seconds_from_ns(self.stamps_ns)

    @property
    def position(self) -> np.ndarray:
        """(N, 3) translation [m] of ``child`` in ``parent``."""
        return self.T[:, :3, 3]

    @property
    def quaternion(self) -> np.ndarray:
        """(N, 4) rotation, scalar-last ``(x, y, z, w)``."""
        from scipy.spatial.transform import Rotation

        return Rotation.from_matrix(self.T[:, :3, :3]).as_quat()


def _matrices(q: np.ndarray, p: np.ndarray, where: str) -> np.ndarray:
    """(N, 4, 4) from quaternions (N, 4) scalar-last and translations (N, 3), one batch (SciPy)."""
    from scipy.spatial.transform import Rotation

    with np.errstate(over="ignore", invalid="ignore"):  # a damaged message's 1e300s are refused below, not warned
        n = np.linalg.norm(q, axis=1)
    # tf2 itself refuses a quaternion off unit length by more than 0.01 (tf2::BufferCore::setTransform)
    bad = ~((np.abs(n - 1.0) < 1e-2) & np.all(np.isfinite(p), axis=1))
    if np.any(bad):
        k = int(np.argmax(bad))
        raise InputError(f"{where}: {int(bad.sum())} transform(s) not finite or with a quaternion not of unit length, "
                         f"first sample {k} (|q| = {n[k]:.6g}, translation {p[k].tolist()})")
    T = np.zeros((len(q), 4, 4))
    T[:, :3, :3] = Rotation.from_quat(q).as_matrix()
    T[:, :3, 3], T[:, 3, 3] = p, 1.0
    return T


class TfTree:
    """Every tf edge of a recording; :meth:`lookup` resolves any frame against any other."""

    def __init__(self, edges: dict, source: str = "<recording>"):
        self.edges = edges  # child -> TfEdge
        self.source = source

    @property
    def frames(self) -> list[str]:
        """Every frame named in the tree, sorted."""
        return sorted({e.child for e in self.edges.values()} | {e.parent for e in self.edges.values()})

    def _check(self, frame: str) -> str:
        frame = _frame(frame)
        if frame not in self.frames:
            raise UnknownFrameError(f"{self.source}: no tf frame '{frame}'{closest_names(frame, self.frames)}; "
                                    f"{len(self.frames)} frame(s): {', '.join(self.frames[:15])}")
        return frame

    def _chain(self, frame: str) -> list[str]:
        """``[frame, parent, grandparent, ..., root]``."""
        chain = [frame]
        while chain[-1] in self.edges:
            chain.append(self.edges[chain[-1]].parent)
            if len(chain) > len(self.edges) + 1:
                raise InputError(f"{self.source}: the tf tree has a cycle through '{frame}'")
        return chain

    def path(self, parent: str, child: str) -> tuple[list[str], list[str]]:
        """The frames from ``parent`` up to the common ancestor, and from ``child`` up to it."""
        parent, child = self._check(parent), self._check(child)
        up_p, up_c = self._chain(parent), self._chain(child)
        common = next((f for f in up_c if f in up_p), None)
        if common is None:
            raise UnknownFrameError(f"{self.source}: tf frames '{parent}' (tree root '{up_p[-1]}') and '{child}' "
                                    f"(root '{up_c[-1]}') are not connected: no transform links the two trees")
        return up_p[:up_p.index(common) + 1], up_c[:up_c.index(common) + 1]

    def _edge_at(self, edge: TfEdge, q_ns: np.ndarray, t0: int) -> tuple[np.ndarray, np.ndarray]:
        """``T_parent_child`` at ``q_ns`` and the distance [s] to the nearest sample."""
        from robocal.io import interpolate_poses

        if edge.static:
            return np.broadcast_to(edge.T[-1], (len(q_ns), 4, 4)), np.zeros(len(q_ns))
        s = edge.stamps_ns
        lo, hi = s[0], s[-1]
        out = (q_ns < lo) | (q_ns > hi)
        if np.any(out):
            k = int(np.argmax(out))
            raise InputError(f"{self.source}: tf {edge.parent} -> {edge.child} is recorded from "
                             f"{(lo - t0) / 1e9:.3f} to {(hi - t0) / 1e9:.3f} s; {int(out.sum())} stamp(s) outside, "
                             f"first {(q_ns[k] - t0) / 1e9:.3f} s (relative to the first stamp asked): no extrapolation")
        i = np.clip(np.searchsorted(s, q_ns), 1, len(s) - 1)
        gap = np.minimum(q_ns - s[i - 1], s[i] - q_ns) / 1e9
        if len(s) == 1:
            return np.broadcast_to(edge.T[0], (len(q_ns), 4, 4)), np.zeros(len(q_ns))
        # times relative to the first query, in float seconds: exact to ~1e-16 s instead of the 0.2 us of epoch floats
        return interpolate_poses((s - t0) / 1e9, edge.T, (q_ns - t0) / 1e9), np.abs(gap)

    def lookup(self, parent: str, child: str, stamps=None) -> PoseStream:
        """``T_parent_child`` at ``stamps``.

        Parameters
        ----------
        parent, child : str
            tf frame names (a leading ``/`` is ignored).
        stamps : array_like, shape (N,), optional
            Integer nanoseconds (int64) or float seconds, on the header clock;
            default: the stamps of the chain's fastest dynamic edge (or one
            stamp for an all-static chain).

        Raises
        ------
        UnknownFrameError
            A frame not in the tree (closest names offered) or not connected.
        InputError
            A stamp outside a dynamic edge's recorded span (no extrapolation).
        """
        up_p, up_c = self.path(parent, child)
        chain = [self.edges[f] for f in up_p[:-1]] + [self.edges[f] for f in up_c[:-1]]
        if stamps is None:
            dyn = [e for e in chain if not e.static]
            q_ns = max(dyn, key=lambda e: len(e.stamps_ns)).stamps_ns if dyn else np.zeros(1, np.int64)
            if dyn:  # only the stamps every edge covers
                q_ns = q_ns[(q_ns >= max(e.stamps_ns[0] for e in dyn)) & (q_ns <= min(e.stamps_ns[-1] for e in dyn))]
                if not len(q_ns):
                    raise InputError(f"{self.source}: the dynamic tf edges from '{parent}' to '{child}' "
                                     f"({', '.join(f'{e.parent} -> {e.child}' for e in dyn)}) are never recorded "
                                     "at the same time")
        else:
            st = np.atleast_1d(np.asarray(stamps))
            q_ns = st.astype(np.int64) if np.issubdtype(st.dtype, np.integer) else np.round(st * 1e9).astype(np.int64)
        t0 = int(q_ns[0]) if len(q_ns) else 0

        def root_from(frames):  # T_common_frame for frames[0]: the product along its chain
            T = np.broadcast_to(np.eye(4), (len(q_ns), 4, 4))
            gap = np.zeros(len(q_ns))
            for f in frames[:-1]:
                Te, g = self._edge_at(self.edges[f], q_ns, t0)
                T, gap = Te @ T, np.maximum(gap, g)
            return T, gap

        T_cp, g_p = root_from(up_p)
        T_cc, g_c = root_from(up_c)
        from robocal.geometry import invert_transform

        T = invert_transform(T_cp) @ T_cc
        edges = tuple((e.parent, e.child, "static" if e.static else "dynamic") for e in chain)
        return PoseStream(_frame(parent), _frame(child), q_ns, T, np.maximum(g_p, g_c), edges)


def read_tf(path, *, topics=("/tf", "/tf_static"), show_progress: bool = True) -> TfTree:
    """Read a recording's tf tree (every transform of ``topics`` that is in it).

    A child published with two different parents, or on both topics, is an
    error naming both. Samples of one edge are sorted by header stamp;
    repeated stamps keep the last value (tf's behaviour).
    """
    samples: dict = {}
    with open_recording(path) as rec:
        present = [t for t in topics if t in rec.topics]
        if not present:
            raise InputError(f"{rec.path}: no tf topic ({', '.join(topics)}); tf topics: "
                             f"{', '.join(rec.topics_of_type(TF_TYPES)) or 'none'}")
        for t in present:
            rec.topic(t, TF_TYPES)
        for topic, recv, data in rec.raw(present, show_progress=show_progress):
            msg = rec.deserialize(topic, data)
            static = topic.endswith("tf_static")
            for tr in msg.transforms:
                child, parent = _frame(tr.child_frame_id), _frame(tr.header.frame_id)
                key = samples.setdefault(child, {"parent": parent, "static": static, "s": [], "T": [], "r": []})
                if key["parent"] != parent or key["static"] != static:
                    raise InputError(f"{rec.path}: tf frame '{child}' has two parents or kinds: "
                                     f"'{key['parent']}' ({'static' if key['static'] else 'dynamic'}) and "
                                     f"'{parent}' ({'static' if static else 'dynamic'}, on {topic})")
                key["s"].append(stamp_ns(tr.header.stamp))
                r, t = tr.transform.rotation, tr.transform.translation
                key["T"].append((r.x, r.y, r.z, r.w, t.x, t.y, t.z))
                key["r"].append(recv)
        edges = {}
        for child, k in samples.items():
            s = np.asarray(k["s"], np.int64)
            order = np.argsort(s, kind="stable")
            qp = np.asarray(k["T"], float)[order]
            T = _matrices(qp[:, :4], qp[:, 4:], f"{rec.path}: tf {k['parent']} -> {child}")
            s, r = s[order], np.asarray(k["r"], np.int64)[order]
            keep = np.append(s[1:] != s[:-1], True)  # a repeated stamp: the last one published wins
            edges[child] = TfEdge(k["parent"], child, k["static"], s[keep], T[keep], r[keep])
        return TfTree(edges, str(rec.path))
