"""MAVLink telemetry logs (``.tlog``) of PX4FLOW-class sensors -> the flow rig's per-sensor flow log.

Written from the published MAVLink protocol (mavlink.io, "Packet Serialization"
and "CRC_EXTRA calculation") and the message definitions of ``common.xml``;
no pymavlink code is used (pymavlink is LGPL, robocal BSD-3-Clause).

The tlog container
------------------
A ``.tlog`` is a sequence of records: an 8-byte **big-endian** uint64
timestamp (microseconds, the recorder's clock, usually UNIX time) followed by
one raw MAVLink frame:

* MAVLink 1: ``0xFE len seq sysid compid msgid payload[len] crc_lo crc_hi``
* MAVLink 2: ``0xFD len incompat compat seq sysid compid msgid(3, LE) payload[len]
  crc_lo crc_hi [signature(13) if incompat & 0x01]``

The checksum is CRC-16/MCRF4XX (MAVLink's "X.25": reflected polynomial 0x8408,
initial value 0xFFFF, no final XOR) over every byte after the magic byte up to
the end of the payload, then the message's ``CRC_EXTRA`` byte. ``CRC_EXTRA`` is
computed here from the field definitions (:func:`crc_extra`): the CRC of
``"NAME "`` followed by ``"type name "`` of every non-extension field in wire
order (plus a byte with the array length for array fields), folded to 8 bits as
``(crc & 0xFF) ^ (crc >> 8)``. Fields go on the wire sorted by the size of their
base type, largest first (stable for equal sizes); extension fields follow in
definition order. MAVLink 2 drops trailing zero bytes of the payload: the
reader pads it back with zeros.

The parser (:func:`read_tlog`) resynchronises after garbage (it scans for the
next magic byte whose frame checks), checks the CRC of every known message,
skips (does not verify) the signature of signed MAVLink 2 frames and counts
every frame or byte it could not use (:class:`ParseStats`).

From OPTICAL_FLOW_RAD to the rig's flow log
-------------------------------------------
See :func:`flow_records` and docs/rigs/flow.md ("MAVLink logs"): the sensor's
axes are taken as the rig's camera axes (x = image u, y = image v, z = optical
axis, down), and by the message definition's sign rules
(RH rotation about X gives positive ``integrated_x``, motion along +Y negative;
RH rotation about Y gives positive ``integrated_y``, motion along +X positive)
the kernel-convention image flow in pixels is::

    flow_u = -f * integrated_y,   flow_v = +f * integrated_x,   gyro = integrated_*gyro / dt

which the rig's eqs. 3-5 (:func:`~robocal.rigs.flow.kernel.compensate_rotation`,
:func:`~robocal.rigs.flow.kernel.metric_displacement`) turn into the ground
displacement ``dS = ((iy - iy_gyro) h, (ix - ix_gyro) h)`` in the sensor frame S:
the focal length ``f`` cancels exactly.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from robocal.errors import FileFormatError, InputError

__all__ = [
    "MessageDef",
    "MESSAGES",
    "OPTICAL_FLOW",
    "OPTICAL_FLOW_RAD",
    "ParseStats",
    "MavlinkLog",
    "crc16_mcrf4xx",
    "crc_extra",
    "read_tlog",
    "parse_tlog",
    "encode_frame",
    "parse_sensor_map",
    "flow_records",
    "write_flow_log",
    "ConvertedFlow",
]

# ---------------------------------------------------------------------------------------------------------------
# CRC-16/MCRF4XX (MAVLink "X.25"): poly 0x1021 reflected (0x8408), init 0xFFFF, refin/refout, xorout 0


def _make_table():
    tab = []
    for b in range(256):
        c = b
        for _ in range(8):
            c = (c >> 1) ^ 0x8408 if c & 1 else c >> 1
        tab.append(c)
    return tuple(tab)


_CRC_TABLE = _make_table()


def crc16_mcrf4xx(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/MCRF4XX of ``data`` continuing from ``crc`` (check value of b"123456789": 0x6F91)."""
    tab = _CRC_TABLE
    for b in data:
        crc = (crc >> 8) ^ tab[(crc ^ b) & 0xFF]
    return crc


