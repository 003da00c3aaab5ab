"""The flow rig's workflow: simulate -> files, odometry, calibration, evaluation, as library functions.

Each returns plain result objects and a :class:`~robocal.io.CalibrationResult`
(whose report :mod:`robocal.rigs.flow.report` builds from it alone), so
everything the commands do can be done from Python. The steps of the rig's
:class:`~robocal.workflow.Workflow` (``robocal flow calibrate``) are
:func:`calibrate_input`, :func:`calibration_result` and :func:`summary`; the
run functions of the other commands are in :mod:`robocal.rigs.flow.commands`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from robocal.diagnostics import Diagnostic
from robocal.errors import InputError
from robocal.io import CalibrationResult, atomic_write_text
from robocal.rigs.flow import background
from robocal.rigs.flow.calibrate import array_estimate, calibrate_array, interpolate_poses
from robocal.rigs.flow.evaluate import evaluate_trajectory
from robocal.rigs.flow.kernel import FlowConfig, compute_flow_sequence, kernel_name, speed_limit
from robocal.rigs.flow.log import (RunSpec, load_steps, read_poses_csv, write_flow_csv, write_frames_npz,
                                   write_poses_csv)
from robocal.rigs.flow.model import SensorArray, median, seed_array
from robocal.rigs.flow.inputs import load_input  # noqa: F401 (the step, in a light module)
from robocal.rigs.flow.odometry import Odometry, dead_reckon
from robocal.rigs.flow.report import compare_text, display, plot_series, systematic_note  # noqa: F401 (re-exported)

__all__ = ["write_simulation", "judge_run", "odometry_run", "calibration_run", "evaluation_run", "array_yaml",
           "mounted_array", "calibrate_input", "calibration_result", "odometry_result", "evaluation_result",
           "summary", "trajectory_curves", "frames_table", "read_reference", "read_wheel", "load_input", "KERNEL_OPTIONS", "flow_config",
           "check_kernel_options"]

#: The kernel's options (``--subpixel`` ...): they act on raw frames only.
KERNEL_OPTIONS = ("subpixel", "refine", "search", "aggregate")


def flow_config(options: dict, spec: RunSpec | None = None) -> FlowConfig:
    """The kernel configuration of the given options (None: the default), the run's window, ``debias``."""
    d = FlowConfig()
    kw = {k: options[k] if options.get(k) is not None else getattr(d, k) for k in KERNEL_OPTIONS}
    if spec is not None:
        kw["window"] = spec.window
    kw["debias"] = bool(options.get("debias", False))
    return FlowConfig(**kw)


def check_kernel_options(options: dict, spec: RunSpec) -> None:
    """Kernel options act on raw frames only: on a flow log they would be silently ignored."""
    given = [f"--{k}" for k in KERNEL_OPTIONS if options.get(k) is not None]
    if given and spec.frames is None:
        raise InputError(f"{spec.path}: {', '.join(given)} {'acts' if len(given) == 1 else 'act'} on raw frames, but "
                         f"this run gives only a flow log ('flow_log: {spec.flow_log.name}', flow computed by the "
                         "sensors); drop the option(s) or add 'frames'")


def read_reference(spec: RunSpec):
    """The run's reference trajectory ``(t, poses)``, or None when it names none (read once per command:
    0.2 s per 10^5 rows in the core CSV loader; read beside the kernel when :func:`odometry_run` or
    :func:`calibration_run` started it, :mod:`robocal.rigs.flow.background`)."""
    if getattr(spec, "reference_data", None) is not None:  # a recording's reference topic (robocal.rigs.flow.bag)
        return spec.reference_data
    if spec.reference is None:
        return None
    return background.collect(spec, "reference", lambda: read_poses_csv(spec.reference))


def read_wheel(spec: RunSpec):
    """The run's wheel odometry ``(t, poses)`` (the run must name one), read beside the kernel when started."""
    return background.collect(spec, "wheel", lambda: read_poses_csv(spec.wheel))


