"""End-to-end workflows behind the CLI: simulate -> files, odometry, calibration, evaluation.

Each returns plain result objects (and a :class:`~robocal.io.CalibrationResult`
plus report sections) so everything the CLI does can be done from Python.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from robocal.diagnostics import Diagnostic
from robocal.io import CalibrationResult, atomic_write_text, hash_inputs
from robocal.report import Report, new_figure
from robocal.rigs.flow.calibrate import array_estimate, calibrate_array, interpolate_poses
from robocal.rigs.flow.evaluate import evaluate_trajectory, plot_trajectories
from robocal.rigs.flow.kernel import FlowConfig, compute_flow_sequence, speed_limit
from robocal.rigs.flow.log import RunSpec, load_steps, read_poses_csv, write_flow_csv, write_poses_csv
from robocal.rigs.flow.model import SensorArray, seed_array
from robocal.rigs.flow.odometry import Odometry, dead_reckon
from robocal.rigs.flow.simulate import SimConfig, SimRun, simulate_run

__all__ = ["write_simulation", "judge_run", "odometry_run", "calibration_run", "evaluation_run", "array_yaml", "mounted_array"]


def _read_poses(path):
    """:func:`read_poses_csv`, read once per file version: the plausibility check, the calibration and
    the evaluation all need the reference (1.5 s per 10^5 rows in the core CSV loader)."""
    p = Path(path)
    st = p.stat()
    key = (str(p.resolve()), st.st_mtime_ns, st.st_size)
    if _POSES_CACHE.get("key") != key:
        _POSES_CACHE.clear()
        _POSES_CACHE.update(key=key, value=read_poses_csv(p))
    t, poses = _POSES_CACHE["value"]
    return t.copy(), poses.copy()


_POSES_CACHE: dict = {}

#: most points a figure line gets: a 10^6-row log's velocity figure took minutes to draw in full
_PLOT_POINTS = 5000


def _every(n: int) -> int:
    return max(1, -(-n // _PLOT_POINTS))


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
        buf = out / "frames.npz"
        np.savez_compressed(buf, frames=run.frames, t=run.t, gyro=run.gyro, height=run.height)
        paths["frames"] = buf
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
              accept_implausible: bool = False) -> list:
    """The run's plausibility (:mod:`robocal.rigs.flow.plausibility`): against its reference when it has
    one, else its heights against the optics. Raises :class:`~robocal.errors.ImplausibleInputError`
    naming the likely slip; with ``accept_implausible`` returns the ``implausible_input`` warning."""
    from dataclasses import replace as _replace

    from robocal.rigs.flow.log import read_flow_csv, steps_from_records
    from robocal.rigs.flow.plausibility import check_height, check_reference

    from_frames = spec.frames is not None                   # load_steps prefers the frames
    height_from = (spec.frames if from_frames else spec.flow_log).name
    src = str(spec.path)
    if spec.reference is not None:
        t_ref, p_ref = _read_poses(spec.reference)
        _interp(spec.reference, t_ref, p_ref, steps.t)      # coverage, with the file named
        rescaled = refocused = None
        if not from_frames:
            # the slips' rebuilds from the log's records (read again, once for all the slips: only on an
            # implausible run)
            records = []

            def rebuild(gyro=1.0, focal=spec.focal_px):
                if not records:
                    records.append(read_flow_csv(spec.flow_log, spec.array.n, allow_missing=allow_missing))
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
                 accept_implausible: bool = False):
    """Dead reckoning of a logged run; returns (Odometry, flows or None, steps).

    The run is judged first (:func:`judge_run`): an implausible one raises
    :class:`~robocal.errors.ImplausibleInputError` unless ``accept_implausible``.
    """
    config = config or FlowConfig(window=spec.window)
    steps, flows = load_steps(spec, config, allow_missing=allow_missing, progress=progress)
    judged = judge_run(spec, steps, config, allow_missing=allow_missing, accept_implausible=accept_implausible)
    od = dead_reckon(steps, array or spec.array, robust=robust, method=method)
    od.warnings[:0] = judged
    if flows is not None:
        for i, ff in enumerate(flows):
            lim = config.search + 0.5
            fast = np.abs(ff.flow_px[np.isfinite(ff.flow_px[:, 0])]).max(initial=0.0)
            if fast > lim - 0.75:
                od.warnings.append(Diagnostic("degenerate_geometry",
                                              f"sensor {spec.array.names[i]}: flow reached {fast:.2f} px per frame, near the "
                                              f"+/-{config.search} px search range (speed ceiling (S + 0.5) h rate / f); "
                                              "faster motion aliases", params=(spec.array.names[i],)))
    return od, flows, steps


def _traj_section(report: Report, title: str, curves: dict, errors: dict) -> None:
    sec = report.section(title)
    fig, ax = new_figure(size=(6.0, 5.0))
    k = _every(max(len(c) for c in curves.values()))
    plot_trajectories({n: np.concatenate([c[::k], c[-1:]]) for n, c in ((n, np.asarray(c)) for n, c in curves.items())},
                      ax=ax, title="true / flow odometry / wheel odometry (cf. seed Fig. 4)")
    sec.figure(fig, "Trajectories in the world frame; dots mark the end.")
    rows = []
    first = next(iter(errors.values()), None)
    label = first.rpe_label() if first is not None else "RPE@0.5m"
    seg = f"{first.rpe_headline:g} m" if first is not None and first.rpe_headline is not None else "0.5 m"
    for name, ev in errors.items():
        r1 = ev.headline_rpe()
        rows.append({"trajectory": name, "ATE [mm]": ev.ate_rmse * 1e3, "final error [mm]": ev.final_error * 1e3,
                     "final heading [deg]": np.degrees(ev.heading_error_final),
                     f"{label} [%]": r1["trans_per_m"] * 100, "RPE rot [deg/m]": np.degrees(r1["rot_per_m"])})
    sec.table(rows, digits=4, caption="ATE: RMS position error after least-squares rigid 2D alignment (Umeyama); "
              f"RPE: RMS over all segment starts of the relative pose error over {seg} of travelled path "
              "(translation error per metre of path, rotation error per metre; other lengths, mean and median in "
              "result.json).")
    for note in dict.fromkeys(ev.rpe_note for ev in errors.values() if ev.rpe_note):
        sec.text(f"Note: {note}.")
    cal, nom = errors.get("flow odometry (calibrated)"), errors.get("flow odometry")
    if cal is not None and nom is not None:
        sec.text(compare_text(nom, cal))


def compare_text(nom, cal) -> str:
    """One line: calibrated vs nominal array in ATE and the headline RPE (0.5 m), saying which got worse."""
    def word(a, b):
        return "better" if b < a else "WORSE" if b > a else "same"

    rn, rc = nom.headline_rpe(), cal.headline_rpe()
    tn, tc = rn["trans_per_m"], rc["trans_per_m"]
    on, oc = np.degrees(rn["rot_per_m"]), np.degrees(rc["rot_per_m"])
    ate = (f"calibrated vs nominal array: ATE {nom.ate_rmse * 1e3:.1f} -> {cal.ate_rmse * 1e3:.1f} mm "
           f"({word(nom.ate_rmse, cal.ate_rmse)})")
    if not (rn["n"] and rc["n"]):
        return ate + "; no RPE (the reference path is too short)"
    return (ate + f"; {nom.rpe_label()} {tn * 100:.2f} -> {tc * 100:.2f} % ({word(tn, tc)}), "
            f"{on:.2f} -> {oc:.2f} deg/m ({word(on, oc)})")


def _interp(path, t_ref, p_ref, t):
    """:func:`interpolate_poses` with errors naming the file."""
    from robocal.errors import InputError

    try:
        return interpolate_poses(t_ref, p_ref, t)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None


def evaluation_run(spec: RunSpec, od: Odometry, *, calibrated: Odometry | None = None):
    """Errors of flow odometry (and wheel odometry, when logged) against the run's reference."""
    if spec.reference is None:
        from robocal.errors import InputError

        raise InputError(f"{spec.path}: evaluation needs a 'reference' trajectory file")
    t_ref, p_ref = _read_poses(spec.reference)
    ref = _interp(spec.reference, t_ref, p_ref, od.t)
    curves = {"true": ref, "flow odometry": od.poses}
    errors = {"flow odometry": evaluate_trajectory(od.poses, ref)}
    if calibrated is not None:
        curves["flow odometry (calibrated)"] = calibrated.poses
        errors["flow odometry (calibrated)"] = evaluate_trajectory(calibrated.poses, ref)
    if spec.wheel is not None:
        t_w, p_w = read_poses_csv(spec.wheel)
        wheel = _interp(spec.wheel, t_w, p_w, od.t)
        curves["wheel odometry"] = wheel
        errors["wheel odometry"] = evaluate_trajectory(wheel, ref)
    return curves, errors