# ---------------------------------------------------------------------------------------------------------------
# message definitions

_TYPES = {  # MAVLink type -> (struct code, size)
    "uint64_t": ("Q", 8), "int64_t": ("q", 8), "double": ("d", 8),
    "uint32_t": ("I", 4), "int32_t": ("i", 4), "float": ("f", 4),
    "uint16_t": ("H", 2), "int16_t": ("h", 2),
    "uint8_t": ("B", 1), "int8_t": ("b", 1), "char": ("c", 1),
}


@dataclass(frozen=True)
class MessageDef:
    """One message of a MAVLink dialect: fields ``(type, name)`` in definition (XML) order."""

    id: int
    name: str
    fields: tuple          # base fields, XML order
    extensions: tuple = ()  # extension fields, XML order (MAVLink 2 only; not in CRC_EXTRA)

    # cached: decode() runs once per frame (a tlog holds thousands); a frozen dataclass without
    # slots keeps them in the instance __dict__
    @cached_property
    def wire_fields(self) -> tuple:
        """Fields in wire order: base fields sorted by type size (largest first, stable), then extensions."""
        return tuple(sorted(self.fields, key=lambda f: -_TYPES[f[0]][1])) + tuple(self.extensions)

    @cached_property
    def min_length(self) -> int:
        return sum(_TYPES[t][1] for t, _ in self.fields)

    @cached_property
    def max_length(self) -> int:
        return self.min_length + sum(_TYPES[t][1] for t, _ in self.extensions)

    @cached_property
    def struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(_TYPES[t][0] for t, _ in self.wire_fields))

    @property
    def crc_extra(self) -> int:
        return crc_extra(self)

    def decode(self, payload: bytes) -> dict:
        """Field values of a payload (zero-padded to the full length, as MAVLink 2 truncation requires)."""
        n = self.max_length
        if len(payload) < n:
            payload = bytes(payload) + bytes(n - len(payload))
        vals = self.struct.unpack(payload[:n])
        return {name: v for (_, name), v in zip(self.wire_fields, vals)}

    def encode(self, values: dict, *, extensions: bool = True) -> bytes:
        """Payload of ``values`` in wire order (missing fields are 0); without the extensions if asked."""
        flds = self.wire_fields if extensions else self.wire_fields[:len(self.fields)]
        fmt = "<" + "".join(_TYPES[t][0] for t, _ in flds)
        return struct.pack(fmt, *(values.get(nm, 0) for _, nm in flds))


def crc_extra(msg: MessageDef) -> int:
    """``CRC_EXTRA`` of a message from its definition (mavlink.io "CRC_EXTRA calculation").

    CRC-16/MCRF4XX over ``name + " "``, then for each non-extension field in wire order
    ``type + " "`` and ``name + " "`` (array fields would add one byte with their length; the
    messages here have none), folded to one byte: ``(crc & 0xFF) ^ (crc >> 8)``.
    """
    crc = crc16_mcrf4xx((msg.name + " ").encode("ascii"))
    for t, nm in msg.wire_fields[:len(msg.fields)]:
        crc = crc16_mcrf4xx((t + " ").encode("ascii"), crc)
        crc = crc16_mcrf4xx((nm + " ").encode("ascii"), crc)
    return (crc & 0xFF) ^ (crc >> 8)


#: common.xml, message 106 (in XML order)
OPTICAL_FLOW_RAD = MessageDef(106, "OPTICAL_FLOW_RAD", (
    ("uint64_t", "time_usec"), ("uint8_t", "sensor_id"), ("uint32_t", "integration_time_us"),
    ("float", "integrated_x"), ("float", "integrated_y"), ("float", "integrated_xgyro"),
    ("float", "integrated_ygyro"), ("float", "integrated_zgyro"), ("int16_t", "temperature"),
    ("uint8_t", "quality"), ("uint32_t", "time_delta_distance_us"), ("float", "distance")))