def mounted_array() -> SensorArray:
    """The seed's rig as built: the drawing's 350 mm / 60, 120, 270 deg with mounting errors."""
    return seed_array().copy(R=np.array([0.356, 0.344, 0.353]), psi=np.radians([61.2, 118.4, 271.0]),
                             phi=np.radians([2.0, -2.5, 3.0]))


def array_yaml(array: SensorArray, camera: dict, extra: dict | None = None) -> str:
    """A ``run.yaml`` text for ``array`` (lengths in mm, angles in deg)."""
    d = {"units": {"length": "mm", "angle": "deg"}, "camera": camera,
         "sensors": [{"name": nm, "R": round(float(r) * 1e3, 4), "psi": round(float(np.degrees(p)), 5),
                      "phi": round(float(np.degrees(f)), 5), "scale": round(float(s), 6)}
                     for nm, r, p, f, s in zip(array.names, array.R, array.psi, array.phi, array.scale)]}
    d.update(extra or {})
    return yaml.safe_dump(d, sort_keys=False)


def write_simulation(run: SimRun, out_dir, *, frames: bool = True, flow_config: FlowConfig = FlowConfig(),
                     progress=None) -> dict:
    """Write a simulated run as user files: run.yaml, flow.csv, [frames.npz], truth.csv, wheel.csv.

    ``flow.csv`` holds what the sensors themselves would report (the kernel's
    raw flow, gyro, height, quality); ``run.yaml`` lists the *nominal* array,
    as a user would start from the drawings.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cfg = run.config
    n, K = run.height.shape
    flow = np.empty((n, K, 2))
    quality = np.empty((n, K))
    it = range(n) if progress is None else progress(range(n), desc="flow")
    for i in it:
        ff = compute_flow_sequence(run.frames[i], flow_config)
        flow[i] = ff.flow_px
        quality[i] = ff.quality
    note = (f"simulated by robocal flow: texture {run.texture_note}; {cfg.trajectory} drive {cfg.duration} s at "
            f"{cfg.camera.rate} Hz; height {cfg.height} m")
    paths = {"flow_log": write_flow_csv(out / "flow.csv", run.t, flow, run.gyro, run.height, quality, comment=note)}
    if frames:
        paths["frames"] = write_frames_npz(out / "frames.npz", run.frames, run.t, run.gyro, run.height)
    paths["reference"] = write_poses_csv(out / "truth.csv", run.t, run.poses, comment="true robot poses (simulation)")
    paths["wheel"] = write_poses_csv(out / "wheel.csv", run.t, run.wheel_poses, comment="wheel odometry with slip")
    cam = {"focal_px": round(cfg.camera.focal_px, 4), "window": cfg.camera.window, "rate": {"value": cfg.camera.rate, "unit": "Hz"},
           "sigma_px": flow_config.sigma_px}
    extra = {k: Path(v).name for k, v in paths.items()}
    paths["run"] = atomic_write_text(out / "run.yaml", array_yaml(cfg.array_nominal, cam, extra))
    truth = array_yaml(cfg.array_true, cam)
    hs = np.ones(n) if cfg.height_scale is None else np.asarray(cfg.height_scale)
    truth += yaml.safe_dump({"true_scale": [round(float(1 / h), 6) for h in hs],
                             "note": "the simulator's true sensor placement; 'true_scale' = 1 / height-scale error"})
    paths["array_true"] = atomic_write_text(out / "array_true.yaml", truth)
    return paths


def judge_run(spec: RunSpec, steps, config: FlowConfig, *, allow_missing: bool = False,
              accept_implausible: bool = False, reference=None) -> list:
    """The run's plausibility (:mod:`robocal.rigs.flow.plausibility`): against its reference when it has
    one, else its heights against the optics. Raises :class:`~robocal.errors.ImplausibleInputError`
    naming the likely slip; with ``accept_implausible`` returns the ``implausible_input`` warning.
    ``reference``: the run's ``(t, poses)`` when already read (:func:`read_reference`)."""
    from dataclasses import replace as _replace

    from robocal.rigs.flow.log import read_flow_csv, steps_from_records
    from robocal.rigs.flow.plausibility import check_height, check_reference

    from_frames = spec.frames is not None                   # load_steps prefers the frames
    height_from = (spec.frames if from_frames else spec.flow_log).name
    src = str(spec.path)
    if spec.reference is not None:
        t_ref, p_ref = reference if reference is not None else read_reference(spec)
        _interp(spec.reference, t_ref, p_ref, steps.t)      # coverage, with the file named
        rescaled = refocused = None
        if not from_frames:
            # the slips' rebuilds from the log's records (read again, once for all the slips: only on an
            # implausible run)
            records = []

            def rebuild(gyro=1.0, focal=spec.focal_px):
                if not records:
                    records.append(getattr(spec, "records", None)
                                   or read_flow_csv(spec.flow_log, spec.array.n, allow_missing=allow_missing))
                rec = records[0]
                return steps_from_records(_replace(rec, gyro=rec.gyro * gyro), focal, config, sigma_px=spec.sigma_px)

            def rescaled(k):
                return rebuild(gyro=k)

            def refocused(f):
                return rebuild(focal=f)
        d = check_reference(steps, t_ref, p_ref, spec.array, height_from=height_from,
                            reference_name=spec.reference.name, rescaled_gyro=rescaled, refocused=refocused,
                            focal_px=spec.focal_px, accept=accept_implausible, source=src)
    elif steps.height is not None:
        d = check_height(steps.height, spec.focal_px, spec.array, height_from=height_from,
                         accept=accept_implausible, source=src)
    else:
        d = None
    return [d] if d is not None else []