def calibration_run(spec: RunSpec, *, config: FlowConfig | None = None, window: float = 0.1, loss: str = "linear",
                    progress=None, accept_implausible: bool = False):
    """Array calibration from a logged run with a reference trajectory (judged first, see :func:`judge_run`)."""
    from robocal.errors import InputError

    if spec.reference is None:
        raise InputError(f"{spec.path}: calibration needs a 'reference' trajectory file (t, x, y, theta)")
    config = config or FlowConfig(window=spec.window)
    nominal = spec.array.copy(scale=np.ones(spec.array.n))
    steps, flows = load_steps(spec, config, progress=progress)
    t_ref, p_ref = _read_poses(spec.reference)
    _interp(spec.reference, t_ref, p_ref, steps.t)          # coverage, with the file named
    judged = judge_run(spec, steps, config, accept_implausible=accept_implausible)
    cal = calibrate_array(steps, t_ref, p_ref, nominal, window=window, loss=loss)
    cal.warnings[:0] = judged
    return cal, steps


def calibration_result(cal, spec: RunSpec | None = None, *, method: str = "windowed-lsq") -> CalibrationResult:
    """The shared result schema: ``std`` is the statistical std (segment jackknife, see
    :func:`~robocal.rigs.flow.calibrate.calibrate_array`); the kernel systematic, their
    combination and the parameters kept at nominal are in ``diagnostics``."""
    keys = cal.estimate_dict()
    return CalibrationResult(
        rig="flow", method=method, estimate=keys,
        std={k: cal.std.get(k) for k in keys}, units=cal.units(),
        residual_rms=cal.residual_rms, residual_unit="m", warnings=list(cal.warnings),
        inputs=hash_inputs(spec.inputs()) if spec is not None else {},
        diagnostics={"undetermined_kept_nominal": list(cal.undetermined),
                     "std_systematic_kernel": {k: cal.systematic.get(k) for k in keys},
                     "std_systematic_kernel_source": cal.systematic_source,
                     "estimate_kernel_debiased": (None if cal.array_debiased is None else array_estimate(cal.array_debiased)),
                     "std_total": cal.total_std(),
                     "std_model_white_noise": {k: cal.std_model.get(k) for k in keys},
                     "std_jackknife": {k: cal.std_jackknife.get(k) for k in keys},
                     "windows_per_sensor": cal.n_windows.tolist(), "iterations": cal.lsq.iterations,
                     "condition_number": cal.lsq.condition_number, "cost_history": cal.lsq.cost_history},
    )