#: common.xml, message 100 (in XML order); flow_rate_x/y are MAVLink 2 extensions
OPTICAL_FLOW = MessageDef(100, "OPTICAL_FLOW", (
    ("uint64_t", "time_usec"), ("uint8_t", "sensor_id"), ("int16_t", "flow_x"), ("int16_t", "flow_y"),
    ("float", "flow_comp_m_x"), ("float", "flow_comp_m_y"), ("uint8_t", "quality"), ("float", "ground_distance")),
    extensions=(("float", "flow_rate_x"), ("float", "flow_rate_y")))

#: common.xml, message 0: not used, but recognised (its CRC checked) so that a log's heartbeats are not "unknown"
HEARTBEAT = MessageDef(0, "HEARTBEAT", (
    ("uint8_t", "type"), ("uint8_t", "autopilot"), ("uint8_t", "base_mode"), ("uint32_t", "custom_mode"),
    ("uint8_t", "system_status"), ("uint8_t", "mavlink_version")))

MESSAGES = {m.id: m for m in (HEARTBEAT, OPTICAL_FLOW, OPTICAL_FLOW_RAD)}
_CRC_EXTRA = {m.id: crc_extra(m) for m in MESSAGES.values()}


def encode_frame(msg: MessageDef, values: dict, *, version: int = 2, seq: int = 0, sysid: int = 1, compid: int = 100,
                 signature: bytes | None = None, truncate: bool = True, crc_extra_byte: int | None = None) -> bytes:
    """One MAVLink frame (for tests and examples). MAVLink 2 drops trailing zero payload bytes when ``truncate``."""
    extra = _CRC_EXTRA.get(msg.id, crc_extra(msg)) if crc_extra_byte is None else crc_extra_byte
    if version == 1:
        payload = msg.encode(values, extensions=False)
        hdr = bytes([len(payload), seq & 0xFF, sysid, compid, msg.id])
        magic = b"\xfe"
    else:
        payload = msg.encode(values)
        if truncate:
            payload = payload.rstrip(b"\x00") or payload[:1]   # a v2 payload keeps at least one byte
        incompat = 0x01 if signature is not None else 0
        hdr = bytes([len(payload), incompat, 0, seq & 0xFF, sysid, compid]) + msg.id.to_bytes(3, "little")
        magic = b"\xfd"
    crc = crc16_mcrf4xx(bytes([extra]), crc16_mcrf4xx(hdr + payload))
    out = magic + hdr + payload + crc.to_bytes(2, "little")
    if version != 1 and signature is not None:
        if len(signature) != 13:
            raise InputError("a MAVLink 2 signature is 13 bytes (link id, 6-byte timestamp, 6-byte signature)")
        out += signature
    return out


# ---------------------------------------------------------------------------------------------------------------
# the tlog parser


@dataclass
class ParseStats:
    """What the parser met: good frames per message name, and everything it skipped."""

    frames: dict = field(default_factory=dict)        # message name -> good frames
    crc_errors: int = 0                                # known message, checksum wrong
    bad_length: int = 0                                # known message, payload length impossible
    unknown: dict = field(default_factory=dict)        # message id -> frames of messages this reader does not know
    unsupported_flags: int = 0                         # MAVLink 2 incompat flags other than "signed"
    signed: int = 0                                    # signed MAVLink 2 frames (signature skipped, not verified)
    truncated_end: int = 0                             # bytes of an incomplete record at the end of the file
    garbage_bytes: int = 0                             # bytes skipped while resynchronising (rejected frames too)

    @property
    def bad_frames(self) -> int:
        return self.crc_errors + self.bad_length + self.unsupported_flags

    def summary(self) -> str:
        good = ", ".join(f"{k} {v}" for k, v in sorted(self.frames.items())) or "none"
        parts = [f"good frames: {good}"]
        if self.signed:
            parts.append(f"{self.signed} signed (signature not verified)")
        if self.crc_errors:
            parts.append(f"{self.crc_errors} with a bad CRC")
        if self.bad_length:
            parts.append(f"{self.bad_length} with an impossible length")
        if self.unsupported_flags:
            parts.append(f"{self.unsupported_flags} with unsupported MAVLink 2 flags")
        if self.unknown:
            parts.append(f"{sum(self.unknown.values())} of unknown messages (ids "
                         f"{', '.join(str(k) for k in sorted(self.unknown)[:10])}{', ...' if len(self.unknown) > 10 else ''})")
        if self.garbage_bytes:
            parts.append(f"{self.garbage_bytes} garbage bytes skipped")
        if self.truncated_end:
            parts.append(f"{self.truncated_end} bytes of an incomplete record at the end")
        return "; ".join(parts)