def odometry_run(spec: RunSpec, *, config: FlowConfig | None = None, array: SensorArray | None = None,
                 allow_missing: bool = False, robust: bool = True, method: str = "exact", progress=None,
                 accept_implausible: bool = False, reference=None):
    """Dead reckoning of a logged run; returns (Odometry, flows or None, steps).

    The run is judged first (:func:`judge_run`): an implausible one raises
    :class:`~robocal.errors.ImplausibleInputError` unless ``accept_implausible``.
    ``reference``: the run's ``(t, poses)`` when already read.
    """
    config = config or FlowConfig(window=spec.window)
    # the inputs' hashes and the trajectories are read while the kernel runs (they do not depend on it); the
    # CSVs once the kernel starts (robocal.rigs.flow.background)
    background.start(spec, ("inputs",))
    csvs = ("reference", "wheel") if reference is None else ("wheel",)
    steps, flows = load_steps(spec, config, allow_missing=allow_missing, progress=progress,
                              before_kernel=lambda: background.start(spec, csvs))
    judged = judge_run(spec, steps, config, allow_missing=allow_missing, accept_implausible=accept_implausible,
                       reference=reference)
    od = dead_reckon(steps, array or spec.array, robust=robust, method=method)
    od.warnings[:0] = judged
    if flows is not None:
        od.frames["flow_kernel"] = kernel_name()      # which block matcher ran (C or the numba fallback)
        for i, ff in enumerate(flows):
            lim = config.search + 0.5
            fast = np.abs(ff.flow_px[np.isfinite(ff.flow_px[:, 0])]).max(initial=0.0)
            if fast > lim - 0.75:
                od.warnings.append(Diagnostic("degenerate_geometry",
                                              f"sensor {spec.array.names[i]}: flow reached {fast:.2f} px per frame, near the "
                                              f"+/-{config.search} px search range (speed ceiling (S + 0.5) h rate / f); "
                                              "faster motion aliases", params=(spec.array.names[i],)))
    return od, flows, steps


def _interp(path, t_ref, p_ref, t):
    """:func:`interpolate_poses` with errors naming the file."""
    try:
        return interpolate_poses(t_ref, p_ref, t)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None


