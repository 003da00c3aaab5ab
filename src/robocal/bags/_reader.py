"""Opening a recording (ROS 1 ``.bag``, ROS 2 ``.db3`` / folder, ``.mcap``) and reading raw messages.

Everything that touches the ``rosbags`` library goes through :class:`Recording`,
so that every failure of a damaged file (``rosbags`` raises its own errors, and
``struct``/``sqlite3``/decompression errors from deeper down) reaches the user
as one :class:`~robocal.errors.FileFormatError` line naming the file, and
never as a traceback.

Times: a message has two stamps. The *receive* (log) time is when the
recorder wrote it, on the recording machine's clock; the *header* stamp is
``header.stamp``, set by the sender (a driver's hardware clock, sim time, or
another machine's clock). Calibration wants the header stamp; both are kept.
"""

from __future__ import annotations

import difflib
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal.errors import FileFormatError, InputError
from robocal.progress import progress

__all__ = ["Recording", "TopicInfo", "MissingTopicError", "UnknownFrameError", "open_recording", "closest_names"]

#: The suffixes of the recordings robocal reads (a ROS 2 bag may also be its folder).
RECORDING_SUFFIXES = (".bag", ".db3", ".mcap")

#: Reads of fewer messages take well under a second: no progress bar.
PROGRESS_MIN_MESSAGES = 5000

_REPAIR = ("truncated or unindexed? (`rosbag reindex FILE` repairs a ROS 1 bag, `ros2 bag reindex DIR` a ROS 2 one; "
           "a bag still being recorded is not readable)")


class MissingTopicError(InputError):
    """A topic asked for is not in the recording."""


class UnknownFrameError(InputError):
    """A tf frame asked for is not in the recording's tf tree, or not connected to the other frame."""


