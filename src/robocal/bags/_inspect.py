"""What is in a recording: topics, types, counts, rates, time span, gaps, clocks, the tf tree.

The library side of ``robocal bag inspect FILE``: :func:`inspect_recording`
returns a :class:`RecordingSummary`; its :meth:`~RecordingSummary.text` is what
the command prints.

Gaps: a pause between two messages of a topic longer than ``GAP_FACTOR``
times its median period (dropped messages, a stalled driver).
Clocks: for topics whose messages carry a ``std_msgs/Header``, the median of
receive time minus header stamp. Transport takes milliseconds; a median
below ``-CLOCK_AHEAD`` s (a header stamp from the recorder's future) or above
``CLOCK_LATE`` s means the sender stamps on another clock than the recorder
(sim time, an unsynchronised machine, a camera's own clock): flagged.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robocal.bags._reader import open_recording
from robocal.bags._tf import TF_TYPES, read_tf

__all__ = ["TopicSummary", "RecordingSummary", "inspect_recording", "GAP_FACTOR"]

GAP_FACTOR = 3.0
CLOCK_AHEAD = 0.05  # s: more than any clock jitter of a synchronised (NTP/PTP) machine
CLOCK_LATE = 1.0    # s: more than any transport or buffering delay


@dataclass(frozen=True)
class TopicSummary:
    """One topic: ``rate`` [Hz] from the median receive period, ``gaps`` as ``(start [s from the recording's
    start], length [s])``, ``clock_offset`` [s] = median(receive - header) (None without header)."""

    name: str
    msgtype: str
    count: int
    start: float
    end: float
    rate: float
    gaps: tuple
    clock_offset: float | None
    clock_flag: str = ""
    detail: str = ""


@dataclass(frozen=True)
class RecordingSummary:
    """A recording's topics (:class:`TopicSummary`) and tf edges (``(parent, child, kind, rate [Hz], count)``)."""

    path: str
    format: str
    size_bytes: int
    start_ns: int
    end_ns: int
    topics: tuple
    tf_edges: tuple = field(default_factory=tuple)

    @property
    def duration(self) -> float:
        """Seconds from the first to the last message (receive time)."""
        return (self.end_ns - self.start_ns) / 1e9

    @property
    def flagged_clocks(self) -> list[TopicSummary]:
        return [t for t in self.topics if t.clock_flag]

    def tf_text(self) -> list[str]:
        """The tf tree, one frame a line, children indented under their parent."""
        children: dict = {}
        for parent, child, kind, rate, count in self.tf_edges:
            children.setdefault(parent, []).append((child, kind, rate, count))
        kids = {c for _, c, *_ in self.tf_edges}
        lines = []

        def walk(frame, depth):
            for child, kind, rate, count in sorted(children.get(frame, [])):
                what = "static" if kind == "static" else f"dynamic, {rate:.1f} Hz, {count} samples"
                lines.append(f"{'  ' * depth}{child}  <- {frame}  ({what})")
                walk(child, depth + 1)

        for root in sorted(set(children) - kids):
            lines.append(root)
            walk(root, 1)
        return lines

    def text(self) -> str:
        """The report ``robocal bag inspect`` prints."""
        out = [f"recording: {self.path}",
               f"format: {self.format}, {self.size_bytes / 1e6:.1f} MB, {len(self.topics)} topics, "
               f"{sum(t.count for t in self.topics)} messages",
               f"time span: {self.duration:.3f} s (receive time {self.start_ns / 1e9:.3f} .. {self.end_ns / 1e9:.3f} s)",
               "", f"{'topic':32s} {'type':34s} {'count':>7s} {'rate Hz':>8s} {'clock':>10s}"]
        for t in self.topics:
            clock = "-" if t.clock_offset is None else f"{1e3 * t.clock_offset:+.1f} ms"
            out.append(f"{t.name:32s} {t.msgtype:34s} {t.count:7d} {t.rate:8.2f} {clock:>10s}")
        details = [t for t in self.topics if t.detail]
        if details:
            out += ["", "images and cameras (first message):"]
            out += [f"  {t.name}: {t.detail}" for t in details]
        out += ["", "clock: receive time minus header stamp (median); '-' for messages without a header"]
        for t in self.flagged_clocks:
            out.append(f"  FLAG {t.name}: {t.clock_flag}")
        gaps = [(t, g) for t in self.topics for g in t.gaps]
        out += ["", f"gaps (> {GAP_FACTOR:g}x the topic's median period): {len(gaps) or 'none'}"]
        for t, (s, length) in gaps[:20]:
            out.append(f"  {t.name}: {length:.3f} s at {s:.3f} s (median period {1 / t.rate:.4f} s)")
        if len(gaps) > 20:
            out.append(f"  ... {len(gaps) - 20} more")
        out += ["", "tf tree (child <- parent):" if self.tf_edges else "tf tree: no /tf or /tf_static"]
        out += [f"  {line}" for line in self.tf_text()]
        return "\n".join(out)