def evaluation_run(spec: RunSpec, od: Odometry, *, calibrated: Odometry | None = None, reference=None):
    """Errors of flow odometry (and wheel odometry, when logged) against the run's reference.

    Returns ``(curves, errors)``: named ``(N, 3)`` trajectories at the odometry's
    times and named :class:`~robocal.rigs.flow.evaluate.TrajectoryErrors`.
    ``reference``: the run's ``(t, poses)`` when already read.
    """
    if spec.reference is None:
        raise InputError(f"{spec.path}: evaluation needs a 'reference' trajectory file")
    t_ref, p_ref = reference if reference is not None else read_reference(spec)
    ref = _interp(spec.reference, t_ref, p_ref, od.t)
    curves = {"true": ref, "flow odometry": od.poses}
    errors = {"flow odometry": evaluate_trajectory(od.poses, ref)}
    if calibrated is not None:
        curves["flow odometry (calibrated)"] = calibrated.poses
        errors["flow odometry (calibrated)"] = evaluate_trajectory(calibrated.poses, ref)
    if spec.wheel is not None:
        t_w, p_w = read_wheel(spec)
        wheel = _interp(spec.wheel, t_w, p_w, od.t)
        curves["wheel odometry"] = wheel
        errors["wheel odometry"] = evaluate_trajectory(wheel, ref)
    return curves, errors


def trajectory_curves(spec: RunSpec, od: Odometry) -> dict:
    """The trajectories of a run without a reference: flow odometry, and wheel odometry when logged."""
    curves = {"flow odometry": od.poses}
    if spec.wheel is not None:
        t_w, p_w = read_wheel(spec)
        curves["wheel odometry"] = _interp(spec.wheel, t_w, p_w, od.t)
    return curves


def calibration_run(spec: RunSpec, *, config: FlowConfig | None = None, window: float = 0.1, loss: str = "linear",
                    progress=None, accept_implausible: bool = False):
    """Array calibration from a logged run with a reference trajectory (judged first, see :func:`judge_run`)."""
    if spec.reference is None:
        raise InputError(f"{spec.path}: calibration needs a 'reference' trajectory file (t, x, y, theta)")
    config = config or FlowConfig(window=spec.window)
    nominal = spec.array.copy(scale=np.ones(spec.array.n))
    background.start(spec, ("inputs",))
    steps, flows = load_steps(spec, config, progress=progress, before_kernel=lambda: background.start(spec, ("reference",)))
    reference = t_ref, p_ref = read_reference(spec)
    _interp(spec.reference, t_ref, p_ref, steps.t)          # coverage, with the file named
    judged = judge_run(spec, steps, config, accept_implausible=accept_implausible, reference=reference)
    cal = calibrate_array(steps, t_ref, p_ref, nominal, window=window, loss=loss)
    cal.warnings[:0] = judged
    return cal, steps


#: The file ``calibrate`` writes beside result.json: the calibrated array as a ``run.yaml`` sensor list.
ARRAY_FILE = "array_calibrated.yaml"


def calibrate_input(spec: RunSpec, *, out_dir=None, progress: bool = False, accept_implausible: bool = False,
                    window: float = 0.1, loss: str = "linear", no_progress: bool = False, **kernel_options):
    """``robocal flow calibrate``'s calibrate step: :func:`calibration_run` on a loaded ``run.yaml``.

    ``kernel_options``: ``subpixel``, ``refine``, ``search``, ``aggregate``
    (raw frames only; None = default) and ``debias``. With ``out_dir``, the
    calibrated array is also written there as :data:`ARRAY_FILE` (lengths mm,
    angles deg, the run's camera block). Returns the
    :class:`~robocal.rigs.flow.calibrate.ArrayCalibration` with ``spec`` and
    ``window`` attached for :func:`calibration_result`.
    """
    from robocal.progress import progress as bar

    if not np.isfinite(window) or window <= 0:
        raise InputError(f"--window must be > 0 s, got {window}")
    check_kernel_options(kernel_options, spec)
    show = progress and not no_progress
    # a stage bar on a terminal for long runs (10^6 log rows: minutes, mostly reading)
    stages = iter(bar(range(2), desc="flow calibrate: read, judge, fit; report", total=2, enabled=show))
    next(stages, None)
    cal, _ = calibration_run(spec, config=flow_config(kernel_options, spec), window=window, loss=loss,
                             progress=lambda it, desc: bar(it, desc=desc, enabled=show),
                             accept_implausible=accept_implausible)
    next(stages, None)
    if out_dir is not None:
        cam = {"focal_px": spec.focal_px, "window": spec.window}
        if spec.rate is not None:
            cam["rate"] = {"value": spec.rate, "unit": "Hz"}
        extra = {"undetermined_kept_nominal": list(cal.undetermined)} if cal.undetermined else None
        atomic_write_text(Path(out_dir) / ARRAY_FILE, array_yaml(cal.array, cam, extra))
        cal.array_file = ARRAY_FILE
    return cal