@dataclass
class MavlinkLog:
    """Decoded messages of a tlog: per message name, a dict of numpy arrays (one entry per frame).

    Every message table also has ``log_time_us`` (the tlog record's timestamp), ``sysid``,
    ``compid``, ``version`` (1 or 2).
    """

    messages: dict
    stats: ParseStats

    def table(self, name: str) -> dict:
        return self.messages.get(name, {})


def _try_frame(buf, p: int, n: int):
    """Parse the frame whose magic byte is at ``p``: ``(status, end, msgid, version, header, payload)``.

    status: "ok", "crc", "length", "unknown", "flags", "short" (runs past the end of the data).
    """
    magic = buf[p]
    if magic == 0xFE:
        if p + 6 > n:
            return "short", n, None, 1, None, None
        ln = buf[p + 1]
        end = p + 6 + ln + 2
        if end > n:
            return "short", n, None, 1, None, None
        msgid = buf[p + 5]
        hdr = (buf[p + 1], buf[p + 2], buf[p + 3], buf[p + 4])
        ver, body, payload, crc_at = 1, buf[p + 1:p + 6 + ln], buf[p + 6:p + 6 + ln], p + 6 + ln
        flags = 0
    else:
        if p + 10 > n:
            return "short", n, None, 2, None, None
        ln = buf[p + 1]
        flags = buf[p + 2]
        end = p + 10 + ln + 2 + (13 if flags & 0x01 else 0)
        if end > n:
            return "short", n, None, 2, None, None
        msgid = buf[p + 7] | (buf[p + 8] << 8) | (buf[p + 9] << 16)
        hdr = (ln, buf[p + 4], buf[p + 5], buf[p + 6])
        ver, body, payload, crc_at = 2, buf[p + 1:p + 10 + ln], buf[p + 10:p + 10 + ln], p + 10 + ln
    msg = MESSAGES.get(msgid)
    if msg is None:
        return "unknown", end, msgid, ver, hdr, None
    if ver == 2 and flags & ~0x01:
        return "flags", end, msgid, ver, hdr, None
    if (ver == 1 and not msg.min_length <= ln <= msg.max_length) or (ver == 2 and ln > msg.max_length):
        return "length", end, msgid, ver, hdr, None
    crc = crc16_mcrf4xx(bytes([_CRC_EXTRA[msgid]]), crc16_mcrf4xx(body))
    if crc != (buf[crc_at] | (buf[crc_at + 1] << 8)):
        return "crc", end, msgid, ver, hdr, None
    return "ok", end, msgid, ver, hdr, bytes(payload)