def odometry_result(od: Odometry, spec: RunSpec, errors: dict | None = None) -> CalibrationResult:
    est = {"final_pose": od.poses[-1], "distance": od.summary()["distance_m"],
           "mean_speed": float(np.mean(np.linalg.norm(od.velocity[:, :2], axis=1)))}
    units = {"final_pose": "m, m, rad", "distance": "m", "mean_speed": "m/s"}
    diag = {"summary": od.summary(), "velocity_std_median": np.nanmedian(od.velocity_std, axis=0)}
    if errors:
        diag["evaluation"] = {k: v.to_dict() for k, v in errors.items()}
        fo = errors.get("flow odometry")
        if fo is not None:
            est["ate_rmse"] = fo.ate_rmse
            units["ate_rmse"] = "m"
    return CalibrationResult(rig="flow", method="multi-sensor-lsq", estimate=est, units=units,
                             std={"final_pose": None}, warnings=list(od.warnings),
                             inputs=hash_inputs(spec.inputs()), diagnostics=diag)


def velocity_figure(od: Odometry):
    fig, axs = new_figure(3, 1, size=(6.4, 5.5), sharex=True)
    k = _every(len(od.t) - 1)                                # drawn every k-th interval on long runs
    tm = (0.5 * (od.t[1:] + od.t[:-1]))[::k]
    for a, lab in enumerate(("vx [m/s]", "vy [m/s]", "omega [rad/s]")):
        v, s = od.velocity[::k, a], od.velocity_std[::k, a]
        axs[a].plot(tm, v, lw=0.6)
        axs[a].fill_between(tm, v - 3 * s, v + 3 * s, alpha=0.3, lw=0)
        axs[a].set_ylabel(lab)
    axs[-1].set_xlabel("t [s]")
    fig.suptitle("robot velocity from the array, +/-3 sigma band from the geometry")
    return fig


def quality_figure(steps, names):
    fig, ax = new_figure(size=(6.4, 3.0))
    k = _every(len(steps.t) - 1)
    tm = steps.t[1:][::k]
    for i, nm in enumerate(names):
        ax.plot(tm, steps.quality[i][::k], lw=0.7, label=nm)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("quality (0..255)")
    ax.legend(fontsize=8)
    return fig


def speed_ceiling(config: FlowConfig, height: float, rate: float, focal_px: float) -> float:
    return speed_limit(config, height, rate, focal_px)


def default_sim(trajectory: str = "loop", duration: float = 8.0, **kw) -> SimConfig:
    """The seed's rig with mounting errors and per-sensor height-scale errors (a sonar is never exact)."""
    base = dict(array_true=mounted_array(), height_scale=(0.99, 1.02, 1.04), trajectory=trajectory, duration=duration)
    base.update(kw)
    return SimConfig(**base)