def calibration_result(cal, spec: RunSpec | None = None, *, method: str = "windowed-lsq") -> CalibrationResult:
    """The shared result schema: ``std`` is the statistical std (segment jackknife, see
    :func:`~robocal.rigs.flow.calibrate.calibrate_array`); the kernel systematic, their
    combination, the parameters kept at nominal, the window residuals and the solver's
    record are in ``diagnostics`` (what :func:`robocal.rigs.flow.report.calibration_report` draws)."""
    keys = cal.estimate_dict()
    windows = {nm: {"t": cal.window_times[nm], "residual": cal.lsq.obs_residuals(nm)} for nm in cal.array.names}
    diag = {"undetermined_kept_nominal": list(cal.undetermined),
            "std_systematic_kernel": {k: cal.systematic.get(k) for k in keys},
            "std_systematic_kernel_source": cal.systematic_source,
            "kernel_debiased": cal.array_debiased is not None and cal.array_debiased is cal.array,
            "estimate_kernel_debiased": (None if cal.array_debiased is None else array_estimate(cal.array_debiased)),
            "std_total": cal.total_std(),
            "std_model_white_noise": {k: cal.std_model.get(k) for k in keys},
            "std_jackknife": {k: cal.std_jackknife.get(k) for k in keys},
            "windows_per_sensor": cal.n_windows.tolist(), "iterations": cal.lsq.iterations,
            "condition_number": cal.lsq.condition_number, "cost_history": cal.lsq.cost_history,
            "window_s": cal.window, "window_residuals": windows, "solver": cal.lsq.to_dict()}
    if cal.array_file:
        diag["array_file"] = cal.array_file
    if getattr(spec, "notes", None):  # a recording's: topics, intervals, clock used (robocal.rigs.flow.bag)
        diag["messages"] = list(spec.notes)
    return CalibrationResult(
        rig="flow", method=method, estimate=keys,
        std={k: cal.std.get(k) for k in keys}, units=cal.units(),
        residual_rms=cal.residual_rms, residual_unit="m",
        warnings=list(cal.warnings) + list(getattr(spec, "warnings", ())),  # a recording's clock_mismatch
        inputs=background.inputs_hash(spec) if spec is not None else {}, diagnostics=diag)


def summary(result: CalibrationResult) -> str:
    """The lines ``robocal flow calibrate`` prints: each parameter with its statistical and kernel std."""
    d = result.diagnostics
    und = set(d.get("undetermined_kept_nominal") or ())
    sysk = d.get("std_systematic_kernel") or {}
    lines = [f"wrote {d['array_file']} (beside result.json)"] if d.get("array_file") else []
    lines.append(f"  {'parameter':14s} {'value':>10s} {'unit':5s} +/- statistical  +/- kernel systematic")
    for k, v in result.estimate.items():
        conv, u = display(result.units[k])
        if k in und:
            lines.append(f"  {k:14s} {conv(v):10.4f} {u:5s} not determined by this drive (kept nominal)")
        else:
            lines.append(f"  {k:14s} {conv(v):10.4f} {u:5s} +/- {conv(result.std[k]):<12.4f} +/- {conv(sysk[k]):.4f}")
    how = systematic_note(d.get("std_systematic_kernel_source", "constant"), bool(d.get("kernel_debiased")))
    lines.append(f"  kernel systematic: {how}")
    return "\n".join([f"note: {m}" for m in d.get("messages") or []] + lines)