def _has_header(typestore, msgtype: str) -> bool:
    try:
        first = typestore.fielddefs[msgtype][1][0]
    except (KeyError, IndexError):
        return False
    return first[0] == "header" and "Header" in str(first[1][1])


def _clock_flag(offset: float | None) -> str:
    if offset is None:
        return ""
    if offset < -CLOCK_AHEAD:
        return (f"header stamps are {-offset:.3f} s AHEAD of the receive time: the sender's clock is not the "
                "recorder's (sim time? an unsynchronised machine?)")
    if offset > CLOCK_LATE:
        return (f"header stamps are {offset:.3f} s behind the receive time: another clock than the recorder's, "
                "or a driver that buffers (estimate the offset before combining this stream with others)")
    return ""


def _detail(rec, topic: str, msgtype: str, data) -> str:
    """``640x480 mono8`` of an image, ``png`` of a compressed one, the model and size of a CameraInfo."""
    if data is None or msgtype not in ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage",
                                       "sensor_msgs/msg/CameraInfo"):
        return ""
    m = rec.deserialize(topic, data)
    if msgtype.endswith("/Image"):
        return f"{m.width}x{m.height} {m.encoding}"
    if msgtype.endswith("CompressedImage"):
        return f"compressed ({m.format})"
    return f"{m.width}x{m.height}, distortion_model {m.distortion_model or '(none)'}"


def inspect_recording(path, *, show_progress: bool = True) -> RecordingSummary:
    """Read every message's stamps (not its content, except tf's) and summarise the recording."""
    topics = []
    with open_recording(path) as rec:
        fmt = ("ROS 1 bag" if not rec.is_ros2 else
               "MCAP" if any(p.suffix == ".mcap" for p in ([rec.path] if rec.path.is_file() else rec.path.iterdir()))
               else "ROS 2 bag (sqlite3)")
        typestore = rec._open_reader().typestore
        t0 = rec.start_ns
        for info in rec.topics.values():
            header = _has_header(typestore, info.msgtype)
            recv, head, first = [], [], None
            for _, r, data in rec.raw(info.name, show_progress=show_progress):
                first = bytes(data) if first is None else first
                recv.append(r)
                if header:
                    head.append(rec.header_stamp_ns(data))
            recv = np.asarray(recv, np.int64)
            period = float(np.median(np.diff(recv))) / 1e9 if len(recv) > 1 else 0.0
            gaps = ()
            if period > 0:
                d = np.diff(recv) / 1e9
                idx = np.flatnonzero(d > GAP_FACTOR * period)
                gaps = tuple(((recv[i] - t0) / 1e9, float(d[i])) for i in idx)
            offset = float(np.median(recv - np.asarray(head, np.int64))) / 1e9 if head else None
            topics.append(TopicSummary(info.name, info.msgtype, info.count, (recv[0] - t0) / 1e9 if len(recv) else 0.0,
                                       (recv[-1] - t0) / 1e9 if len(recv) else 0.0, 1 / period if period > 0 else 0.0,
                                       gaps, offset, _clock_flag(offset),
                                       _detail(rec, info.name, info.msgtype, first)))
        tf_topics = rec.topics_of_type(TF_TYPES)
        summary = dict(path=str(rec.path), format=fmt, size_bytes=rec.size_bytes, start_ns=t0, end_ns=rec.end_ns)
        tree = read_tf(rec, topics=tuple(tf_topics), show_progress=show_progress) if tf_topics else None
    edges = ()
    if tree is not None:
        edges = tuple((e.parent, e.child, "static" if e.static else "dynamic", e.rate, len(e.stamps_ns))
                      for e in tree.edges.values())
        # tf's own header stamps are per transform: their clock is judged from the tf samples
        offs = {t: [] for t in tf_topics}
        for e in tree.edges.values():
            if not e.static:
                offs.setdefault("/tf", []).extend((e.receive_ns - e.stamps_ns).tolist())
        topics = [t if t.name not in offs or not offs[t.name] else
                  TopicSummary(t.name, t.msgtype, t.count, t.start, t.end, t.rate, t.gaps,
                               float(np.median(offs[t.name])) / 1e9, _clock_flag(float(np.median(offs[t.name])) / 1e9),
                               t.detail)
                  for t in topics]
    return RecordingSummary(**summary, topics=tuple(topics), tf_edges=edges)