def parse_tlog(data: bytes) -> MavlinkLog:
    """Parse the bytes of a tlog (see module doc) into decoded messages and :class:`ParseStats`.

    A record is accepted when its frame checks (known message: length and CRC). After anything
    else the parser moves one byte on and looks for the next magic byte (0xFE/0xFD) that has 8
    bytes of timestamp before it. A frame of an unknown message cannot be checked: it is skipped
    by its length only when the next record starts right after it (or the data ends there).
    """
    raw = bytes(data)
    buf = memoryview(raw)
    n = len(buf)
    stats = ParseStats()
    rows: dict = {}
    p = 0              # start of the current candidate record (its timestamp)
    last_good = 0      # end of the last accepted record

    def next_candidate(q):
        # the next record start >= q whose byte at +8 is a magic byte
        cands = [i for i in (raw.find(b"\xfe", q + 8), raw.find(b"\xfd", q + 8)) if i >= 0]
        return min(cands) - 8 if cands else -1

    while p + 9 <= n:
        m = p + 8
        if buf[m] not in (0xFE, 0xFD):
            q = next_candidate(p + 1)
            if q < 0:
                break
            p = q
            continue
        status, end, msgid, ver, hdr, payload = _try_frame(buf, m, n)
        if status == "short":
            q = next_candidate(p + 1)
            if q < 0:
                break
            p = q
            continue
        if status == "unknown":
            nxt = end + 8
            if end == n or (nxt < n and buf[nxt] in (0xFE, 0xFD)):
                stats.garbage_bytes += p - last_good
                stats.unknown[msgid] = stats.unknown.get(msgid, 0) + 1
                p = last_good = end
                continue
            p += 1
            continue
        if status != "ok":
            # a frame that names a known message but does not check: count it when it is framed like
            # one (the next record starts right after it, or the data ends there; a magic byte met in
            # garbage is only garbage), then resync byte by byte (its length may be corrupt)
            if end == n or (end + 8 < n and buf[end + 8] in (0xFE, 0xFD)):
                if status == "crc":
                    stats.crc_errors += 1
                elif status == "length":
                    stats.bad_length += 1
                else:
                    stats.unsupported_flags += 1
            p += 1
            continue
        stats.garbage_bytes += p - last_good
        msg = MESSAGES[msgid]
        vals = msg.decode(payload)
        ts = int.from_bytes(buf[p:p + 8], "big")
        if ver == 2 and buf[m + 2] & 0x01:
            stats.signed += 1
        tab = rows.setdefault(msg.name, [])
        tab.append((ts, hdr[2], hdr[3], ver, vals))
        stats.frames[msg.name] = stats.frames.get(msg.name, 0) + 1
        p = last_good = end
    tail = n - last_good
    if tail:
        # bytes after the last good record: an incomplete record if a magic byte sits where one would
        # start, else garbage
        if tail >= 9 and buf[last_good + 8] in (0xFE, 0xFD) and _try_frame(buf, last_good + 8, n)[0] == "short":
            stats.truncated_end = tail
        else:
            stats.garbage_bytes += tail
    messages = {}
    for name, tab in rows.items():
        cols = {"log_time_us": np.array([r[0] for r in tab], np.uint64),
                "sysid": np.array([r[1] for r in tab], np.uint8), "compid": np.array([r[2] for r in tab], np.uint8),
                "version": np.array([r[3] for r in tab], np.uint8)}
        msg = next(m for m in MESSAGES.values() if m.name == name)
        for t, fname in msg.wire_fields:
            dtype = {"Q": np.uint64, "q": np.int64, "d": np.float64, "I": np.uint32, "i": np.int32, "f": np.float32,
                     "H": np.uint16, "h": np.int16, "B": np.uint8, "b": np.int8}.get(_TYPES[t][0], object)
            cols[fname] = np.array([r[4][fname] for r in tab], dtype)
        messages[name] = cols
    return MavlinkLog(messages, stats)


def read_tlog(path) -> MavlinkLog:
    """Read and parse a ``.tlog`` file (see :func:`parse_tlog`)."""
    src = str(path)
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise FileFormatError("file not found", source=src) from None
    except IsADirectoryError:
        raise FileFormatError("is a directory, expected a .tlog file", source=src) from None
    except OSError as exc:
        raise FileFormatError(f"cannot read ({exc.strerror or exc})", source=src) from None
    return parse_tlog(data)


# the conversion to the rig's flow log lives in its own module; its names stay importable from here
from robocal.rigs.flow.mavlink_convert import ConvertedFlow, flow_records, parse_sensor_map, write_flow_log  # noqa: E402
