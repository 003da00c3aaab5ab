"""OPTICAL_FLOW_RAD records of a MAVLink log -> the flow rig's per-sensor flow log (``flow.csv``).

The sensor's axes are taken as the rig's camera axes (x = image u, y = image
v, z = optical axis, down); by the message definition's sign rules the
kernel-convention image flow in pixels is::

    flow_u = -f * integrated_y,   flow_v = +f * integrated_x,   gyro = integrated_*gyro / dt

(see :mod:`.mavlink` for the tlog parser and docs/rigs/flow.md, "MAVLink logs").
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robocal.errors import FileFormatError, InputError

if TYPE_CHECKING:  # the parser's module imports this one at its end: no run-time import back
    from robocal.rigs.flow.mavlink import MavlinkLog

__all__ = ["parse_sensor_map", "ConvertedFlow", "flow_records", "write_flow_log"]




def parse_sensor_map(text: str, names) -> dict:
    """``"0:s60,1:s120"`` -> ``{0: index of s60 in names, 1: ...}`` (names: the array's sensor names)."""
    names = list(names)
    out: dict = {}
    for item in (s.strip() for s in str(text).split(",")):
        if not item:
            continue
        sid, sep, nm = item.partition(":")
        try:
            k = int(sid)
        except ValueError:
            k = -1
        if not sep or not 0 <= k <= 255 or not nm.strip():
            raise InputError(f"--sensor-map takes SENSOR_ID:NAME pairs (sensor_id 0..255), e.g. 0:s60,1:s120; got '{item}'")
        nm = nm.strip()
        if nm not in names:
            raise InputError(f"--sensor-map: '{nm}' is not a sensor of the array ({', '.join(names)})")
        if k in out:
            raise InputError(f"--sensor-map: sensor_id {k} is mapped twice")
        if names.index(nm) in out.values():
            raise InputError(f"--sensor-map: sensor '{nm}' is mapped twice")
        out[k] = names.index(nm)
    if not out:
        raise InputError("--sensor-map is empty; give SENSOR_ID:NAME pairs, e.g. 0:s60,1:s120,2:s270")
    return out


@dataclass
class ConvertedFlow:
    """Flow records on a common time grid, as :func:`write_flow_log` writes them."""

    t: np.ndarray          # (K+1,) s, relative to t0
    flow: np.ndarray       # (n, K, 2) px, kernel convention, not gyro-compensated
    gyro: np.ndarray       # (n, K, 3) rad/s, mean over the interval
    height: np.ndarray     # (n, K) m
    quality: np.ndarray    # (n, K)
    present: np.ndarray    # (n, K) bool: the interval is covered by the sensor's records
    t0_us: int             # clock value of t = 0, us
    records: dict          # sensor index -> number of OPTICAL_FLOW_RAD records used
    notes: list


def flow_records(log: MavlinkLog, sensor_map: dict, n_sensors: int, focal_px: float, *, clock: str = "log",
                 rate: float | None = None, sysid: int | None = None, source: str = "tlog") -> ConvertedFlow:
    """OPTICAL_FLOW_RAD records of the mapped sensors on one time grid, in the rig's units.

    Each record covers ``[t_end - integration_time_us, t_end]`` (``t_end``: the tlog timestamp,
    ``clock="log"``, or the message's ``time_usec``, ``clock="message"`` — only when every sensor
    stamps on one clock). A record's start is moved back to the previous record's end when the
    gap between them is under a quarter of the integration time (clock jitter), or forward when
    they overlap. Inside a record the rates are taken as constant, so the integrated flow, gyro
    and distance are redistributed exactly (linear in time) onto the grid: by default the first
    mapped sensor's record ends (identical to the records for sensors sampled together), or a
    uniform grid at ``rate`` Hz. A grid interval not covered (to 1 %) by a sensor's records is
    left out for that sensor (a missing record); one that touches a record with quality 0 or
    an unknown (negative) distance gets quality 0; otherwise its quality is the lowest of the
    records it touches.
    """
    if clock not in ("log", "message"):
        raise InputError(f"clock must be 'log' or 'message', got {clock!r}")
    tab = log.table("OPTICAL_FLOW_RAD")
    if not tab:
        raise FileFormatError(f"no OPTICAL_FLOW_RAD (id 106) messages ({log.stats.summary()})", source=source)
    keep = np.ones(len(tab["sensor_id"]), bool)
    if sysid is not None:
        keep &= tab["sysid"] == sysid
    tt = (tab["log_time_us"] if clock == "log" else tab["time_usec"]).astype(np.int64)
    origin = int(tt[keep].min()) if keep.any() else 0
    tt = tt - origin                       # float64 keeps microseconds exactly from here on
    found = sorted(set(int(s) for s in tab["sensor_id"][keep]))
    missing = [k for k in sensor_map if k not in found]
    if missing:
        raise InputError(f"--sensor-map: no OPTICAL_FLOW_RAD records of sensor_id {', '.join(map(str, missing))} in the "
                         f"log (it has sensor_id {', '.join(map(str, found)) or 'none'})")
    notes = []
    unmapped = [k for k in found if k not in sensor_map]
    if unmapped:
        notes.append(f"records of sensor_id {', '.join(map(str, unmapped))} are not in --sensor-map: left out")
    segs = {}
    for sid, i in sensor_map.items():
        sel = keep & (tab["sensor_id"] == sid)
        order = np.argsort(tt[sel], kind="stable")
        end = tt[sel][order].astype(float)
        it = tab["integration_time_us"][sel][order].astype(float)
        q = np.stack([tab[k][sel][order].astype(float) for k in ("integrated_x", "integrated_y", "integrated_xgyro",
                                                                 "integrated_ygyro", "integrated_zgyro")], 1)
        d = tab["distance"][sel][order].astype(float)
        qual = tab["quality"][sel][order].astype(float)
        dup = np.flatnonzero(np.diff(end) <= 0)
        if dup.size:
            # records stamped at the same time (a recorder that stamps a whole read at once): each is
            # moved to end one integration time after the previous one; the overlap is clipped below
            for k in dup + 1:
                if end[k] <= end[k - 1]:
                    end[k] = end[k - 1] + max(it[k], 1.0)
            notes.append(f"sensor_id {sid}: {dup.size} record(s) stamped at the same {clock} time as the one before: "
                         "moved one integration time later")
        start = end - it
        prev_end = np.concatenate([[-np.inf], end[:-1]])
        tol = 0.25 * np.maximum(it, 1.0)
        start = np.where(start < prev_end, prev_end, start)                              # overlap: clip
        start = np.where((start - prev_end <= tol) & np.isfinite(prev_end), prev_end, start)  # jitter: close
        ok = end > start
        if (~ok).any():
            notes.append(f"sensor {sid}: {int((~ok).sum())} record(s) with integration time 0 left out")
        segs[i] = (start[ok], end[ok], q[ok], d[ok], qual[ok])
    first = segs[next(iter(sensor_map.values()))]
    if rate is None:
        grid = np.concatenate([[first[0][0]], first[1]])
        # where the reference sensor itself has a gap, the grid keeps its own intervals: an interval
        # from a gap's start is dropped, so the gap becomes a missing stretch
        grid = np.unique(np.concatenate([grid, first[0]]))
    else:
        if not rate > 0:
            raise InputError(f"--rate must be > 0 Hz, got {rate}")
        lo = max(s[0][0] for s in segs.values())
        hi = min(s[1][-1] for s in segs.values())
        step = 1e6 / rate
        if hi - lo < step:
            raise InputError(f"the sensors' records overlap for {(hi - lo) / 1e6:.6f} s only: less than one "
                             f"interval at --rate {rate:g} Hz")
        grid = lo + step * np.arange(int(np.floor((hi - lo) / step + 1e-9)) + 1)
    K = grid.size - 1
    flow = np.zeros((n_sensors, K, 2))
    gyro = np.zeros((n_sensors, K, 3))
    height = np.ones((n_sensors, K))
    quality = np.zeros((n_sensors, K))
    present = np.zeros((n_sensors, K), bool)
    dtg = np.diff(grid)
    records = {}
    for i, (s, e, q, d, qual) in segs.items():
        records[i] = int(s.size)
        ln = e - s
        # cumulative functions of time, piecewise linear over the records, flat in gaps:
        # knots at every start and end
        knots = np.empty(2 * s.size)
        knots[0::2], knots[1::2] = s, e
        def cum(v):
            c = np.concatenate([np.zeros((1,) + v.shape[1:]), np.cumsum(v, axis=0)])
            vals = np.empty((2 * s.size,) + v.shape[1:])
            vals[0::2], vals[1::2] = c[:-1], c[1:]
            return vals

        def over(v):
            vals = cum(v)
            if vals.ndim == 1:
                return np.diff(np.interp(grid, knots, vals))
            return np.stack([np.diff(np.interp(grid, knots, vals[:, a])) for a in range(vals.shape[1])], 1)

        cover = over(ln)
        integ = over(q)
        dist = over(d * ln)
        bad_t = over(ln * ((qual <= 0) | (d < 0)))
        # lowest quality of the records each grid interval touches
        k0 = np.searchsorted(e, grid[:-1], side="right")
        k1 = np.searchsorted(s, grid[1:], side="left")
        has = (k1 > k0) & (cover > 0)
        qmin = np.zeros(K)
        if has.any():
            idx = np.flatnonzero(has)
            # reduceat over [k0, k1) per interval: interleave starts/ends
            ext = np.append(qual, np.inf)
            qmin[idx] = np.minimum.reduceat(ext, np.stack([k0[idx], k1[idx]], 1).ravel())[0::2]
        pres = cover >= 0.99 * dtg
        present[i] = pres
        with np.errstate(invalid="ignore", divide="ignore"):
            h = np.where(cover > 0, dist / np.where(cover > 0, cover, 1.0), np.nan)
        good_h = pres & (bad_t <= 0) & (h > 0)
        # flow in px (kernel convention), gyro as the interval's mean rate
        flow[i, :, 0] = -focal_px * integ[:, 1]
        flow[i, :, 1] = focal_px * integ[:, 0]
        gyro[i] = integ[:, 2:5] / (dtg[:, None] * 1e-6)
        quality[i] = np.where(good_h, qmin, 0.0)
        # a placeholder height where unknown (quality 0 there: the row's flow is not used)
        fill = np.nanmedian(h[good_h]) if good_h.any() else 1.0
        height[i] = np.where(good_h, h, fill)
        n_bad = int((pres & ~good_h).sum())
        if n_bad:
            notes.append(f"sensor {i}: {n_bad} interval(s) touch a record with quality 0 or unknown distance: quality 0")
    # the run starts when every sensor has started and ends when the first one stops
    full = np.flatnonzero(present.all(axis=0))
    if full.size == 0:
        raise InputError("the mapped sensors' records never cover one interval together (see --clock and --rate)")
    a, b = int(full[0]), int(full[-1]) + 1
    if a > 0 or b < K:
        notes.append(f"{a + K - b} interval(s) at the ends, where not every sensor has records, left out")
        grid = grid[a:b + 1]
        flow, gyro, height, quality, present = (x[:, a:b] for x in (flow, gyro, height, quality, present))
    for i in range(n_sensors):
        n_miss = int((~present[i]).sum())
        if n_miss:
            notes.append(f"sensor {i}: {n_miss} of {present.shape[1]} interval(s) not covered by its records: "
                         "left out (missing)")
    t0 = grid[0]
    return ConvertedFlow((grid - t0) * 1e-6, flow, gyro, height, quality, present, origin + int(round(t0)), records, notes)


def write_flow_log(path, conv: ConvertedFlow, *, comment: str = "") -> Path:
    """Write :class:`ConvertedFlow` as a flow log (``flow.csv``, log.py's format); missing rows are left out."""
    from robocal.io import atomic_write_text
    from robocal.rigs.flow.log import FLOW_COLUMNS

    n, K = conv.quality.shape
    lines = [f"# {ln}" for ln in comment.splitlines()] if comment else []
    lines.append(",".join(FLOW_COLUMNS))
    t, dt = conv.t, np.diff(conv.t)
    for k in range(K):
        for i in range(n):
            if not conv.present[i, k]:
                continue
            fu, fv = conv.flow[i, k]
            g = conv.gyro[i, k]
            lines.append(f"{t[k + 1]:.6f},{dt[k]:.6f},{i},{fu:.6f},{fv:.6f},{g[0]:.8f},{g[1]:.8f},{g[2]:.8f},"
                         f"{conv.height[i, k]:.6f},{conv.quality[i, k]:.0f}")
    return atomic_write_text(Path(path), "\n".join(lines) + "\n")
