"""The flow rig's commands besides ``calibrate``: the simulate step and the run functions of
``odometry``, ``evaluate`` and ``convert-mavlink`` (declared in :mod:`robocal.rigs.flow.cli`).

Each run function takes the parsed arguments, does its work through the library
(:mod:`robocal.rigs.flow.workflow`, :mod:`robocal.rigs.flow.mavlink`), writes
into ``args.out`` and prints what the command reports; the report of a result
is :func:`robocal.rigs.flow.report.build_report`'s, so ``robocal report``
rebuilds it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from robocal.errors import InputError
from robocal.io import atomic_write_text
from robocal.progress import progress as _bar

__all__ = ["simulate_files", "run_odometry", "run_evaluate", "run_convert_mavlink", "physical_memory",
           "SIM_BYTES_PER_FRAME_BYTE"]

#: the simulator renders every frame in memory, as float64 before quantising (measured: 557 MB
#: peak for the default 8 s run, of which ~40 MB are the uint8 frames): bytes per uint8 frame byte
SIM_BYTES_PER_FRAME_BYTE = 10.0


def physical_memory() -> float:
    """This machine's physical memory, bytes (16 GB when the system does not say)."""
    try:
        return float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return 16e9


def _stages(desc: str, n: int, enabled: bool):
    """A stage bar on a terminal for long runs (10^6 log rows: minutes, mostly reading): ``tick()`` starts
    the next stage."""
    it = iter(_bar(range(n), desc=desc, total=n, enabled=enabled))
    return lambda: next(it, None)


def _progress(enabled: bool):
    return lambda it, desc: _bar(it, desc=desc, enabled=enabled)


def _kernel_options(args) -> dict:
    from robocal.rigs.flow.workflow import KERNEL_OPTIONS

    return {k: getattr(args, k, None) for k in (*KERNEL_OPTIONS, "debias")}


def _out(args, label: str) -> Path:
    # the core's output-folder claim (cli._common, which imports nothing of the CLI's parser): the
    # Command contract's way for an extra command to write into --out
    from robocal.io import prepare_out_dir

    return prepare_out_dir(args.out, label)


def _write(out: Path, result, report) -> None:
    from robocal.io import write_run

    write_run(out, result, report)


def simulate_files(out_dir, rng, *, progress: bool = True, trajectory: str = "loop", duration: float = 8.0,
                   rate: float = 400.0, speed: float = 0.4, texture: str = "gravel", supersample: int = 2,
                   gap=None, no_frames: bool = False, no_progress: bool = False, **kernel_options) -> list:
    """``robocal flow simulate``: a drive's files (see :func:`robocal.rigs.flow.workflow.write_simulation`).

    ``gap``: ``"X,Y,RADIUS"`` strings (m) of texture-less discs on the floor;
    ``kernel_options``: the kernel (``subpixel``, ``refine``, ``search``,
    ``aggregate``; None = default) that computes the written flow log.
    Prints the texture used and, near the sensors' speed ceiling, a warning.
    """
    if duration <= 0:
        raise InputError(f"--duration must be > 0 s, got {duration}")
    if not rate > 0:
        raise InputError(f"--rate must be > 0 Hz, got {rate}")
    if supersample < 1:
        raise InputError(f"--supersample must be >= 1 (sub-rays per pixel side), got {supersample}")
    if not (np.isfinite(speed) and speed >= 0):
        raise InputError(f"--speed must be >= 0 m/s, got {speed}")
    n_frames = duration * rate + 1
    need = n_frames * 3 * 64 * 64 * SIM_BYTES_PER_FRAME_BYTE
    limit = 0.75 * physical_memory()
    if not need <= limit:
        raise InputError(f"--duration {duration:g} s at --rate {rate:g} Hz is {n_frames:,.0f} frames per sensor, "
                         f"about {need / 1e9:,.1f} GB of memory to render; this machine allows {limit / 1e9:.1f} GB "
                         f"(about {limit / (3 * 64 * 64 * SIM_BYTES_PER_FRAME_BYTE * rate):.3g} s at this rate)")
    gaps = ()
    if gap:
        try:
            gaps = tuple(tuple(float(v) for v in g.split(",")) for g in gap)
        except ValueError:
            raise InputError("--gap takes X,Y,RADIUS in metres, e.g. --gap 0.5,0.2,0.05") from None
        if any(len(g) != 3 for g in gaps):
            raise InputError("--gap takes X,Y,RADIUS in metres, e.g. --gap 0.5,0.2,0.05")
    from robocal.rigs.flow.simulate import max_speed, simulate_run
    from robocal.rigs.flow.workflow import default_sim, flow_config, write_simulation

    sim = default_sim(trajectory, duration, texture=texture, supersample=supersample, gaps=gaps, speed=speed)
    sim.camera = type(sim.camera)(rate=rate)
    vmax = max_speed(sim)
    if speed * 1.3 > vmax:
        print(f"warning: speed {speed} m/s approaches the sensors' ceiling {vmax:.2f} m/s "
              "((S + 0.5) h rate / f); flow will alias")
    run = simulate_run(sim, rng)
    paths = write_simulation(run, out_dir, frames=not no_frames, flow_config=flow_config(kernel_options),
                             progress=_progress(progress and not no_progress))
    print(f"texture: {run.texture_note}")
    return list(paths.values())