def frames_table(od: Odometry) -> list:
    """Per sensor: frames without a valid flow, by reason, and steps left out as outliers."""
    n_steps = len(od.twists)
    return [{"sensor": nm, "frames without flow": c, "of": n_steps,
             "reasons": ", ".join(f"{r} {k}" for r, k in od.frames["invalid_by_reason"][nm].items()) or "-",
             "left out as outlier": int(od.rejected[i].sum())}
            for i, (nm, c) in enumerate(od.frames["invalid_frames"].items())]


def odometry_result(od: Odometry, spec: RunSpec, errors: dict | None = None, *, curves: dict | None = None,
                    steps=None) -> CalibrationResult:
    """``robocal flow odometry``'s result; with ``curves`` and ``steps`` also what its report draws."""
    est = {"final_pose": od.poses[-1], "distance": od.summary()["distance_m"],
           "mean_speed": float(np.mean(np.linalg.norm(od.velocity[:, :2], axis=1)))}
    units = {"final_pose": "m, m, rad", "distance": "m", "mean_speed": "m/s"}
    from robocal.rigs.flow.odometry import final_pose_covariance

    # The last pose's std under the fusion's white-noise model (NaN -> None when a step was bridged) is
    # a diagnostic, not the pose's std: the array geometry's error and the kernel's time-correlated
    # bias dominate a drive's drift and are not in it (the loop example ends 15.5 mm / 1.1 deg off,
    # 18 / 9 times this std), so `std.final_pose` stays None: the run alone does not determine it.
    std_white = np.sqrt(np.abs(np.diag(final_pose_covariance(od.poses, od.twists, od.twist_cov,
                                                             method=od.method))))
    # np.nanmedian per column, without its numpy.ma import (model.median)
    vstd = np.array([median(c[~np.isnan(c)]) for c in od.velocity_std.T])
    diag = {"summary": od.summary(), "velocity_std_median": vstd,
            "final_pose_std_white_noise": std_white}
    if errors:
        diag["evaluation"] = {k: v.to_dict() for k, v in errors.items()}
        fo = errors.get("flow odometry")
        if fo is not None:
            est["ate_rmse"] = fo.ate_rmse
            units["ate_rmse"] = "m"
    diag["frames_without_flow"] = frames_table(od)
    diag["plots"] = plot_series(od, steps, spec.array.names, curves)
    return CalibrationResult(rig="flow", method="multi-sensor-lsq", estimate=est, units=units,
                             std={"final_pose": None}, warnings=list(od.warnings),
                             inputs=background.inputs_hash(spec), diagnostics=diag)


def evaluation_result(od: Odometry, spec: RunSpec, curves: dict, errors: dict,
                      calibrated: Odometry | None = None) -> CalibrationResult:
    """``robocal flow evaluate``'s result: ATE per trajectory, the full errors and the plotted curves."""
    warnings = list(od.warnings) + ([w for w in calibrated.warnings if w not in od.warnings] if calibrated else [])
    diag = {"evaluation": {k: v.to_dict() for k, v in errors.items()}, "plots": plot_series(curves=curves)}
    return CalibrationResult(rig="flow", method="ate-rpe", estimate={f"{k} ATE": v.ate_rmse for k, v in errors.items()},
                             units={f"{k} ATE": "m" for k in errors}, warnings=warnings,
                             inputs=background.inputs_hash(spec), diagnostics=diag)


def speed_ceiling(config: FlowConfig, height: float, rate: float, focal_px: float) -> float:
    return speed_limit(config, height, rate, focal_px)


def default_sim(trajectory: str = "loop", duration: float = 8.0, **kw) -> SimConfig:
    """The seed's rig with mounting errors and per-sensor height-scale errors (a sonar is never exact)."""
    from robocal.rigs.flow.simulate import SimConfig  # here: the simulator's renderer imports numba

    base = dict(array_true=mounted_array(), height_scale=(0.99, 1.02, 1.04), trajectory=trajectory, duration=duration)
    base.update(kw)
    return SimConfig(**base)