def closest_names(name: str, names, n: int = 3) -> str:
    """``" (closest: a, b)"`` for an error message, or ``""`` when nothing is close."""
    close = difflib.get_close_matches(name, list(names), n=n, cutoff=0.5)
    return f" (closest: {', '.join(close)})" if close else ""


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a recording: its message type (``sensor_msgs/msg/Image``) and message count."""

    name: str
    msgtype: str
    count: int


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) < 200 else text[:197] + "..."


class Recording:
    """An open recording; use as a context manager (``with open_recording(path) as rec:``).

    Parameters
    ----------
    path : str or Path
        A ROS 1 ``.bag`` file, a ROS 2 bag (its folder with ``metadata.yaml``,
        or a bare ``.db3`` / ``.mcap`` file).

    Every ``read_*`` function of :mod:`robocal.bags` takes a path or an open
    ``Recording`` (``with open_recording(p) as rec: read_tf(rec); read_joint_states(rec)``).

    Notes
    -----
    Reading is lazy: :meth:`raw` yields ``(topic, receive_ns, raw bytes)`` for
    the topics asked for only, so a bag's image data is never read when the
    tf and joint topics are (ROS 1 reads through its index, ROS 2 through its
    SQL or MCAP chunk indexes).
    """

    def __init__(self, path):
        self.path = Path(path)
        self._reader = None

    # -- opening ---------------------------------------------------------------
    def __enter__(self) -> "Recording":
        from rosbags.highlevel import AnyReader

        path = self.path
        if not path.exists():
            raise InputError(f"{path}: no such recording (a ROS 1 .bag, a ROS 2 bag folder, .db3 or .mcap)")
        if path.is_file() and path.suffix not in RECORDING_SUFFIXES:
            raise FileFormatError(f"{path}: not a recording: expected a .bag, .db3 or .mcap file or a ROS 2 bag "
                                  f"folder, got a '{path.suffix}' file")
        if path.is_dir() and not (path / "metadata.yaml").exists():
            raise FileFormatError(f"{path}: a folder without metadata.yaml is not a ROS 2 bag")
        try:
            # the ROS 2 store deserialises ROS 2 bags that carry no message definitions; ROS 1 bags carry theirs
            self._reader = AnyReader([path], default_typestore=_default_typestore())
            self._reader.open()
            # AnyReader.topics rebuilds its mapping on each access: read it once
            self._topics = {name: TopicInfo(name, info.msgtype or "", int(info.msgcount))
                            for name, info in sorted(self._reader.topics.items())}
            self._is2 = bool(self._reader.is2)
        except Exception as exc:  # rosbags and the parsers below it: a damaged file, not a bug of ours
            self._reader = None
            raise FileFormatError(f"{path}: cannot open the recording: {_one_line(exc)}; {_REPAIR}") from None
        return self

    def __exit__(self, *exc) -> None:
        if self._reader is not None:
            try:
                self._reader.close()
            except Exception:  # noqa: BLE001 closing a damaged file must not hide the first error
                pass
            self._reader = None

    def _open_reader(self):
        if self._reader is None:
            raise InputError(f"{self.path}: the recording is not open (use `with open_recording(path) as rec:`)")
        return self._reader

    # -- what is in it ---------------------------------------------------------
    @property
    def is_ros2(self) -> bool:
        """Whether messages are CDR (ROS 2, MCAP) rather than ROS 1 serialised."""
        self._open_reader()
        return self._is2

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Every topic, by name."""
        self._open_reader()
        return self._topics

    @property
    def start_ns(self) -> int:
        """Receive time of the first message [ns since the epoch of the recording clock]."""
        return int(self._open_reader().start_time)

    @property
    def end_ns(self) -> int:
        """Receive time just after the last message [ns]."""
        return int(self._open_reader().end_time)

    @property
    def size_bytes(self) -> int:
        """Bytes on disk (a folder: all its files)."""
        if self.path.is_dir():
            return sum(p.stat().st_size for p in self.path.rglob("*") if p.is_file())
        return self.path.stat().st_size

    def topic(self, name: str, msgtypes=None) -> TopicInfo:
        """The topic ``name``; a one-line error naming the closest topics when it is not there.

        ``msgtypes``: accepted message types (``"sensor_msgs/msg/Image"``); another type is an error.
        """
        topics = self.topics
        if name not in topics:
            alt = f"/{name}" if not name.startswith("/") else name.lstrip("/")
            if alt in topics:
                name = alt
            else:
                raise MissingTopicError(f"{self.path}: no topic '{name}'{closest_names(name, topics)}; "
                                        f"{len(topics)} topic(s): {', '.join(list(topics)[:12])}")
        info = topics[name]
        if msgtypes is not None and info.msgtype not in msgtypes:
            raise InputError(f"{self.path}: topic '{name}' holds {info.msgtype}, expected "
                             f"{' or '.join(msgtypes)}")
        return info

    def topics_of_type(self, msgtypes) -> list[str]:
        """The topics holding one of ``msgtypes``."""
        return [t.name for t in self.topics.values() if t.msgtype in msgtypes]

    # -- reading -----------------------------------------------------------------
    def raw(self, topics, *, show_progress: bool = True):
        """Yield ``(topic, receive_ns, rawdata)`` for ``topics`` in receive order.

        A progress bar (on a terminal, for reads of over a few thousand
        messages) names the topics and the fraction of their messages read.
        """
        reader = self._open_reader()
        names = [topics] if isinstance(topics, str) else list(topics)
        conns = [c for c in reader.connections if c.topic in names]
        if not conns:
            return
        total = sum(self.topics[n].count for n in names if n in self.topics)
        desc = ", ".join(names) if len(names) <= 2 else f"{names[0]} + {len(names) - 1} topics"
        it = reader.messages(connections=conns)
        try:
            bar = show_progress and total >= PROGRESS_MIN_MESSAGES
            for conn, stamp, data in progress(it, desc=desc, total=total, enabled=bar):
                yield conn.topic, int(stamp), data
        except GeneratorExit:
            raise
        except Exception as exc:  # a damaged chunk or record deep in the file
            raise FileFormatError(f"{self.path}: topic {desc}: cannot read a message: {_one_line(exc)}; "
                                  f"{_REPAIR}") from None

    def deserialize(self, topic: str, data):
        """The message object of one raw message of ``topic`` (fields as in the .msg definition)."""
        reader = self._open_reader()
        msgtype = self.topics[topic].msgtype
        try:
            return reader.deserialize(data, msgtype)
        except Exception as exc:
            raise FileFormatError(f"{self.path}: topic {topic}: a {msgtype} message does not decode: "
                                  f"{_one_line(exc)}") from None

    def header_stamp_ns(self, data) -> int:
        """``header.stamp`` [ns] of a raw message whose first field is a ``std_msgs/Header``, without decoding it.

        ROS 1: ``uint32 seq, uint32 sec, uint32 nsec`` little-endian; CDR: a
        4-byte encapsulation header (byte 1 odd: little-endian), then
        ``int32 sec, uint32 nanosec``. Lets a reader pick image frames by stamp
        without copying their pixels.
        """
        try:
            if self.is_ros2:
                endian = "<" if data[1] & 1 else ">"
                sec, nsec = struct.unpack_from(f"{endian}iI", data, 4)
            else:
                sec, nsec = struct.unpack_from("<II", data, 4)
        except (struct.error, IndexError) as exc:
            raise FileFormatError(f"{self.path}: a message too short for a header ({_one_line(exc)})") from None
        return int(sec) * 1_000_000_000 + int(nsec)


_TYPESTORE = []


def _default_typestore():
    """The ROS 2 Humble message definitions (built once: ~0.3 s), for ROS 2 bags that carry none."""
    from rosbags.typesys import Stores, get_typestore

    if not _TYPESTORE:
        _TYPESTORE.append(get_typestore(Stores.ROS2_HUMBLE))
    return _TYPESTORE[0]


def open_recording(path) -> Recording:
    """Open a recording for reading: ``with open_recording("run.bag") as rec: ...`` (see :class:`Recording`).

    ``path`` may be a :class:`Recording` already open: it is used as it is and
    left open, so that several reads share one opening (each opening parses
    the message definitions: ~0.1 s).
    """
    if isinstance(path, Recording):
        return _Borrowed(path) if path._reader is not None else path
    return Recording(path)


class _Borrowed:
    """An open recording passed in: ``with`` gives it back without closing it."""

    def __init__(self, rec: Recording):
        self.rec = rec

    def __enter__(self) -> Recording:
        return self.rec

    def __exit__(self, *exc) -> None:
        pass


def seconds_from_ns(ns) -> np.ndarray:
    """Float seconds from integer nanoseconds (float64: ~0.25 us resolution at today's epoch times)."""
    return np.asarray(ns, dtype=np.int64) / 1e9


def stamp_ns(stamp) -> int:
    """Nanoseconds of a header stamp (rosbags gives ROS 1's ``time`` the fields of ROS 2's ``builtin_interfaces/Time``)."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