def run_odometry(args) -> int:
    """``robocal flow odometry RUN --out DIR``: trajectory.csv, result.json, report.html (not with ``--no-report``:
    ``robocal flow report DIR/result.json`` draws it from the result later)."""
    from robocal.rigs.flow.log import write_poses_csv
    from robocal.rigs.flow.workflow import (check_kernel_options, evaluation_run, flow_config, frames_table,
                                            load_input, odometry_result, odometry_run, read_reference,
                                            trajectory_curves)

    spec = load_input(args.input, bag=args.bag, map=args.map)  # run.yaml, or a recording (issue 15)
    out = _out(args, "flow-odometry")
    opts = _kernel_options(args)
    check_kernel_options(opts, spec)
    show = not args.no_progress
    tick = _stages("flow odometry: read, judge, fuse; report", 2, show)
    tick()
    # the reference (and the wheel log, the inputs' hashes) are read beside the kernel (workflow.odometry_run)
    od, flows, steps = odometry_run(spec, config=flow_config(opts, spec), allow_missing=args.allow_missing,
                                    robust=not args.no_robust, method=args.integration, progress=_progress(show),
                                    accept_implausible=args.accept_implausible)
    reference = read_reference(spec)
    od.warnings.extend(getattr(spec, "warnings", ()))  # a recording's clock_mismatch
    tick()
    write_poses_csv(out / "trajectory.csv", od.t, od.poses, comment=f"flow odometry of {spec.path.name}")
    errors = None
    if spec.reference is not None:
        curves, errors = evaluation_run(spec, od, reference=reference)
    else:
        curves = trajectory_curves(spec, od)
    res = odometry_result(od, spec, errors, curves=curves, steps=steps)
    report = None
    if not getattr(args, "no_report", False):
        from robocal.rigs.flow.report import build_report  # here: --no-report draws nothing (issue 16)

        report = build_report(res)
    _write(out, res, report)
    print(f"wrote {out / 'trajectory.csv'}")
    s = od.summary()
    line = f"distance {s['distance_m']:.3f} m, {s['bridged_steps']} bridged steps"
    if errors:
        fo = errors["flow odometry"]
        r1 = fo.headline_rpe()
        line += f", ATE {fo.ate_rmse * 1e3:.1f} mm"
        if r1["n"]:
            line += f", {fo.rpe_label()} {r1['trans_per_m'] * 100:.2f} % {np.degrees(r1['rot_per_m']):.2f} deg/m"
    print(line)
    if errors and errors["flow odometry"].rpe_note:
        print(f"  note: {errors['flow odometry'].rpe_note}")
    for row in frames_table(od):
        if row["frames without flow"]:
            print(f"  sensor {row['sensor']}: {row['frames without flow']} frames without flow ({row['reasons']})")
    return 0


def run_evaluate(args) -> int:
    """``robocal flow evaluate RUN [--array CAL.yaml] --out DIR``: ATE / RPE of flow (and wheel) odometry."""
    from robocal.io import load_document
    from robocal.rigs.flow.log import load_run
    from robocal.rigs.flow.model import SensorArray
    from robocal.rigs.flow.odometry import dead_reckon
    from robocal.rigs.flow.report import build_report, compare_text
    from robocal.rigs.flow.workflow import (check_kernel_options, evaluation_result, evaluation_run, flow_config,
                                            odometry_run, read_reference)

    spec = load_run(args.input)
    out = _out(args, "flow-evaluate")
    opts = _kernel_options(args)
    check_kernel_options(opts, spec)
    show = not args.no_progress
    tick = _stages("flow evaluate: read, judge, fuse; evaluate, report", 2, show)
    tick()
    od, _, steps = odometry_run(spec, config=flow_config(opts, spec), progress=_progress(show),
                                accept_implausible=args.accept_implausible)
    reference = read_reference(spec)      # read beside the kernel
    cal_od = None
    if args.array is not None:
        arr = SensorArray.from_document(load_document(args.array))
        if arr.n != spec.array.n:
            raise InputError(f"{args.array}: {arr.n} sensors, but {spec.path} has {spec.array.n}")
        cal_od = dead_reckon(steps, arr)
    tick()
    curves, errors = evaluation_run(spec, od, calibrated=cal_od, reference=reference)
    res = evaluation_result(od, spec, curves, errors, calibrated=cal_od)
    _write(out, res, build_report(res))
    for k, v in errors.items():
        r1 = v.headline_rpe()
        rpe = (f"{v.rpe_label()} {r1['trans_per_m'] * 100:5.2f} %  {np.degrees(r1['rot_per_m']):5.2f} deg/m (RMS)"
               if r1["n"] else "RPE: none (see below)")
        print(f"  {k:28s} ATE {v.ate_rmse * 1e3:7.1f} mm   {rpe}")
    for note in dict.fromkeys(v.rpe_note for v in errors.values() if v.rpe_note):
        print(f"  note: {note}")
    if cal_od is not None:
        print(compare_text(errors["flow odometry"], errors["flow odometry (calibrated)"]))
    return 0


