"""Log formats of the flow rig and the step from a log to per-sensor displacements.

A run is described by a YAML file (``run.yaml``)::

    units: {length: mm, angle: deg}
    camera: {focal_px: 166.67, window: 64}     # focal length in (binned) pixels;
                                                 # optional sigma_px: flow error per frame, px
    sensors:                                     # >= 2 sensors, in log order
      - {name: s60,  R: 350, psi: 60,  phi: 0, scale: 1}
      - {name: s120, R: 350, psi: 120, phi: 0}
      - {name: s270, R: 350, psi: 270, phi: 0}
    flow_log: flow.csv          # per-sensor flow records ... or
    frames: frames.npz          # raw frames + gyro + height
    reference: truth.csv        # optional: t [s], x [m], y [m], theta [rad]
    wheel: wheel.csv            # optional: wheel-odometry poses, same columns

**Per-sensor flow records** (``flow.csv``; what a PX4FLOW-class sensor
reports per frame, cf. MAVLink OPTICAL_FLOW_RAD): one row per sensor per
frame interval, units in the header::

    t [s],dt [s],sensor,flow_u [px],flow_v [px],gyro_x [rad/s],gyro_y [rad/s],gyro_z [rad/s],height [m],quality

``t`` is the end of the interval, ``sensor`` the 0-based index into
``sensors``; ``flow_u, flow_v`` the image motion of the ground (kernel
convention), not yet gyro-compensated; gyro rates are the interval's mean in
the camera frame (x = u, y = v, z = optical axis, down); ``height`` the
distance to the ground along the optical axis; ``quality`` 0..255 (0: no
flow; the row's flow is then ignored, it may be NaN-free zeros). Every
interval must have a row for every sensor (otherwise an error names the time
and the sensor, unless missing rows are explicitly allowed: then that sensor
is invalid there).

**Raw frames** (``frames.npz``, SI units): ``frames`` uint8 ``(n, T, W, W)``,
``t`` ``(T,)`` s, ``gyro`` ``(n, T-1, 3)`` rad/s, ``height`` ``(n, T-1)`` m.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robocal.diagnostics import Diagnostic
from robocal.errors import FileFormatError, InputError, ShapeError
from robocal.io import atomic_write_text, load_csv, load_document
from robocal.rigs.flow.kernel import FlowConfig, compensate_rotation, compute_flow_sequence, metric_displacement
from robocal.rigs.flow.kernel_bias import KernelTrace, sample_frames
from robocal.rigs.flow.model import SensorArray
from robocal.rigs.flow.odometry import SensorSteps, flow_sigma

__all__ = [
    "FLOW_COLUMNS",
    "RunSpec",
    "load_run",
    "steps_from_frames",
    "steps_from_records",
    "read_flow_csv",
    "write_flow_csv",
    "read_poses_csv",
    "write_poses_csv",
    "read_frames_npz",
    "write_frames_npz",
    "array_and_camera",
]

FLOW_COLUMNS = ["t [s]", "dt [s]", "sensor", "flow_u [px]", "flow_v [px]", "gyro_x [rad/s]", "gyro_y [rad/s]",
                "gyro_z [rad/s]", "height [m]", "quality"]


@dataclass
class FlowRecords:
    """Per-sensor flow records, reshaped to ``(n, K)`` per field."""

    t: np.ndarray        # (K+1,) frame times
    flow: np.ndarray     # (n, K, 2) px
    gyro: np.ndarray     # (n, K, 3) rad/s
    height: np.ndarray   # (n, K) m
    quality: np.ndarray  # (n, K)
    present: np.ndarray  # (n, K) bool
    gaps: np.ndarray = field(default_factory=lambda: np.zeros(0))         # start times of dropped stretches, s
    gap_lengths: np.ndarray = field(default_factory=lambda: np.zeros(0))  # their lengths, s


def write_flow_csv(path, t, flow, gyro, height, quality, *, comment: str = "") -> Path:
    """Write per-sensor flow records (see module doc). Arrays as in :class:`FlowRecords`."""
    n, K = quality.shape
    lines = [f"# {ln}" for ln in comment.splitlines()] if comment else []
    lines.append(",".join(FLOW_COLUMNS))
    dt = np.diff(t)
    for k in range(K):
        for i in range(n):
            fu, fv = flow[i, k]
            q = quality[i, k]
            if not np.isfinite(fu) or not np.isfinite(fv):
                fu, fv, q = 0.0, 0.0, 0.0
            g = gyro[i, k]
            lines.append(f"{t[k + 1]:.6f},{dt[k]:.6f},{i},{fu:.4f},{fv:.4f},{g[0]:.6f},{g[1]:.6f},{g[2]:.6f},"
                         f"{height[i, k]:.5f},{q:.0f}")
    return atomic_write_text(Path(path), "\n".join(lines) + "\n")


def read_flow_csv(path, n_sensors: int, *, allow_missing: bool = False) -> FlowRecords:
    """Read per-sensor flow records; errors name the row, time and sensor at fault."""
    tab = load_csv(path, required=["t", "dt", "sensor", "flow_u", "flow_v", "gyro_x", "gyro_y", "gyro_z", "height", "quality"])
    src = str(path)
    t = tab.column("t", kind="time")
    dt = tab.column("dt", kind="time")
    sensor = tab.column("sensor")
    if len(t) == 0:
        raise FileFormatError("no records", source=src)
    if np.any(sensor != np.round(sensor)) or np.any(sensor < 0) or np.any(sensor >= n_sensors):
        r = int(np.flatnonzero((sensor != np.round(sensor)) | (sensor < 0) | (sensor >= n_sensors))[0])
        raise FileFormatError(f"row {r + 1}: sensor index {sensor[r]:g} is not one of 0..{n_sensors - 1}", source=src)
    sensor = sensor.astype(int)
    h = tab.column("height", kind="length")
    if np.any(h <= 0):
        r = int(np.flatnonzero(h <= 0)[0])
        raise FileFormatError(f"row {r + 1} (t = {t[r]:.6f} s, sensor {sensor[r]}): height must be > 0 m, got {h[r]:g}", source=src)
    if np.any(dt <= 0):
        r = int(np.flatnonzero(dt <= 0)[0])
        raise FileFormatError(f"row {r + 1}: dt must be > 0 s, got {dt[r]:g}", source=src)
    q = tab.column("quality")
    if np.any((q < 0) | (q > 255)):
        r = int(np.flatnonzero((q < 0) | (q > 255))[0])
        raise FileFormatError(f"row {r + 1} (t = {t[r]:.6f} s, sensor {sensor[r]}): quality must be in 0..255, got {q[r]:g}",
                              source=src)
    # timestamps must not go back; rows of one interval share a timestamp
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        r = int(back[0]) + 1
        raise FileFormatError(f"timestamps must not decrease: row {r + 1} has t = {t[r]:.6f} s after t = {t[r - 1]:.6f} s", source=src)
    times, inv = np.unique(t, return_inverse=True)
    K = times.size
    dup = np.zeros((n_sensors, K), int)
    np.add.at(dup, (sensor, inv), 1)
    if np.any(dup > 1):
        i, k = np.argwhere(dup > 1)[0]
        raise FileFormatError(f"sensor {i} has {dup[i, k]} records at t = {times[k]:.6f} s (expected one)", source=src)
    present = dup == 1
    if not allow_missing and not present.all():
        i, k = np.argwhere(~present)[0]
        raise FileFormatError(
            f"sensor {i} has no record at t = {times[k]:.6f} s ({(~present).sum()} missing records in all; "
            "every interval needs a row per sensor, or allow missing records)", source=src)
    flow = np.full((n_sensors, K, 2), np.nan)
    gyro = np.zeros((n_sensors, K, 3))
    height = np.full((n_sensors, K), np.nan)
    quality = np.zeros((n_sensors, K))
    flow[sensor, inv, 0] = tab.column("flow_u")
    flow[sensor, inv, 1] = tab.column("flow_v")
    for a, nm in enumerate(("gyro_x", "gyro_y", "gyro_z")):
        gyro[sensor, inv, a] = tab.column(nm, kind="angular_rate") if tab.units.get(nm) else tab.column(nm)
    height[sensor, inv] = h
    quality[sensor, inv] = q
    # dt: every row of an interval gives the same one, and each interval starts where the
    # previous one ended; a later start is a dropped stretch of records (motion lost)
    dts = np.zeros(K)
    dts[inv] = dt
    row_of = np.zeros(K, int)
    row_of[inv[::-1]] = np.arange(len(t))[::-1]            # first row of each interval
    tol = 0.1 * dts
    bad = np.abs(dt - dts[inv]) > tol[inv]
    if np.any(bad):
        r = int(np.flatnonzero(bad)[0])
        raise FileFormatError(f"row {r + 1} (t = {t[r]:.6f} s): dt = {dt[r]:g} s disagrees with dt = {dts[inv[r]]:g} s "
                              "of the other rows of that interval", source=src)
    start = times - dts
    lag = start[1:] - times[:-1]                            # > 0: a gap before interval k+1
    over = np.flatnonzero(lag < -tol[1:])
    if over.size:
        k = int(over[0]) + 1
        raise FileFormatError(f"row {row_of[k] + 1} (t = {times[k]:.6f} s): dt = {dts[k]:g} s reaches back to "
                              f"{start[k]:.6f} s, before the previous interval's end {times[k - 1]:.6f} s", source=src)
    gaps = np.flatnonzero(lag > tol[1:]) + 1
    if gaps.size and not allow_missing:
        k = int(gaps[0])
        raise FileFormatError(
            f"row {row_of[k] + 1} (t = {times[k]:.6f} s): the interval starts at {start[k]:.6f} s but the previous one "
            f"ended at {times[k - 1]:.6f} s: {lag[k - 1]:.6f} s of records are missing ({gaps.size} such gaps, "
            f"{lag[gaps - 1].sum():.4f} s in all); allow missing records to bridge them", source=src)
    t_all = np.concatenate([[start[0]], times])
    if gaps.size:
        # each gap becomes an interval without any sensor (fusion bridges it at the last velocity)
        new_t = np.sort(np.concatenate([t_all, start[gaps]]))
        pos = np.searchsorted(new_t, times) - 1             # new index of each original interval
        K2 = new_t.size - 1

        def spread(a, fill):
            out = np.full((a.shape[0], K2) + a.shape[2:], fill, dtype=a.dtype)
            out[:, pos] = a
            return out

        return FlowRecords(new_t, spread(flow, np.nan), spread(gyro, 0.0), spread(height, np.nan),
                           spread(quality, 0.0), spread(present, False), gaps=times[gaps - 1], gap_lengths=lag[gaps - 1])
    return FlowRecords(t_all, flow, gyro, height, quality, present)


def steps_from_records(rec: FlowRecords, focal_px: float, config: FlowConfig = FlowConfig(), *,
                       sigma_px: float | None = None) -> SensorSteps:
    """Gyro-compensate (eqs. 3–4) and scale (eq. 5) logged flow into :class:`SensorSteps`.

    ``sigma_px``: the sensors' per-frame flow error with all blocks in use (px); by default
    ``config.sigma_px`` (the simulator's equiangular kernel). A real log should state its own
    (``camera: sigma_px`` in run.yaml: about 0.16 px for PX4FLOW's half-pixel firmware).
    """
    sigma_px = config.sigma_px if sigma_px is None else float(sigma_px)
    n, K = rec.quality.shape
    dt = np.diff(rec.t)
    disp = np.full((n, K, 2), np.nan)
    valid = rec.present & (rec.quality > 0) & np.all(np.isfinite(rec.flow), axis=2)
    for i in range(n):
        comp = compensate_rotation(rec.flow[i], rec.gyro[i], dt, focal_px, threshold=config.gyro_threshold)
        h = np.where(rec.present[i], rec.height[i], 1.0)
        disp[i] = metric_displacement(comp, h, focal_px)
    disp = np.where(valid[..., None], disp, np.nan)
    n_used = np.maximum(rec.quality / 255.0 * config.n_blocks, 1.0)
    sigma = flow_sigma(n_used, np.nan_to_num(rec.height, nan=1.0), focal_px, sigma_px=sigma_px, n_blocks=config.n_blocks)
    in_gap = np.zeros(K, bool)
    if rec.gaps.size:
        in_gap[np.searchsorted(rec.t, rec.gaps)] = True
    reasons = []
    for i in range(n):
        why = {"dropped interval": int((in_gap & ~rec.present[i]).sum()),
               "no record": int((~in_gap & ~rec.present[i]).sum()),
               "quality 0 in the log": int((rec.present[i] & (rec.quality[i] <= 0)).sum()),
               "non-finite flow": int((rec.present[i] & (rec.quality[i] > 0) & ~np.all(np.isfinite(rec.flow[i]), axis=1)).sum())}
        reasons.append({k: v for k, v in why.items() if v})
    warnings = []
    if rec.gaps.size:
        warnings.append(Diagnostic("dropped", f"{rec.gaps.size} stretch(es) of the flow log are missing, "
                                   f"{rec.gap_lengths.sum():.4f} s in all (first at t = {rec.gaps[0]:.6f} s, "
                                   f"{rec.gap_lengths[0]:.4f} s): bridged at the last velocity over their real length",
                                   indices=tuple(int(k) for k in np.flatnonzero(in_gap)[:200])))
    # the calibration's kernel-bias model: the logged raw flow is this kernel's only when the log
    # does not state another flow error than the kernel's (a PX4FLOW half-pixel log says 0.16 px)
    trace = None
    if abs(sigma_px - config.sigma_px) < 1e-9:
        trace = KernelTrace(flow_px=np.where(valid[..., None], rec.flow, np.nan),
                            px_to_m=np.nan_to_num(rec.height, nan=1.0) / float(focal_px), frames=None, config=config)
        if config.debias:
            disp = trace.debias(disp)
    elif config.debias:
        raise InputError(f"camera: sigma_px = {sigma_px:g} px says the log comes from another flow kernel than this one "
                         f"({config.sigma_px:g} px): its sub-pixel bias is unknown, so it cannot be removed (drop debias)")
    return SensorSteps(rec.t, disp, valid, sigma, rec.quality, reasons=reasons, warnings=warnings, kernel=trace,
                       height=np.where(rec.present, rec.height, np.nan))


def steps_from_frames(frames, t, gyro, height, focal_px: float, config: FlowConfig = FlowConfig(), *,
                      sigma_px: float | None = None, progress=None):
    """Run the flow kernel on every sensor's frames and build :class:`SensorSteps`.

    Parameters
    ----------
    frames : array_like of uint8, shape (n, T, W, W)
    t : array_like, shape (T,)
    gyro : array_like, shape (n, T-1, 3)
    height : array_like, shape (n, T-1)
    focal_px : float
    sigma_px : float, optional
        Flow error with all blocks in use, px; default ``config.sigma_px`` (the kernel mode's).
    progress : callable, optional
        ``progress(iterable, desc=...)`` wrapper for a progress bar.

    Returns
    -------
    steps : SensorSteps
    flows : list of FrameFlow
        Per-sensor kernel output (flow in px, quality, reasons).
    """
    sigma_px = config.sigma_px if sigma_px is None else float(sigma_px)
    frames = np.asarray(frames)
    if frames.ndim != 4:
        raise ShapeError(f"frames must have shape (n_sensors, T, {config.window}, {config.window}), got {frames.shape}")
    n, T = frames.shape[:2]
    if frames.shape[2:] != (config.window, config.window):
        raise ShapeError(f"frames must be {config.window}x{config.window} (the sensor window), got {frames.shape[2]}x{frames.shape[3]}")
    t = np.asarray(t, float)
    if t.shape != (T,):
        raise ShapeError(f"t must have shape ({T},), got {t.shape}")
    d = np.diff(t)
    if np.any(~(d > 0)):
        k = int(np.flatnonzero(~(d > 0))[0])
        raise InputError(f"frame timestamps must increase strictly: t[{k + 1}] = {t[k + 1]:.6f} s follows t[{k}] = {t[k]:.6f} s")
    gyro = np.asarray(gyro, float)
    height = np.asarray(height, float)
    if gyro.shape != (n, T - 1, 3):
        raise ShapeError(f"gyro must have shape ({n}, {T - 1}, 3), got {gyro.shape}")
    if height.shape != (n, T - 1):
        raise ShapeError(f"height must have shape ({n}, {T - 1}), got {height.shape}")
    if np.any(~np.isfinite(height)) or np.any(height <= 0):
        i, k = np.argwhere(~(height > 0))[0]
        raise InputError(f"height must be > 0 m: sensor {i}, interval {k} has {height[i, k]:g}")
    disp = np.empty((n, T - 1, 2))
    valid = np.empty((n, T - 1), bool)
    sigma = np.empty((n, T - 1))
    quality = np.empty((n, T - 1))
    flows = []
    it = range(n) if progress is None else progress(range(n), desc="flow")
    for i in it:
        ff = compute_flow_sequence(frames[i], config, gyro=gyro[i], dt=d, height=height[i], focal_px=focal_px)
        flows.append(ff)
        disp[i] = ff.displacement
        valid[i] = ff.valid
        quality[i] = ff.quality
        sigma[i] = flow_sigma(np.maximum(ff.quality / 255.0 * config.n_blocks, 1.0), height[i], focal_px,
                              sigma_px=sigma_px, n_blocks=config.n_blocks)
    reasons = []
    for ff in flows:
        r = [x for x in ff.reason if x]
        reasons.append({k: r.count(k) for k in sorted(set(r))})
    # what the calibration's kernel-bias model needs: the raw flow, its scale and a few frames
    trace = KernelTrace(flow_px=np.stack([ff.flow_px for ff in flows]), px_to_m=height / float(focal_px),
                        frames=sample_frames(frames), config=config)
    if config.debias:
        disp = trace.debias(disp)
    return SensorSteps(t, disp, valid, sigma, quality, reasons=reasons, kernel=trace, height=height), flows


#: peak working bytes per byte of a flow.csv (measured: 1.4 GB for 10^6 rows, 70 MB), rounded up
FLOW_LOG_BYTES_PER_BYTE = 25.0

#: working bytes per frame byte of ``odometry`` on raw frames: the loaded frames, the kernel's
#: pixel-major copy of one sensor's frames and its per-frame outputs; measured peak 2.3x on the
#: frames example and a 60 s simulated run, rounded up
FRAMES_BYTES_PER_BYTE = 3.0


def _npz_members(path, src: str) -> dict:
    """Each array of an .npz archive: ``(shape, dtype, offset)``, offset being where its raw data
    start in the file when the member is stored uncompressed in C order (else None).

    Read from the archive's directory and the arrays' .npy headers, before any array data.
    """
    import zipfile

    members = {}
    with zipfile.ZipFile(path) as zf, open(path, "rb") as raw:
        for info in zf.infolist():
            if not info.filename.endswith(".npy"):
                continue
            with zf.open(info) as fh:
                version = np.lib.format.read_magic(fh)
                read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
                shape, fortran, dtype = read(fh)
                header = fh.tell()
            offset = None
            if info.compress_type == zipfile.ZIP_STORED and not fortran and not dtype.hasobject:
                # the local header's own name and extra lengths (they may differ from the directory's)
                raw.seek(info.header_offset + 26)
                name_len, extra_len = np.frombuffer(raw.read(4), "<u2")
                offset = info.header_offset + 30 + int(name_len) + int(extra_len) + header
                nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
                if info.file_size != header + nbytes:
                    raise FileFormatError(f"array '{info.filename[:-4]}' holds {info.file_size - header} bytes, its "
                                          f"header says {nbytes} ({dtype}, shape {shape}): the file is damaged",
                                          source=src)
            members[info.filename[:-4]] = (shape, dtype, offset)
    return members


def _require_frames_memory(shape, dtype, src: str, *, mapped: bool = False) -> None:
    """Refuse before reading when the frames would not fit (the header gives their shape); memory-mapped
    frames live in the page cache, not in the process: the working copies only."""
    from robocal.resources import require_memory

    nbytes = float(np.prod(shape, dtype=float)) * np.dtype(dtype).itemsize
    per_byte = FRAMES_BYTES_PER_BYTE - 1.0 if mapped else FRAMES_BYTES_PER_BYTE
    require_memory(nbytes * per_byte, f"reading the {'x'.join(map(str, shape))} frames", source=src)


def write_frames_npz(path, frames, t, gyro, height) -> Path:
    """Write a raw-frames file (see module doc) that :func:`read_frames_npz` memory-maps.

    The arrays are stored uncompressed: camera frames of a textured floor shrink by only
    ~10 % under zlib (133 of 147 MB for 30 s of 3 sensors at 400 Hz), while inflating them
    cost 3x the flow kernel's time on them (docs/rigs/flow.md, "Speed").
    """
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as fh:
        np.savez(fh, frames=np.ascontiguousarray(frames, dtype=np.uint8), t=np.asarray(t, float),
                 gyro=np.asarray(gyro, float), height=np.asarray(height, float))
    tmp.replace(path)
    return path


def read_frames_npz(path):
    """Load ``frames, t, gyro, height`` from a raw-frames file (see module doc).

    ``frames`` stored uncompressed (:func:`write_frames_npz`, ``np.savez``) are
    memory-mapped read-only, not read: the kernel pages in what it reads,
    once. Compressed archives (``np.savez_compressed``, files written before
    0.2) are inflated into memory as before. The shapes, the frame count and
    the finiteness of ``t``, ``gyro`` and ``height`` are checked here, so
    that every error names this file.
    """
    import zipfile

    src = str(path)
    try:
        if not zipfile.is_zipfile(path):
            with open(path, "rb") as fh:
                bare = fh.read(6) == b"\x93NUMPY"
            raise FileFormatError("is a single .npy array, not an .npz archive of frames, t, gyro, height" if bare
                                  else "cannot read as .npz (not a zip archive)", source=src)
        members = _npz_members(path, src)
        missing = [k for k in ("frames", "t", "gyro", "height") if k not in members]
        if missing:
            raise FileFormatError(f"missing array(s) {', '.join(missing)} (have: {', '.join(members) or 'none'})",
                                  source=src)
        shape, dtype, offset = members["frames"]
        _require_frames_memory(shape, dtype, src, mapped=offset is not None)
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in ("t", "gyro", "height")}
            data["frames"] = (z["frames"] if offset is None or 0 in shape
                              else np.memmap(path, dtype=dtype, mode="r", offset=offset, shape=shape))
    except FileFormatError:
        raise
    except FileNotFoundError:
        raise FileFormatError("file not found", source=src) from None
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        raise FileFormatError(f"cannot read as .npz ({exc})", source=src) from None
    fr = data["frames"]
    if fr.dtype != np.uint8:
        raise FileFormatError(f"frames must be uint8 grey levels, got {fr.dtype}", source=src)
    if fr.ndim != 4 or fr.shape[2] != fr.shape[3]:
        raise FileFormatError(f"frames must have shape (n_sensors, T, W, W), got {fr.shape}", source=src)
    n, T = fr.shape[:2]
    if T < 2:
        raise FileFormatError(f"needs at least 2 frames per sensor for a flow, got {T}", source=src)
    for k, shape in (("t", (T,)), ("gyro", (n, T - 1, 3)), ("height", (n, T - 1))):
        a = data[k]
        if a.shape != shape:
            raise FileFormatError(f"{k} must have shape {shape} for frames of shape {fr.shape}, got {a.shape}", source=src)
        if not np.issubdtype(a.dtype, np.number):
            raise FileFormatError(f"{k} must be numbers, got dtype {a.dtype}", source=src)
        bad = ~np.isfinite(a)
        if bad.any():
            raise FileFormatError(f"{k} has {int(bad.sum())} NaN/infinite value(s), first at index "
                                  f"{tuple(int(i) for i in np.argwhere(bad)[0])}", source=src)
        data[k] = a.astype(float)
    if np.any(data["height"] <= 0):
        i, k = np.argwhere(data["height"] <= 0)[0]
        raise FileFormatError(f"height must be > 0 m: sensor {i}, interval {k} has {data['height'][i, k]:g}", source=src)
    d = np.diff(data["t"])
    if np.any(d <= 0):
        k = int(np.flatnonzero(d <= 0)[0])
        raise FileFormatError(f"frame times must increase strictly: t[{k + 1}] = {data['t'][k + 1]:.6f} s follows "
                              f"t[{k}] = {data['t'][k]:.6f} s", source=src)
    return data


def write_poses_csv(path, t, poses, *, comment: str = "") -> Path:
    """A ``t, x, y, theta`` CSV (s, m, m, rad; :func:`read_poses_csv` reads it), ``comment`` as ``#`` lines."""
    lines = [f"# {ln}" for ln in comment.splitlines()] if comment else []
    lines.append("t [s],x [m],y [m],theta [rad]")
    rows = np.column_stack([np.asarray(t, float), np.asarray(poses, float)])
    # every row in one %-format of C doubles: the text of a per-row f-string, 5x faster (12,000 rows: 12 ms)
    body = ("%.6f,%.6f,%.6f,%.7f\n" * len(rows)) % tuple(rows.ravel().tolist())
    return atomic_write_text(Path(path), "\n".join(lines) + "\n" + body)


def read_poses_csv(path):
    """``t (N,)``, poses ``(N, 3)`` (x, y [m], theta [rad]) from a ``t, x, y, theta`` CSV (units in the header).

    Read by the core's pose-list reader (:func:`robocal.io.load_poses`), which
    checks units, NaN and strictly increasing times; a planar log needs its
    timestamps.
    """
    from robocal.io import load_poses

    poses = load_poses(path)
    if not poses.planar or poses.t is None:
        raise FileFormatError("a trajectory needs the columns t, x, y, theta with units in the header "
                              "(t [s], x [m], y [m], theta [rad])", source=str(path))
    return poses.t, poses.xy_theta


@dataclass
class RunSpec:
    """A parsed ``run.yaml``."""

    path: Path
    array: SensorArray
    focal_px: float
    window: int
    flow_log: Path | None
    frames: Path | None
    reference: Path | None
    wheel: Path | None
    rate: float | None
    sigma_px: float | None = None

    def inputs(self) -> list:
        return [p for p in (self.path, self.flow_log, self.frames, self.reference, self.wheel) if p is not None]


def array_and_camera(doc):
    """``(array, focal_px, window, rate, sigma_px)`` of a run description's ``sensors`` and ``camera``
    sections (run.yaml, and the topic map of a recording, which holds the same two sections)."""
    array = SensorArray.from_document(doc)
    cam = doc.sub("camera")
    focal = cam.float("focal_px", positive=True)
    window = cam.int("window", default=64, minimum=8)
    rate = cam.float("rate", kind="frequency", default=None) if "rate" in cam else None
    sigma_px = cam.float("sigma_px", positive=True) if "sigma_px" in cam else None
    return array, focal, window, rate, sigma_px


def load_run(path) -> RunSpec:
    """Parse and check a run description (see module doc)."""
    doc = load_document(path)
    base = Path(path).parent
    array, focal, window, rate, sigma_px = array_and_camera(doc)

    def opt(key):
        if key not in doc:
            return None
        p = Path(doc.str(key))
        p = p if p.is_absolute() else base / p
        if not p.is_file():
            raise FileFormatError(f"field '{key}': file {p} not found", source=str(path))
        return p

    flow_log, frames = opt("flow_log"), opt("frames")
    if flow_log is None and frames is None:
        raise FileFormatError("needs 'flow_log' (per-sensor flow records) or 'frames' (raw frames)", source=str(path))
    return RunSpec(Path(path), array, focal, window, flow_log, frames, opt("reference"), opt("wheel"), rate, sigma_px)


def load_steps(spec: RunSpec, config: FlowConfig | None = None, *, allow_missing: bool = False, progress=None,
               prefer: str = "frames", before_kernel=None):
    """Per-sensor displacements of a run (from raw frames when present, else the flow log).

    ``before_kernel``: called once the frames are read and checked, before the flow kernel (or the flow
    log's conversion) starts: :func:`~robocal.rigs.flow.workflow.odometry_run` starts reading the
    trajectories there, to overlap the kernel (:mod:`robocal.rigs.flow.background`)."""
    config = config or FlowConfig(window=spec.window)
    use_frames = spec.frames is not None and (prefer == "frames" or spec.flow_log is None)
    go = before_kernel or (lambda: None)
    if use_frames:
        d = read_frames_npz(spec.frames)
        if d["frames"].ndim != 4 or d["frames"].shape[0] != spec.array.n:
            raise ShapeError(f"{spec.frames}: frames must have shape ({spec.array.n}, T, W, W) for the "
                             f"{spec.array.n} sensors of {spec.path.name}, got {d['frames'].shape}")
        go()
        steps, flows = steps_from_frames(d["frames"], d["t"], d["gyro"], d["height"], spec.focal_px, config, progress=progress)
        return steps, flows
    if getattr(spec, "records", None) is not None:  # a recording's records (robocal.rigs.flow.bag), in memory
        go()
        return steps_from_records(spec.records, spec.focal_px, config, sigma_px=spec.sigma_px), None
    from robocal.resources import require_memory

    # peak 1.4 GB for a 10^6-row, 70 MB flow.csv (odometry, calibrate, evaluate): ~20 x the file
    size = spec.flow_log.stat().st_size
    require_memory(FLOW_LOG_BYTES_PER_BYTE * size, f"the {size / 1e6:,.0f} MB flow log", source=str(spec.flow_log))
    rec = read_flow_csv(spec.flow_log, spec.array.n, allow_missing=allow_missing)
    go()
    return steps_from_records(rec, spec.focal_px, config, sigma_px=spec.sigma_px), None