def run_convert_mavlink(args) -> int:
    """``robocal flow convert-mavlink LOG.tlog --array A.yaml --sensor-map ... --out DIR``: flow.csv + run.yaml."""
    from robocal.io import load_document
    from robocal.rigs.flow.log import load_run
    from robocal.rigs.flow.mavlink import flow_records, parse_sensor_map, read_tlog, write_flow_log
    from robocal.rigs.flow.model import SensorArray
    from robocal.rigs.flow.workflow import array_yaml

    if args.focal_px is not None and not args.focal_px > 0:
        raise InputError(f"--focal-px must be > 0 px, got {args.focal_px}")
    if not args.sigma_px > 0:
        raise InputError(f"--sigma-px must be > 0 px, got {args.sigma_px}")
    if not args.frame_rate > 0:
        raise InputError(f"--frame-rate must be > 0 Hz, got {args.frame_rate}")
    if args.rate is not None and not args.rate > 0:
        raise InputError(f"--rate must be > 0 Hz, got {args.rate}")
    doc = load_document(args.array)
    array = SensorArray.from_document(doc)
    smap = parse_sensor_map(args.sensor_map, array.names)
    unmapped = [nm for i, nm in enumerate(array.names) if i not in smap.values()]
    if unmapped:
        raise InputError(f"--sensor-map: the array's sensor(s) {', '.join(unmapped)} have no sensor_id; map every "
                         f"sensor of {args.array} (or give an array with only the logged sensors)")
    focal = args.focal_px
    if focal is None:
        cam = doc.sub("camera") if "camera" in doc else None
        focal = cam.float("focal_px", positive=True) if cam is not None and "focal_px" in cam else 666.7
    log = read_tlog(args.input)
    conv = flow_records(log, smap, array.n, focal, clock=args.clock, rate=args.rate, sysid=args.sysid,
                        source=str(args.input))
    out = _out(args, "flow-convert-mavlink")
    note = (f"converted by robocal flow convert-mavlink from {Path(args.input).name}: OPTICAL_FLOW_RAD, "
            f"clock '{args.clock}', t = 0 at {conv.t0_us} us; sensor map {args.sensor_map}\n"
            f"flow_u = -f integrated_y, flow_v = f integrated_x (f = {focal:g} px), gyro = integrated_*gyro / dt")
    write_flow_log(out / "flow.csv", conv, comment=note)
    # a record integrates several of the sensor's frames: its flow error grows as the root of their number
    n_frames = max(1.0, float(np.median(np.diff(conv.t))) * args.frame_rate)
    sigma = float(args.sigma_px) * float(np.sqrt(n_frames))
    cam = {"focal_px": float(focal), "window": 64, "sigma_px": round(sigma, 6)}
    atomic_write_text(out / "run.yaml", array_yaml(array, cam, {"flow_log": "flow.csv"}))
    spec = load_run(out / "run.yaml")   # the written run must read back
    print(f"wrote {out / 'flow.csv'}")
    print(f"wrote {spec.path}")
    print(f"log: {log.stats.summary()}")
    K = conv.quality.shape[1]
    print(f"{K} intervals of {np.median(np.diff(conv.t)) * 1e3:.3f} ms (median), {conv.t[-1]:.3f} s; records per "
          "sensor: " + ", ".join(f"{array.names[i]} {c}" for i, c in conv.records.items()))
    print(f"flow error per interval: {sigma:.4g} px (--sigma-px {args.sigma_px:g} per frame x sqrt({n_frames:.3g} "
          f"frames at --frame-rate {args.frame_rate:g} Hz)), written as camera: sigma_px")
    for n in conv.notes:
        print(f"  note: {n}")
    if not conv.present.all():
        print("  note: some intervals have no record of some sensor: run odometry with --allow-missing")
    return 0
